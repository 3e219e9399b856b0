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
