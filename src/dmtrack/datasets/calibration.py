"""Camera calibration from views of a checkerboard or a ChArUco board (``dmtrack calibrate-camera``).

Views come from a folder of images, a video file or a live camera (``camera:N``): every ``every``-th frame is
searched for the board — a checkerboard with ``columns × rows`` *inner* corners (``cv2.findChessboardCorners``,
refined with ``cv2.cornerSubPix``) or a ChArUco board with the same inner corners, i.e. ``(columns + 1) ×
(rows + 1)`` squares (``cv2.aruco.CharucoDetector``; partial views count).  ``cv2.calibrateCamera`` then fits
the radial-tangential model ``k1 k2 p1 p2`` (``k3`` is held at 0: the DSO calibration line has no place for it,
and it over-fits ordinary lenses).  Views whose RMS reprojection error is an outlier — above
``outlier_ratio ×`` the median and above :data:`MIN_OUTLIER_PX` — are rejected one at a time, worst first, and
the camera is calibrated again without them.

The result is written as a 4-line DSO calibration file (what :func:`~dmtrack.datasets.undistort.read_calibration_file`
reads, what ``--intrinsics FILE`` and a video's ``camera.txt`` sidecar accept)::

    RadTan fx fy cx cy k1 k2 p1 p2      (pixels)
    W H                                 (input size)
    fx' fy' cx' cy' 0                   (output: the largest undistorted rectangle without invalid pixels,
                                         relative to W H; DSO's own "crop" folds a k1 < 0 lens, so it is written out)
    W H                                 (output size, reduced to a multiple of 16 when used)

It is read back before it replaces any existing file.  A JSON sidecar (``camera.json`` for ``camera.txt``)
holds the full result: K, the distortion coefficients, the RMS error, each view's error, the rejected views, the
image size and the board.

Squares are measured in any unit (metres, millimetres): the intrinsics do not depend on it; the board poses
(not written) would be in that unit.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np

from dmtrack.datasets.imagefolder import list_images
from dmtrack.datasets.stream import CaptureFactory, capture_target, is_stream
from dmtrack.datasets.undistort import crop_camera, crop_output_line, radtan_text, read_calibration_file
from dmtrack.datasets.video import detect as is_video
from dmtrack.errors import DmtrackError, InputError, OutputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.geometry.distortion import RadTanModel
from dmtrack.io.atomic import atomic_path, write_text
from dmtrack.io.images import read_image

#: Fewest usable views ``cv2.calibrateCamera`` is given (10–20 from different angles are recommended).
MIN_VIEWS = 3
#: A view is only rejected as an outlier when its RMS reprojection error is above this many pixels too.
MIN_OUTLIER_PX = 0.5
#: Fewest ChArUco corners a partial view must show to be used.
MIN_CHARUCO_CORNERS = 8
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)


# ----------------------------------------------------------------------------------------------------
# the board
# ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Board:
    """A calibration board.

    Attributes
    ----------
    columns, rows : inner corners along a row and along a column (a 10 × 7-square checkerboard is 9 × 6).
    square : side of one square, in any unit.
    charuco : ArUco dictionary name (e.g. ``"DICT_5X5_100"``) of a ChArUco board, or ``None`` for a checkerboard.
    marker : side of a ChArUco marker (default 0.75 × ``square``).
    legacy : ChArUco boards printed with OpenCV < 4.6 (``setLegacyPattern``: the pattern differs for an even
        number of square rows).
    """

    columns: int
    rows: int
    square: float
    charuco: str | None = None
    marker: float | None = None
    legacy: bool = False

    def __post_init__(self) -> None:
        if self.columns < 2 or self.rows < 2:
            raise InputError(f"board {self.columns}x{self.rows}: needs at least 2x2 inner corners")
        if not (math.isfinite(self.square) and self.square > 0):
            raise InputError(f"square size {self.square}: must be a positive number")
        if self.charuco is not None:
            marker = self.marker_size
            if not (math.isfinite(marker) and 0 < marker < self.square):
                raise InputError(f"ChArUco marker size {marker:g}: must be positive and smaller than the square "
                                 f"({self.square:g})")

    @property
    def size_text(self) -> str:
        return f"{self.columns}x{self.rows}"

    @property
    def marker_size(self) -> float:
        return 0.75 * self.square if self.marker is None else float(self.marker)

    def object_points(self) -> np.ndarray:
        """(columns·rows, 3) float32 corners in the board's plane (z = 0), row by row, as OpenCV orders them."""
        grid = np.mgrid[0 : self.columns, 0 : self.rows].T.reshape(-1, 2)
        pts = np.zeros((grid.shape[0], 3), np.float32)
        pts[:, :2] = grid * self.square
        return pts

    def describe(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "type": "charuco" if self.charuco else "checkerboard",
            "inner_corners": [self.columns, self.rows],
            "square": self.square,
        }
        if self.charuco:
            d.update(squares=[self.columns + 1, self.rows + 1], dictionary=self.charuco, marker=self.marker_size,
                     legacy_pattern=self.legacy)
        return d


def parse_board(text: str) -> tuple[int, int]:
    """``"9x6"`` → ``(9, 6)`` (inner corners)."""
    m = re.fullmatch(r"\s*([0-9]+)\s*[xX×,]\s*([0-9]+)\s*", text)
    if not m:
        raise InputError(f"--board {text!r}: expected COLUMNSxROWS inner corners, e.g. 9x6")
    return int(m.group(1)), int(m.group(2))


class _Detector:
    """Finds the board in a grey image: ``(image points (N, 2), object points (N, 3))`` or ``None``."""

    def __init__(self, board: Board) -> None:
        self.board = board
        self._objp = board.object_points()
        self._charuco: Any = None
        if board.charuco is not None:
            aruco = getattr(cv2, "aruco", None)
            if aruco is None or not hasattr(aruco, "CharucoDetector"):
                raise InputError(f"ChArUco boards need cv2.aruco (OpenCV ≥ 4.7); this OpenCV {cv2.__version__} has "
                                 "none: pip install opencv-contrib-python-headless, or use a checkerboard")
            name = board.charuco.upper()
            if not name.startswith("DICT_"):
                name = "DICT_" + name
            if not hasattr(aruco, name):
                known = ", ".join(sorted(n for n in dir(aruco) if n.startswith("DICT_")))
                raise InputError(f"--charuco {board.charuco!r}: unknown ArUco dictionary (known: {known})")
            dictionary = aruco.getPredefinedDictionary(getattr(aruco, name))
            cb = aruco.CharucoBoard((board.columns + 1, board.rows + 1), board.square, board.marker_size, dictionary)
            if board.legacy:
                cb.setLegacyPattern(True)
            self._charuco_board = cb
            self._charuco = aruco.CharucoDetector(cb)

    def __call__(self, grey: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        if self._charuco is not None:
            return self._detect_charuco(grey)
        size = (self.board.columns, self.board.rows)
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH + cv2.CALIB_CB_NORMALIZE_IMAGE + cv2.CALIB_CB_FAST_CHECK
        found, corners = cv2.findChessboardCorners(grey, size, flags=flags)
        if not found or corners is None:
            return None
        pts = corners.reshape(-1, 2)
        # the refinement window: below half the smallest corner spacing, so that it sees one corner only
        grid = pts.reshape(self.board.rows, self.board.columns, 2)
        spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=-1).min(),
                      np.linalg.norm(np.diff(grid, axis=1), axis=-1).min())
        half = int(max(2, min(11, math.floor(spacing * 0.4))))
        corners = cv2.cornerSubPix(grey, corners, (half, half), (-1, -1), _SUBPIX_CRITERIA)
        return corners.reshape(-1, 2).astype(np.float32), self._objp

    def _detect_charuco(self, grey: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        corners, ids, _, _ = self._charuco.detectBoard(grey)
        if corners is None or ids is None or len(ids) < MIN_CHARUCO_CORNERS:
            return None
        obj, img = self._charuco_board.matchImagePoints(corners, ids)
        obj = np.asarray(obj, np.float32).reshape(-1, 3)
        img = np.asarray(img, np.float32).reshape(-1, 2)
        if obj.shape[0] < MIN_CHARUCO_CORNERS:
            return None
        # corners on one line do not constrain a homography
        centred = obj[:, :2] - obj[:, :2].mean(axis=0)
        if np.linalg.svd(centred, compute_uv=False)[-1] < 1e-6 * self.board.square:
            return None
        return img, obj


# ----------------------------------------------------------------------------------------------------
# views from a folder, a video or a camera
# ----------------------------------------------------------------------------------------------------
def _grey(image: np.ndarray) -> np.ndarray:
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def _capture_frames(cap: Any, label: str, every: int, max_frames: int | None) -> Iterator[tuple[str, np.ndarray]]:
    """Every ``every``-th frame of an open capture (``grab`` skips the others without decoding them)."""
    i = 0
    try:
        while max_frames is None or i < max_frames:
            if i % every == 0:
                ok, frame = cap.read()
                if not ok or frame is None:
                    return
                yield f"{label} frame {i}", _grey(frame)
            elif not cap.grab():
                return
            i += 1
    finally:
        cap.release()


def iter_frames(
    source: str | Path,
    every: int = 1,
    max_frames: int | None = None,
    capture: CaptureFactory = cv2.VideoCapture,
) -> Iterator[tuple[str, np.ndarray]]:
    """``(name, grey uint8 image)`` of every ``every``-th image of a folder, frame of a video file or of a live
    camera / stream (``camera:N``, ``rtsp://…``), at most ``max_frames`` frames looked at."""
    if every < 1:
        raise InputError(f"--every must be ≥ 1, got {every}")
    spec = str(source)
    if is_stream(spec):
        target = capture_target(spec)
        cap = capture(target)
        if cap is None or not cap.isOpened():
            if cap is not None:
                cap.release()
            raise InputError(f"cannot open {spec}: no such device, it is busy, or OpenCV cannot decode it")
        return _capture_frames(cap, spec, every, max_frames)
    path = Path(source)
    if path.is_dir():
        images = list_images(path)
        if not images:
            raise InputError("no images (.png, .jpg, …) in this folder", path=path)
        chosen = images[::every][: max_frames if max_frames is not None else None]
        return ((p.name, read_image(p, grey=True)) for p in chosen)
    if path.is_file() and is_video(path):
        cap = capture(str(path))
        if cap is None or not cap.isOpened():
            if cap is not None:
                cap.release()
            raise InputError("OpenCV cannot open this video (unsupported container or codec, or not a video)",
                             path=path)
        return _capture_frames(cap, path.name, every, max_frames)
    if path.exists():
        raise InputError("calibration source must be a folder of images, a video file or camera:N", path=path)
    raise InputError("no such folder or video file (a camera is camera:N)", path=path)


@dataclass
class _View:
    name: str
    image_points: np.ndarray
    object_points: np.ndarray


def collect_views(
    source: str | Path,
    board: Board,
    every: int = 1,
    max_views: int = 30,
    max_frames: int | None = None,
    capture: CaptureFactory = cv2.VideoCapture,
    on_view: Callable[[str, int], None] | None = None,
) -> tuple[list[_View], tuple[int, int], int]:
    """Find the board in the frames of ``source`` (see :func:`iter_frames`).

    A folder or a video is searched to its end and ``max_views`` views spread evenly over it are kept; a live
    source is read until ``max_views`` views are found, ``max_frames`` frames were looked at, it ends, or Ctrl-C
    (then the views found so far are used).

    Returns
    -------
    views, image size ``(width, height)``, number of frames looked at.
    """
    if max_views < MIN_VIEWS:
        raise InputError(f"--max-views must be ≥ {MIN_VIEWS}, got {max_views}")
    detector = _Detector(board)
    live = is_stream(str(source))
    views: list[_View] = []
    size: tuple[int, int] | None = None
    first = ""
    looked = 0
    frames = iter_frames(source, every, max_frames, capture)
    try:
        for name, grey in frames:
            looked += 1
            shape = (int(grey.shape[1]), int(grey.shape[0]))
            if size is None:
                size, first = shape, name
            elif shape != size:
                folder = Path(source)
                raise InputError(f"image is {shape[0]}x{shape[1]}, the first one ({first}) is {size[0]}x{size[1]}: "
                                 "all views must come from one camera at one resolution",
                                 path=folder / name if folder.is_dir() else name)
            found = detector(grey)
            if found is None:
                continue
            views.append(_View(name, *found))
            if on_view is not None:
                on_view(name, len(views))
            if live and len(views) >= max_views:
                break
    except KeyboardInterrupt:
        if not live:
            raise
    finally:
        close = getattr(frames, "close", None)
        if close is not None:
            close()  # releases a capture
    if size is None:
        raise InputError("no frames to calibrate from", path=None if live else Path(source))
    if not views:
        kind = f"ChArUco board ({board.charuco})" if board.charuco else "checkerboard"
        raise InputError(f"no {board.size_text} {kind} (inner corners) found in any of the {looked} frames looked at; "
                         "check --board (inner corners, not squares), the lighting and the focus",
                         path=None if live else Path(source))
    if len(views) > max_views:
        keep = np.unique(np.linspace(0, len(views) - 1, max_views).round().astype(int))
        views = [views[i] for i in keep]
    return views, size, looked


# ----------------------------------------------------------------------------------------------------
# calibration
# ----------------------------------------------------------------------------------------------------
@dataclass
class CameraCalibration:
    """The result of :func:`calibrate_camera`.

    Attributes
    ----------
    K : 3×3 camera matrix (pixels; pixel centres at integer coordinates, as OpenCV and dmtrack).
    dist : ``(k1, k2, p1, p2, k3)``, OpenCV's order (``k3`` is 0).
    image_size : ``(width, height)``.
    rms : RMS reprojection error over the views used (pixels).
    view_errors : RMS reprojection error of each view used (pixels), by view name.
    rejected : views rejected as outliers, with their error when they were rejected.
    board : the board.
    source : what the views came from.
    frames : frames looked at; ``detected``: views in which the board was found (before any thinning).
    """

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]
    rms: float
    view_errors: dict[str, float]
    rejected: dict[str, float]
    board: Board
    source: str
    frames: int = 0
    detected: int = 0
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    @property
    def coefficients(self) -> tuple[float, float, float, float]:
        """``(k1, k2, p1, p2)`` — the DSO RadTan coefficients."""
        return tuple(float(v) for v in self.dist[:4])  # type: ignore[return-value]

    def model(self) -> RadTanModel:
        w, h = self.image_size
        return RadTanModel(self.fx, self.fy, self.cx, self.cy, w, h, *self.coefficients)

    def dso_text(self, output: Literal["crop", "full"] = "crop") -> str:
        """The 4-line DSO calibration file (numbers written to round-trip exactly); ``crop``'s output camera is
        written out (:func:`~dmtrack.datasets.undistort.crop_output_line`: DSO's own ``crop`` folds k1 < 0 lenses)."""
        model = self.model()
        return radtan_text(model, crop_output_line(model, self.image_size) if output == "crop" else output)

    def to_dict(self) -> dict[str, Any]:
        k1, k2, p1, p2 = self.coefficients
        return {
            "model": "radtan",
            "image_size": list(self.image_size),
            "fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy,
            "k1": k1, "k2": k2, "p1": p1, "p2": p2, "k3": float(self.dist[4]),
            "K": self.K.tolist(),
            "dist": [float(v) for v in self.dist],
            "rms_px": self.rms,
            "views_used": len(self.view_errors),
            "view_errors_px": self.view_errors,
            "rejected_views_px": self.rejected,
            "frames_looked_at": self.frames,
            "views_detected": self.detected,
            "board": self.board.describe(),
            "source": self.source,
            "opencv": cv2.__version__,
            **self.extra,
        }


def _calibrate(
    views: list[_View], size: tuple[int, int],
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    flags = cv2.CALIB_FIX_K3
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    try:
        out = cv2.calibrateCameraExtended(
            [v.object_points for v in views], [v.image_points for v in views], size, None, None, flags=flags,
            criteria=criteria,
        )
    except cv2.error as e:
        raise InputError(f"cv2.calibrateCamera failed on {len(views)} views: {str(e).strip().splitlines()[-1]}") \
            from None
    rms, K, dist, std, per_view = out[0], out[1], out[2], out[5], out[7]
    return (float(rms), np.asarray(K, np.float64), np.asarray(dist, np.float64).reshape(-1)[:5],
            np.asarray(per_view, np.float64).reshape(-1), np.asarray(std, np.float64).reshape(-1))


def calibrate_views(
    views: list[_View], size: tuple[int, int], outlier_ratio: float = 3.0,
) -> tuple[float, np.ndarray, np.ndarray, dict[str, float], dict[str, float], dict[str, float]]:
    """Calibrate, rejecting outlier views one at a time (see the module documentation).

    Returns ``rms, K, dist, view_errors, rejected, std`` (``std``: OpenCV's standard deviations of fx, fy, cx,
    cy, k1, k2, p1, p2).
    """
    views = list(views)
    if len(views) < MIN_VIEWS:
        raise InputError(f"only {len(views)} usable views (at least {MIN_VIEWS}; 10–20 from different angles and "
                         "distances, the board reaching the image corners, give good results)")
    rejected: dict[str, float] = {}
    while True:
        rms, K, dist, errors, std = _calibrate(views, size)
        if not (np.isfinite(K).all() and np.isfinite(dist).all() and K[0, 0] > 0 and K[1, 1] > 0):
            raise InputError("the calibration did not converge (too few or too similar views?)")
        worst = int(np.argmax(errors))
        limit = max(outlier_ratio * float(np.median(errors)), MIN_OUTLIER_PX)
        if errors[worst] <= limit or len(views) <= MIN_VIEWS:
            break
        rejected[views[worst].name] = float(errors[worst])
        del views[worst]
    names = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")
    return (rms, K, dist, {v.name: float(e) for v, e in zip(views, errors, strict=True)}, rejected,
            {n: float(v) for n, v in zip(names, std, strict=False)})


def calibrate_camera(
    source: str | Path,
    board: Board,
    *,
    every: int = 1,
    max_views: int = 30,
    max_frames: int | None = None,
    outlier_ratio: float = 3.0,
    capture: CaptureFactory = cv2.VideoCapture,
    on_view: Callable[[str, int], None] | None = None,
) -> CameraCalibration:
    """Calibrate a camera from views of ``board`` in ``source`` (a folder of images, a video file or
    ``camera:N`` / a stream URL).  From a live source, Ctrl-C ends the search and calibrates with the views found.

    Parameters
    ----------
    every : look at every ``every``-th image or frame.
    max_views : use at most this many views (spread over a folder or video; the first ones of a live camera).
    max_frames : look at no more than this many frames.
    outlier_ratio : reject views whose error is above this × the median (and above :data:`MIN_OUTLIER_PX`).
    capture : the ``VideoCapture`` factory for video files and cameras.
    on_view : called with ``(view name, views so far)`` each time the board is found.

    Raises
    ------
    InputError
        No board in any image (naming the source and the board size), fewer than :data:`MIN_VIEWS` usable views,
        images of different sizes (naming the file), an unreadable source.
    """
    views, size, looked = collect_views(source, board, every, max_views, max_frames, capture, on_view)
    try:
        rms, K, dist, errors, rejected, std = calibrate_views(views, size, outlier_ratio)
    except InputError as e:
        raise InputError(f"{e} — found the {board.size_text} board in {len(views)} of {looked} frames",
                         path=None if is_stream(str(source)) else Path(source)) from None
    return CameraCalibration(K, dist, size, rms, errors, rejected, board, str(source), looked, len(views),
                             {"std_dev": std})


# ----------------------------------------------------------------------------------------------------
# the files
# ----------------------------------------------------------------------------------------------------
def sidecar_path(path: str | Path) -> Path:
    """The JSON file written next to a calibration file: ``camera.txt`` → ``camera.json``."""
    path = Path(path)
    side = path.with_suffix(".json")
    return side if side != path else path.with_name(path.name + ".result.json")


def write_calibration(
    calib: CameraCalibration, path: str | Path, output: Literal["crop", "full"] = "crop",
) -> tuple[Path, Path]:
    """Write the DSO calibration file ``path`` and its JSON sidecar; returns both paths.

    The file is read back with :func:`~dmtrack.datasets.undistort.read_calibration_file` (and its undistortion
    built) before it replaces ``path``; a mismatch is an :class:`~dmtrack.errors.OutputError`.
    """
    path = Path(path)
    if output not in ("crop", "full"):
        raise InputError(f"output mode {output!r}: expected crop or full")
    text = calib.dso_text(output)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
        try:
            back = read_calibration_file(tmp, flavour="dso")
            back.undistorter()
        except DmtrackError as e:
            raise OutputError(f"the calibration does not read back as written ({e.__class__.__name__}: "
                              f"{getattr(e, 'reason', e)}); nothing written", path) from None
        m = back.model
        expected = calib.model()
        out = back.output
        if output == "crop":  # written out as crop's camera (see crop_output_line)
            crop = crop_camera(expected, calib.image_size)
            same_output = (isinstance(out, PinholeCamera) and (out.width, out.height) == calib.image_size
                           and np.allclose([out.fx, out.fy, out.cx, out.cy], [crop.fx, crop.fy, crop.cx, crop.cy],
                                           rtol=0, atol=1e-6))  # fmt: skip
        else:
            same_output = out == output
        if not (isinstance(m, RadTanModel) and m == expected and same_output and not back.relative):
            raise OutputError("the calibration does not read back as written; nothing written", path)
    side = sidecar_path(path)
    result = {**calib.to_dict(), "calibration_file": path.name, "output": output}
    write_text(side, json.dumps(result, indent=2) + "\n")
    return path, side
