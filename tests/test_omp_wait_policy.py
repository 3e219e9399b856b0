"""``import dmtrack`` makes libgomp's idle threads sleep (``OMP_WAIT_POLICY=PASSIVE``) and puts numba's OpenMP layer
before TBB, unless the user chose."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

_PROBE = "import os, dmtrack; print(os.environ.get('OMP_WAIT_POLICY'))"


def _probe(**env: str) -> str:
    base = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    proc = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, env={**base, **env},
                          timeout=120, check=True)  # fmt: skip
    return proc.stdout.strip()


def test_passive_by_default() -> None:
    assert _probe() == "PASSIVE"


@pytest.mark.parametrize("value", ["active", "PASSIVE", "passive"])
def test_the_users_choice_is_kept(value: str) -> None:
    assert _probe(OMP_WAIT_POLICY=value) == value



_LAYER = (
    "import os, dmtrack, numba, numpy as np\n"
    "@numba.njit(parallel=True)\n"
    "def f(a):\n"
    "    s = 0.0\n"
    "    for i in numba.prange(a.size):\n"
    "        s += a[i]\n"
    "    return s\n"
    "f(np.ones(8))\n"
    "print(os.environ.get('NUMBA_THREADING_LAYER_PRIORITY'), numba.threading_layer())\n"
)


def _layer(**env: str) -> tuple[str, str]:
    base = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_THREADING_LAYER")}
    proc = subprocess.run([sys.executable, "-c", _LAYER], capture_output=True, text=True, env={**base, **env},
                          timeout=120, check=True)  # fmt: skip
    priority, layer = proc.stdout.strip().rsplit(" ", 1)
    return priority, layer


def test_openmp_comes_before_tbb() -> None:
    """numba would take a system TBB first (its workers spin between the odometry's short parallel regions);
    ``import dmtrack`` puts OpenMP first, and numba uses it wherever libgomp loads."""
    priority, layer = _layer()
    assert priority == "omp tbb workqueue"
    try:
        from numba.np.ufunc import omppool  # noqa: F401 - only whether numba's OpenMP layer can load here
    except ImportError:
        pytest.skip("numba's OpenMP layer cannot load here (no libgomp)")
    assert layer == "omp"


def test_the_users_layer_is_kept() -> None:
    priority, layer = _layer(NUMBA_THREADING_LAYER="workqueue")
    assert (priority, layer) == ("None", "workqueue")
    priority, _ = _layer(NUMBA_THREADING_LAYER_PRIORITY="workqueue omp tbb")
    assert priority == "workqueue omp tbb"
