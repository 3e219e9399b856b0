"""Geometric undistortion to a pinhole camera, as LSD-SLAM's / DSO's ``Undistorter``.

An :class:`Undistorter` precomputes, for every pixel of the *output* pinhole image, the position in the
*input* (distorted) image it samples — ``cv2.remap`` maps — and marks output pixels whose ray leaves the
input image as invalid (value 0).  The output camera is chosen as in the calibration files of LSD-SLAM and DSO:

* ``crop`` — the largest output rectangle all of whose pixels see valid input pixels (DSO's
  ``makeOptimalK_crop``: start from the extent of the two centre lines, shrink the offending sides by 0.5 %
  until the whole border maps inside the input image; LSD-SLAM computes the same rectangle in closed form for
  the FOV model only);
* ``full`` — the smallest rectangle that shows every input pixel (invalid corners stay black);
* ``none`` — no resampling: the pinhole part of the model is used as is (exact only without distortion);
* explicit output intrinsics (a :class:`~dmtrack.geometry.camera.PinholeCamera`).

The output size is made a multiple of 16 (LSD-SLAM needs it): ``crop`` and ``full`` compute their intrinsics
for the reduced size directly, ``none`` and explicit intrinsics crop the centre.

Calibration files (4 lines) are read by :func:`read_calibration_file` in the two dialects that differ in
details:

=========  ================================================  ==================================================
line       DSO (``camera.txt`` of TUM monoVO)                 LSD-SLAM (``cameraCalibration.cfg``)
=========  ================================================  ==================================================
1          ``[FOV|RadTan|KannalaBrandt|EquiDistant|Pinhole]``  ``fx fy cx cy ω`` (FOV, always relative) or
           ``fx fy cx cy p…``; no prefix: 5 numbers = FOV      ``fx fy cx cy k1 k2 p1 p2`` (OpenCV, pixels;
           (``ω = 0``: pinhole), 8 numbers = RadTan.           relative when ``cx < 1``: ×width, ×height,
           Relative when ``cx < 1`` and ``cy < 1``:           *without* the −0.5 shift).
           ``f·size``, ``c·size − 0.5``.
2          input ``width height``                             same
3          ``crop`` / ``full`` / ``none`` / ``fx fy cx cy 0``  same
           (relative to the output size, ``c·size − 0.5``)
4          output ``width height``                            same
=========  ================================================  ==================================================

The −0.5: relative calibrations (PTAM's) put the centre of pixel (0, 0) at (0.5, 0.5); dmtrack (and DSO,
LSD-SLAM internally) put it at (0, 0).  Sources: DSO ``src/util/Undistort.cpp`` (``readFromFile``,
``makeOptimalK_crop``), LSD-SLAM ``lsd_slam_core/src/util/Undistorter.cpp``.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np

from dmtrack.datasets.base import Frame
from dmtrack.datasets.intrinsics import check_range
from dmtrack.errors import DatasetError, InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.geometry.distortion import (
    CameraModel,
    EquidistantModel,
    FOVModel,
    PinholeModel,
    RadTanModel,
)
from dmtrack.io.files import read_text_file
from dmtrack.io.trajectory import Trajectory

MIN_FOCAL_PX = 1e-3  # smaller focal lengths (in pixels) are a broken calibration, not a lens
MIN_FOV_OMEGA = 1e-9  # a FOV model with |ω| below this is a pinhole to double precision (and 1/tan(ω/2) overflows)

__all__ = [
    "CalibrationFile",
    "OutputMode",
    "UndistortedSequence",
    "Undistorter",
    "read_calibration_file",
]

OutputMode = Literal["crop", "full", "none"]
MULTIPLE = 16
#: Largest image side accepted from a calibration file (OpenCV's ``remap`` handles sides below 2¹⁵).
MAX_SIDE = 32767


# ----------------------------------------------------------------------------------------------------
# calibration files
# ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CalibrationFile:
    """Contents of a 4-line LSD-SLAM / DSO calibration file.

    Attributes
    ----------
    model : the input camera (pixel intrinsics after the relative-to-pixel conversion).
    output : ``"crop"``, ``"full"``, ``"none"`` or the output :class:`PinholeCamera` (pixels).
    output_size : ``(width, height)`` asked for on line 4.
    path : the file.
    relative : whether line 1 was given relative to the image size.
    """

    model: CameraModel
    output: OutputMode | PinholeCamera
    output_size: tuple[int, int]
    path: Path
    relative: bool

    def undistorter(self, multiple: int = MULTIPLE) -> Undistorter:
        """The :class:`Undistorter` this file describes (output size reduced to a multiple of ``multiple``)."""
        return Undistorter.create(self.model, self.output, self.output_size, multiple=multiple, source=self.path)


_PREFIXES = {
    "fov": ("fov", 5),
    "radtan": ("radtan", 8),
    "kannalabrandt": ("equidistant", 8),
    "equidistant": ("equidistant", 8),
    "pinhole": ("pinhole", 5),
}


def _numbers(text: str, path: Path, lineno: int, what: str) -> list[float]:
    out = []
    for f in text.replace(",", " ").split():
        try:
            out.append(float(f))
        except ValueError:
            raise InputError(f"{what}: cannot read {f!r} as a number", path=path, line=lineno) from None
    return out


def _size(text: str, path: Path, lineno: int, what: str) -> tuple[int, int]:
    fields = text.split()
    if len(fields) != 2 or not all(re.fullmatch(r"[0-9]+", f) for f in fields):
        raise InputError(f"{what}: expected 'width height' (two positive integers), found {text.strip()[:60]!r}",
                         path=path, line=lineno)
    if any(len(f.lstrip("0")) > 6 for f in fields) or max(int(f) for f in fields) > MAX_SIDE:
        raise InputError(f"{what}: {fields[0][:12]}x{fields[1][:12]} is too large (at most {MAX_SIDE} pixels a side)",
                         path=path, line=lineno)
    w, h = int(fields[0]), int(fields[1])
    if w <= 0 or h <= 0:
        raise InputError(f"{what}: image size must be positive, found {w}x{h}", path=path, line=lineno)
    return w, h


def read_calibration_file(path: str | Path, flavour: Literal["dso", "lsdslam"] = "dso") -> CalibrationFile:
    """Read a 4-line calibration file (TUM monoVO ``camera.txt`` or LSD-SLAM ``cameraCalibration.cfg``).

    Parameters
    ----------
    flavour : ``"dso"`` or ``"lsdslam"`` — the two programs disagree on which numbers are relative (see the
        module documentation).

    Raises
    ------
    InputError
        Naming the file and line, for a missing line, a wrong number of parameters or an unknown model.
    """
    path = Path(path)
    lines = [ln.strip() for ln in read_text_file(path, "calibration file").splitlines()]
    while lines and not lines[-1]:
        lines.pop()
    if len(lines) < 4:
        raise InputError(
            f"calibration file needs 4 lines (camera parameters, input size, crop|full|none|fx fy cx cy 0, "
            f"output size), found {len(lines)}",
            path=path,
        )
    in_w, in_h = _size(lines[1], path, 2, "input image size")
    out_w, out_h = _size(lines[3], path, 4, "output image size")

    # line 1 ------------------------------------------------------------------------------------------
    first = lines[0]
    m = re.match(r"^([A-Za-z]+)\s+(.*)$", first)
    if m and m.group(1).lower() in ("nan", "inf", "infinity"):  # a number, not a model name
        m = None
    if m:
        prefix = m.group(1).lower()
        if prefix not in _PREFIXES or flavour == "lsdslam":
            known = "FOV, RadTan, KannalaBrandt, EquiDistant, Pinhole"
            raise InputError(
                f"unknown camera model {m.group(1)!r}" + (f" (known: {known})" if flavour == "dso" else
                                                          " (LSD-SLAM files have 5 (FOV) or 8 (OpenCV) numbers)"),
                path=path, line=1,
            )
        kind, npar = _PREFIXES[prefix]
        pars = _numbers(m.group(2), path, 1, f"{m.group(1)} camera parameters")
        if len(pars) != npar:
            raise InputError(f"{m.group(1)} model needs {npar} numbers, found {len(pars)}", path=path, line=1)
    else:
        pars = _numbers(first, path, 1, "camera parameters")
        if len(pars) == 8:
            kind = "radtan"
        elif len(pars) == 5:
            kind = "fov" if (abs(pars[4]) >= MIN_FOV_OMEGA or flavour == "lsdslam") else "pinhole"
        else:
            raise InputError(
                f"expected 5 numbers (FOV 'fx fy cx cy omega') or 8 numbers (OpenCV 'fx fy cx cy k1 k2 p1 p2'), "
                f"found {len(pars)}",
                path=path, line=1,
            )
    check_range(pars, "camera parameters", path, 1)
    fx, fy, cx, cy = pars[:4]
    relative = False
    if flavour == "dso":
        if cx < 1 and cy < 1:
            relative = True
            fx, fy, cx, cy = fx * in_w, fy * in_h, cx * in_w - 0.5, cy * in_h - 0.5
    elif kind == "fov":  # LSD-SLAM's UndistorterPTAM: always relative
        relative = True
        fx, fy, cx, cy = fx * in_w, fy * in_h, cx * in_w - 0.5, cy * in_h - 0.5
    elif cx < 1.0:  # LSD-SLAM's UndistorterOpenCV auto-conversion (no -0.5)
        relative = True
        fx, fy, cx, cy = fx * in_w, fy * in_h, cx * in_w, cy * in_h
    if not min(fx, fy) >= MIN_FOCAL_PX:
        raise InputError(f"camera parameters: focal lengths fx = {fx:g}, fy = {fy:g} pixels; they must be at least "
                         f"{MIN_FOCAL_PX:g}", path=path, line=1)
    try:
        model: CameraModel
        if kind == "pinhole" or (kind == "fov" and abs(pars[4]) < MIN_FOV_OMEGA):
            model = PinholeModel(fx, fy, cx, cy, in_w, in_h)
        elif kind == "fov":
            model = FOVModel(fx, fy, cx, cy, in_w, in_h, omega=pars[4])
        elif kind == "radtan":
            model = RadTanModel(fx, fy, cx, cy, in_w, in_h, *pars[4:8])
        else:
            model = EquidistantModel(fx, fy, cx, cy, in_w, in_h, *pars[4:8])
    except ValueError as e:
        raise InputError(f"camera parameters: {e}", path=path, line=1) from None

    # line 3 ------------------------------------------------------------------------------------------
    mode = lines[2].lower()
    output: OutputMode | PinholeCamera
    if mode in ("crop", "full", "none"):
        output = mode  # type: ignore[assignment]
    else:
        vals = _numbers(lines[2], path, 3, "output calibration ('crop', 'full', 'none' or 'fx fy cx cy 0')")
        if len(vals) != 5:
            raise InputError(
                f"output calibration: expected 'crop', 'full', 'none' or 5 numbers 'fx fy cx cy 0', found "
                f"{lines[2]!r}",
                path=path, line=3,
            )
        check_range(vals, "output calibration", path, 3)
        ofx, ofy, ocx, ocy = vals[:4]
        if not min(ofx * out_w, ofy * out_h) >= MIN_FOCAL_PX:
            raise InputError(f"output calibration: focal lengths of {ofx * out_w:g}, {ofy * out_h:g} pixels; they must "
                             f"be at least {MIN_FOCAL_PX:g}", path=path, line=3)
        if ocx > 1 or ocy > 1:
            raise InputError("output calibration must be relative to the output size (cx, cy < 1)",
                             path=path, line=3)
        try:
            output = PinholeCamera(ofx * out_w, ofy * out_h, ocx * out_w - 0.5, ocy * out_h - 0.5, out_w, out_h)
        except ValueError as e:
            raise InputError(f"output calibration: {e}", path=path, line=3) from None
    if output == "none" and (out_w, out_h) != (in_w, in_h):
        raise InputError(
            f"'none' (no rectification) needs the output size to equal the input size ({in_w} {in_h}), "
            f"found {out_w} {out_h}",
            path=path, line=4,
        )
    return CalibrationFile(model, output, (out_w, out_h), path, relative)


# ----------------------------------------------------------------------------------------------------
# the undistorter
# ----------------------------------------------------------------------------------------------------
def _to_input_pixels(model: CameraModel, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Input pixel coordinates of normalised undistorted points, and their validity (strictly inside)."""
    r = np.hypot(xy[..., 0], xy[..., 1])
    d = model.distort(xy)
    u = d[..., 0] * model.fx + model.cx
    v = d[..., 1] * model.fy + model.cy
    ok = (r <= model.max_radius) & np.isfinite(u) & np.isfinite(v)
    ok &= (u > 0) & (u < model.width - 1) & (v > 0) & (v < model.height - 1)
    return np.stack([u, v], axis=-1), ok


def _centre_interval(model: CameraModel, axis: int, source: Path | None = None) -> tuple[float, float]:
    """Extent of the valid part of a centre line (x axis or y axis) in normalised undistorted coordinates."""
    t = (np.arange(100000) - 50000.0) / 10000.0  # [-5, 5) as DSO
    xy = np.zeros((t.size, 2))
    xy[:, axis] = t
    _, ok = _to_input_pixels(model, xy)
    i0 = 50000
    if not ok[i0]:
        raise DatasetError("the principal ray does not hit the input image: cannot undistort", path=source)
    lo = i0
    while lo > 0 and ok[lo - 1]:
        lo -= 1
    hi = i0
    while hi < t.size - 1 and ok[hi + 1]:
        hi += 1
    return float(t[lo]), float(t[hi])


def _border_ok(model: CameraModel, box: list[float], w: int, h: int) -> tuple[bool, bool, bool, bool]:
    min_x, max_x, min_y, max_y = box
    ys = min_y + (max_y - min_y) * np.arange(h) / (h - 1.0)
    xs = min_x + (max_x - min_x) * np.arange(w) / (w - 1.0)
    _, left = _to_input_pixels(model, np.stack([np.full(h, min_x), ys], axis=-1))
    _, right = _to_input_pixels(model, np.stack([np.full(h, max_x), ys], axis=-1))
    _, top = _to_input_pixels(model, np.stack([xs, np.full(w, min_y)], axis=-1))
    _, bottom = _to_input_pixels(model, np.stack([xs, np.full(w, max_y)], axis=-1))
    return bool(left.all()), bool(right.all()), bool(top.all()), bool(bottom.all())


def _camera_from_box(box: list[float], w: int, h: int, source: Path | None = None) -> PinholeCamera:
    min_x, max_x, min_y, max_y = box
    if not (max_x > min_x and max_y > min_y):  # e.g. an input image one pixel high: no field of view to fit
        raise DatasetError(f"the undistorted image has no extent ({max_x - min_x:.3g} × {max_y - min_y:.3g} in "
                           "normalised coordinates): is the input image size sensible?", path=source)
    fx = (w - 1.0) / (max_x - min_x)
    fy = (h - 1.0) / (max_y - min_y)
    return PinholeCamera(fx, fy, -min_x * fx, -min_y * fy, w, h)


def _optimal_crop(model: CameraModel, w: int, h: int, source: Path | None = None) -> PinholeCamera:
    """DSO's ``makeOptimalK_crop``, plus a final check of every output pixel."""
    min_x, max_x = _centre_interval(model, 0, source)
    min_y, max_y = _centre_interval(model, 1, source)
    box = [min_x * 1.01, max_x * 1.01, min_y * 1.01, max_y * 1.01]
    for _ in range(2000):
        left, right, top, bottom = _border_ok(model, box, w, h)
        oob_l, oob_r, oob_t, oob_b = not left, not right, not top, not bottom
        if not (oob_l or oob_r or oob_t or oob_b):
            cam = _camera_from_box(box, w, h, source)
            _, ok = _to_input_pixels(model, _output_rays(cam))
            if ok.all():
                return cam
            oob_l = oob_r = oob_t = oob_b = True  # interior hole (non-convex valid region): shrink all sides
        elif (oob_l or oob_r) and (oob_t or oob_b):
            if box[1] - box[0] > box[3] - box[2]:
                oob_t = oob_b = False
            else:
                oob_l = oob_r = False
        if oob_l:
            box[0] *= 0.995
        if oob_r:
            box[1] *= 0.995
        if oob_t:
            box[2] *= 0.995
        if oob_b:
            box[3] *= 0.995
    raise DatasetError("failed to find a valid crop for the undistorted image (is the calibration sensible?)",
                       path=source)


def _optimal_full(model: CameraModel, w: int, h: int, source: Path | None = None) -> PinholeCamera:
    """The smallest rectangle (in normalised undistorted coordinates) containing every input pixel."""
    W, H = model.width, model.height
    us = np.arange(W, dtype=np.float64)
    vs = np.arange(H, dtype=np.float64)
    border = np.concatenate([
        np.stack([us, np.zeros(W)], -1), np.stack([us, np.full(W, H - 1.0)], -1),
        np.stack([np.zeros(H), vs], -1), np.stack([np.full(H, W - 1.0), vs], -1),
    ])
    xy_d = np.stack([(border[:, 0] - model.cx) / model.fx, (border[:, 1] - model.cy) / model.fy], -1)
    xy = model.undistort(xy_d)
    if not np.isfinite(xy).all():
        raise DatasetError(
            "'full' undistortion: some input border pixels have no undistorted ray (field of view of 180° or "
            "more, or a distortion polynomial past its turning point); use 'crop'",
            path=source,
        )
    box = [float(xy[:, 0].min()), float(xy[:, 0].max()), float(xy[:, 1].min()), float(xy[:, 1].max())]
    return _camera_from_box(box, w, h, source)


def _distortion_free(model: CameraModel) -> bool:
    """Whether ``model`` is a plain pinhole (``ω = 0`` FOV, all-zero radial-tangential coefficients, …)."""
    if isinstance(model, PinholeModel):
        return True
    if isinstance(model, FOVModel):
        return model.omega == 0.0
    if isinstance(model, RadTanModel):
        return model.k1 == model.k2 == model.p1 == model.p2 == model.k3 == 0.0
    return False


def _output_rays(cam: PinholeCamera) -> np.ndarray:
    """Normalised undistorted coordinates of every output pixel, (H, W, 2)."""
    return cam.pixel_grid_rays()[..., :2]


class Undistorter:
    """Resample distorted images into a pinhole camera with precomputed ``cv2.remap`` maps.

    Use :meth:`create`; the constructor takes the finished pieces.

    Attributes
    ----------
    model : the input camera model.
    camera : the output :class:`PinholeCamera` (size a multiple of 16 unless ``multiple=1``).
    mode : ``"crop"``, ``"full"``, ``"none"`` or ``"given"``.
    map_x, map_y : float32 (H_out, W_out) input pixel coordinates of each output pixel (−1 where invalid), or
        ``None`` for ``none`` (then :attr:`box` crops the input).
    box : ``(left, top, width, height)`` crop of the input for ``none`` mode.
    valid : bool (H_out, W_out) — output pixels that see the input image.
    """

    def __init__(
        self,
        model: CameraModel,
        camera: PinholeCamera,
        mode: str,
        map_x: np.ndarray | None,
        map_y: np.ndarray | None,
        box: tuple[int, int, int, int] | None = None,
        source: Path | None = None,
    ) -> None:
        self.model = model
        self.camera = camera
        self.mode = mode
        self.map_x = map_x
        self.map_y = map_y
        self.box = box
        self.source = source
        if map_x is not None:
            assert map_y is not None
            self.valid = map_x >= 0
        else:
            self.valid = np.ones(camera.shape, dtype=bool)

    @classmethod
    def create(
        cls,
        model: CameraModel,
        output: OutputMode | PinholeCamera = "crop",
        size: tuple[int, int] | None = None,
        multiple: int = MULTIPLE,
        source: Path | None = None,
    ) -> Undistorter:
        """Build the maps for ``model`` → pinhole.

        Parameters
        ----------
        model : input camera.
        output : ``"crop"``, ``"full"``, ``"none"`` or the output camera in pixels.
        size : output ``(width, height)`` before the reduction to a multiple (default: the input size, or the
            given camera's size).
        multiple : the output width and height are reduced to multiples of this (16 for LSD-SLAM).
        """
        try:
            if isinstance(output, PinholeCamera):
                cam, _ = output.crop_to_multiple(multiple)
                mode = "given"
            elif output == "none" or (output in ("crop", "full") and _distortion_free(model)
                                       and (size is None or tuple(size) == (model.width, model.height))):
                # "none", or a camera without distortion: nothing to undistort, the images pass through as they
                # are (only cropped at the centre where a side is not a multiple of ``multiple``)
                pin = model.pinhole()
                cam, box = pin.crop_to_multiple(multiple)
                return cls(model, cam, "none", None, None, box, source)
            elif output in ("crop", "full"):
                w, h = size if size is not None else (model.width, model.height)
                w, h = w - w % multiple, h - h % multiple
                if w <= 1 or h <= 1:
                    raise InputError(f"output size {size} has no multiple of {multiple}", path=source)
                if _distortion_free(model):
                    return cls._resize(model, w, h, output, source)
                cam = _optimal_crop(model, w, h, source) if output == "crop" else _optimal_full(model, w, h, source)
                mode = output
            else:
                raise InputError(f"unknown undistortion output {output!r} (use crop, full, none or a camera)",
                                 path=source)
        except ValueError as e:  # a degenerate camera (e.g. an image smaller than ``multiple``)
            raise DatasetError(f"cannot undistort: {e}", path=source) from None
        uv, ok = _to_input_pixels(model, _output_rays(cam))
        map_x = np.where(ok, uv[..., 0], -1.0).astype(np.float32)
        map_y = np.where(ok, uv[..., 1], -1.0).astype(np.float32)
        return cls(model, cam, mode, map_x, map_y, None, source)

    @classmethod
    def _resize(cls, model: CameraModel, w: int, h: int, mode: str, source: Path | None) -> Undistorter:
        """A camera without distortion to another size: input pixel centres 0 and W − 1 land on output pixels 0
        and w − 1 (``crop`` and ``full`` agree: the whole image is valid)."""
        W, H = model.width, model.height
        if W < 2 or H < 2:
            raise InputError(f"cannot resize a {W}x{H} image", path=source)
        box = [-model.cx / model.fx, (W - 1 - model.cx) / model.fx, -model.cy / model.fy, (H - 1 - model.cy) / model.fy]
        cam = _camera_from_box(box, w, h, source)
        uv = model.normalised_to_pixel(model.distort(_output_rays(cam)))  # type: ignore[attr-defined]
        map_x = np.clip(uv[..., 0], 0.0, W - 1.0).astype(np.float32)
        map_y = np.clip(uv[..., 1], 0.0, H - 1.0).astype(np.float32)
        return cls(model, cam, mode, map_x, map_y, None, source)

    @property
    def input_size(self) -> tuple[int, int]:
        return (self.model.width, self.model.height)

    @property
    def is_identity(self) -> bool:
        """True when images pass through unchanged (``none`` mode without cropping)."""
        return self.map_x is None and self.box == (0, 0, self.model.width, self.model.height)

    def __call__(self, image: np.ndarray, interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
        """Undistort one image ``(H_in, W_in[, C])`` (any dtype OpenCV remaps: uint8, float32, …)."""
        if image.shape[1] != self.model.width or image.shape[0] != self.model.height:
            raise InputError(
                f"image is {image.shape[1]}x{image.shape[0]}, the calibration is for "
                f"{self.model.width}x{self.model.height}",
                path=self.source,
            )
        if self.map_x is None:
            left, top, w, h = self.box  # type: ignore[misc]
            return np.ascontiguousarray(image[top : top + h, left : left + w])
        return cv2.remap(image, self.map_x, self.map_y, interpolation, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0)

    def describe(self) -> dict[str, Any]:
        """JSON-ready facts for ``dmtrack info``."""
        return {
            "distortion_model": self.model.to_dict(),
            "undistortion": self.mode,
            "undistorted_size": [self.camera.width, self.camera.height],
            "invalid_pixels": int((~self.valid).sum()),
            **({"calibration_file": str(self.source)} if self.source else {}),
        }

    def __repr__(self) -> str:
        return (f"Undistorter({self.model.name} {self.model.width}x{self.model.height} -> {self.mode} "
                f"{self.camera.width}x{self.camera.height})")


# ----------------------------------------------------------------------------------------------------
# a sequence wrapper
# ----------------------------------------------------------------------------------------------------
class UndistortedSequence:
    """A sequence whose images are undistorted on the fly; ``camera`` is the output pinhole camera.

    Depth maps (if any) are resampled with nearest-neighbour interpolation (invalid → 0).  Poses are unchanged
    (undistortion does not move the camera).
    """

    def __init__(self, seq: Any, undistorter: Undistorter) -> None:
        if (seq.width, seq.height) != undistorter.input_size:
            raise InputError(
                f"the calibration is for {undistorter.input_size[0]}x{undistorter.input_size[1]} images, the "
                f"sequence has {seq.width}x{seq.height}",
                path=undistorter.source,
            )
        self.base = seq
        self.undistorter = undistorter
        self.name = seq.name
        self.format = seq.format
        self.root = getattr(seq, "root", None)
        self.camera: PinholeCamera | None = undistorter.camera
        self.details: dict[str, Any] = {**getattr(seq, "details", {}), **undistorter.describe()}

    @property
    def width(self) -> int:
        return self.undistorter.camera.width

    @property
    def height(self) -> int:
        return self.undistorter.camera.height

    @property
    def timestamps(self) -> np.ndarray:
        return self.base.timestamps

    @property
    def groundtruth(self) -> Trajectory | None:
        return self.base.groundtruth

    @property
    def has_groundtruth(self) -> bool:
        return bool(self.base.has_groundtruth)

    @property
    def has_depth(self) -> bool:
        return bool(getattr(self.base, "has_depth", False))

    def __len__(self) -> int:
        return len(self.base)

    def __getitem__(self, index: int) -> Frame:
        return self.read_frame(index)

    def read_frame(self, index: int, depth: bool = True) -> Frame:
        """Frame ``index``; ``depth=False`` does not read (nor undistort) its ground-truth depth."""
        read = getattr(self.base, "read_frame", None)
        f = self.base[index] if read is None else read(index, depth=depth)
        image = self.undistorter(f.image)
        depth = None if f.depth is None else self.undistorter(f.depth, interpolation=cv2.INTER_NEAREST)
        return Frame(f.index, f.timestamp, image, f.pose, depth, f.path)

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]

    def slice(self, start: int = 0, stop: int | None = None) -> UndistortedSequence:
        return UndistortedSequence(self.base.slice(start, stop), self.undistorter)

    def __repr__(self) -> str:
        return f"UndistortedSequence({self.base!r}, {self.undistorter!r})"


def crop_camera(model: CameraModel, size: tuple[int, int]) -> PinholeCamera:
    """The output camera of ``crop`` for ``model`` at ``size`` (not reduced to a multiple)."""
    return Undistorter.create(model, "crop", size, multiple=1).camera


def crop_output_line(model: CameraModel, size: tuple[int, int]) -> str:
    """Line 3 of a DSO calibration file whose output is ``crop``, written out: the output camera dmtrack's ``crop``
    computes for ``model`` at ``size``, relative to the size as DSO reads it (``fx/w fy/h (cx+½)/w (cy+½)/h 0``).

    DSO's own ``crop`` starts from the widest ray on the centre lines whose image lies inside the input, out to ±5
    in normalised units; where a radial polynomial with k1 < 0 turns back, rays far out land inside the image again
    and DSO chooses a folded image (fx ≈ 63 px for a 7-Scenes file with k1 = −0.036, ``tools/dso_oracle``). dmtrack
    walks out from the centre and stops at the first invalid ray, so the camera written here is valid for both."""
    w, h = size
    cam = crop_camera(model, size)
    return f"{cam.fx / w!r} {cam.fy / h!r} {(cam.cx + 0.5) / w!r} {(cam.cy + 0.5) / h!r} 0"


def radtan_text(model: RadTanModel, line3: str) -> str:
    """The 4-line DSO calibration file of ``model``: ``RadTan fx fy cx cy k1 k2 p1 p2``, the size, ``line3`` (the
    output: ``crop``, ``full``, or a camera such as :func:`crop_output_line`'s) and the size again. The numbers are
    written to read back exactly; DSO's format has no k3, so it must be 0."""
    if model.k3 != 0.0:
        raise ValueError(f"DSO's RadTan file has no k3, got k3 = {model.k3!r}")
    numbers = " ".join(repr(float(v)) for v in (model.fx, model.fy, model.cx, model.cy, *model.coefficients[:4]))
    return f"RadTan {numbers}\n{model.width} {model.height}\n{line3}\n{model.width} {model.height}\n"


def undistort_sequence(seq: Any, calibration: CalibrationFile, multiple: int = MULTIPLE) -> Any:
    """``seq`` wrapped in an :class:`UndistortedSequence`, or ``seq`` itself when nothing changes."""
    und = calibration.undistorter(multiple)
    if und.is_identity:
        if (seq.width, seq.height) != und.input_size:
            raise InputError(
                f"the calibration is for {und.input_size[0]}x{und.input_size[1]} images, the sequence has "
                f"{seq.width}x{seq.height}",
                path=calibration.path,
            )
        seq.camera = und.camera
        return seq
    return UndistortedSequence(seq, und)
