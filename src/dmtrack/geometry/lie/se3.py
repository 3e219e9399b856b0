"""SE(3): the rigid transformation value class :class:`SE3` (tangent order (υ, ω)).

``SE3 @ Sim3`` gives a :class:`~dmtrack.geometry.lie.sim3.Sim3`; it is implemented by ``Sim3.__rmatmul__``
(Sim(3) builds on this module, not the other way round).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from dmtrack.geometry.lie._coeffs import _se3_v_coeffs, _se3_vinv_coeff
from dmtrack.geometry.lie._common import _ORTHO_ATOL, FloatArray, _as_points, _Frozen, _readonly, _vector
from dmtrack.geometry.lie._rotation import hat, so3_exp
from dmtrack.geometry.lie.so3 import SO3, _rotation_arg


class SE3(_Frozen):
    """A rigid transformation ``p ↦ R p + t``.

    Parameters
    ----------
    rotation : SO3 or array_like, shape (3, 3)
    translation : array_like, shape (3,)
    """

    __slots__ = ("_rot", "_t")
    _rot: SO3
    _t: FloatArray

    def __init__(self, rotation: SO3 | ArrayLike, translation: ArrayLike):
        object.__setattr__(self, "_rot", _rotation_arg(rotation))
        object.__setattr__(self, "_t", _readonly(_vector(translation, 3, "translation")))

    @classmethod
    def _wrap(cls, R: FloatArray, t: FloatArray) -> SE3:
        obj = object.__new__(cls)
        t.setflags(write=False)
        object.__setattr__(obj, "_rot", SO3._wrap(R))
        object.__setattr__(obj, "_t", t)
        return obj

    def __reduce__(self) -> tuple[Any, ...]:
        return (SE3, (self._rot.matrix(), np.array(self._t)))

    # constructors ------------------------------------------------------------------------------------
    @classmethod
    def identity(cls) -> SE3:
        """The identity transformation."""
        return cls._wrap(np.eye(3), np.zeros(3))

    @classmethod
    def from_rt(cls, R: SO3 | ArrayLike, t: ArrayLike) -> SE3:
        """From a rotation (SO3 or 3×3 matrix) and a translation (3,)."""
        return cls(R, t)

    @classmethod
    def from_matrix(cls, matrix: ArrayLike, orthonormalize: bool = False, atol: float = _ORTHO_ATOL) -> SE3:
        """From a 4×4 homogeneous matrix (bottom row must be ``[0, 0, 0, 1]``) or a 3×4 ``[R | t]``.

        ``orthonormalize`` and ``atol`` apply to the rotation block as in :meth:`SO3.from_matrix`.
        """
        M = np.asarray(matrix, dtype=np.float64)
        if M.shape not in ((4, 4), (3, 4)):
            raise ValueError(f"SE3 matrix must have shape (4, 4) or (3, 4), got {M.shape}")
        if not np.all(np.isfinite(M)):
            raise ValueError("SE3 matrix has non-finite entries")
        if M.shape == (4, 4) and not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=1e-12):
            raise ValueError(f"bottom row of an SE3 matrix must be [0, 0, 0, 1], got {M[3].tolist()}")
        rot = SO3.from_matrix(M[:3, :3], orthonormalize=orthonormalize, atol=atol)
        return cls._wrap(rot._R, np.array(M[:3, 3]))

    @classmethod
    def from_quaternion(cls, t: ArrayLike, q: ArrayLike) -> SE3:
        """From a translation (3,) and a quaternion ``(x, y, z, w)`` (TUM order: ``tx ty tz qx qy qz qw``)."""
        return cls._wrap(SO3.from_quaternion(q)._R, np.array(_vector(t, 3, "translation")))

    @classmethod
    def exp(cls, xi: ArrayLike) -> SE3:
        """Exponential of ``ξ = (υ, ω)`` (shape (6,)): ``R = exp(ω)``, ``t = V(ω) υ`` with
        ``V = I + (1 - cos θ)/θ² ω^ + (θ - sin θ)/θ³ ω^²``."""
        xi = _vector(xi, 6, "se3 tangent")
        ups, om = xi[:3], xi[3:]
        theta = math.sqrt(float(om @ om))
        b, c = _se3_v_coeffs(theta)
        W = hat(om)
        V = np.eye(3) + b * W + c * (W @ W)
        return cls._wrap(so3_exp(om), V @ ups)

    @classmethod
    def sample(cls, rng: np.random.Generator, translation_scale: float = 1.0) -> SE3:
        """A random transform: uniform rotation, Gaussian translation with std ``translation_scale``."""
        return cls(SO3.sample_uniform(rng), translation_scale * rng.standard_normal(3))

    # accessors ---------------------------------------------------------------------------------------
    @property
    def rotation(self) -> SO3:
        """The rotation part."""
        return self._rot

    @property
    def translation(self) -> FloatArray:
        """The translation part, shape (3,) (read-only)."""
        return self._t

    def matrix(self) -> FloatArray:
        """The 4×4 homogeneous matrix (fresh, writable)."""
        M = np.eye(4)
        M[:3, :3] = self._rot._R
        M[:3, 3] = self._t
        return M

    def matrix3x4(self) -> FloatArray:
        """The 3×4 matrix ``[R | t]`` (fresh, writable)."""
        return np.concatenate([self._rot._R, self._t[:, None]], axis=1)

    def to_quaternion(self) -> tuple[FloatArray, FloatArray]:
        """``(t, q)``: translation (3,) and quaternion ``(x, y, z, w)`` with ``w ≥ 0`` (4,)."""
        return np.array(self._t), self._rot.to_quaternion()

    def log(self) -> FloatArray:
        """Tangent vector ``ξ = (υ, ω)``, shape (6,), rotation angle in [0, π]."""
        om = self._rot.log()
        theta = math.sqrt(float(om @ om))
        W = hat(om)
        Vinv = np.eye(3) - 0.5 * W + _se3_vinv_coeff(theta) * (W @ W)
        return np.concatenate([Vinv @ self._t, om])

    def inverse(self) -> SE3:
        """The inverse transformation ``(Rᵀ, -Rᵀ t)``."""
        Rt = np.array(self._rot._R.T)
        return SE3._wrap(Rt, -(Rt @ self._t))

    def adjoint(self) -> FloatArray:
        """Adjoint 6×6 matrix in ``(υ, ω)`` order, ``[[R, t^ R], [0, R]]``:
        ``exp(Ad ξ) = T exp(ξ) T⁻¹``."""
        R = self._rot._R
        A = np.zeros((6, 6))
        A[:3, :3] = R
        A[3:, 3:] = R
        A[:3, 3:] = hat(self._t) @ R
        return A

    def act(self, points: ArrayLike) -> FloatArray:
        """Transform points of shape (3,) or (N, 3): ``R p + t``; returns the same shape."""
        p = _as_points(points)
        return p @ self._rot._R.T + self._t

    def __matmul__(self, other: Any) -> Any:
        if isinstance(other, SE3):
            R = self._rot._R
            return SE3._wrap(R @ other._rot._R, R @ other._t + self._t)
        if isinstance(other, np.ndarray | list | tuple):
            return self.act(other)
        return NotImplemented

    def allclose(self, other: SE3, atol: float = 1e-9) -> bool:
        """Whether rotation and translation agree entry-wise within ``atol``."""
        return self._rot.allclose(other._rot, atol) and bool(
            np.allclose(self._t, other._t, rtol=0.0, atol=atol)
        )

    def __repr__(self) -> str:
        w = self._rot.log()
        t = self._t
        return (
            f"SE3(rotvec=[{w[0]:.6g}, {w[1]:.6g}, {w[2]:.6g}], "
            f"translation=[{t[0]:.6g}, {t[1]:.6g}, {t[2]:.6g}])"
        )
