"""SO(3): the rotation value class :class:`SO3` (and the validation of user-given rotation matrices)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from dmtrack.geometry.lie._common import _ORTHO_ATOL, FloatArray, _as_points, _Frozen, _readonly, _vector
from dmtrack.geometry.lie._rotation import (
    hat,
    matrix_to_quaternion,
    quaternion_to_matrix,
    rotation_angle,
    so3_exp,
    so3_log,
    vee,
)


def _project_to_rotation(M: FloatArray) -> FloatArray:
    """Nearest rotation matrix (Frobenius norm) of a 3×3 matrix with positive determinant."""
    U, _, Vt = np.linalg.svd(M)
    if np.linalg.det(U @ Vt) < 0.0:
        raise ValueError("matrix has negative determinant: it is not close to a rotation")
    return U @ Vt


def _check_rotation(M: FloatArray, atol: float) -> None:
    if M.shape != (3, 3):
        raise ValueError(f"rotation matrix must have shape (3, 3), got {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ValueError("rotation matrix has non-finite entries")
    err = np.abs(M.T @ M - np.eye(3)).max()
    if err > atol:
        raise ValueError(f"matrix is not orthonormal (max |RᵀR - I| = {err:.3g} > {atol:.3g})")
    if np.linalg.det(M) <= 0.0:
        raise ValueError("matrix has non-positive determinant: it is a reflection, not a rotation")


class SO3(_Frozen):
    """A 3D rotation.

    Parameters
    ----------
    matrix : array_like, shape (3, 3)
        Rotation matrix; must be orthonormal with determinant +1 within 1e-6 (use
        :meth:`from_matrix` with ``orthonormalize=True`` for noisy matrices).
    """

    __slots__ = ("_R",)
    _R: FloatArray

    def __init__(self, matrix: ArrayLike):
        M = np.asarray(matrix, dtype=np.float64)
        _check_rotation(M, _ORTHO_ATOL)
        object.__setattr__(self, "_R", _readonly(M))

    @classmethod
    def _wrap(cls, R: FloatArray) -> SO3:
        """Trusted constructor: no validation; takes ownership of ``R``."""
        obj = object.__new__(cls)
        R.setflags(write=False)
        object.__setattr__(obj, "_R", R)
        return obj

    def __reduce__(self) -> tuple[Any, ...]:
        return (SO3, (np.array(self._R),))

    # constructors ------------------------------------------------------------------------------------
    @classmethod
    def identity(cls) -> SO3:
        """The identity rotation."""
        return cls._wrap(np.eye(3))

    @classmethod
    def from_matrix(cls, matrix: ArrayLike, orthonormalize: bool = False, atol: float = _ORTHO_ATOL) -> SO3:
        """Rotation from a 3×3 matrix.

        Parameters
        ----------
        matrix : array_like, shape (3, 3)
        orthonormalize : bool
            Project onto the nearest rotation (SVD) instead of only checking orthonormality — use this for
            matrices read from text files.
        atol : float
            Tolerance of the orthonormality check (max abs entry of ``RᵀR - I``) when not orthonormalizing.
        """
        M = np.asarray(matrix, dtype=np.float64)
        if M.shape != (3, 3):
            raise ValueError(f"rotation matrix must have shape (3, 3), got {M.shape}")
        if not np.all(np.isfinite(M)):
            raise ValueError("rotation matrix has non-finite entries")
        if orthonormalize:
            return cls._wrap(_project_to_rotation(M))
        _check_rotation(M, atol)
        return cls._wrap(np.array(M))

    @classmethod
    def exp(cls, w: ArrayLike) -> SO3:
        """Rotation of a rotation vector ``w`` (shape (3,), radians)."""
        return cls._wrap(so3_exp(_vector(w, 3, "rotation vector")))

    @classmethod
    def from_quaternion(cls, q: ArrayLike) -> SO3:
        """Rotation of a quaternion ``(x, y, z, w)`` (normalised; raises ValueError on zero norm)."""
        return cls._wrap(quaternion_to_matrix(_vector(q, 4, "quaternion")))

    @classmethod
    def sample_uniform(cls, rng: np.random.Generator) -> SO3:
        """A rotation drawn uniformly (Haar measure) with the given generator."""
        q = rng.standard_normal(4)
        while np.linalg.norm(q) < 1e-8:  # pragma: no cover - probability ~0
            q = rng.standard_normal(4)
        return cls.from_quaternion(q)

    # accessors ---------------------------------------------------------------------------------------
    def matrix(self) -> FloatArray:
        """The 3×3 rotation matrix (a fresh writable copy)."""
        return np.array(self._R)

    def log(self) -> FloatArray:
        """Rotation vector, shape (3,), angle in [0, π]."""
        return so3_log(self._R)

    def to_quaternion(self) -> FloatArray:
        """Unit quaternion ``(x, y, z, w)`` with ``w ≥ 0``, shape (4,)."""
        return matrix_to_quaternion(self._R)

    def angle(self) -> float:
        """Rotation angle in radians, in [0, π]."""
        return float(rotation_angle(self._R))

    def inverse(self) -> SO3:
        """The inverse rotation ``Rᵀ``."""
        return SO3._wrap(np.array(self._R.T))

    def adjoint(self) -> FloatArray:
        """Adjoint 3×3 matrix (``R`` itself): ``exp(Ad ω) = R exp(ω) Rᵀ``."""
        return np.array(self._R)

    def act(self, points: ArrayLike) -> FloatArray:
        """Rotate points of shape (3,) or (N, 3); returns the same shape."""
        p = _as_points(points)
        return p @ self._R.T

    def __matmul__(self, other: Any) -> Any:
        if isinstance(other, SO3):
            return SO3._wrap(self._R @ other._R)
        if isinstance(other, np.ndarray | list | tuple):
            return self.act(other)
        return NotImplemented

    def allclose(self, other: SO3, atol: float = 1e-9) -> bool:
        """Whether the rotation matrices agree entry-wise within ``atol``."""
        return bool(np.allclose(self._R, other._R, rtol=0.0, atol=atol))

    def __repr__(self) -> str:
        w = self.log()
        return f"SO3(rotvec=[{w[0]:.6g}, {w[1]:.6g}, {w[2]:.6g}])"

    hat = staticmethod(hat)
    vee = staticmethod(vee)


def _rotation_arg(rotation: SO3 | ArrayLike) -> SO3:
    return rotation if isinstance(rotation, SO3) else SO3(rotation)
