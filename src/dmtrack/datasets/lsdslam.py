"""LSD-SLAM sample sequences (``LSD_room``, ``LSD_machine``, ``LSD_foodcourt``, ``LSD_eccv``), image layout.

::

    LSD_room/
      images/ (or the images directly in the folder)   00000.png …  grey 640×480, natural name order
      cameraCalibration.cfg                            LSD-SLAM calibration, 4 lines (see below)
      times.txt                                        optional, one timestamp per image (first column)

``cameraCalibration.cfg`` (LSD-SLAM README §3.1.3, ``Undistorter.cpp``): line 1 ``fx/w fy/h cx/w cy/h ω``
(FOV model, always relative to the image size; ``ω = 0``: pinhole) or ``fx fy cx cy k1 k2 p1 p2`` (OpenCV
radial-tangential, pixels); line 2 input ``width height``; line 3 ``crop`` / ``full`` / ``none`` /
``fx/w fy/h cx/w cy/h 0``; line 4 output ``width height``.  The images are undistorted accordingly
(:mod:`dmtrack.datasets.undistort`); ``camera`` is the output pinhole camera.

These sequences have no ground truth (the paper used them for 3-D reconstruction only).  They were recorded
at 50 fps (paper, Table 1); without ``times.txt`` the timestamps are ``index / fps``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dmtrack.datasets.base import FileSequence
from dmtrack.datasets.imagefolder import image_dir, list_images
from dmtrack.datasets.undistort import read_calibration_file, undistort_sequence
from dmtrack.errors import DatasetError, InputError
from dmtrack.io.images import read_image
from dmtrack.io.trajectory import read_times

FORMAT = "lsd-slam"
CALIBRATION_FILES = ("cameraCalibration.cfg", "camera.cfg", "calib.cfg")
DEFAULT_FPS = 50.0


def _calibration(root: Path) -> Path | None:
    for n in CALIBRATION_FILES:
        if (root / n).is_file():
            return root / n
    return None


def _any_calibration(root: Path) -> Path | None:
    """The first calibration name that exists at all (a folder of that name is reported as such when opening)."""
    return next((root / n for n in CALIBRATION_FILES if (root / n).exists()), None)


def detect(path: Path) -> bool:
    return path.is_dir() and _calibration(path) is not None and image_dir(path) is not None


def open_lsdslam(path: str | Path, fps: float = DEFAULT_FPS, undistort: bool = True, multiple: int = 16):
    """Open an LSD-SLAM image sequence.

    Parameters
    ----------
    fps : frame rate for timestamps when there is no ``times.txt`` (50, as the paper's Table 1).
    undistort : rectify with the calibration file (default).  ``False`` delivers the raw images.
    multiple : the undistorted size is reduced to a multiple of this.
    """
    root = Path(path)
    if not root.is_dir():
        raise DatasetError("not a folder", path=root)
    cfg = _calibration(root) or _any_calibration(root)
    if cfg is None:
        raise DatasetError(f"LSD-SLAM calibration file not found (nor {', '.join(CALIBRATION_FILES[1:])})",
                           path=root / CALIBRATION_FILES[0])
    folder = image_dir(root)
    if folder is None:
        raise DatasetError("no images in the folder or in images/", path=root)
    images = list_images(folder)
    calib = read_calibration_file(cfg, flavour="lsdslam")
    first = read_image(images[0], grey=True)
    if (first.shape[1], first.shape[0]) != (calib.model.width, calib.model.height):
        raise InputError(
            f"the calibration is for {calib.model.width}x{calib.model.height} images, {images[0].name} is "
            f"{first.shape[1]}x{first.shape[0]}",
            path=cfg,
        )
    times = root / "times.txt"
    if times.exists():
        timestamps = read_times(times)
        if timestamps.shape[0] != len(images):
            raise InputError(f"{timestamps.shape[0]} timestamps for {len(images)} images", path=times)
        ts_note = "times.txt"
    else:
        timestamps = np.arange(len(images)) / float(fps)
        ts_note = f"index / {fps:g} fps"
    base = FileSequence(
        name=root.name,
        format=FORMAT,
        root=root,
        image_paths=images,
        timestamps=timestamps,
        camera=calib.model.pinhole(),
        grey=True,
        size=(calib.model.width, calib.model.height),
        details={"timestamps": ts_note, "calibration_file": cfg.name},
    )
    if not undistort:
        base.details["undistortion"] = "off (raw images; camera is only the pinhole part of the model)"
        return base
    return undistort_sequence(base, calib, multiple)
