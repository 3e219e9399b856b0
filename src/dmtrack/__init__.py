"""dmtrack — direct multichannel tracking.

Semi-dense monocular visual odometry (LSD-SLAM style) that aligns images directly on per-pixel
multichannel features.  Conventions (poses are camera-to-world, OpenCV camera axes, Lie algebra
tangent order (υ, ω)) are documented in ``docs/conventions.md``.

>>> import dmtrack
>>> result = dmtrack.track("data/7scenes-redkitchen-0000-0299", feature="gray", max_frames=50)  # doctest: +SKIP

The heavy modules (numba kernels, OpenCV) are imported on first use, so ``import dmtrack`` is cheap.
"""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"

__all__ = ["RunResult", "__version__", "open_sequence", "run_to_directory", "track"]

_LAZY = {
    "track": "dmtrack.api",
    "run_to_directory": "dmtrack.api",
    "RunResult": "dmtrack.api",
    "open_sequence": "dmtrack.datasets",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'dmtrack' has no attribute {name!r}")
