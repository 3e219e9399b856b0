"""Video files (``.mp4``, ``.avi``, ``.mov``, ``.mkv``, …) read frame by frame with OpenCV.

Frames are decoded lazily: reading frame ``i`` after frame ``i − 1`` decodes one frame; any other access seeks
(``CAP_PROP_POS_FRAMES``) first.  When the sequence is opened the file is scanned once with ``grab()`` (no
colour conversion) to count the frames exactly and to read each frame's presentation time
(``CAP_PROP_POS_MSEC``); ``scan=False`` trusts the container's frame count and uses ``index / fps`` instead.

Intrinsics: ``--intrinsics fx,fy,cx,cy`` (``open_sequence(..., intrinsics=…)``), or a sidecar file next to the
video — ``VIDEO.camera.txt`` (e.g. ``walk.mp4.camera.txt``), ``VIDEO_STEM.txt``-style ``walk.camera.txt``, or
``camera.txt`` in the same folder — containing either ``fx fy cx cy`` / a 3×3 K (pixels) or a 4-line
DSO/LSD-SLAM calibration (then the frames are undistorted and ``camera`` is the output pinhole camera).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from dmtrack.datasets.base import LoaderSequence
from dmtrack.datasets.intrinsics import read_intrinsics_file
from dmtrack.datasets.undistort import UndistortedSequence, read_calibration_file, undistort_sequence
from dmtrack.errors import DatasetError, InputError
from dmtrack.io.files import read_text_file

FORMAT = "video"
VIDEO_EXTENSIONS = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg", ".wmv", ".flv", ".ts")


def detect(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() in VIDEO_EXTENSIONS


def sidecar_calibration(video: Path) -> Path | None:
    """The intrinsics file belonging to ``video``, if any."""
    for p in (video.with_name(video.name + ".camera.txt"), video.with_suffix(".camera.txt"),
              video.parent / "camera.txt"):
        if p.exists():  # a folder of that name is reported when it is read
            return p
    return None


class _Reader:
    """One ``cv2.VideoCapture``, reopened on demand, that remembers where it is."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._cap: cv2.VideoCapture | None = None
        self._next = 0  # index of the frame the next read() returns

    def _open(self) -> cv2.VideoCapture:
        if self._cap is None:
            cap = cv2.VideoCapture(str(self.path))
            if not cap.isOpened():
                raise InputError("OpenCV cannot open this video (unsupported container or codec, or not a video)",
                                 path=self.path)
            self._cap = cap
            self._next = 0
        return self._cap

    def read(self, i: int) -> np.ndarray:
        cap = self._open()
        if i != self._next:
            cap.set(cv2.CAP_PROP_POS_FRAMES, float(i))
            self._next = i
        ok, frame = cap.read()
        if not ok or frame is None:
            self.close()
            raise InputError(f"OpenCV cannot decode frame {i}", path=self.path)
        self._next = i + 1
        if frame.ndim == 2:
            return frame
        return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
        self._cap = None
        self._next = 0

    def __getstate__(self) -> dict[str, Any]:
        return {"path": self.path, "_cap": None, "_next": 0}


def _scan(path: Path) -> tuple[int, np.ndarray, float, tuple[int, int]]:
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise InputError("OpenCV cannot open this video (unsupported container or codec, or not a video)", path=path)
    try:
        fps = float(cap.get(cv2.CAP_PROP_FPS))
        w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        times = []
        while cap.grab():
            times.append(cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0)
    finally:
        cap.release()
    return len(times), np.asarray(times, dtype=np.float64), fps, (w, h)


def open_video(
    path: str | Path,
    fps: float | None = None,
    scan: bool = True,
    undistort: bool = True,
    multiple: int = 16,
) -> LoaderSequence | UndistortedSequence:
    """Open a video file.

    Parameters
    ----------
    fps : override the frame rate: timestamps become ``index / fps``.
    scan : count frames and read presentation times by scanning the file once (default); otherwise use the
        container's frame count and ``index / fps``.
    undistort : apply a 4-line calibration sidecar (default).
    """
    p = Path(path)
    if p.is_dir():
        raise DatasetError("video file expected, but this is a folder", path=p)
    if not p.is_file():
        raise DatasetError("no such video file", path=p)
    if scan:
        n, times, container_fps, (w, h) = _scan(p)
    else:
        cap = cv2.VideoCapture(str(p))
        if not cap.isOpened():
            raise InputError("OpenCV cannot open this video (unsupported container or codec, or not a video)",
                             path=p)
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        container_fps = float(cap.get(cv2.CAP_PROP_FPS))
        w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        cap.release()
        times = np.full(max(n, 0), np.nan)
    if n <= 0 or w <= 0 or h <= 0:
        raise InputError("OpenCV cannot decode any frame of this video (unsupported codec?)", path=p)
    details: dict[str, Any] = {"container_fps": container_fps if math.isfinite(container_fps) else None,
                               "decoder": "OpenCV VideoCapture"}
    if fps is not None:
        timestamps = np.arange(n) / float(fps)
        details["timestamps"] = f"index / {fps:g} fps"
    elif scan and np.isfinite(times).all() and (np.diff(times) > 0).all():
        timestamps = times
        details["timestamps"] = "container presentation times (CAP_PROP_POS_MSEC)"
    elif container_fps > 0 and math.isfinite(container_fps):
        timestamps = np.arange(n) / container_fps
        details["timestamps"] = f"index / {container_fps:g} fps (container frame rate)"
    else:
        timestamps = np.arange(n, dtype=np.float64)
        details["timestamps"] = "frame index"

    reader = _Reader(p)
    camera = None
    calib = None
    side = sidecar_calibration(p)
    if side is not None:
        lines = [ln for ln in read_text_file(side, "intrinsics file").splitlines() if ln.strip()]
        if len(lines) >= 4:
            calib = read_calibration_file(side, flavour="dso")
            camera = calib.model.pinhole()
        else:
            camera = read_intrinsics_file(side, w, h)
        details["intrinsics_source"] = side.name
    else:
        details["intrinsics_source"] = None
    seq = LoaderSequence(
        name=p.stem,
        format=FORMAT,
        root=p,
        load_image=reader.read,
        timestamps=timestamps,
        camera=camera,
        size=(w, h),
        details=details,
    )
    if calib is not None and undistort:
        return undistort_sequence(seq, calib, multiple)
    return seq
