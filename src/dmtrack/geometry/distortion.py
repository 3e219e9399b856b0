"""Camera models with lens distortion, as used by the datasets of the paper.

Every model maps **normalised undistorted** coordinates ``(x, y) = (X/Z, Y/Z)`` to **normalised distorted**
coordinates (``distort``) and back (``undistort``); pixel coordinates are ``u = fx·x_d + cx``,
``v = fy·y_d + cy`` with pixel centres at integer coordinates.  All functions are vectorised over arrays of
shape ``(..., 2)``.

Models
------
* :class:`PinholeModel` — no distortion.
* :class:`FOVModel` — the field-of-view ("ATAN") model of Devernay & Faugeras (2001) in the convention of
  PTAM, LSD-SLAM and DSO (``UndistortFOV::distortCoordinates``): ``r_d = atan(2·r_u·tan(ω/2)) / ω``.
* :class:`RadTanModel` — OpenCV's radial-tangential ("plumb bob") model ``k1 k2 p1 p2 [k3]``.
* :class:`EquidistantModel` — the equidistant fisheye model of Kannala & Brandt (OpenCV ``fisheye``, DSO
  ``KannalaBrandt``/``EquiDistant``): ``θ = atan(r_u)``, ``r_d = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸)``.

Where a model cannot be inverted (a FOV radius beyond ``π/(2ω)``, a polynomial past its turning point) the
result is NaN.  :attr:`max_radius` is the largest normalised undistorted radius on which ``distort`` is
monotonic — beyond it distinct rays would land on the same pixel, so an undistortion map must not use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dmtrack.geometry.camera import PinholeCamera

__all__ = [
    "CameraModel",
    "EquidistantModel",
    "FOVModel",
    "PinholeModel",
    "RadTanModel",
    "model_from_dict",
]

FloatArray = NDArray[np.float64]


def _xy(points: ArrayLike) -> FloatArray:
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1:] != (2,):
        raise ValueError(f"normalised coordinates must have shape (..., 2), got {p.shape}")
    return p


@runtime_checkable
class CameraModel(Protocol):
    """What :class:`~dmtrack.datasets.undistort.Undistorter` needs from a camera model."""

    name: ClassVar[str]
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @property
    def max_radius(self) -> float: ...

    def distort(self, xy: ArrayLike) -> FloatArray: ...

    def undistort(self, xy: ArrayLike) -> FloatArray: ...

    def pinhole(self) -> PinholeCamera: ...

    def to_dict(self) -> dict[str, Any]: ...


@dataclass(frozen=True)
class _Base:
    """Intrinsics shared by every model: focal lengths and principal point in pixels, image size."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        # validates the pinhole part (finite, positive focal lengths and sizes)
        PinholeCamera(self.fx, self.fy, self.cx, self.cy, self.width, self.height)
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, float(getattr(self, name)))
        for name in ("width", "height"):
            object.__setattr__(self, name, int(getattr(self, name)))

    def pinhole(self) -> PinholeCamera:
        """The pinhole part (``fx, fy, cx, cy``, size) — exact only for an undistorted model."""
        return PinholeCamera(self.fx, self.fy, self.cx, self.cy, self.width, self.height)

    # pixel helpers ----------------------------------------------------------------------------------
    def pixel_to_normalised(self, uv: ArrayLike) -> FloatArray:
        """Distorted pixel coordinates → normalised distorted coordinates, (..., 2)."""
        uv = _xy(uv)
        return np.stack([(uv[..., 0] - self.cx) / self.fx, (uv[..., 1] - self.cy) / self.fy], axis=-1)

    def normalised_to_pixel(self, xy: ArrayLike) -> FloatArray:
        """Normalised distorted coordinates → pixel coordinates, (..., 2)."""
        xy = _xy(xy)
        return np.stack([xy[..., 0] * self.fx + self.cx, xy[..., 1] * self.fy + self.cy], axis=-1)

    def project(self, points: ArrayLike) -> FloatArray:
        """Pixel coordinates of camera-frame points (..., 3) → (..., 2); NaN behind the camera or where the
        model is not defined."""
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (..., 3), got {p.shape}")
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = np.where((z > 0)[..., None], p[..., :2] / z[..., None], np.nan)
        return self.normalised_to_pixel(self.distort(xy))  # type: ignore[attr-defined]

    def unproject_pixels(self, uv: ArrayLike) -> FloatArray:
        """Normalised undistorted coordinates (rays ``(x, y, 1)``) of distorted pixels, (..., 2)."""
        return self.undistort(self.pixel_to_normalised(uv))  # type: ignore[attr-defined]


@dataclass(frozen=True)
class PinholeModel(_Base):
    """No distortion (DSO's ``Pinhole`` model, LSD-SLAM's FOV file with ``ω = 0``)."""

    name: ClassVar[str] = "pinhole"

    @property
    def max_radius(self) -> float:
        return math.inf

    def distort(self, xy: ArrayLike) -> FloatArray:
        return np.array(_xy(xy))

    def undistort(self, xy: ArrayLike) -> FloatArray:
        return np.array(_xy(xy))

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.name, **self.pinhole().to_dict()}


@dataclass(frozen=True)
class FOVModel(_Base):
    """The FOV / ATAN model (Devernay & Faugeras 2001) with parameter ``omega`` (radians).

    ``r_d = atan(2·r_u·tan(ω/2)) / ω`` and inversely ``r_u = tan(r_d·ω) / (2·tan(ω/2))`` (defined for
    ``r_d·ω < π/2``), where ``r_u``, ``r_d`` are the radii of the normalised undistorted and distorted
    coordinates.  ``ω`` is the field of view of an ideal fisheye lens; ``ω = 0`` is the pinhole limit.
    This is exactly PTAM's / LSD-SLAM's ``UndistorterPTAM`` and DSO's ``UndistortFOV`` mapping.
    """

    omega: float = 0.0
    name: ClassVar[str] = "fov"

    def __post_init__(self) -> None:
        super().__post_init__()
        w = float(self.omega)
        if not (math.isfinite(w) and 0.0 <= w < math.pi):
            raise ValueError(f"FOV parameter omega must be in [0, π), got {w!r}")
        object.__setattr__(self, "omega", w)

    @property
    def max_radius(self) -> float:
        return math.inf  # atan is monotonic

    def _scale_distort(self, r: FloatArray) -> FloatArray:
        w = self.omega
        if w == 0.0:
            return np.ones_like(r)
        d2t = 2.0 * math.tan(w / 2.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.arctan(r * d2t) / (w * r)
        # limit r → 0: atan(r·d2t)/(ω r) → d2t/ω
        return np.where(r > 1e-12, s, d2t / w)

    def distort(self, xy: ArrayLike) -> FloatArray:
        xy = _xy(xy)
        r = np.hypot(xy[..., 0], xy[..., 1])
        return xy * self._scale_distort(r)[..., None]

    def undistort(self, xy: ArrayLike) -> FloatArray:
        xy = _xy(xy)
        w = self.omega
        if w == 0.0:
            return np.array(xy)
        rd = np.hypot(xy[..., 0], xy[..., 1])
        d2t = 2.0 * math.tan(w / 2.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.tan(rd * w) / (d2t * rd)
        s = np.where(rd > 1e-12, s, w / d2t)
        s = np.where(rd * w < math.pi / 2.0, s, np.nan)
        return xy * s[..., None]

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.name, **self.pinhole().to_dict(), "omega": self.omega}


def _first_turning_point(f: Any, r_max: float = 20.0, n: int = 20001) -> float:
    """Largest ``r`` in ``[0, r_max]`` up to which the radial function ``f`` increases (sampled)."""
    r = np.linspace(0.0, r_max, n)
    with np.errstate(over="ignore", invalid="ignore"):  # absurd coefficients overflow: not increasing there
        v = f(r)
        d = np.diff(v)
    bad = np.flatnonzero(~(d > 0))
    if bad.size == 0:
        return math.inf
    return float(r[bad[0]])


@dataclass(frozen=True)
class RadTanModel(_Base):
    """OpenCV's radial-tangential model ``(k1, k2, p1, p2, k3)`` on normalised coordinates.

    ``x_d = x·(1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2x²)`` and
    ``y_d = y·(1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2y²) + 2 p2 x y`` with ``r² = x² + y²``
    (``cv::projectPoints``; DSO ``UndistortRadTan`` uses the same with ``k3 = 0``).  The inverse is computed
    by Newton's method (NaN where it does not converge).
    """

    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    name: ClassVar[str] = "radtan"
    _max_r: float = field(default=math.inf, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        for n in ("k1", "k2", "p1", "p2", "k3"):
            v = float(getattr(self, n))
            if not math.isfinite(v):
                raise ValueError(f"distortion coefficient {n} must be finite, got {v!r}")
            object.__setattr__(self, n, v)
        # radial monotonicity r·(1 + k1 r² + k2 r⁴ + k3 r⁶); the tangential part is small where this holds
        radial = lambda r: r * (1 + self.k1 * r**2 + self.k2 * r**4 + self.k3 * r**6)  # noqa: E731
        object.__setattr__(self, "_max_r", _first_turning_point(radial))

    @property
    def coefficients(self) -> tuple[float, float, float, float, float]:
        """``(k1, k2, p1, p2, k3)`` as OpenCV's ``distCoeffs``."""
        return (self.k1, self.k2, self.p1, self.p2, self.k3)

    @property
    def max_radius(self) -> float:
        return self._max_r

    def distort(self, xy: ArrayLike) -> FloatArray:
        xy = _xy(xy)
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        xd = x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x)
        yd = y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y
        return np.stack([xd, yd], axis=-1)

    def _jacobian(self, x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        dradial = self.k1 + r2 * (2.0 * self.k2 + 3.0 * self.k3 * r2)  # d radial / d r2
        dxx = radial + x * dradial * 2 * x + 2 * self.p1 * y + self.p2 * 6 * x
        dxy = x * dradial * 2 * y + 2 * self.p1 * x + self.p2 * 2 * y
        dyx = y * dradial * 2 * x + self.p1 * 2 * x + 2 * self.p2 * y
        dyy = radial + y * dradial * 2 * y + self.p1 * 6 * y + 2 * self.p2 * x
        return dxx, dxy, dyx, dyy

    def undistort(self, xy: ArrayLike, iterations: int = 30, tol: float = 1e-12) -> FloatArray:
        xy_d = _xy(xy)
        shape = xy_d.shape
        target = xy_d.reshape(-1, 2)
        cur = target.copy()  # initial guess: no distortion
        for _ in range(iterations):
            f = self.distort(cur) - target
            a, b, c, d = self._jacobian(cur[:, 0], cur[:, 1])
            det = a * d - b * c
            with np.errstate(divide="ignore", invalid="ignore"):
                dx = (d * f[:, 0] - b * f[:, 1]) / det
                dy = (-c * f[:, 0] + a * f[:, 1]) / det
            step = np.stack([dx, dy], axis=-1)
            cur = cur - np.where(np.isfinite(step), step, 0.0)
            if np.nanmax(np.abs(step), initial=0.0) < tol:
                break
        err = np.abs(self.distort(cur) - target).max(axis=-1)
        r = np.hypot(cur[:, 0], cur[:, 1])
        bad = ~(err < 1e-9) | (r > self.max_radius)
        cur[bad] = np.nan
        return cur.reshape(shape)

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.name, **self.pinhole().to_dict(), "k1": self.k1, "k2": self.k2, "p1": self.p1,
                "p2": self.p2, "k3": self.k3}


@dataclass(frozen=True)
class EquidistantModel(_Base):
    """Kannala–Brandt equidistant fisheye model ``(k1, k2, k3, k4)`` (OpenCV ``cv::fisheye``).

    ``θ = atan(r_u)``, ``θ_d = θ·(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸)``, ``(x_d, y_d) = (θ_d / r_u)·(x, y)``.
    """

    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    name: ClassVar[str] = "equidistant"
    _max_theta: float = field(default=math.pi / 2, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        for n in ("k1", "k2", "k3", "k4"):
            v = float(getattr(self, n))
            if not math.isfinite(v):
                raise ValueError(f"distortion coefficient {n} must be finite, got {v!r}")
            object.__setattr__(self, n, v)
        theta_max = _first_turning_point(self._theta_d, r_max=math.pi / 2 - 1e-9)
        object.__setattr__(self, "_max_theta", min(theta_max, math.pi / 2))

    def _theta_d(self, t: FloatArray) -> FloatArray:
        t2 = t * t
        return t * (1.0 + t2 * (self.k1 + t2 * (self.k2 + t2 * (self.k3 + t2 * self.k4))))

    @property
    def max_radius(self) -> float:
        return math.tan(self._max_theta) if self._max_theta < math.pi / 2 else math.inf

    def distort(self, xy: ArrayLike) -> FloatArray:
        xy = _xy(xy)
        r = np.hypot(xy[..., 0], xy[..., 1])
        theta = np.arctan(r)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(r > 1e-12, self._theta_d(theta) / r, 1.0)
        return xy * s[..., None]

    def undistort(self, xy: ArrayLike, iterations: int = 30) -> FloatArray:
        xy = _xy(xy)
        rd = np.hypot(xy[..., 0], xy[..., 1])
        theta = np.array(rd)  # θ_d ≈ θ for small distortion
        for _ in range(iterations):
            t2 = theta * theta
            f = self._theta_d(theta) - rd
            df = 1.0 + t2 * (3 * self.k1 + t2 * (5 * self.k2 + t2 * (7 * self.k3 + t2 * 9 * self.k4)))
            with np.errstate(divide="ignore", invalid="ignore"):
                theta = theta - np.where(df != 0, f / df, 0.0)
        ok = (np.abs(self._theta_d(theta) - rd) < 1e-9) & (theta >= 0) & (theta <= self._max_theta)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(rd > 1e-12, np.tan(theta) / rd, 1.0)
        s = np.where(ok, s, np.nan)
        return xy * s[..., None]

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.name, **self.pinhole().to_dict(), "k1": self.k1, "k2": self.k2, "k3": self.k3,
                "k4": self.k4}


_MODELS: dict[str, type] = {
    "pinhole": PinholeModel,
    "fov": FOVModel,
    "radtan": RadTanModel,
    "equidistant": EquidistantModel,
}


def model_from_dict(d: dict[str, Any]) -> CameraModel:
    """Inverse of ``to_dict()``: ``{"model": name, fx, fy, cx, cy, width, height, <parameters>}``."""
    d = dict(d)
    name = d.pop("model", None)
    if name not in _MODELS:
        raise ValueError(f"unknown camera model {name!r}; known: {', '.join(_MODELS)}")
    return _MODELS[name](**d)
