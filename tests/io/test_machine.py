"""dmtrack.io.machine: numba's BLAS table loaded without all of scipy.linalg; LLVM's idle pages given back."""

from __future__ import annotations

import subprocess
import sys

import pytest

from dmtrack.io.machine import _clean_library_mappings


def _python(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.strip()


def test_the_odometry_loads_its_kernels_without_scipy_linalg():
    """Importing the odometry loads scipy's BLAS table on its own; numba's compiler set-up (the warm-up's kernels)
    then finds it, and all of scipy.linalg (0.1 s, 27 MB) is never imported."""
    code = ("import sys\nimport dmtrack.pipeline.run as r\nr.warm_up('gray', strict=True)\n"
            "print('numba.np.arraymath' in sys.modules, 'scipy.linalg.cython_blas' in sys.modules,"
            " 'scipy.linalg' in sys.modules)\n")  # fmt: skip
    assert _python(code) == "True True False"


def test_scipy_linalg_and_numba_blas_still_work_afterwards():
    """The module put in place is scipy's own extension: a later ``import scipy.linalg`` runs its package and finds
    it, its functions give the right answers, and a numba kernel that calls BLAS (``np.dot`` of matrices) compiles
    and computes against it."""
    code = """
import numpy as np
from dmtrack.io.machine import numba_blas_without_scipy_linalg
assert numba_blas_without_scipy_linalg()
assert not numba_blas_without_scipy_linalg()  # once
import sys
blas = sys.modules['scipy.linalg.cython_blas']
import numba
@numba.njit
def product(a, b):
    return np.dot(a, b)
a = np.arange(6.0).reshape(2, 3); b = np.arange(12.0).reshape(3, 4)
assert np.array_equal(product(a, b), a @ b)
import scipy.linalg
from scipy.linalg import cython_blas
assert cython_blas is blas and 'dgemm' in blas.__pyx_capi__
m = np.array([[4.0, 1.0], [1.0, 3.0]])
assert np.allclose(scipy.linalg.cho_solve(scipy.linalg.cho_factor(m), [1.0, 2.0]), np.linalg.solve(m, [1.0, 2.0]))
print('ok')
"""
    assert _python(code) == "ok"


def test_nothing_is_done_where_scipy_linalg_is_already_there():
    code = ("import scipy.linalg\nfrom dmtrack.io.machine import numba_blas_without_scipy_linalg\n"
            "print(numba_blas_without_scipy_linalg())\n")  # fmt: skip
    assert _python(code) == "False"


_SMAPS = """\
7f0000000000-7f0000100000 r--p 00000000 08:01 11 /venv/llvmlite/binding/libllvmlite.so
Size:               1024 kB
Rss:                 512 kB
Anonymous:             0 kB
7f0000100000-7f0000300000 r-xp 00100000 08:01 11 /venv/llvmlite/binding/libllvmlite.so
Rss:                2048 kB
Anonymous:             0 kB
7f0000300000-7f0000400000 r--p 00300000 08:01 11 /venv/llvmlite/binding/libllvmlite.so
Rss:                 100 kB
Anonymous:           100 kB
7f0000400000-7f0000500000 rw-p 00400000 08:01 11 /venv/llvmlite/binding/libllvmlite.so
Rss:                  64 kB
Anonymous:            64 kB
7f0000500000-7f0000600000 r-xs 00000000 08:01 12 /usr/lib/libLLVM-15.so
Rss:                 256 kB
Anonymous:             0 kB
7f0000600000-7f0000700000 r-xp 00000000 08:01 12 /usr/lib/libLLVM-15.so
Rss:                   0 kB
Anonymous:             0 kB
7f0000700000-7f0000800000 r-xp 00000000 08:01 13 /usr/lib/libcv2.so
Rss:                 400 kB
Anonymous:             0 kB
7f0000800000-7f0000900000 r-xp 00000000 08:01 12 /usr/lib/libLLVM-15.so
Rss:                  12 kB
Anonymous:             0 kB
7ffd00000000-7ffd00021000 rw-p 00000000 00:00 0                          [stack]
Rss:                  20 kB
Anonymous:            20 kB
"""


def test_only_unwritten_private_read_only_pages_of_the_named_libraries_are_given_back(tmp_path):
    """A relocated read-only segment (pages of its own: RELRO), a writable or shared mapping, an empty one and other
    libraries are left alone."""
    smaps = tmp_path / "smaps"
    smaps.write_text(_SMAPS)
    assert _clean_library_mappings(("libllvmlite", "libLLVM"), str(smaps)) == [
        (0x7F0000000000, 0x7F0000100000, 512 * 1024),
        (0x7F0000100000, 0x7F0000300000, 2048 * 1024),
        (0x7F0000800000, 0x7F0000900000, 12 * 1024),
    ]
    assert _clean_library_mappings(("libcv2",), str(smaps)) == [(0x7F0000700000, 0x7F0000800000, 400 * 1024)]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/smaps (Linux)")
def test_llvm_pages_given_back_and_numba_still_compiles_and_loads():
    """After ``import numba`` LLVM's library holds resident pages; they are given back (resident file-backed memory
    falls by as much), and afterwards numba still compiles a new kernel and loads a cached one, with the right
    results — the pages it needs are read back from the file."""
    code = """
import numpy as np, numba
from dmtrack.io.machine import release_idle_library_pages

def file_kb():
    return next(int(l.split()[1]) for l in open('/proc/self/status') if l.startswith('RssFile'))

before = file_kb()
released = release_idle_library_pages()
after = file_kb()
assert released > 8 << 20, released
assert before - after >= 0.8 * released / 1024, (before, after, released)

@numba.njit
def poly(x):
    return x * x - 3.0 * x + 2.0

assert poly(4.0) == 6.0
from dmtrack.odometry._cloud import warm_up
warm_up()  # kernels from numba's cache (or compiled)
assert release_idle_library_pages() > 0  # what compiling and loading read back, given back again
assert poly(5.0) == 12.0 and np.isclose(poly(0.5), 0.75)
print('ok')
"""
    assert _python(code) == "ok"


def test_compile_bytecode_writes_what_is_missing_or_stale(tmp_path, monkeypatch) -> None:
    """Missing caches are written (also under PYTHONDONTWRITEBYTECODE), fresh ones are left alone, a changed source
    gets a new one that Python's import accepts, and a file that does not compile is counted, not raised."""
    import importlib
    import importlib.util
    import os
    from pathlib import Path

    from dmtrack.io.machine import _bytecode_fresh, compile_bytecode

    pkg = tmp_path / "bcpkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("VALUE = 1\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "b.py").write_text("def f():\n    return 2\n")
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    assert compile_bytecode(pkg) == (4, 0)
    a_pyc = Path(importlib.util.cache_from_source(str(pkg / "a.py")))
    assert a_pyc.is_file() and _bytecode_fresh(pkg / "a.py", a_pyc)
    assert compile_bytecode(pkg) == (0, 0)
    (pkg / "a.py").write_text("VALUE = 12\n")  # another size: stale whatever the clock's resolution
    assert not _bytecode_fresh(pkg / "a.py", a_pyc)
    assert compile_bytecode(pkg) == (1, 0)
    # Python's import takes that cache: a source changed under the same size and time still imports as cached
    st = (pkg / "a.py").stat()
    (pkg / "a.py").write_text("VALUE = 13\n")
    os.utime(pkg / "a.py", ns=(st.st_atime_ns, st.st_mtime_ns))
    monkeypatch.syspath_prepend(str(tmp_path))
    assert importlib.import_module("bcpkg.a").VALUE == 12
    (pkg / "bad.py").write_text("def (:\n")
    assert compile_bytecode(pkg) == (0, 1)
    (pkg / "sub" / "b.py").write_text("def f():\n    return 22\n")
    for cached in (pkg / "sub" / "__pycache__").iterdir():
        cached.unlink()
    (pkg / "sub" / "__pycache__").rmdir()
    (pkg / "sub" / "__pycache__").write_text("")  # a file where the cache's folder should be: nothing can be written
    assert compile_bytecode(pkg) == (0, 3)  # sub/__init__.py, sub/b.py and bad.py
