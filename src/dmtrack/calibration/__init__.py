"""Intrinsics from a sequence's own images by a self-calibrating bundle adjustment of corner tracks (COLMAP's way):
:mod:`~dmtrack.calibration.tracks` follows corners over keyframes, :mod:`~dmtrack.calibration.bundle` adjusts the
keyframes' poses, the points and the focal length (and k1) together. ``dmtrack calibrate-from-video`` runs it on the
odometry's poses (:mod:`dmtrack.pipeline.self_calibration`)."""

from dmtrack.calibration.bundle import MODELS, BundleCalibration, Observations, self_calibrate, triangulate
from dmtrack.calibration.tracks import track_keyframes

__all__ = ["MODELS", "BundleCalibration", "Observations", "self_calibrate", "track_keyframes", "triangulate"]
