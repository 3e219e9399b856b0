"""Fast-math flags shared by the multichannel numba loops of the odometry kernels.

Re-association lets LLVM vectorise the sums over channels (AVX2: 8 float32 / 4 float64 lanes); no nnan/ninf, so a
select may see inf/nan in its unused branch safely. Only N > 1 takes these loops: grey keeps the scalar arithmetic
of the numpy references. The order of the vectorised sums is chosen by LLVM per compilation context, so a loop
must reach its callers through one compiled kernel wherever bit-identical results are required (the serial
tracker evaluation and depth update run the parallel build on one thread for that reason); the results equal the
references up to rounding.
"""

FASTMATH = frozenset({"reassoc", "contract", "arcp", "nsz"})


def kernel_target() -> dict[str, str]:
    """What the numba kernels are compiled for on this machine: the reproducibility key of multichannel runs.

    ``kernel_target`` is LLVM's CPU name (``NUMBA_CPU_NAME`` when set, e.g. ``generic``), ``simd`` the widest vector
    instruction set it has (avx512 / avx2 / avx / sse4.2 / neon / baseline) and ``cpu`` the processor's model name.
    Two machines with the same ``kernel_target`` run the same machine code, so every feature's trajectory is
    byte-identical there; across targets only grey (scalar arithmetic) is, because the re-associated channel sums
    above are vectorised to the target's width and round differently.
    """
    import os

    import llvmlite.binding as ll

    from dmtrack.io.machine import cpu_model

    name = os.environ.get("NUMBA_CPU_NAME") or ll.get_host_cpu_name()
    if os.environ.get("NUMBA_CPU_NAME"):
        features = set((os.environ.get("NUMBA_CPU_FEATURES") or "").replace("+", " ").replace(",", " ").split())
    else:
        features = {k for k, v in ll.get_host_cpu_features().items() if v}
    simd = next((s for s in ("avx512f", "avx2", "avx", "sse4.2", "neon") if s in features), "baseline")
    return {"kernel_target": name, "simd": simd.removesuffix("f"), "cpu": cpu_model()}
