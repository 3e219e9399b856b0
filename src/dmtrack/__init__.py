"""dmtrack — direct multichannel tracking.

Semi-dense monocular visual odometry (LSD-SLAM style) that aligns images directly on per-pixel
multichannel features.  Conventions (poses are camera-to-world, OpenCV camera axes, Lie algebra
tangent order (υ, ω)) are documented in ``docs/conventions.md``.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
