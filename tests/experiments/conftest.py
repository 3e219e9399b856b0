"""Fixtures shared by the bench tests: a changeable copy of a module's bench folder, file modification times.

A test module that uses :func:`bench_copy` defines a module-scoped ``grid`` fixture returning
``(bench folder, BenchResult)`` of the real bench it runs once.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest


@pytest.fixture
def bench_copy(grid: tuple[Path, Any], tmp_path: Path) -> Path:
    """A copy of the module's bench folder (its ``grid`` fixture) that the test may change."""
    dst = tmp_path / "copy"
    shutil.copytree(grid[0], dst)
    return dst


def _mtimes(root: Path) -> dict[str, int]:
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in sorted((root / "runs").rglob("*.json"))}


@pytest.fixture
def mtimes() -> Callable[[Path], dict[str, int]]:
    """``mtimes(DIR)``: the modification time (ns) of every JSON file under ``DIR/runs/``, by path in ``DIR``."""
    return _mtimes
