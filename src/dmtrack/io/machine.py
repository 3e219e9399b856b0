"""Facts about this machine that results are stamped with, and what a process can do about its own start-up and
memory (standard library only: cheap to import anywhere)."""

from __future__ import annotations

import os
import platform
import sys
from collections.abc import Callable
from typing import Any


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
    libc = _libc()
    return bool(libc and libc.malloc_trim(0))


def _libc():  # glibc with ``malloc_trim`` and ``madvise`` typed, or False where there is none
    import ctypes
    import ctypes.util

    global _LIBC
    if _LIBC is None:
        try:
            _LIBC = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            _LIBC.malloc_trim.argtypes = [ctypes.c_size_t]
            _LIBC.madvise.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
        except (OSError, AttributeError):
            _LIBC = False
    return _LIBC


_LIBC = None

#: Names of shared libraries whose pages :func:`release_idle_library_pages` gives back: LLVM's, which numba needs only
#: to compile or to load a kernel, and whose static initialisers touch tens of MB of it at ``import numba``.
IDLE_LIBRARIES = ("libllvmlite", "libLLVM")

_MADV_DONTNEED = 4  # <sys/mman.h> on Linux


def _clean_library_mappings(names: tuple[str, ...], smaps: str = "/proc/self/smaps") -> list[tuple[int, int, int]]:
    """``(start, end, resident bytes)`` of the mappings of the libraries called ``names`` that can be given back
    safely: private, not writable, file-backed and without a page of their own (``Anonymous: 0 kB`` in ``smaps``: no
    relocated or otherwise written copy, so every resident page is the file's and reads back the same)."""
    found: list[tuple[int, int, int]] = []
    head: list[str] | None = None
    rss = anonymous = -1

    def close() -> None:
        if head is not None and len(head) >= 6 and anonymous == 0 and rss > 0:
            perms, base = head[1], head[5].rsplit("/", 1)[-1]
            if perms.startswith("r") and "w" not in perms and perms.endswith("p") and base.startswith(names):
                start, end = (int(x, 16) for x in head[0].split("-"))
                found.append((start, end, rss * 1024))

    with open(smaps, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            parts = line.split()
            if not parts:
                continue
            if parts[0].endswith(":"):
                if parts[0] == "Rss:":
                    rss = int(parts[1])
                elif parts[0] == "Anonymous:":
                    anonymous = int(parts[1])
                continue
            close()
            head, rss, anonymous = parts, -1, -1
    close()
    return found


def release_idle_library_pages(names: tuple[str, ...] = IDLE_LIBRARIES) -> int:
    """Give back the resident pages of the libraries ``names`` (by default LLVM's) that are copies of their files;
    return the bytes that were resident in them (0 where nothing was done: not Linux, no such library).

    ``import numba`` loads LLVM, whose static initialisers touch about 35 MB of its code and read-only data that are
    not run again; loading the kernels from numba's cache touches more, and once they are loaded a run does not use
    LLVM at all. Those pages count in the process's resident memory as long as they are mapped. This drops them
    (``madvise(MADV_DONTNEED)``) from the mappings that hold nothing but the file's own bytes (private, read-only, no
    written page: :func:`_clean_library_mappings`): a page used again — a kernel compiled or loaded later — is read
    back from the file (the page cache), with the same bytes, so nothing changes but resident memory."""
    libc = _libc() if sys.platform.startswith("linux") else False
    if not libc:
        return 0
    try:
        mappings = _clean_library_mappings(tuple(names))
    except (OSError, ValueError):
        return 0
    return sum(resident for start, end, resident in mappings if libc.madvise(start, end - start, _MADV_DONTNEED) == 0)


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


def compile_bytecode(root: str | os.PathLike[str]) -> tuple[int, int]:
    """Write the bytecode cache (``__pycache__/*.pyc``) of every Python file under ``root`` whose cache is missing or
    stale; return (files compiled, files that could not be: a read-only install or a syntax error).

    Python compiles a module's source on every import when no valid cache is there: in an editable install under
    ``PYTHONDONTWRITEBYTECODE=1`` that is 0.1 s of every run's start-up for dmtrack's modules. An installed wheel
    has its caches written by pip. A cache is fresh when its header holds this interpreter's magic number and the
    source's modification time and size (the check Python's import makes)."""
    import importlib.util
    import py_compile
    from pathlib import Path

    written = failed = 0
    for source in sorted(Path(root).rglob("*.py")):
        cached = importlib.util.cache_from_source(str(source))
        if _bytecode_fresh(source, Path(cached)):
            continue
        try:
            py_compile.compile(str(source), cfile=cached, doraise=True,
                               invalidation_mode=py_compile.PycInvalidationMode.TIMESTAMP)
        except (OSError, py_compile.PyCompileError):
            failed += 1
        else:
            written += 1
    return written, failed


def _bytecode_fresh(source: os.PathLike[str], cached: os.PathLike[str]) -> bool:
    import importlib.util

    try:
        with open(cached, "rb") as f:
            head = f.read(16)
        st = os.stat(source)
    except OSError:
        return False
    return (len(head) == 16 and head[:4] == importlib.util.MAGIC_NUMBER and head[4:8] == b"\0\0\0\0"
            and int.from_bytes(head[8:12], "little") == int(st.st_mtime) & 0xFFFFFFFF
            and int.from_bytes(head[12:16], "little") == st.st_size & 0xFFFFFFFF)


def lazy_exports(package: str, where: dict[str, str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """A package's ``__getattr__`` and ``__dir__`` (PEP 562) that import each name of ``where`` (name → submodule)
    from its submodule on first use, so that importing one submodule does not import the others."""
    import importlib

    def getattr_(name: str) -> Any:
        if name in where:
            return getattr(importlib.import_module(f"{package}.{where[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def dir_() -> list[str]:
        return sorted([*vars(sys.modules[package]), *where])

    return getattr_, dir_
