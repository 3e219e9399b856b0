"""Datasets: one reader per format, format detection, and the synthetic renderer.

>>> from dmtrack.datasets import open_sequence
>>> seq = open_sequence("data/7scenes-redkitchen-0000-0299")   # doctest: +SKIP
>>> frame = seq[0]; frame.image.shape, frame.pose.shape           # doctest: +SKIP
((480, 640, 3), (4, 4))
"""

from dmtrack.datasets.base import FileSequence, Frame, LoaderSequence, Sequence
from dmtrack.datasets.registry import FORMATS, READERS, detect_format, open_sequence
from dmtrack.datasets.undistort import CalibrationFile, UndistortedSequence, Undistorter, read_calibration_file

__all__ = [
    "FORMATS",
    "READERS",
    "CalibrationFile",
    "FileSequence",
    "Frame",
    "LoaderSequence",
    "Sequence",
    "UndistortedSequence",
    "Undistorter",
    "detect_format",
    "open_sequence",
    "read_calibration_file",
]
