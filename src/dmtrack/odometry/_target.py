"""What the numba kernels are compiled for on this machine (``kernel_target`` in ``metrics.json``).

The odometry's kernels (tracking, mapping, pyramids) are IEEE arithmetic in an order fixed by the source — no
fast-math; the channel sums in explicit lanes (:mod:`dmtrack.odometry._lanes`) — so they give the same bits for
every compilation and on every x86-64 target (``tests/faults/test_kernel_targets.py``). Two numba feature kernels
fuse multiply-adds where the target has FMA (``fastmath={"contract"}``: AlexNet's ``fft`` backend and tracknet's
layers), so those features' maps, and the trajectories tracked on them, follow the target; BLAS, oneDNN and OpenCV
choose their code paths by the CPU itself. The record names both, so two result folders can be checked for
comparability.
"""

from __future__ import annotations

#: widest vector set of the LLVM CPU names one sets in ``NUMBA_CPU_NAME`` (used when ``NUMBA_CPU_FEATURES`` is empty)
_NAMED_SIMD = {
    "generic": "baseline", "x86-64": "baseline", "x86-64-v2": "sse4.2", "nehalem": "sse4.2", "sandybridge": "avx",
    "x86-64-v3": "avx2", "haswell": "avx2", "broadwell": "avx2", "skylake": "avx2", "znver1": "avx2", "znver2": "avx2",
    "znver3": "avx2", "x86-64-v4": "avx512", "skylake-avx512": "avx512", "cascadelake": "avx512",
    "icelake-server": "avx512", "sapphirerapids": "avx512", "znver4": "avx512",
}  # fmt: skip


def kernel_target() -> dict[str, str]:
    """What the numba kernels are compiled for on this machine.

    ``kernel_target`` is LLVM's CPU name (``NUMBA_CPU_NAME`` when set, e.g. ``generic``), ``simd`` the widest vector
    instruction set it has (avx512 / avx2 / avx / sse4.2 / neon / baseline) and ``cpu`` the processor's model name.
    The odometry's output does not depend on ``kernel_target``; a feature computed with FMA contraction or by a CPU-
    dispatched library (see the module docstring) may depend on ``kernel_target`` or ``cpu``.
    """
    import os

    import llvmlite.binding as ll

    from dmtrack.io.machine import cpu_model

    name = os.environ.get("NUMBA_CPU_NAME") or ll.get_host_cpu_name()
    if os.environ.get("NUMBA_CPU_NAME"):
        raw = os.environ.get("NUMBA_CPU_FEATURES")
        if raw is None and name != "generic":  # numba adds the host's features to a named CPU
            features = {k for k, v in ll.get_host_cpu_features().items() if v}
        else:
            features = set((raw or "").replace("+", " ").replace(",", " ").split())
            if not features:  # the named CPU's own instruction set
                return {"kernel_target": name, "simd": _NAMED_SIMD.get(name, "unknown"), "cpu": cpu_model()}
    else:
        features = {k for k, v in ll.get_host_cpu_features().items() if v}
    simd = next((s for s in ("avx512f", "avx2", "avx", "sse4.2", "neon") if s in features), "baseline")
    return {"kernel_target": name, "simd": simd.removesuffix("f"), "cpu": cpu_model()}
