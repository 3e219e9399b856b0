"""Feature generation time per 640×480 frame, beside the paper's Table 7.

Usage::

    python benchmarks/bench_features.py [--repeats 7] [--warmup 2] [--features gray,bitplanes,dsift]
                                        [--image PATH] [--threads N] [--pca 64,32,16,8]
                                        [--alexnet-weights auto|random|PATH] [--alexnet-backends auto|all|fft,...]

For each feature: ``warmup`` untimed calls (numba compilation, caches), then the median of ``repeats`` timed calls
of ``feature.compute(image)`` on one 640×480 RGB frame of the repository's sample (``data/7scenes-…``; the frame
is read once, outside the timing).  The paper's "generation" column (i7-4790K + GTX 1080) also counts file I/O,
undistortion and cropping, so it is an upper reference rather than a like-for-like number.  Learned features are
timed only if they are registered and their weights/dependencies are available; otherwise they are reported as
skipped.  ``--pca 64,32,…`` also times the PCA-reduced variants (Table 7, bottom, for AlexNet).

AlexNet's weights cannot be shipped: without them (or with ``--alexnet-weights random``) ``alexnet`` is timed with
seeded random weights of the real shapes (conv1 weight (96, 3, 11, 11), bias (96,); :func:`random_alexnet_weights`),
labelled ``[random w]`` — a timing proxy, as the convolution's run time does not depend on the values.
``--alexnet-backends all`` times each conv1 backend (``fft`` — the default —, ``numpy``, ``torch``).  Between
features the script sleeps 0.3 s, so that the spinning worker threads of the previous one (OpenMP, OpenBLAS) are
idle again.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_IMAGE = REPO / "data" / "7scenes-redkitchen-0000-0299" / "frame-000000.color.jpg"

#: Table 7 (top) of the paper: feature generation time per frame in ms (TUM DSO, 640×480 after cropping).
PAPER_MS = {
    "gray": 10.0,
    "gray-affine": 10.0,
    "bitplanes": 20.0,
    "dsift": 530.0,
    "siamese": 8000.0,
    "alexnet": 79.0,
}
PAPER_NAME = {"gray": "Gray", "gray-affine": "Gray-A", "bitplanes": "Bit-Planes", "dsift": "SIFT",
              "siamese": "Siamese", "alexnet": "AlexNet"}
#: Table 7 (bottom): AlexNet reduced to K dimensions by PCA (1×1 projection on the GPU), generation ms.
PAPER_ALEXNET_PCA_MS = {64: 61.0, 32: 40.0, 16: 29.0, 8: 24.0, 4: 22.0, 2: 21.0, 1: 20.0}


def random_alexnet_weights(directory: str | Path, seed: int = 0) -> Path:
    """Write seeded random AlexNet conv1 weights of the real shapes (BVLC: weight (96, 3, 11, 11), bias (96,);
    N(0, 0.01²) kernels — Caffe's initialisation of conv1 — and N(0, 1) biases) to ``directory`` and return the
    ``.npz`` path (loadable with ``get_feature("alexnet", weights=path)``).  For timing only."""
    rng = np.random.default_rng(seed)
    path = Path(directory) / "alexnet-conv1-random.npz"
    np.savez(path, weight=(rng.standard_normal((96, 3, 11, 11)) * 0.01).astype(np.float32),
             bias=rng.standard_normal(96).astype(np.float32))
    return path


def time_feature(feature, image: np.ndarray, repeats: int, warmup: int) -> list[float]:
    """Wall times (s) of ``repeats`` calls of ``feature.compute(image)`` after ``warmup`` untimed calls.

    Features slower than 2 s per call get at most 3 timed calls.
    """
    t0 = time.perf_counter()
    for _ in range(warmup):
        feature.compute(image)
    if warmup and (time.perf_counter() - t0) / warmup > 2.0:
        repeats = min(repeats, 3)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        feature.compute(image)
        times.append(time.perf_counter() - t0)
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="timed runs per feature (median reported)")
    parser.add_argument("--warmup", type=int, default=2, help="untimed runs before timing")
    parser.add_argument("--features", default="", help="comma-separated names (default: all registered)")
    parser.add_argument("--image", type=Path, default=DEFAULT_IMAGE, help="a 640x480 image")
    parser.add_argument("--threads", type=int, default=0, help="OpenCV/numba threads (0: leave as is)")
    parser.add_argument("--pca", default="", help="comma-separated K: also time BASE-pcaK for each timed feature "
                        "with more than K channels (basis fitted on the sample's frames, e.g. 64,32,16,8)")
    parser.add_argument("--alexnet-weights", default="auto",
                        help="'auto' (the installed weights, else random ones), 'random' (seeded random weights of "
                        "the real shapes: a timing proxy, the run time does not depend on the values) or a path")
    parser.add_argument("--alexnet-backends", default="auto",
                        help="conv1 backends to time: 'auto', 'all' (fft, numpy, torch if installed) or a list")
    args = parser.parse_args(argv)

    import cv2

    from dmtrack.errors import InputError
    from dmtrack.features import fit_pca, get_feature, list_features
    from dmtrack.features.pca import ReducedFeature
    from dmtrack.io.images import read_image

    if args.threads > 0:
        cv2.setNumThreads(args.threads)
        try:
            import numba

            numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
        except (ImportError, ValueError):
            pass

    image = read_image(args.image)
    if image.shape[:2] != (480, 640):
        print(f"warning: {args.image} is {image.shape[1]}x{image.shape[0]}, not 640x480", file=sys.stderr)
    names = [n.strip() for n in args.features.split(",") if n.strip()] or [d["name"] for d in list_features()]

    print(f"# feature generation per frame ({image.shape[1]}x{image.shape[0]} RGB, {args.image.name}); "
          f"median of {args.repeats} after {args.warmup} warm-up")
    print(f"# python {platform.python_version()}, numpy {np.__version__}, opencv {cv2.__version__}, "
          f"{os.cpu_count()} CPUs, cv2 threads {cv2.getNumThreads()}")
    print(f"{'feature':<26} {'N':>4} {'scale':>8} {'median ms':>10} {'min ms':>8} {'max ms':>8}   paper Table 7")
    ks = sorted({int(k) for k in args.pca.split(",") if k.strip()}, reverse=True)
    pca_frames = sorted(args.image.parent.glob("*.color.jpg"))[::30] or [args.image]

    def report(label: str, feature, paper: str) -> None:
        times = time_feature(feature, image, args.repeats, args.warmup)
        med, lo, hi = (1000 * statistics.median(times), 1000 * min(times), 1000 * max(times))
        print(f"{label:<26} {feature.channels:>4} {feature.scale:>8.4g} {med:>10.1f} {lo:>8.1f} {hi:>8.1f}   {paper}",
              flush=True)

    tmp = Path(tempfile.mkdtemp(prefix="dmtrack-bench-features-"))

    def build(name: str) -> list[tuple[str, object]]:
        """(label, feature) pairs to time for ``name`` (one per AlexNet backend)."""
        if name != "alexnet":
            return [(name, get_feature(name))]
        from dmtrack.features.alexnet import AUTO_BACKEND

        opts: dict = {}
        suffix = ""
        if args.alexnet_weights == "random":
            opts["weights"] = random_alexnet_weights(tmp)
        elif args.alexnet_weights != "auto":
            opts["weights"] = args.alexnet_weights
        if args.alexnet_weights == "auto":
            try:
                get_feature(name)
            except InputError:
                opts["weights"] = random_alexnet_weights(tmp)
        if "weights" in opts and args.alexnet_weights in ("auto", "random"):
            suffix = " [random w]"
        if args.alexnet_backends == "auto":
            backends = [AUTO_BACKEND]
        elif args.alexnet_backends == "all":
            from dmtrack.features import _nn

            backends = ["fft", "numpy"] + (["torch"] if _nn.have_torch() else [])
        else:
            backends = [b.strip() for b in args.alexnet_backends.split(",") if b.strip()]
        return [(f"{name}[{b}]{suffix}", get_feature(name, backend=b, **opts)) for b in backends]

    for name in names:
        try:
            built = build(name)
        except InputError as exc:
            reason = str(exc)
            print(f"{name:<26} skipped: {reason[:110] + ('…' if len(reason) > 110 else '')}")
            continue
        paper = PAPER_MS.get(name)
        for label, feature in built:
            time.sleep(0.3)
            report(label, feature, f"{PAPER_NAME[name]} {paper:g} ms" if paper is not None else "-")
            pca_ks = [k for k in ks if k < feature.channels]
            if pca_ks:
                basis = fit_pca(feature, pca_frames, n_samples=50_000, seed=0)
                for k in pca_ks:
                    paper_k = PAPER_ALEXNET_PCA_MS.get(k) if name == "alexnet" else None
                    ref = f"AlexNet-{k}D {paper_k:g} ms" if paper_k is not None else "-"
                    time.sleep(0.3)
                    tag = label[label.index("[") : label.index("]") + 1] if "[" in label else ""
                    report(f"{name}-pca{k}{tag}", ReducedFeature(feature, basis, k=k), ref)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
