"""Sim(3): the similarity value class :class:`Sim3` (tangent order (υ, ω, σ), as Sophus)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from dmtrack.geometry.lie._coeffs import _sim3_w_coeffs
from dmtrack.geometry.lie._common import _ORTHO_ATOL, FloatArray, _as_points, _Frozen, _readonly, _vector
from dmtrack.geometry.lie._rotation import hat, so3_exp
from dmtrack.geometry.lie.se3 import SE3
from dmtrack.geometry.lie.so3 import SO3, _rotation_arg


class Sim3(_Frozen):
    """A similarity transformation ``p ↦ s R p + t`` (matrix ``[[s R, t], [0, 1]]``).

    Parameters
    ----------
    rotation : SO3 or array_like, shape (3, 3)
    translation : array_like, shape (3,)
    scale : float
        Must be finite and > 0.
    """

    # Both the scale and its logarithm are kept, so that log(exp(ν)) recovers a tiny σ to full relative
    # precision (log(1 + 1e-10) computed from the rounded scale would lose ~7 digits).
    __slots__ = ("_rot", "_t", "_s", "_sigma")
    _rot: SO3
    _t: FloatArray
    _s: float
    _sigma: float

    def __init__(self, rotation: SO3 | ArrayLike, translation: ArrayLike, scale: float = 1.0):
        s = float(scale)
        if not (math.isfinite(s) and s > 0.0):
            raise ValueError(f"Sim3 scale must be finite and > 0, got {scale}")
        object.__setattr__(self, "_rot", _rotation_arg(rotation))
        object.__setattr__(self, "_t", _readonly(_vector(translation, 3, "translation")))
        object.__setattr__(self, "_s", s)
        object.__setattr__(self, "_sigma", math.log(s))

    @classmethod
    def _wrap(cls, R: FloatArray, t: FloatArray, s: float, sigma: float | None = None) -> Sim3:
        obj = object.__new__(cls)
        t.setflags(write=False)
        object.__setattr__(obj, "_rot", SO3._wrap(R))
        object.__setattr__(obj, "_t", t)
        object.__setattr__(obj, "_s", float(s))
        object.__setattr__(obj, "_sigma", math.log(s) if sigma is None else float(sigma))
        return obj

    def __reduce__(self) -> tuple[Any, ...]:
        return (_sim3_from_state, (self._rot.matrix(), np.array(self._t), self._s, self._sigma))

    # constructors ------------------------------------------------------------------------------------
    @classmethod
    def identity(cls) -> Sim3:
        """The identity similarity."""
        return cls._wrap(np.eye(3), np.zeros(3), 1.0)

    @classmethod
    def from_se3(cls, T: SE3, s: float = 1.0) -> Sim3:
        """``[[s R, t], [0, 1]]`` from a rigid transform ``T = (R, t)`` and a scale ``s > 0``."""
        return cls(T.rotation, T.translation, s)

    @classmethod
    def from_matrix(cls, matrix: ArrayLike, orthonormalize: bool = False, atol: float = _ORTHO_ATOL) -> Sim3:
        """From a 4×4 matrix ``[[s R, t], [0, 1]]``; ``s = det(sR)^(1/3)`` must be positive.

        ``orthonormalize`` and ``atol`` apply to ``R = (sR)/s`` as in :meth:`SO3.from_matrix`.
        """
        M = np.asarray(matrix, dtype=np.float64)
        if M.shape != (4, 4):
            raise ValueError(f"Sim3 matrix must have shape (4, 4), got {M.shape}")
        if not np.all(np.isfinite(M)):
            raise ValueError("Sim3 matrix has non-finite entries")
        if not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=1e-12):
            raise ValueError(f"bottom row of a Sim3 matrix must be [0, 0, 0, 1], got {M[3].tolist()}")
        det = float(np.linalg.det(M[:3, :3]))
        if not det > 0.0:
            raise ValueError(f"Sim3 matrix has non-positive determinant {det:.3g}")
        s = det ** (1.0 / 3.0)
        rot = SO3.from_matrix(M[:3, :3] / s, orthonormalize=orthonormalize, atol=atol)
        return cls._wrap(rot._R, np.array(M[:3, 3]), s)

    @classmethod
    def exp(cls, v: ArrayLike) -> Sim3:
        """Exponential of ``ν = (υ, ω, σ)`` (shape (7,)) exactly as Sophus ``Sim3::exp``:
        ``s = e^σ``, ``R = exp(ω)``, ``t = W υ`` with ``W = A ω^ + B ω^² + C I`` (see Strasdat 2012)."""
        v = _vector(v, 7, "sim3 tangent")
        ups, om, sigma = v[:3], v[3:6], float(v[6])
        theta = math.sqrt(float(om @ om))
        A, B, C = _sim3_w_coeffs(sigma, theta)
        W = hat(om)
        Wm = A * W + B * (W @ W) + C * np.eye(3)
        return cls._wrap(so3_exp(om), Wm @ ups, math.exp(sigma), sigma)

    # accessors ---------------------------------------------------------------------------------------
    @property
    def rotation(self) -> SO3:
        """The rotation part."""
        return self._rot

    @property
    def translation(self) -> FloatArray:
        """The translation part, shape (3,) (read-only)."""
        return self._t

    @property
    def scale(self) -> float:
        """The scale ``s > 0``."""
        return self._s

    @property
    def log_scale(self) -> float:
        """``σ = log(s)`` (tracked exactly through exp, composition and inverse)."""
        return self._sigma

    def matrix(self) -> FloatArray:
        """The 4×4 matrix ``[[s R, t], [0, 1]]`` (fresh, writable)."""
        M = np.eye(4)
        M[:3, :3] = self._s * self._rot._R
        M[:3, 3] = self._t
        return M

    def to_se3(self) -> SE3:
        """The rigid part ``(R, t)`` (the scale is dropped)."""
        return SE3._wrap(np.array(self._rot._R), np.array(self._t))

    def log(self) -> FloatArray:
        """Tangent vector ``ν = (υ, ω, σ)``, shape (7,), rotation angle in [0, π]."""
        om = self._rot.log()
        sigma = self._sigma
        theta = math.sqrt(float(om @ om))
        A, B, C = _sim3_w_coeffs(sigma, theta)
        W = hat(om)
        Wm = A * W + B * (W @ W) + C * np.eye(3)
        ups = np.linalg.solve(Wm, self._t)
        return np.concatenate([ups, om, [sigma]])

    def inverse(self) -> Sim3:
        """The inverse ``(Rᵀ, -Rᵀ t / s, 1/s)``."""
        Rt = np.array(self._rot._R.T)
        return Sim3._wrap(Rt, -(Rt @ self._t) / self._s, 1.0 / self._s, -self._sigma)

    def adjoint(self) -> FloatArray:
        """Adjoint 7×7 matrix in ``(υ, ω, σ)`` order (as Sophus):
        ``[[sR, t^ R, -t], [0, R, 0], [0, 0, 1]]``, so that ``exp(Ad ν) = S exp(ν) S⁻¹``."""
        R = self._rot._R
        A = np.zeros((7, 7))
        A[:3, :3] = self._s * R
        A[:3, 3:6] = hat(self._t) @ R
        A[:3, 6] = -self._t
        A[3:6, 3:6] = R
        A[6, 6] = 1.0
        return A

    def act(self, points: ArrayLike) -> FloatArray:
        """Transform points of shape (3,) or (N, 3): ``s R p + t``; returns the same shape."""
        p = _as_points(points)
        return self._s * (p @ self._rot._R.T) + self._t

    def __matmul__(self, other: Any) -> Any:
        if isinstance(other, SE3):
            other = Sim3.from_se3(other)
        if isinstance(other, Sim3):
            R = self._rot._R
            return Sim3._wrap(
                R @ other._rot._R,
                self._s * (R @ other._t) + self._t,
                self._s * other._s,
                self._sigma + other._sigma,
            )
        if isinstance(other, np.ndarray | list | tuple):
            return self.act(other)
        return NotImplemented

    def __rmatmul__(self, other: Any) -> Any:
        # SE3 @ Sim3: SE3.__matmul__ leaves it to this method (se3 does not import sim3)
        if isinstance(other, SE3):
            return Sim3.from_se3(other) @ self
        return NotImplemented

    def allclose(self, other: Sim3, atol: float = 1e-9) -> bool:
        """Whether rotation, translation and scale agree within ``atol``."""
        return (
            self._rot.allclose(other._rot, atol)
            and bool(np.allclose(self._t, other._t, rtol=0.0, atol=atol))
            and abs(self._s - other._s) <= atol
        )

    def __repr__(self) -> str:
        w = self._rot.log()
        t = self._t
        return (
            f"Sim3(rotvec=[{w[0]:.6g}, {w[1]:.6g}, {w[2]:.6g}], "
            f"translation=[{t[0]:.6g}, {t[1]:.6g}, {t[2]:.6g}], scale={self._s:.6g})"
        )


def _sim3_from_state(R: ArrayLike, t: ArrayLike, s: float, sigma: float) -> Sim3:
    """Unpickling helper: validates like the constructor and keeps ``σ`` exactly."""
    S = Sim3(R, t, s)
    return Sim3._wrap(np.array(S.rotation.matrix()), np.array(S.translation), s, sigma)
