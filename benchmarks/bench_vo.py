"""Per-frame and per-stage timing of the full VO pipeline (decode → feature → pyramid → tracking → mapping).

Usage::

    python benchmarks/bench_vo.py [--sequence data/7scenes-redkitchen-0000-0299] [--frames 300]
                                  [--feature gray] [--repeat 3] [--threads N] [--out PATH]

What it measures
----------------
1. Warm-up: a short :func:`dmtrack.api.track` run (``--warmup-frames``, default 40: enough to create a keyframe), so
   numba compilation / cache loading is not timed.
2. ``--repeat`` staged runs: the loop of :func:`dmtrack.api.track` written out sequentially (no prefetching), with a
   wall-clock timer around every stage of every frame:

   * ``decode`` — ``seq[i]`` (JPEG read + decode) and the crop to multiples of 16;
   * ``feature`` — ``feature.compute(image)``;
   * ``pyramid`` — :func:`~dmtrack.odometry.frame.build_frame` (``FrameResult.pyramid_ms``);
   * ``reference`` — rebuilding the tracking reference after a map update (``FrameResult.reference_ms``);
   * ``tracking`` — the LM tracker (``tracking_ms − reference_ms``);
   * ``map_update`` — :meth:`DepthMap.update` on frames that did not become keyframes;
   * ``keyframe`` — keyframe creation (finalise + propagate + regularise) on frames that did;
   * ``other`` — the rest of ``VisualOdometry.process`` (pose bookkeeping, keyframe score).

   Runs are deterministic, so the same frame does the same work in every repeat: per frame and stage the
   minimum over repeats is taken (this removes most of the noise of a shared machine), then mean / median over
   frames. ``mean_ms`` of ``map_update`` / ``keyframe`` is per frame where the stage ran; ``per_frame_ms`` is
   the amortised cost (sum / all frames), and ``share`` is that stage's part of the per-frame total — what
   bounds the run.
3. ``--repeat`` end-to-end runs of :func:`dmtrack.api.track` itself (whatever prefetching / threading it does);
   the best wall time of their frame loop gives ``fps_track``. ``fps_staged`` is frames / (sum of the per-frame
   minimum totals).

Every run's trajectory is hashed (SHA-256 of the float64 poses): all hashes must agree (determinism), and the
hash lets a before/after comparison check that an optimisation left the results bit-identical.

The load average before and after is recorded: on a shared machine compare relative changes only.
Results go to ``out/benchmarks/vo_<feature>.json`` (or ``--out``) and a table is printed.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
STAGES = ("decode", "feature", "pyramid", "reference", "tracking", "map_update", "keyframe", "other")


def _load() -> list[float]:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:  # pragma: no cover - platform without getloadavg
        return []


def _hash_poses(poses: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(poses, dtype=np.float64).tobytes()).hexdigest()[:16]


def staged_run(
    sequence: str, feature_name: str, frames: int, device: str | None = None
) -> tuple[dict[str, np.ndarray], np.ndarray, str, int]:
    """One sequential run with per-frame stage timers (``device``: where a network feature runs; None: its
    default).

    Returns (stage → (n,) ms array, (n,) total ms per frame, trajectory hash, number of keyframes).
    """
    from dmtrack.datasets import open_sequence
    from dmtrack.features import get_feature
    from dmtrack.geometry.camera import crop_image
    from dmtrack.odometry.config import VOConfig
    from dmtrack.odometry.vo import VisualOdometry

    seq = open_sequence(sequence)
    feat = get_feature(feature_name, **({} if device is None else {"device": device}))
    config = VOConfig(init="random")  # the odometry alone
    if getattr(feat, "affine_brightness", False):
        config = config.with_overrides("tracker.affine=true")
    camera, box = seq.camera.crop_to_multiple(16)
    vo = VisualOdometry(camera, config)
    recompute = getattr(feat, "pyramid", "downsample") == "recompute"
    n = min(frames, len(seq))
    t = {s: np.zeros(n) for s in STAGES}
    total = np.zeros(n)
    for i in range(n):
        t0 = time.perf_counter()
        fr = seq[i]
        image = crop_image(fr.image, box)
        t1 = time.perf_counter()
        fmap = feat.compute_pyramid(image, config.pyramid_levels) if recompute else feat.compute(image)
        t2 = time.perf_counter()
        res = vo.process(i, fr.timestamp, image, fmap)
        t3 = time.perf_counter()
        t["decode"][i] = 1e3 * (t1 - t0)
        t["feature"][i] = 1e3 * (t2 - t1)
        t["pyramid"][i] = res.pyramid_ms
        ref_ms = getattr(res, "reference_ms", 0.0)  # (older versions: included in tracking)
        t["reference"][i] = ref_ms
        t["tracking"][i] = res.tracking_ms - ref_ms
        if res.is_keyframe:
            t["keyframe"][i] = res.mapping_ms
        else:
            t["map_update"][i] = res.mapping_ms
        process_ms = 1e3 * (t3 - t2)
        t["other"][i] = max(0.0, process_ms - res.pyramid_ms - res.tracking_ms - res.mapping_ms)
        total[i] = 1e3 * (t3 - t0)
        if vo.stopped:
            raise SystemExit(f"tracking lost at frame {i}: {res.lost_reason}")
    out = vo.finish()
    return t, total, _hash_poses(out.poses), len(out.keyframes)


def track_run(sequence: str, feature_name: str, frames: int) -> tuple[float, str, dict[str, float]]:
    """One :func:`dmtrack.api.track` run: (wall seconds of its frame loop, trajectory hash, its timings_ms).

    The frame loop's wall time (``timings_ms["wall_s"]``) excludes opening the sequence and the evaluation
    against the ground truth that ``track`` does afterwards.
    """
    from dmtrack.api import track

    res = track(sequence, feature=feature_name, max_frames=frames)
    assert res.vo is not None
    return float(res.timings_ms["wall_s"]), _hash_poses(res.vo.poses), dict(res.timings_ms)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sequence", default=str(REPO / "data" / "7scenes-redkitchen-0000-0299"))
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--feature", default="gray")
    ap.add_argument("--repeat", type=int, default=3, help="staged runs and track() runs (each); min over them")
    ap.add_argument("--threads", type=int, default=None, help="numba threads (default: numba's default)")
    ap.add_argument("--warmup-frames", type=int, default=40)
    ap.add_argument("--no-track", action="store_true", help="skip the end-to-end dmtrack.track() runs")
    ap.add_argument("--out", default=None, help="JSON path (default out/benchmarks/vo_<feature>.json)")
    ap.add_argument("--label", default="", help="free text stored in the JSON (e.g. 'before', 'after')")
    args = ap.parse_args(argv)

    import numba

    if args.threads is not None:
        numba.set_num_threads(args.threads)
    threads = numba.get_num_threads()
    load_before = _load()
    try:
        affinity = sorted(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        affinity = []

    t0 = time.perf_counter()
    track_run(args.sequence, args.feature, args.warmup_frames)
    warmup_s = time.perf_counter() - t0
    print(f"warm-up ({args.warmup_frames} frames): {warmup_s:.1f} s; numba threads {threads}; load {load_before}")

    per_frame: dict[str, np.ndarray] | None = None
    totals: np.ndarray | None = None
    hashes: list[str] = []
    staged_wall: list[float] = []
    n_kf = 0
    for r in range(args.repeat):
        t, total, h, n_kf = staged_run(args.sequence, args.feature, args.frames)
        hashes.append(h)
        staged_wall.append(float(total.sum()) / 1e3)
        if per_frame is None:
            per_frame, totals = t, total
        else:
            assert totals is not None
            per_frame = {s: np.minimum(per_frame[s], t[s]) for s in STAGES}
            totals = np.minimum(totals, total)
        print(f"staged run {r + 1}/{args.repeat}: {len(total) / total.sum() * 1e3:.2f} fps, hash {h}")
    assert per_frame is not None and totals is not None
    n = len(totals)

    track_walls: list[float] = []
    track_timings: dict[str, float] = {}
    if not args.no_track:
        for r in range(args.repeat):
            wall, h, tm = track_run(args.sequence, args.feature, args.frames)
            hashes.append(h)
            track_walls.append(wall)
            track_timings = tm
            print(f"track() run {r + 1}/{args.repeat}: {n / wall:.2f} fps (wall {wall:.2f} s), hash {h}")
    load_after = _load()

    kf_mask = per_frame["keyframe"] > 0
    upd_mask = per_frame["map_update"] > 0
    stage_sum = sum(float(per_frame[s].sum()) for s in STAGES)
    table: dict[str, dict[str, float]] = {}
    for s in STAGES:
        a = per_frame[s]
        sel = a[kf_mask] if s == "keyframe" else a[upd_mask] if s == "map_update" else a
        sel = sel if sel.size else np.zeros(1)
        table[s] = {
            "mean_ms": float(sel.mean()),
            "median_ms": float(np.median(sel)),
            "per_frame_ms": float(a.sum() / n),
            "share": float(a.sum() / stage_sum) if stage_sum > 0 else 0.0,
            "frames": int(sel.size if s in ("keyframe", "map_update") else n),
        }
    fps_staged = n / (float(totals.sum()) / 1e3)
    fps_track = n / min(track_walls) if track_walls else None
    bound = max(STAGES, key=lambda s: table[s]["share"])
    deterministic = len(set(hashes)) == 1

    print()
    print(f"{'stage':<11} {'mean ms':>8} {'median':>8} {'per frame':>10} {'share':>7}  (frames)")
    for s in STAGES:
        row = table[s]
        print(f"{s:<11} {row['mean_ms']:8.2f} {row['median_ms']:8.2f} {row['per_frame_ms']:10.2f} "
              f"{100 * row['share']:6.1f}%  ({row['frames']})")  # fmt: skip
    print(f"{'total':<11} {float(totals.mean()):8.2f} {float(np.median(totals)):8.2f} {float(totals.mean()):10.2f}")
    print(f"fps staged (sequential, min per frame over {args.repeat}): {fps_staged:.2f}")
    if fps_track is not None:
        print(f"fps track() (best of {len(track_walls)}): {fps_track:.2f}")
    print(f"bound by: {bound} ({100 * table[bound]['share']:.0f}% of the time); keyframes {n_kf}")
    print(f"trajectory hash {hashes[0]}; deterministic across runs: {deterministic}")
    print(f"load average before {load_before}, after {load_after}")

    out = Path(args.out) if args.out else REPO / "out" / "benchmarks" / f"vo_{args.feature}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    doc = {
        "label": args.label,
        "sequence": str(args.sequence),
        "feature": args.feature,
        "frames": n,
        "repeat": args.repeat,
        "numba_threads": threads,
        "cpu_affinity": affinity,
        "cpu_count": os.cpu_count(),
        "load_before": load_before,
        "load_after": load_after,
        "stages": table,
        "total_mean_ms": float(totals.mean()),
        "total_median_ms": float(np.median(totals)),
        "fps_staged": fps_staged,
        "fps_track": fps_track,
        "track_walls_s": track_walls,
        "staged_walls_s": staged_wall,
        "track_timings_ms": track_timings,
        "bound_by": bound,
        "keyframes": n_kf,
        "trajectory_hash": hashes[0],
        "deterministic": deterministic,
        "python": sys.version.split()[0],
        "numba": numba.__version__,
        "machine": platform.machine(),
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }
    out.write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {out}")
    return 0 if deterministic else 1


if __name__ == "__main__":
    sys.exit(main())
