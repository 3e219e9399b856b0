"""Pinhole camera model, image pyramids of intrinsics and crops.

Conventions: OpenCV camera axes (x right, y down, z forward); pixel centres at integer coordinates, so
the image of width ``w`` covers ``u ∈ [-0.5, w - 0.5]`` and the pixel ``image[v, u]`` is centred at
``(u, v)``.  Pixel coordinates are ``(u, v)`` = (column, row) pairs, stored as the last axis of arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["PinholeCamera", "crop_image"]

FloatArray = NDArray[np.float64]
Box = tuple[int, int, int, int]


def plain(value: Any) -> str:
    """``repr`` of a value for a message, with NumPy scalars as plain numbers (``1.5``, not ``np.float64(1.5)``)."""
    if isinstance(value, np.generic):
        value = value.item()
    elif isinstance(value, tuple | list):
        return repr(type(value)(v.item() if isinstance(v, np.generic) else v for v in value))
    return repr(value)


def _as_int(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        if isinstance(value, float | np.floating) and float(value).is_integer():
            return int(value)
        raise ValueError(f"{name} must be an integer, got {plain(value)}")
    return int(value)


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole intrinsics of an undistorted image.

    Parameters
    ----------
    fx, fy : float
        Focal lengths in pixels (> 0).
    cx, cy : float
        Principal point in pixels (pixel centres at integer coordinates).
    width, height : int
        Image size in pixels (> 0).

    Raises
    ------
    ValueError
        If a value is not finite, a focal length or a size is not positive, or a size is not an integer.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "cx", "cy"):
            v = getattr(self, name)
            try:
                f = float(v)
            except (TypeError, ValueError):
                raise ValueError(f"{name} must be a number, got {plain(v)}") from None
            if not math.isfinite(f):
                raise ValueError(f"{name} must be finite, got {plain(v)}")
            object.__setattr__(self, name, f)
        if self.fx <= 0.0 or self.fy <= 0.0:
            raise ValueError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        for name in ("width", "height"):
            n = _as_int(getattr(self, name), name)
            if n <= 0:
                raise ValueError(f"{name} must be positive, got {n}")
            object.__setattr__(self, name, n)

    # construction ------------------------------------------------------------------------------------
    @classmethod
    def from_K(cls, K: ArrayLike, width: int, height: int) -> PinholeCamera:
        """From a 3×3 intrinsic matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (zero skew required)."""
        K = np.asarray(K, dtype=np.float64)
        if K.shape != (3, 3):
            raise ValueError(f"K must have shape (3, 3), got {K.shape}")
        if not np.allclose([K[0, 1], K[1, 0], K[2, 0], K[2, 1]], 0.0, rtol=0.0, atol=1e-12) or not np.isclose(
            K[2, 2], 1.0, rtol=0.0, atol=1e-12
        ):
            raise ValueError(f"K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")
        return cls(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), width, height)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> PinholeCamera:
        """From a mapping with keys ``fx, fy, cx, cy, width, height`` (as written by :meth:`to_dict`)."""
        keys = ("fx", "fy", "cx", "cy", "width", "height")
        missing = [k for k in keys if k not in d]
        if missing:
            raise ValueError(f"camera dict lacks {', '.join(missing)}")
        return cls(*(d[k] for k in keys))

    def to_dict(self) -> dict[str, float | int]:
        """JSON-ready dict ``{fx, fy, cx, cy, width, height}``."""
        return {
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "width": self.width,
            "height": self.height,
        }

    # matrices ----------------------------------------------------------------------------------------
    @property
    def K(self) -> FloatArray:
        """The 3×3 intrinsic matrix (fresh array)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def K_inv(self) -> FloatArray:
        """The inverse of :attr:`K` (computed in closed form)."""
        return np.array(
            [
                [1.0 / self.fx, 0.0, -self.cx / self.fx],
                [0.0, 1.0 / self.fy, -self.cy / self.fy],
                [0.0, 0.0, 1.0],
            ]
        )

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return (self.width, self.height)

    @property
    def shape(self) -> tuple[int, int]:
        """``(height, width)``: the shape of a single-channel image of this camera."""
        return (self.height, self.width)

    # pyramid -----------------------------------------------------------------------------------------
    def level(self, level: int) -> PinholeCamera:
        """Intrinsics of pyramid level ``level`` (this camera is level 0), as LSD-SLAM.

        ``f_l = f_0 / 2^l``, ``c_l = (c_0 + 0.5) / 2^l - 0.5``, size ``(w >> l, h >> l)`` — the camera of an
        image down-sampled by averaging 2×2 blocks ``level`` times.

        Raises
        ------
        ValueError
            If ``level`` is negative or the level would be empty.
        """
        lv = _as_int(level, "level")
        if lv < 0:
            raise ValueError(f"pyramid level must be >= 0, got {lv}")
        if lv == 0:
            return self
        f = 0.5**lv
        w, h = self.width >> lv, self.height >> lv
        if w == 0 or h == 0:
            raise ValueError(f"pyramid level {lv} of a {self.width}x{self.height} image is empty")
        return PinholeCamera(
            self.fx * f, self.fy * f, (self.cx + 0.5) * f - 0.5, (self.cy + 0.5) * f - 0.5, w, h
        )

    def pyramid(self, n_levels: int) -> list[PinholeCamera]:
        """Cameras of levels ``0 .. n_levels - 1``."""
        n = _as_int(n_levels, "n_levels")
        if n < 1:
            raise ValueError(f"n_levels must be >= 1, got {n}")
        return [self.level(i) for i in range(n)]

    def resized(self, width: int, height: int) -> PinholeCamera:
        """Camera of the image resized (e.g. ``cv2.resize``) to ``width × height``.

        With per-axis factors ``s_x = width / self.width`` and ``s_y = height / self.height``:
        ``f' = f·s``, ``c' = (c + 0.5)·s - 0.5`` (the image borders map onto each other).
        """
        w = _as_int(width, "width")
        h = _as_int(height, "height")
        if w <= 0 or h <= 0:
            raise ValueError(f"size must be positive, got {w}x{h}")
        sx, sy = w / self.width, h / self.height
        return PinholeCamera(
            self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5, w, h
        )

    def scaled(self, factor: float) -> PinholeCamera:
        """Camera of the image resized by ``factor``: size ``round(w·factor) × round(h·factor)``.

        ``f' = f·factor``, ``c' = (c + 0.5)·factor - 0.5`` when ``w·factor`` and ``h·factor`` are integers;
        otherwise the exact per-axis factors of the rounded size are used (see :meth:`resized`).
        """
        fac = float(factor)
        if not (math.isfinite(fac) and fac > 0.0):
            raise ValueError(f"scale factor must be finite and > 0, got {plain(factor)}")
        return self.resized(round(self.width * fac), round(self.height * fac))

    # crops -------------------------------------------------------------------------------------------
    def crop(self, left: int, top: int, width: int, height: int) -> PinholeCamera:
        """Camera of the sub-image ``image[top:top+height, left:left+width]`` (``c' = c - offset``).

        Raises
        ------
        ValueError
            If the box is empty or not inside the image.
        """
        box = _check_box((left, top, width, height), self.width, self.height)
        return PinholeCamera(self.fx, self.fy, self.cx - box[0], self.cy - box[1], box[2], box[3])

    def crop_to_multiple(self, multiple: int = 16) -> tuple[PinholeCamera, Box]:
        """Crop the fewest pixels so that both sizes are multiples of ``multiple``, centred.

        Returns
        -------
        camera : PinholeCamera
            The cropped camera.
        box : tuple of int
            ``(left, top, width, height)`` with ``width = w - w % multiple``, ``left = (w - width) // 2``
            (likewise vertically); pass it to :func:`crop_image`.
        """
        m = _as_int(multiple, "multiple")
        if m < 1:
            raise ValueError(f"multiple must be >= 1, got {m}")
        w, h = self.width - self.width % m, self.height - self.height % m
        if w == 0 or h == 0:
            raise ValueError(f"a {self.width}x{self.height} image has no crop to a multiple of {m}")
        box = ((self.width - w) // 2, (self.height - h) // 2, w, h)
        return self.crop(*box), box

    # projection --------------------------------------------------------------------------------------
    def project_with_depth(self, points: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Project camera-frame points; also return their depths.

        Parameters
        ----------
        points : array_like, shape (..., 3)
            Points in the camera frame.

        Returns
        -------
        uv : ndarray, shape (..., 2)
            Pixel coordinates; NaN where ``z <= 0`` (or z is NaN).
        z : ndarray, shape (...)
            Depths (the points' z).
        """
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (..., 3), got {p.shape}")
        z = p[..., 2]
        valid = z > 0.0
        inv_z = np.divide(1.0, z, out=np.full_like(z, np.nan), where=valid)
        uv = np.empty(p.shape[:-1] + (2,), dtype=np.float64)
        uv[..., 0] = self.fx * p[..., 0] * inv_z + self.cx
        uv[..., 1] = self.fy * p[..., 1] * inv_z + self.cy
        return uv, np.array(z)

    def project(self, points: ArrayLike) -> FloatArray:
        """Pixel coordinates ``(u, v)`` of camera-frame points, shape (..., 3) -> (..., 2).

        ``u = fx·x/z + cx``, ``v = fy·y/z + cy``; NaN for points with ``z <= 0``.
        """
        return self.project_with_depth(points)[0]

    def unproject(self, uv: ArrayLike, depth: ArrayLike) -> FloatArray:
        """Camera-frame points of pixels at given depths (z, not ray length).

        Parameters
        ----------
        uv : array_like, shape (..., 2)
            Pixel coordinates.
        depth : array_like, shape (...)
            Depths along the optical axis (broadcast against ``uv[..., 0]``).

        Returns
        -------
        ndarray, shape (..., 3)
        """
        uv = np.asarray(uv, dtype=np.float64)
        if uv.shape[-1:] != (2,):
            raise ValueError(f"pixel coordinates must have shape (..., 2), got {uv.shape}")
        d = np.asarray(depth, dtype=np.float64)
        x = (uv[..., 0] - self.cx) / self.fx
        y = (uv[..., 1] - self.cy) / self.fy
        x, y, d = np.broadcast_arrays(x, y, d)
        return np.stack([x * d, y * d, d], axis=-1)

    def pixel_grid_rays(self) -> FloatArray:
        """Rays ``((u - cx)/fx, (v - cy)/fy, 1)`` of every pixel, shape (height, width, 3), ``[v, u]``."""
        rays = np.empty((self.height, self.width, 3), dtype=np.float64)
        rays[..., 0] = ((np.arange(self.width, dtype=np.float64) - self.cx) / self.fx)[None, :]
        rays[..., 1] = ((np.arange(self.height, dtype=np.float64) - self.cy) / self.fy)[:, None]
        rays[..., 2] = 1.0
        return rays

    def in_image(self, uv: ArrayLike, border: float = 0.0) -> NDArray[np.bool_]:
        """Mask of pixel coordinates inside the image, at least ``border`` pixels from the edge pixels.

        True where ``border <= u <= width - 1 - border`` and likewise for ``v`` (so with ``border = 0`` the
        point lies within the hull of the pixel centres, where bilinear interpolation is defined); NaN
        coordinates give False.

        Parameters
        ----------
        uv : array_like, shape (..., 2)
        border : float
            Margin in pixels.

        Returns
        -------
        ndarray of bool, shape (...)
        """
        uv = np.asarray(uv, dtype=np.float64)
        if uv.shape[-1:] != (2,):
            raise ValueError(f"pixel coordinates must have shape (..., 2), got {uv.shape}")
        u, v = uv[..., 0], uv[..., 1]
        return (
            (u >= border) & (u <= self.width - 1 - border) & (v >= border) & (v <= self.height - 1 - border)
        )


def _check_box(box: tuple[Any, Any, Any, Any], width: int, height: int) -> Box:
    if len(box) != 4:
        raise ValueError(f"crop box must be (left, top, width, height), got {plain(box)}")
    left, top, w, h = (_as_int(b, n) for b, n in zip(box, ("left", "top", "width", "height"), strict=True))
    if w <= 0 or h <= 0:
        raise ValueError(f"crop box must be non-empty, got {w}x{h}")
    if left < 0 or top < 0 or left + w > width or top + h > height:
        raise ValueError(
            f"crop box (left={left}, top={top}, width={w}, height={h}) is not inside a {width}x{height} image"
        )
    return (left, top, w, h)


def crop_image(image: ArrayLike, box: tuple[int, int, int, int]) -> NDArray[Any]:
    """Crop an image to ``box = (left, top, width, height)`` (see :meth:`PinholeCamera.crop_to_multiple`).

    Parameters
    ----------
    image : array_like, shape (H, W) or (H, W, C)
    box : tuple of int

    Returns
    -------
    ndarray, shape (height, width) or (height, width, C)
        A C-contiguous array of the same dtype (a copy unless the crop already is contiguous).
    """
    img = np.asarray(image)
    if img.ndim not in (2, 3):
        raise ValueError(f"image must have shape (H, W) or (H, W, C), got {img.shape}")
    left, top, w, h = _check_box(box, img.shape[1], img.shape[0])
    return np.ascontiguousarray(img[top : top + h, left : left + w])
