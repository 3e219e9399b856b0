"""The promise across CPUs (issue 41): every feature's trajectory is the same bits whatever machine code the kernels
are compiled into and whatever kernels the libraries pick.

Each target runs in a subprocess with its own cold ``NUMBA_CACHE_DIR``: numba compiles every kernel for
``NUMBA_CPU_NAME`` (with ``NUMBA_CPU_FEATURES`` empty, so the target's own instruction set and nothing of the host's),
and OpenBLAS is told to use that CPU's kernels (``OPENBLAS_CORETYPE``), so one host stands in for several machines:

* ``generic`` — baseline x86-64 (SSE2), OpenBLAS's Prescott kernels;
* ``haswell`` — AVX2 and FMA, OpenBLAS's Haswell kernels;
* ``znver3`` — AMD Zen 3, OpenBLAS's Zen kernels;
* ``skylake-avx512`` — AVX-512, OpenBLAS's SkylakeX kernels;

and this process is the host's own choice of both (``native``, its warm cache). A target the host cannot run is
skipped (by the CPU flags it needs). In each subprocess the tracker's kernel identity and lane-order tests run
(tests/odometry/test_tracker_multi.py, tests/odometry/test_lanes.py), then four short runs — grey with the random and
with the geometric start, rgb and Bit-Planes with the random start — whose trajectory, keyframes and point cloud must
hash to the same digests under every target and in this process.

Not emulated: OpenCV's own dispatch. The geometric start's essential matrix (``cv2.findEssentialMat``) comes out
differently when OpenCV may not use AVX2 and FMA (``OPENCV_CPU_DISABLE=AVX2,FMA3,AVX``, measured): the start, and a
run from it, is the same on every x86-64 CPU with AVX2 and FMA, and differs on older ones. Its corners and KLT
tracks are the same either way.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from dmtrack.pipeline import run_to_directory

REPO = Path(__file__).resolve().parents[2]
SEQUENCE = "synthetic:n_frames=30,width=160,height=120,seed=1"  # the geometric start accepts frame 10
RUNS = (("gray-random", "gray", "random"), ("gray-geometric", "gray", "geometric"), ("rgb-random", "rgb", "random"),
        ("bitplanes-random", "bitplanes", "random"))  # fmt: skip
KERNEL_TESTS = ("tests/odometry/test_tracker_multi.py", "tests/odometry/test_lanes.py")

#: target → (CPU flags it needs in /proc/cpuinfo, OPENBLAS_CORETYPE)
TARGETS: dict[str, tuple[frozenset[str], str]] = {
    "generic": (frozenset(), "Prescott"),
    "haswell": (frozenset({"avx2", "fma", "bmi2", "movbe", "f16c"}), "Haswell"),
    "znver3": (frozenset({"avx2", "fma", "bmi2", "sse4a", "clzero", "sha_ni", "vaes"}), "Zen"),
    "skylake-avx512": (frozenset({"avx512f", "avx512bw", "avx512dq", "avx512vl", "avx512cd"}), "SkylakeX"),
}

# the kernel tests, then the runs, in one interpreter (the kernels compile once)
_TARGET_SCRIPT = f"""
import hashlib, json, sys
import pytest
rc = pytest.main(["-q", "-x", "-p", "no:cacheprovider", *{KERNEL_TESTS!r}])
if rc != 0:
    sys.exit(10 + int(rc))
from dmtrack.pipeline import run_to_directory
out = {{}}
for name, feature, init in {RUNS!r}:
    d = sys.argv[1] + "/" + name
    run_to_directory({SEQUENCE!r}, d, feature=feature, seed=1, init=init, depth_images=False)
    h = hashlib.sha256()
    for f in ("trajectory.txt", "keyframes.txt", "pointcloud.ply"):
        h.update(open(d + "/" + f, "rb").read())
    out[name] = h.hexdigest()
print(json.dumps(out))
"""


def _cpu_flags() -> set[str]:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def _digest(out: Path) -> str:
    h = hashlib.sha256()
    for f in ("trajectory.txt", "keyframes.txt", "pointcloud.ply"):
        h.update((out / f).read_bytes())
    return h.hexdigest()


def _target_env(target: str, cache: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_", "OPENBLAS_CORETYPE"))}
    env["NUMBA_CACHE_DIR"] = str(cache)  # cold
    env["NUMBA_CPU_NAME"] = target
    env["NUMBA_CPU_FEATURES"] = ""  # the target's own instruction set only, none of the host's
    env["OPENBLAS_CORETYPE"] = TARGETS[target][1]
    return env


def _run_target(target: str, tmp: Path) -> tuple[int, str, dict[str, str] | None]:
    proc = subprocess.run([sys.executable, "-c", _TARGET_SCRIPT, str(tmp / f"runs-{target}")], cwd=REPO,
                          env=_target_env(target, tmp / f"cache-{target}"), capture_output=True, text=True,
                          timeout=1200)  # fmt: skip
    digests = json.loads(proc.stdout.strip().splitlines()[-1]) if proc.returncode == 0 else None
    return proc.returncode, proc.stdout[-3000:] + proc.stderr[-3000:], digests


@pytest.mark.slow  # every target compiles its kernels into a cold cache: about a minute each, two at a time
def test_every_kernel_target_gives_the_same_bits(tmp_path: Path, fault_log) -> None:
    flags = _cpu_flags()
    targets = [t for t, (need, _) in TARGETS.items() if need <= flags]
    skipped = sorted(set(TARGETS) - set(targets))
    here = {}
    for name, feature, init in RUNS:  # this process: the host's target, the warm cache
        run_to_directory(SEQUENCE, tmp_path / "here" / name, feature=feature, seed=1, init=init, depth_images=False)
        here[name] = _digest(tmp_path / "here" / name)
        if init == "geometric":  # the start itself ran (KLT, RANSAC, bundle adjustment), no random fallback
            assert json.loads((tmp_path / "here" / name / "metrics.json").read_text())["init_accepted_frame"]
    with ThreadPoolExecutor(2) as pool:  # two subprocesses at a time (two cores)
        results = dict(zip(targets, pool.map(lambda t: _run_target(t, tmp_path), targets), strict=True))
    for target, (rc, out, digests) in results.items():
        assert rc == 0, f"{target}: {'kernel tests' if rc >= 10 else 'runs'} failed (exit {rc})\n{out}"
        assert digests == here, f"{target}: {digests} != {here} (this process)"
    assert len(targets) >= 2, f"only {targets} could run on this host (flags missing for {skipped})"
    fault_log.tried("determinism", f"kernel targets {', '.join(targets)}: identical trajectories", n=len(targets))
