"""A sliding window of keyframes optimised jointly: photometric bundle adjustment on N channels, with the camera's
intrinsics optionally estimated from the images (issue 38; docs/window.md).

:class:`SlidingWindow` is what the odometry is given (``VisualOdometry(window=…)``, ``dmtrack run --window K``);
:class:`PhotometricBundle` is the optimiser; :mod:`dmtrack.window._kernels` its numba kernels with their numpy
reference.
"""

from dmtrack.window.bundle import BundleReport, HostPoints, PhotometricBundle, WindowKeyframe, sample_points
from dmtrack.window.sliding import SlidingWindow, WindowStats

__all__ = [
    "BundleReport",
    "HostPoints",
    "PhotometricBundle",
    "SlidingWindow",
    "WindowKeyframe",
    "WindowStats",
    "sample_points",
]
