"""The reproducibility promise, as stated in README.md ("Reproducibility") and recorded in metrics.json.

Same input, seed, settings and kernel target → byte-identical outputs, for every feature kind (grey, N-channel
re-associated sums, the recompute pyramid of Bit-Planes) and any thread count. metrics.json names the kernel target
(LLVM CPU), its widest SIMD set and the CPU model, so two result folders can be checked for comparability.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from dmtrack.odometry._target import kernel_target
from dmtrack.pipeline import run_to_directory

SAMPLE = Path(__file__).resolve().parents[2] / "data" / "7scenes-redkitchen-0000-0299"


def _digest(out: Path) -> str:
    h = hashlib.sha256()
    for name in ("trajectory.txt", "keyframes.txt", "pointcloud.ply"):
        h.update((out / name).read_bytes())
    return h.hexdigest()


@pytest.mark.parametrize(
    ("feature", "init", "frames"),
    [("gray", "random", 24), ("rgb", "random", 24), ("bitplanes", "random", 24), ("gray", "geometric", 56)],
)
def test_same_input_same_bytes_any_thread_count(tmp_path: Path, feature: str, init: str, frames: int, fault_log,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    import numba

    digests = []
    before = numba.get_num_threads()
    try:
        for threads in (1, 2, 2):
            threads = min(threads, numba.config.NUMBA_NUM_THREADS)
            monkeypatch.setenv("DMTRACK_FEATURE_THREADS", str(threads))  # feature extraction
            numba.set_num_threads(threads)  # tracking and mapping kernels
            out = tmp_path / f"t{threads}-{len(digests)}"
            run_to_directory(SAMPLE, out, feature=feature, max_frames=frames, seed=1, init=init, depth_images=False)
            digests.append(_digest(out))
            if init == "geometric":  # the start accepted (OpenCV's corners, KLT and RANSAC, any thread count)
                assert json.loads((out / "metrics.json").read_text())["init_accepted_frame"] is not None
    finally:
        numba.set_num_threads(before)
    assert len(set(digests)) == 1
    fault_log.tried("determinism", f"{feature} ({init} start): repeated runs, 1 and 2 threads", n=len(digests))


def test_metrics_record_the_kernel_target(tmp_path: Path) -> None:
    run_to_directory(SAMPLE, tmp_path, max_frames=3, depth_images=False, pointcloud=False)
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    target = kernel_target()
    assert metrics["kernel_target"] == target["kernel_target"] and metrics["kernel_target"]
    assert metrics["simd"] in ("avx512", "avx2", "avx", "sse4.2", "neon", "baseline")
    assert metrics["cpu"]


def test_kernel_target_follows_numba_cpu_name(monkeypatch: pytest.MonkeyPatch) -> None:
    """NUMBA_CPU_NAME=generic (portable machine code) is what the kernels are then compiled for, and recorded."""
    monkeypatch.setenv("NUMBA_CPU_NAME", "generic")
    monkeypatch.delenv("NUMBA_CPU_FEATURES", raising=False)
    assert kernel_target()["kernel_target"] == "generic"
    assert kernel_target()["simd"] == "baseline"
    monkeypatch.setenv("NUMBA_CPU_NAME", "haswell")
    monkeypatch.setenv("NUMBA_CPU_FEATURES", "")  # the named CPU's own instruction set
    assert kernel_target() == {**kernel_target(), "kernel_target": "haswell", "simd": "avx2"}


_START_DIGEST = """
import hashlib
from dmtrack.datasets.synthetic.sequence import SyntheticConfig, SyntheticSequence
from dmtrack.initialization import GeometricInitializer
seq = SyntheticSequence(SyntheticConfig(width=320, height=240, n_frames=25, seed=1, texel=0.02))
start = GeometricInitializer(seq.camera)
for i in range(25):
    if start.add(i, seq[i].timestamp, seq[i].image):
        break
m = start.initial_map
print(hashlib.sha256(m.idepth.tobytes() + m.idepth_var.tobytes() + m.valid.tobytes()).hexdigest())
"""


def test_the_geometric_start_gives_the_same_bits_whatever_the_blas_threads(fault_log) -> None:
    """The bundle adjustment's sums must not follow the BLAS thread count (a multi-threaded matrix product splits its
    sums by thread): bench workers run with one BLAS thread, an interactive run with all of them."""
    import os
    import subprocess
    import sys

    digests = set()
    for n in ("1", "2"):
        env = {**os.environ, "OPENBLAS_NUM_THREADS": n, "OMP_NUM_THREADS": n, "MKL_NUM_THREADS": n}
        out = subprocess.run([sys.executable, "-c", _START_DIGEST], env=env, capture_output=True, text=True,
                             check=True)
        digests.add(out.stdout.strip().splitlines()[-1])
    assert len(digests) == 1
    fault_log.tried("determinism", "geometric start: 1 and 2 BLAS threads", n=2)
