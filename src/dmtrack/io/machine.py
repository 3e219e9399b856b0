"""Facts about this machine that results are stamped with (standard library only: cheap to import anywhere)."""

from __future__ import annotations

import platform


def cpu_model() -> str:
    """The processor's model name (``/proc/cpuinfo`` on Linux; ``platform`` elsewhere)."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return cpu


def process_age_s() -> float | None:
    """Seconds since this process was started (Linux: ``/proc/self/stat``'s start time against ``CLOCK_BOOTTIME``;
    10 ms resolution); ``None`` where that cannot be read. For ``dmtrack run`` it is the time since the command was
    launched, interpreter start-up included."""
    import os
    import time

    try:
        with open("/proc/self/stat", encoding="ascii") as fh:
            fields = fh.read().rsplit(")", 1)[1].split()
        started = int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22 of proc(5): start time after boot, ticks
        return max(0.0, time.clock_gettime(time.CLOCK_BOOTTIME) - started)
    except (OSError, ValueError, IndexError, AttributeError):
        return None


def release_free_memory() -> bool:
    """Give the C heap's free pages back to the system (glibc's ``malloc_trim(0)``; elsewhere nothing).

    Memory freed by numpy stays with the allocator, and its pages stay resident, when it sits below memory still in
    use; after a phase that freed much (the geometric start's frames and first map) this returns those pages, so
    the run's resident memory is what it holds. Returns whether any memory was released."""
    import ctypes
    import ctypes.util

    global _LIBC
    if _LIBC is None:
        try:
            _LIBC = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            _LIBC.malloc_trim.argtypes = [ctypes.c_size_t]
        except (OSError, AttributeError):
            _LIBC = False
    return bool(_LIBC and _LIBC.malloc_trim(0))


_LIBC = None


def numba_blas_without_scipy_linalg() -> bool:
    """Load ``scipy.linalg.cython_blas`` — the table of BLAS functions that numba looks up — on its own, without
    running ``scipy.linalg``'s ``__init__``; return whether it was loaded here.

    numba imports that module when it sets up its compiler (``numba.np.arraymath`` checks that BLAS is there), and
    Python imports a submodule's package first: all of ``scipy.linalg``, 0.1 s and 27 MB resident for a module of
    1.6 MB that none of dmtrack's kernels calls (they avoid BLAS). The extension module is the same object either way:
    put in ``sys.modules`` under its own name, as the import system would, it is what numba's check and any later
    ``import scipy.linalg.cython_blas`` find, and ``import scipy.linalg`` still works afterwards. Call it before the
    first kernel is compiled or loaded; it does nothing when ``scipy.linalg`` or the module is already there, and
    leaves the normal import to happen when the module cannot be found (a different scipy layout)."""
    import importlib.machinery
    import importlib.util
    import os
    import sys

    name = "scipy.linalg.cython_blas"
    if name in sys.modules or "scipy.linalg" in sys.modules:
        return False
    try:
        import scipy
    except ImportError:
        return False
    folder = os.path.join(os.path.dirname(scipy.__file__), "linalg")
    path = next((p for p in (os.path.join(folder, "cython_blas" + s) for s in importlib.machinery.EXTENSION_SUFFIXES)
                 if os.path.isfile(p)), None)  # fmt: skip
    spec = importlib.util.spec_from_file_location(name, path) if path else None
    if spec is None or spec.loader is None:
        return False
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except Exception:  # leave it to the normal import
        del sys.modules[name]
        return False
    return True
