"""dmtrack.initialization: a start that does not depend on a random map.

LSD-SLAM (and the paper) start the first keyframe from a random inverse depth; the map converges, or not, over
the first 100–150 frames, and that decides the accuracy of the whole run. :class:`GeometricInitializer` instead
waits until the camera has moved enough, finds the relative motion from tracked corners (OpenCV: KLT, essential
matrix and homography with RANSAC, triangulation; a Schur-complement Levenberg–Marquardt bundle adjustment, with
``scipy.optimize.least_squares`` as its test reference) and makes the first keyframe's map with the odometry's own
stereo from the frames seen (docs/initialization.md).

It sits above :mod:`dmtrack.odometry`, which only receives the result
(:class:`~dmtrack.odometry.initial_map.InitialMap`); :func:`dmtrack.track` runs it when ``VOConfig.init`` is
``"geometric"``.
"""

from dmtrack.initialization.bundle import BundleResult, bundle_adjust
from dmtrack.initialization.first_map import grey_frame, make_first_map
from dmtrack.initialization.initializer import GeometricInitializer
from dmtrack.initialization.tracks import CornerTracks
from dmtrack.initialization.twoview import TwoView, two_view

__all__ = [
    "BundleResult",
    "CornerTracks",
    "GeometricInitializer",
    "TwoView",
    "bundle_adjust",
    "grey_frame",
    "make_first_map",
    "two_view",
]
