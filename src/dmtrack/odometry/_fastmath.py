"""Fast-math flags shared by the multichannel numba loops of the odometry kernels, and where such loops may live.

Re-association lets LLVM vectorise the sums over channels (AVX2: 8 float32 / 4 float64 lanes); no nnan/ninf, so a
select may see inf/nan in its unused branch safely. Only N > 1 takes these loops: grey keeps the scalar arithmetic
of the numpy references. The results equal the references up to rounding.

One compiled copy per loop
--------------------------
The order of the re-associated sums is LLVM's choice *per compilation*: every time such code is optimised again,
the order (and so the rounding) may change. numba optimises a callee again whenever it links it into a caller:
a jitted helper exists as its own compiled function *and* as a copy inside every caller's machine code (the copy
is what the caller's on-disk cache entry holds), and each ``prange`` body is likewise compiled on its own and
copied into its kernel. Which copy runs depends on the process: numba's JIT resolves a symbol to its *first*
definition, so the process that compiles a kernel runs the helpers and ``prange`` bodies as compiled on their
own, while a process that loads the kernel from numba's cache runs the copies inside it. (Grey is not affected:
re-optimising IEEE arithmetic without fast-math flags never changes its result.) The multichannel kernels
therefore keep every fast-math loop

* in a helper that stays a call (not inlined: a loop over channels with several sums, like
  :func:`dmtrack.odometry._tracker_residuals._channel_sums`) — small reductions that LLVM would inline into a
  ``prange`` body use plain IEEE arithmetic instead (e.g. ``frame._magnitude_sum``); and
* *pinned* with :func:`pin_cached`: the helper's own cache entries are loaded when its module is imported, before
  any caller, so that every process — the one that compiles and the ones that load the cache — runs the same,
  separately compiled helper.

Callers reach a loop through that one compiled helper, so for the same input the compiling run and every cached
run give the same bytes (``tests/faults/test_cache_determinism.py``), and the serial and threaded evaluations are
the same compiled code too (the serial tracker evaluation and depth update run the parallel build on one thread).
"""

from typing import Any

FASTMATH = frozenset({"reassoc", "contract", "arcp", "nsz"})


def pin_cached(*helpers: Any) -> None:
    """Load every overload of the numba dispatchers ``helpers`` that their on-disk cache holds, now.

    Called right after a fast-math helper is defined (at import, before any kernel that calls it runs): the
    helper's own compiled code then becomes the definition its callers' cached machine code links to, as in the
    process that compiled them (see the module docstring). Without cache entries (first run, stale source, caching
    off) it does nothing: the callers compile the helper first themselves. Only entries for this machine's code
    generator and this source's bytecode are looked up, so it does not compile (unless a listed cache file vanished).
    """
    for helper in helpers:
        cache = getattr(helper, "_cache", None)
        cache_file = getattr(cache, "_cache_file", None)
        if cache_file is None:  # caching disabled (NullCache)
            continue
        codegen = helper.targetctx.codegen()
        try:
            keys = list(cache_file._load_index())
        except Exception:  # an unreadable index only means nothing to load
            continue
        for key in keys:
            sig = key[0]
            if key == cache._index_key(sig, codegen):
                helper.compile(sig)


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
