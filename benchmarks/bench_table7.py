"""Our Table 7: per-frame generation and tracking times of each feature beside the paper's (its Table 7).

Usage::

    python benchmarks/bench_table7.py [--frames 100] [--features gray,bitplanes,alexnet,alexnet-pca8]
                                      [--learned] [--warmup-frames 10] [--repeat 1] [--threads N]
                                      [--alexnet-weights auto|random|PATH] [--calib-frames 5]
                                      [--sequence DIR] [--out out/benchmarks/table7]
                                      [--device cpu|cuda|cuda:N]

What it measures
----------------
For each feature, after an untimed warm-up run of ``--warmup-frames`` frames (numba compilation / cache loading),
``--repeat`` runs of :func:`bench_vo.staged_run` — the loop of :func:`dmtrack.api.track` written out
sequentially with a timer around every stage — on the first ``--frames`` frames of the repository's sample
sequence (7-Scenes redkitchen, 640×480).  Per frame and stage the minimum over repeats is taken, then the mean
over frames (the paper's "average times").  Columns, per frame:

* **Generation** = decode (JPEG read + decode + crop) + feature (``feature.compute``, or ``compute_pyramid``
  for features whose pyramid is recomputed) — the paper's generation column "also accounts for file I/O,
  undistortion, and cropping";
* **Tracking** = the tracking thread's work on the frame: pyramid (:func:`build_frame`) + reference rebuild +
  LM tracking + bookkeeping;
* **Total** = Generation + Tracking and **fps** = 1000 / Total, as the paper's Table 7 (LSD-SLAM maps in a
  separate thread, so mapping is not in its total);
* **Mapping** = depth-map update + keyframe creation, amortised per frame (reported; not in Total), and
  **Seq. total** = Total + Mapping, the time per frame of this sequential loop;
* **Faster than paper?** — our Total < the paper's Total.

The paper's machine: Intel i7-4790K (4 cores, 4 GHz) + GTX 1080 (features on the GPU); ours is printed with the
table (CPU, cores, versions, load average before/after — on a shared machine compare with care).

Features and their configuration
--------------------------------
Default features: gray, gray-affine, bitplanes, dsift, alexnet, alexnet-pca64/32/16/8/4/2/1; ``--learned`` adds
tfeat and disk (seconds per frame; disk needs PyTorch).  Everything runs with the packaged default scales:
``$DMTRACK_HOME`` is pointed to a temporary directory, so the user's calibrated scales and PCA bases are not used.

AlexNet's weights cannot be shipped.  With ``--alexnet-weights auto`` (default) the installed BVLC weights are
used if found, otherwise — and always with ``random`` — seeded random weights of the real shapes (conv1 weight
(96, 3, 11, 11), bias (96,); :func:`bench_features.random_alexnet_weights`) are written to the temporary
directory.  Their rows are labelled "random weights of the real shape (timing proxy)": the generation time does
not depend on the weights, the tracking time does (through the map's texture), so those tracking numbers are
indicative only.  With random weights the feature scale is calibrated like the paper's default scales
(:func:`dmtrack.features.scale.calibrate_scale`: same number of semi-dense pixels as grey) on ``--calib-frames``
frames spread over the sequence; with the real weights the paper's 1.23 is kept.  The alexnet-pcaK rows use a
PCA basis (:func:`dmtrack.features.pca.fit_pca`) fitted on the same frames, applied as the fused 1×1 projection;
their scales are calibrated the same way (``--pca-scale 1``: the library's default, 1).  Scales and basis are
stored in the temporary ``$DMTRACK_HOME`` (``scales.json``, ``pca/alexnet.npz``), where
:func:`dmtrack.features.get_feature` — and so ``staged_run`` — finds them.  If tracking is lost at frame i (this
happens with random weights), the feature is timed on its first i frames and the row says so.

On a GPU
--------
``--device cuda`` computes the network features (alexnet and alexnet-pcaK, tfeat, disk, tracknet, siamese) on the
GPU (:mod:`dmtrack.features.device`): Generation then includes the upload of the image, the network, the PCA
projection on the device and the transfer of the K-channel map into pinned host memory (each frame is synchronised
before its timer stops).  The hand-crafted features (gray, bitplanes, dsift) run on the CPU either way; their rows
say so.  ``--device cpu`` (the default) is the CPU kernels; the GPU's name is stored with the results.

Results: ``OUT.json`` (every stage, per-frame means/medians, machine, settings) and ``OUT.md`` (the table).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_features import random_alexnet_weights  # noqa: E402
from bench_vo import STAGES, staged_run  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DEFAULT_SEQUENCE = REPO / "data" / "7scenes-redkitchen-0000-0299"
DEFAULT_FEATURES = ("gray", "gray-affine", "bitplanes", "dsift", "alexnet") + tuple(
    f"alexnet-pca{k}" for k in (64, 32, 16, 8, 4, 2, 1)
)
LEARNED = ("tfeat", "disk")

#: The paper's Table 7: (label, generation ms, tracking ms, total ms, total fps) — TUM DSO, i7-4790K + GTX 1080.
PAPER: dict[str, tuple[str, float, float, float, float]] = {
    "gray": ("Gray (1D)", 10.0, 20.0, 30.0, 33.0),
    "gray-affine": ("Gray-A (1D)", 10.0, 21.0, 31.0, 32.0),
    "bitplanes": ("Bit-Planes (8D)", 20.0, 120.0, 140.0, 7.0),
    "dsift": ("SIFT (128D)", 530.0, 740.0, 1270.0, 1.0),
    "siamese": ("Siamese (256D)", 8000.0, 1000.0, 9000.0, 1.0 / 9.0),
    "alexnet": ("AlexNet (96D)", 79.0, 430.0, 509.0, 2.0),
    "alexnet-pca64": ("AlexNet-64D", 61.0, 270.0, 331.0, 3.0),
    "alexnet-pca32": ("AlexNet-32D", 40.0, 150.0, 190.0, 5.0),
    "alexnet-pca16": ("AlexNet-16D", 29.0, 76.0, 105.0, 10.0),
    "alexnet-pca8": ("AlexNet-8D", 24.0, 36.0, 60.0, 17.0),
    "alexnet-pca4": ("AlexNet-4D", 22.0, 23.0, 45.0, 22.0),
    "alexnet-pca2": ("AlexNet-2D", 21.0, 21.0, 42.0, 24.0),
    "alexnet-pca1": ("AlexNet-1D", 20.0, 20.0, 40.0, 25.0),
}
GENERATION = ("decode", "feature")
TRACKING = ("pyramid", "reference", "tracking", "other")
MAPPING = ("map_update", "keyframe")
RANDOM_LABEL = "random weights of the real shape (timing proxy)"


def _load() -> list[float]:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:  # pragma: no cover - platform without getloadavg
        return []


def machine_info() -> dict:
    """CPU model, core counts and library versions of this machine."""
    import cv2
    import numba
    import scipy

    cpu = platform.processor() or platform.machine()
    flags: set[str] = set()
    try:
        text = Path("/proc/cpuinfo").read_text()
        for line in text.splitlines():
            if line.startswith("model name") and cpu in ("", platform.machine()):
                cpu = line.split(":", 1)[1].strip()
            elif line.startswith("flags") and not flags:
                flags = set(line.split(":", 1)[1].split())
    except OSError:
        pass
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        affinity = os.cpu_count()
    try:
        import torch

        torch_version = f"{torch.__version__} ({torch.get_num_threads()} threads)"
    except ImportError:
        torch_version = "not installed"
    return {
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "usable_cpus": affinity,
        "simd": [f for f in ("avx2", "fma", "avx512f") if f in flags],
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": f"{numba.__version__} ({numba.get_num_threads()} threads, layer {numba.config.THREADING_LAYER})",
        "opencv": f"{cv2.__version__} ({cv2.getNumThreads()} threads)",
        "torch": torch_version,
        "platform": platform.platform(),
    }


def setup_alexnet(
    names: list[str], sequence: Path, weights: str, calib_frames: int, tmp: Path, pca_scale: str = "calibrate",
    device: str = "cpu",
) -> dict:
    """Make ``get_feature("alexnet")`` / ``("alexnet-pcaK")`` work without user files (see the module docs).

    Sets ``$DMTRACK_WEIGHTS`` (random weights) and writes the calibrated scale and the PCA basis into the
    temporary ``$DMTRACK_HOME``.  Returns a description stored with the results.
    """
    from dmtrack.errors import InputError
    from dmtrack.features import get_feature as _get_feature
    from dmtrack.features.base import save_user_scale, user_pca_path
    from dmtrack.features.pca import fit_pca
    from dmtrack.features.scale import calibrate_scale_detailed
    from dmtrack.features.weights import find_weights
    from dmtrack.io.images import read_image

    def get_feature(name: str):  # noqa: ANN202 - on the bench's device
        return _get_feature(name, device=device)

    path: Path | None = None
    if weights == "auto":
        try:
            path = find_weights("alexnet")
        except InputError:
            path = None
    elif weights != "random":
        path = Path(weights)
    info: dict = {}
    if path is None:
        wdir = tmp / "weights"
        wdir.mkdir(parents=True, exist_ok=True)
        src = random_alexnet_weights(wdir)
        src.rename(wdir / "alexnet-conv1.npz")  # a file name find_weights("alexnet") accepts
        os.environ["DMTRACK_WEIGHTS"] = str(wdir)
        info["weights"] = RANDOM_LABEL
    else:
        wdir = tmp / "weights"
        wdir.mkdir(parents=True, exist_ok=True)
        shutil.copy(path, wdir / path.name)
        os.environ["DMTRACK_WEIGHTS"] = str(wdir)
        info["weights"] = str(path)
    frames = sorted(sequence.glob("*.color.jpg")) or sorted(sequence.glob("*.png"))
    step = max(1, len(frames) // max(1, calib_frames))
    sample = [read_image(p) for p in frames[::step][:calib_frames]]
    info["calibration_frames"] = [p.name for p in frames[::step][:calib_frames]]
    if path is None:
        t0 = time.perf_counter()
        cal = calibrate_scale_detailed(get_feature("alexnet"), sample)
        save_user_scale("alexnet", cal.scale, note="bench_table7: " + RANDOM_LABEL)
        info["scale"] = cal.scale
        info["scale_target_count"] = cal.target_count
        info["scale_achieved_count"] = cal.achieved_count
        info["calibration_s"] = round(time.perf_counter() - t0, 1)
    else:
        info["scale"] = get_feature("alexnet").scale
    if any(n.startswith("alexnet-pca") for n in names):
        t0 = time.perf_counter()
        basis = fit_pca(get_feature("alexnet"), sample, n_samples=100_000, seed=0)
        out = user_pca_path("alexnet")
        out.parent.mkdir(parents=True, exist_ok=True)
        basis.save(out)
        info["pca_fit_s"] = round(time.perf_counter() - t0, 1)
        info["pca_explained_variance_ratio"] = {
            str(k): round(float(basis.explained_variance_ratio[:k].sum()), 4) for k in (1, 2, 4, 8, 16, 32, 64)
        }
        info["pca_scales"] = {}
        for n in names:
            if n.startswith("alexnet-pca") and pca_scale == "calibrate":
                cal = calibrate_scale_detailed(get_feature(n), sample)
                save_user_scale(n, cal.scale, note="bench_table7")
                info["pca_scales"][n] = round(cal.scale, 4)
            elif n.startswith("alexnet-pca"):
                info["pca_scales"][n] = get_feature(n).scale
    return info


def _lost_frame(exc: SystemExit) -> int | None:
    """The frame index of ``staged_run``'s "tracking lost at frame i: ..." exit, else None."""
    m = re.match(r"tracking lost at frame (\d+)", str(exc.code))
    return int(m.group(1)) if m else None


def run_feature(name: str, sequence: str, frames: int, warmup: int, repeat: int, device: str = "cpu") -> dict:
    """Warm-up + ``repeat`` staged runs of one feature; per-frame minimum over repeats, then frame statistics.

    If tracking is lost at frame i (runs are deterministic), the runs are repeated on the first i frames and
    ``lost_at`` records i.
    """
    t0 = time.perf_counter()
    try:
        staged_run(sequence, name, warmup, device)
    except SystemExit as exc:
        if _lost_frame(exc) is None:
            raise
    warm_s = time.perf_counter() - t0
    per_frame: dict[str, np.ndarray] | None = None
    hashes, kfs = [], []
    lost_at = None
    for _ in range(repeat):
        try:
            t, _total, h, n_kf = staged_run(sequence, name, frames, device)
        except SystemExit as exc:
            lost_at = _lost_frame(exc)
            if lost_at is None or lost_at < 2:
                raise
            frames = lost_at
            print(f"{name}: tracking lost at frame {lost_at}; timing the first {lost_at} frames", flush=True)
            t, _total, h, n_kf = staged_run(sequence, name, frames, device)
        hashes.append(h)
        kfs.append(n_kf)
        per_frame = t if per_frame is None else {s: np.minimum(per_frame[s][:frames], t[s]) for s in STAGES}
    assert per_frame is not None
    n = len(per_frame["feature"])
    gen = sum(per_frame[s] for s in GENERATION)
    trk = sum(per_frame[s] for s in TRACKING)
    mapping = sum(per_frame[s] for s in MAPPING)
    total = gen + trk

    def stat(a: np.ndarray) -> dict[str, float]:
        return {"mean": float(a.mean()), "median": float(np.median(a)), "min": float(a.min()), "max": float(a.max())}

    return {
        "frames": n,
        "warmup_s": round(warm_s, 1),
        "generation_ms": stat(gen),
        "tracking_ms": stat(trk),
        "total_ms": stat(total),
        "mapping_ms": stat(mapping),
        "sequential_total_ms": stat(total + mapping),
        "fps": 1000.0 / float(total.mean()),
        "stages_mean_ms": {s: float(per_frame[s].mean()) for s in STAGES},
        "stages_median_ms": {s: float(np.median(per_frame[s])) for s in STAGES},
        "keyframes": kfs[0],
        "trajectory_hash": hashes[0],
        "deterministic": len(set(hashes)) == 1,
        "lost_at": lost_at,
    }


def _device_lines(doc: dict) -> list[str]:
    """Where the network features ran (``--device``), with the GPU's name."""
    device = doc.get("device", "cpu")
    if device == "cpu":
        return []
    gpu = doc.get("gpu") or {}
    names = ", ".join(gpu.get("devices") or []) or "?"
    return [f"Network features on **{device}** ({names}; PyTorch {gpu.get('torch')}, CUDA {gpu.get('cuda')}): "
            "their Generation includes the image upload, the network, the PCA projection on the GPU and the "
            "transfer into pinned host memory; gray, gray-affine, bitplanes and dsift run on the CPU.", ""]


def markdown(doc: dict) -> str:
    """The table of ``doc`` (see :func:`main`) as Markdown."""
    m = doc["machine"]
    lines = [
        "# Table 7, this machine vs the paper",
        "",
        f"Sequence `{Path(doc['sequence']).name}`, first {doc['frames']} frames (640×480), after a "
        f"{doc['warmup_frames']}-frame warm-up; per frame and stage the minimum over {doc['repeat']} run(s), then "
        "the mean over frames (ms).  Generation = decode + feature; Tracking = pyramid + reference + LM tracking + "
        "bookkeeping; Total = Generation + Tracking (the paper's definition, mapping runs in its own thread); "
        "Mapping (amortised, not in Total) is shown for the sequential loop.",
        "",
        f"Machine: {m['cpu']}, {m['usable_cpus']} usable CPUs ({'/'.join(m['simd'])}); python {m['python']}, "
        f"numpy {m['numpy']}, numba {m['numba']}, opencv {m['opencv']}, torch {m['torch']}.  "
        f"numba threads {doc['numba_threads']}, feature threads {doc['feature_threads'] or doc['numba_threads']}.  "
        f"Load average before {doc['load_before']}, after {doc['load_after']}.  "
        "Paper: i7-4790K @ 4 GHz + GTX 1080, TUM DSO.",
        "",
        *_device_lines(doc),
        "| Feature | Gen. ms | Paper gen. | Track. ms | Paper track. | Total ms | Paper total | fps | Paper fps "
        "| Faster than paper? | Mapping ms | Seq. total ms | KFs |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|:---:|---:|---:|---:|",
    ]
    for name, r in doc["results"].items():
        paper = PAPER.get(name)
        label = name + (" †" if name.startswith("alexnet") and doc.get("alexnet", {}).get("weights") == RANDOM_LABEL
                        else "")
        if "error" in r:
            lines.append(f"| {label} | failed: {r['error']} |" + " |" * 11)
            continue
        g, t, tot = r["generation_ms"]["mean"], r["tracking_ms"]["mean"], r["total_ms"]["mean"]
        if paper:
            faster = "yes" if tot < paper[3] else "no"
            pg, pt, ptot, pfps = f"{paper[1]:g}", f"{paper[2]:g}", f"{paper[3]:g}", f"{paper[4]:.3g}"
        else:
            faster, pg, pt, ptot, pfps = "–", "–", "–", "–", "–"
        if r.get("lost_at") is not None:
            label += f" (lost at frame {r['lost_at']}: first {r['frames']} frames)"
        lines.append(
            f"| {label} | {g:.1f} | {pg} | {t:.1f} | {pt} | {tot:.1f} | {ptot} | {r['fps']:.1f} | {pfps} | {faster} "
            f"| {r['mapping_ms']['mean']:.1f} | {r['sequential_total_ms']['mean']:.1f} | {r['keyframes']} |"
        )
    a = doc.get("alexnet")
    if a:
        lines += ["", f"† AlexNet weights: {a['weights']}; feature scale {a['scale']:.4g}"
                  + (f" (calibrated on {len(a['calibration_frames'])} frames: {a['scale_achieved_count']:.0f} "
                     f"semi-dense pixels per frame, grey {a['scale_target_count']:.0f})" if "scale_target_count" in a
                     else "")
                  + "; alexnet-pcaK: PCA basis fitted on the same frames, fused 1×1 projection, scales "
                  + ", ".join(f"{k.split('-')[1]} {v:.4g}" for k, v in a.get("pca_scales", {}).items()) + "."]
    lines += ["", "Generation stages (mean ms): " + "; ".join(
        f"{n} decode {r['stages_mean_ms']['decode']:.1f} + feature {r['stages_mean_ms']['feature']:.1f}"
        for n, r in doc["results"].items() if "error" not in r), ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sequence", type=Path, default=DEFAULT_SEQUENCE)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--features", default=",".join(DEFAULT_FEATURES), help="comma-separated feature names")
    ap.add_argument("--learned", action="store_true", help=f"also {', '.join(LEARNED)} (seconds per frame)")
    ap.add_argument("--warmup-frames", type=int, default=10)
    ap.add_argument("--repeat", type=int, default=1, help="staged runs per feature (per-frame minimum)")
    ap.add_argument("--threads", type=int, default=None, help="numba threads (default: numba's default)")
    ap.add_argument("--feature-threads", type=int, default=None,
                    help="threads of the CPU features' pool ($DMTRACK_FEATURE_THREADS; default: numba's threads)")
    ap.add_argument("--alexnet-weights", default="auto", help="'auto', 'random' or a weight file")
    ap.add_argument("--calib-frames", type=int, default=5, help="frames for AlexNet's scale and PCA")
    ap.add_argument("--pca-scale", choices=("calibrate", "1"), default="calibrate",
                    help="scale of the alexnet-pcaK features: calibrated like the default scales, or 1")
    ap.add_argument("--out", type=Path, default=REPO / "out" / "benchmarks" / "table7",
                    help="output prefix: OUT.json and OUT.md")
    ap.add_argument("--device", default="cpu", help="where the network features run: cpu (default), cuda, cuda:N")
    args = ap.parse_args(argv)
    from dmtrack.features.device import gpu_status, resolve_device

    resolve_device(args.device)  # one line naming what is missing, before anything runs

    import numba

    if args.threads is not None:
        numba.set_num_threads(args.threads)
    if args.feature_threads is not None:
        os.environ["DMTRACK_FEATURE_THREADS"] = str(args.feature_threads)
    names = [n.strip() for n in args.features.split(",") if n.strip()]
    if args.learned:
        names += [n for n in LEARNED if n not in names]
    tmp = Path(tempfile.mkdtemp(prefix="dmtrack-table7-"))
    os.environ["DMTRACK_HOME"] = str(tmp / "home")  # the packaged default scales only; our scale / PCA go here
    load_before = _load()
    doc: dict = {
        "sequence": str(args.sequence),
        "frames": args.frames,
        "warmup_frames": args.warmup_frames,
        "repeat": args.repeat,
        "numba_threads": numba.get_num_threads(),
        "feature_threads": args.feature_threads,
        "features": names,
        "device": args.device,
        "gpu": gpu_status() if args.device != "cpu" else None,
        "load_before": load_before,
        "machine": machine_info(),
        "paper": {k: dict(zip(("label", "generation_ms", "tracking_ms", "total_ms", "fps"), v, strict=True))
                  for k, v in PAPER.items()},
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }
    try:
        if any(n == "alexnet" or n.startswith("alexnet-pca") for n in names):
            doc["alexnet"] = setup_alexnet(
                names, args.sequence, args.alexnet_weights, args.calib_frames, tmp, args.pca_scale, args.device
            )
            from dmtrack.features.alexnet import AUTO_BACKEND

            doc["alexnet"]["backend"] = AUTO_BACKEND
            print(f"alexnet: {doc['alexnet']}", flush=True)
        results: dict[str, dict] = {}
        head = (f"{'feature':<15} {'gen ms':>8} {'paper':>6} {'track ms':>9} {'paper':>6} {'total':>8} {'paper':>6} "
                f"{'fps':>6} {'faster?':>8} {'mapping':>8}")
        print(f"# {args.sequence.name}, {args.frames} frames; load {load_before}; {doc['machine']['cpu']}", flush=True)
        print(head, flush=True)
        for name in names:
            try:
                r = run_feature(name, str(args.sequence), args.frames, args.warmup_frames, args.repeat, args.device)
            except (SystemExit, Exception) as exc:  # noqa: BLE001 - a lost track / missing dependency: report it
                results[name] = {"error": f"{type(exc).__name__}: {exc}"[:200]}
                print(f"{name:<15} failed: {results[name]['error']}", flush=True)
                continue
            results[name] = r
            p = PAPER.get(name)
            tot = r["total_ms"]["mean"]
            print(f"{name:<15} {r['generation_ms']['mean']:8.1f} {p[1] if p else float('nan'):6.0f} "
                  f"{r['tracking_ms']['mean']:9.1f} {p[2] if p else float('nan'):6.0f} {tot:8.1f} "
                  f"{p[3] if p else float('nan'):6.0f} {r['fps']:6.1f} "
                  f"{('yes' if tot < p[3] else 'no') if p else '-':>8} {r['mapping_ms']['mean']:8.1f}", flush=True)
        doc["results"] = results
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    doc["load_after"] = _load()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    json_path = args.out.with_name(args.out.name + ".json")
    md_path = args.out.with_name(args.out.name + ".md")
    json_path.write_text(json.dumps(doc, indent=2) + "\n")
    md_path.write_text(markdown(doc))
    print(f"load average before {load_before}, after {doc['load_after']}")
    print(f"wrote {json_path} and {md_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
