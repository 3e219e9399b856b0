"""Shared fixtures.

Tests that need the real data in ``../shared`` use the ``shared_dir`` fixture (or the ``SHARED`` path
with ``requires_shared``) and are skipped with a clear reason when it is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("DMTRACK_SHARED", REPO.parent / "shared")).resolve()
SAMPLE = REPO / "data" / "7scenes-redkitchen-0000-0299"

requires_shared = pytest.mark.skipif(
    not (SHARED / "data").is_dir(),
    reason=f"../shared (real datasets) not found at {SHARED}; set DMTRACK_SHARED to its path",
)


@pytest.fixture(autouse=True, scope="session")
def _isolated_user_dir(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The user's calibrated scales / PCA bases (~/.config/dmtrack) must not leak into the tests."""
    os.environ["DMTRACK_HOME"] = str(tmp_path_factory.mktemp("dmtrack-home"))


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    if not (SHARED / "data").is_dir():
        pytest.skip(f"../shared (real datasets) not found at {SHARED}; set DMTRACK_SHARED to its path")
    return SHARED


@pytest.fixture(scope="session")
def sample_dir() -> Path:
    """The real 7-Scenes sample shipped in the repository (data/)."""
    assert SAMPLE.is_dir(), f"the sample sequence is missing from the repository: {SAMPLE}"
    return SAMPLE
