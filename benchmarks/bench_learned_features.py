"""Learned features: generation time per 640×480 frame for each backend, beside the paper's Table 7.

Usage::

    python benchmarks/bench_learned_features.py [--repeats 5] [--warmup 1] [--image PATH]
                                                [--exact-pixels 3000] [--no-numpy] [--pca 64,32,16,8,4,2,1]

The AlexNet and Siamese weights cannot be shipped, so those two are timed with *stand-in* weights of the real
shapes (random values; the run time of a convolution does not depend on the values).  TFeat and DISK use the
shipped weights.  The exact per-patch modes (``normalise="patch"``) are timed on ``--exact-pixels`` random pixels
and extrapolated to the 307,200 pixels of a frame (their cost is linear in the number of pixels after one shared
first layer, which is included).  ``bench_features.py`` times every registered feature with its real weights
when they are installed; this script adds the backends, the stand-in weights and the exact modes.

The paper's numbers (i7-4790K + GTX 1080): AlexNet generation 79 ms (total with tracking 509 ms, ~2 fps),
Siamese generation 8.0 s (total 9 s), AlexNet-K generation 61…20 ms; its generation column includes file I/O,
undistortion and cropping.
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_features import DEFAULT_IMAGE, PAPER_ALEXNET_PCA_MS, time_feature  # noqa: E402

PAPER = {"alexnet": "AlexNet 79 ms (total 509 ms)", "siamese": "Siamese 8000 ms (total 9000 ms)"}


def _median_ms(times: list[float]) -> tuple[float, float]:
    return 1000 * statistics.median(times), 1000 * min(times)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--warmup", type=int, default=1)
    parser.add_argument("--image", type=Path, default=DEFAULT_IMAGE)
    parser.add_argument("--exact-pixels", type=int, default=3000, help="pixels timed for the exact modes")
    parser.add_argument("--no-numpy", action="store_true", help="skip the (slower) numpy backend")
    parser.add_argument("--pca", default="64,32,16,8,4,2,1", help="K of the alexnet-pcaK variants to time")
    parser.add_argument("--device", default="cpu",
                        help="cpu (default: the CPU backends) or cuda / cuda:N: also every feature on that GPU")
    args = parser.parse_args(argv)
    from dmtrack.features.device import resolve_device

    gpu = resolve_device(args.device)  # one line naming what is missing, before anything runs

    from dmtrack.features import _nn
    from dmtrack.features.alexnet import AlexNetFeature
    from dmtrack.features.pca import ReducedFeature, fit_pca
    from dmtrack.features.siamese import SiameseFeature, exact_siam
    from dmtrack.features.tfeat import TFeatFeature, exact_tfeat
    from dmtrack.features.weights import SIAM_SHAPES
    from dmtrack.io.images import read_image

    image = read_image(args.image)
    grey = image if image.ndim == 2 else (image @ np.array([0.299, 0.587, 0.114])).astype(np.float32)
    h, w = image.shape[:2]
    backends = (["torch"] if _nn.have_torch() else []) + ([] if args.no_numpy else ["numpy"])
    torch_info = "not installed"
    if _nn.have_torch():
        import torch

        torch_info = f"{torch.__version__}, {torch.get_num_threads()} threads"
    print(f"# learned features per frame ({w}x{h}, {args.image.name}); median of {args.repeats} "
          f"after {args.warmup} warm-up")
    print(f"# python {platform.python_version()}, numpy {np.__version__}, torch {torch_info}, {os.cpu_count()} CPUs")
    print(f"{'feature':<22} {'backend':<7} {'N':>4} {'median ms':>10} {'min ms':>9}   paper Table 7")

    rng = np.random.default_rng(0)
    tmp = Path(tempfile.mkdtemp(prefix="dmtrack-bench-"))
    alex_w = tmp / "alexnet-conv1.npz"
    np.savez(alex_w, weight=(rng.standard_normal((96, 3, 11, 11)) * 0.01).astype(np.float32),
             bias=rng.standard_normal(96).astype(np.float32))
    siam_w = tmp / "siam_standin.npz"
    np.savez(siam_w, **{k: (rng.standard_normal(s) * 0.05).astype(np.float32) for k, s in SIAM_SHAPES.items()})

    def row(label: str, backend: str, feature, paper: str = "-") -> None:
        times = time_feature(feature, image, args.repeats, args.warmup)
        med, lo = _median_ms(times)
        print(f"{label:<22} {backend:<7} {feature.channels:>4} {med:>10.1f} {lo:>9.1f}   {paper}", flush=True)

    def extrapolated(label: str, backend: str, n_ch: int, fn, paper: str = "-") -> None:
        pix = np.stack([rng.integers(0, h, args.exact_pixels), rng.integers(0, w, args.exact_pixels)], axis=1)
        fn(pix[:64])  # warm-up
        t0 = time.perf_counter()
        fn(pix)
        dt = time.perf_counter() - t0
        # the shared first layer is paid once per frame; the per-pixel layers scale with the pixel count
        t_shared0 = time.perf_counter()
        fn(pix[:1])
        shared = time.perf_counter() - t_shared0
        per_px = max(dt - shared, 0.0) / len(pix)
        est = 1000 * (shared + per_px * h * w)
        print(f"{label:<22} {backend:<7} {n_ch:>4} {est:>10.0f} {'(extrap.)':>9}   {paper}", flush=True)

    # AlexNet has its own exact FFT backend (the default, "auto") besides torch and numpy
    for be in ["fft", *backends]:
        alex = AlexNetFeature(weights=alex_w, backend=be, device="cpu")
        row("alexnet (stand-in w)", be, alex, PAPER["alexnet"])
    be = "fft"
    alex = AlexNetFeature(weights=alex_w, backend=be, device="cpu")
    ks = sorted({int(k) for k in args.pca.split(",") if k.strip()}, reverse=True)
    if ks:
        frames = sorted(args.image.parent.glob("*.color.jpg"))[::60] or [args.image]
        basis = fit_pca(alex, frames, n_samples=20_000, seed=0)
        for k in ks:
            paper = f"AlexNet-{k}D {PAPER_ALEXNET_PCA_MS[k]:g} ms" if k in PAPER_ALEXNET_PCA_MS else "-"
            row(f"alexnet-pca{k}", be, ReducedFeature(alex, basis, k=k), paper)
    for be in backends:
        row("siamese local", be, SiameseFeature(weights=siam_w, backend=be, device="cpu"), PAPER["siamese"])
    for be in backends[:1]:
        params = SiameseFeature(weights=siam_w, backend=be, device="cpu").params
        extrapolated("siamese patch (exact)", be, 256,
                     lambda pix, p=params, b=be: exact_siam(grey, p, pixels=pix, backend=b), PAPER["siamese"])
    for be in backends:
        row("tfeat local", be, TFeatFeature(backend=be, device="cpu"))
    for be in backends[:1]:
        params = TFeatFeature(backend=be, device="cpu").params
        extrapolated("tfeat patch (exact)", be, 128,
                     lambda pix, p=params, b=be: exact_tfeat(grey, p, pixels=pix, backend=b))
    if _nn.have_torch():
        from dmtrack.features.disk import DiskFeature

        row("disk", "torch", DiskFeature(device="cpu"))
    if gpu is not None:
        gpu_rows(row, args, alex_w, siam_w, frames if ks else [args.image], ks, str(gpu))
    return 0


def gpu_rows(row, args, alex_w: Path, siam_w: Path, frames: list, ks: list[int], device: str) -> None:  # noqa: ANN001
    """The same features on the GPU: generation including the upload and the transfer into pinned memory."""
    import torch

    from dmtrack.features.alexnet import AlexNetFeature
    from dmtrack.features.disk import DiskFeature
    from dmtrack.features.pca import ReducedFeature, fit_pca
    from dmtrack.features.siamese import SiameseFeature
    from dmtrack.features.tfeat import TFeatFeature
    from dmtrack.features.tracknet import TrackNetFeature

    dev = torch.device(device)
    label = device.replace("cuda", "gpu")
    print(f"# on {device}: {torch.cuda.get_device_name(dev) if dev.type == 'cuda' else 'the device path'}", flush=True)
    alex = AlexNetFeature(weights=alex_w, device=dev)
    row("alexnet (stand-in w)", label, alex, PAPER["alexnet"])
    if ks:
        basis = fit_pca(alex, frames, n_samples=20_000, seed=0)
        for k in ks:
            paper = f"AlexNet-{k}D {PAPER_ALEXNET_PCA_MS[k]:g} ms" if k in PAPER_ALEXNET_PCA_MS else "-"
            row(f"alexnet-pca{k}", label, ReducedFeature(alex, basis, k=k), paper)
    row("siamese local", label, SiameseFeature(weights=siam_w, device=dev), PAPER["siamese"])
    for name, feat in (("tfeat local", TFeatFeature(device=dev)), ("disk", DiskFeature(device=dev)),
                       ("tracknet", TrackNetFeature(device=dev))):
        row(name, label, feat)
        if ks:
            basis = fit_pca(feat, frames, n_samples=20_000, seed=0)
            k16 = min(16, feat.channels)
            row(f"{name.split()[0]}-pca{k16}", label, ReducedFeature(feat, basis, k=k16))


if __name__ == "__main__":
    raise SystemExit(main())
