"""dmtrack.io.machine: numba's BLAS table loaded without all of scipy.linalg."""

from __future__ import annotations

import subprocess
import sys


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
