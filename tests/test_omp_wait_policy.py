"""``import dmtrack`` makes libgomp's idle threads sleep (``OMP_WAIT_POLICY=PASSIVE``) unless the user chose."""

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

