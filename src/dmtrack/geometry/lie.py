"""Lie groups SO(3), SE(3) and Sim(3) as small immutable value classes (float64).

Conventions
-----------
* **Tangent order.**  SE(3) tangent vectors are ``ξ = (υ, ω)`` — translational part first, then the
  rotation vector — as in Sophus and LSD-SLAM.  Sim(3) tangent vectors are ``ν = (υ, ω, σ)`` with
  ``σ = log(scale)``, exactly Sophus' order.  ``exp`` maps them to the group through the matrix
  generators

  .. code-block:: text

      SE(3):  [[ω^, υ], [0, 0]]            exp(ξ)  = expm of that 4×4 matrix
      Sim(3): [[ω^ + σ I, υ], [0, 0]]      exp(ν)  = expm of that 4×4 matrix

  where ``ω^ = hat(ω)`` is the 3×3 skew-symmetric matrix with ``hat(ω) @ p == cross(ω, p)``.
* **Perturbation.**  Updates are left perturbations, ``T ← exp(δ) · T``; ``adjoint()`` is defined so that
  ``exp(T.adjoint() @ ξ) == T @ exp(ξ) @ T.inverse()``.
* **Quaternions** are stored in ``(x, y, z, w)`` order (scalar last — the TUM trajectory and
  ``scipy.spatial.transform.Rotation`` order).  Quaternions produced here are unit and have ``w ≥ 0``.
* **Group elements act on points** stored as rows: ``T @ pts`` with ``pts`` of shape (3,) or (N, 3)
  returns the same shape; ``Sim3`` acts as ``p ↦ s R p + t``.
* **Numerics.**  ``exp``/``log`` use Taylor expansions below small-angle thresholds (so ``exp`` of a
  1e-9 vector is exact to rounding), ``so3_log`` goes through a Shepperd quaternion and is accurate up to
  and including rotation angle π.  ``log`` returns rotation vectors with angle in [0, π].

Instances are immutable: their arrays are private read-only copies and attributes cannot be set.
``matrix()``-like methods return fresh, writable arrays.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "SE3",
    "SO3",
    "Sim3",
    "hat",
    "matrix_to_quaternion",
    "quaternion_to_matrix",
    "rotation_angle",
    "so3_exp",
    "so3_log",
    "vee",
]

FloatArray = NDArray[np.float64]

# Below these magnitudes closed-form coefficients are replaced by Taylor series.
_SMALL_ANGLE = 1e-4  # so3_exp coefficients: truncation error ~θ⁶/5040
_ORTHO_ATOL = 1e-6  # default tolerance of the orthonormality check of user-given rotations


# ----------------------------------------------------------------------------------------------------
# Batched helpers
# ----------------------------------------------------------------------------------------------------
def hat(w: ArrayLike) -> FloatArray:
    """Skew-symmetric matrix of a 3-vector, ``hat(w) @ p == np.cross(w, p)``.

    Parameters
    ----------
    w : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3), float64
    """
    w = np.asarray(w, dtype=np.float64)
    if w.shape[-1:] != (3,):
        raise ValueError(f"hat expects shape (..., 3), got {w.shape}")
    out = np.zeros(w.shape[:-1] + (3, 3), dtype=np.float64)
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    out[..., 0, 1] = -z
    out[..., 0, 2] = y
    out[..., 1, 0] = z
    out[..., 1, 2] = -x
    out[..., 2, 0] = -y
    out[..., 2, 1] = x
    return out


def vee(W: ArrayLike) -> FloatArray:
    """Inverse of :func:`hat`: the 3-vector of a skew-symmetric matrix.

    Uses the antisymmetric part, ``vee(W) = vee((W - Wᵀ)/2)``, so it is also defined for matrices that
    are only approximately skew-symmetric.

    Parameters
    ----------
    W : array_like, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 3), float64
    """
    W = np.asarray(W, dtype=np.float64)
    if W.shape[-2:] != (3, 3):
        raise ValueError(f"vee expects shape (..., 3, 3), got {W.shape}")
    return 0.5 * np.stack(
        [W[..., 2, 1] - W[..., 1, 2], W[..., 0, 2] - W[..., 2, 0], W[..., 1, 0] - W[..., 0, 1]], axis=-1
    )


def quaternion_to_matrix(q: ArrayLike) -> FloatArray:
    """Rotation matrices of quaternions in ``(x, y, z, w)`` order.

    The quaternions are normalised first; ``q`` and ``-q`` give the same matrix.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions, scalar last.

    Returns
    -------
    ndarray, shape (..., 3, 3), float64

    Raises
    ------
    ValueError
        If the shape is wrong, a quaternion is not finite or has zero norm.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(f"quaternions must have shape (..., 4), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("quaternion has non-finite entries")
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n == 0.0):
        raise ValueError("quaternion has zero norm")
    q = q / n
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    R = np.empty(q.shape[:-1] + (3, 3), dtype=np.float64)
    R[..., 0, 0] = 1.0 - 2.0 * (yy + zz)
    R[..., 0, 1] = 2.0 * (xy - wz)
    R[..., 0, 2] = 2.0 * (xz + wy)
    R[..., 1, 0] = 2.0 * (xy + wz)
    R[..., 1, 1] = 1.0 - 2.0 * (xx + zz)
    R[..., 1, 2] = 2.0 * (yz - wx)
    R[..., 2, 0] = 2.0 * (xz - wy)
    R[..., 2, 1] = 2.0 * (yz + wx)
    R[..., 2, 2] = 1.0 - 2.0 * (xx + yy)
    return R


def _quaternion_single(R: FloatArray) -> tuple[float, float, float, float]:
    """Shepperd's method for one 3×3 matrix in plain floats (fast path of :func:`matrix_to_quaternion`)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist()
    d = (1.0 + r00 + r11 + r22, 1.0 + r00 - r11 - r22, 1.0 - r00 + r11 - r22, 1.0 - r00 - r11 + r22)
    k = max(range(4), key=d.__getitem__)
    if k == 0:
        x, y, z, w = r21 - r12, r02 - r20, r10 - r01, d[0]
    elif k == 1:
        x, y, z, w = d[1], r01 + r10, r02 + r20, r21 - r12
    elif k == 2:
        x, y, z, w = r01 + r10, d[2], r12 + r21, r02 - r20
    else:
        x, y, z, w = r02 + r20, r12 + r21, d[3], r10 - r01
    n = math.sqrt(x * x + y * y + z * z + w * w)  # = 4·q_k·|q| > 0, since d_k = 4·q_k² >= 1
    if w < 0.0:
        n = -n
    return x / n, y / n, z / n, w / n


def _so3_exp_single(wx: float, wy: float, wz: float) -> FloatArray:
    """Rodrigues' formula for one rotation vector in plain floats (fast path of :func:`so3_exp`)."""
    t2 = wx * wx + wy * wy + wz * wz
    theta = math.sqrt(t2)
    if theta < _SMALL_ANGLE:
        a = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
        b = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
    else:
        a = math.sin(theta) / theta
        h = math.sin(0.5 * theta) / theta
        b = 2.0 * h * h
    bxy, bxz, byz = b * wx * wy, b * wx * wz, b * wy * wz
    return np.array(
        [
            [1.0 - b * (wy * wy + wz * wz), bxy - a * wz, bxz + a * wy],
            [bxy + a * wz, 1.0 - b * (wx * wx + wz * wz), byz - a * wx],
            [bxz - a * wy, byz + a * wx, 1.0 - b * (wx * wx + wy * wy)],
        ]
    )


def _so3_log_single(R: FloatArray) -> FloatArray:
    """:func:`so3_log` of one matrix in plain floats."""
    x, y, z, w = _quaternion_single(R)
    n = math.sqrt(x * x + y * y + z * z)
    factor = 2.0 / w * (1.0 - n * n / (3.0 * w * w)) if n < 1e-8 else 2.0 * math.atan2(n, w) / n
    return np.array([factor * x, factor * y, factor * z])


def matrix_to_quaternion(R: ArrayLike) -> FloatArray:
    """Unit quaternions ``(x, y, z, w)`` with ``w ≥ 0`` of rotation matrices (Shepperd's method).

    For each matrix the largest of ``(w², x², y², z²)`` is computed from the diagonal and the others from
    off-diagonal sums/differences divided by it, which is accurate for every angle including π.  Matrices
    that are slightly non-orthonormal give the quaternion of a nearby rotation (the result is normalised).

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 4), float64
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"rotation matrices must have shape (..., 3, 3), got {R.shape}")
    if R.ndim == 2:
        return np.array(_quaternion_single(R))
    r00, r01, r02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    r10, r11, r12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    r20, r21, r22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    # d = 4·(w², x², y², z²) for an exact rotation; they sum to 4, so the largest is >= 1.
    d = np.stack(
        [
            1.0 + r00 + r11 + r22,
            1.0 + r00 - r11 - r22,
            1.0 - r00 + r11 - r22,
            1.0 - r00 - r11 + r22,
        ],
        axis=-1,
    )
    k = np.argmax(d, axis=-1)
    dk = np.take_along_axis(d, k[..., None], axis=-1)[..., 0]
    # (x, y, z, w) candidates, each equal to 4·q_k·q for its k; the chosen one has 4·q_k² = d_k >= 1.
    a = r21 - r12  # 4wx
    b = r02 - r20  # 4wy
    c = r10 - r01  # 4wz
    e = r01 + r10  # 4xy
    f = r02 + r20  # 4xz
    g = r12 + r21  # 4yz
    cand = np.stack(
        [
            np.stack([a, b, c, dk], axis=-1),  # k = w
            np.stack([dk, e, f, a], axis=-1),  # k = x
            np.stack([e, dk, g, b], axis=-1),  # k = y
            np.stack([f, g, dk, c], axis=-1),  # k = z
        ],
        axis=-2,
    )  # (..., 4 candidates, xyzw)
    q = np.take_along_axis(cand, k[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0.0, -q, q)


def so3_exp(w: ArrayLike) -> FloatArray:
    """Rotation matrices of rotation vectors (Rodrigues' formula), batched.

    Parameters
    ----------
    w : array_like, shape (..., 3)
        Rotation vectors (axis × angle, radians).

    Returns
    -------
    ndarray, shape (..., 3, 3), float64
    """
    w = np.asarray(w, dtype=np.float64)
    if w.shape[-1:] != (3,):
        raise ValueError(f"rotation vectors must have shape (..., 3), got {w.shape}")
    if w.ndim == 1:
        return _so3_exp_single(float(w[0]), float(w[1]), float(w[2]))
    theta = np.linalg.norm(w, axis=-1)
    t2 = theta * theta
    small = theta < _SMALL_ANGLE
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, np.sin(safe) / safe)
    half = np.sin(0.5 * safe) / safe
    b = np.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, 2.0 * half * half)  # (1 - cos θ)/θ²
    W = hat(w)
    return np.eye(3) + a[..., None, None] * W + b[..., None, None] * (W @ W)


def so3_log(R: ArrayLike) -> FloatArray:
    """Rotation vectors of rotation matrices, batched; angle in [0, π].

    Goes through the Shepperd quaternion ``(v, w)`` (``w ≥ 0``) and ``θ = 2·atan2(|v|, w)``, which is
    accurate near 0 and near π.  At exactly π the sign of the axis is arbitrary (both are valid logs).

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 3), float64
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape == (3, 3):
        return _so3_log_single(R)
    q = matrix_to_quaternion(R)
    v = q[..., :3]
    w = q[..., 3]
    n = np.linalg.norm(v, axis=-1)
    small = n < 1e-8
    safe_n = np.where(small, 1.0, n)
    safe_w = np.where(small, w, 1.0)  # w ≈ 1 where n is small
    # factor = θ / |v| = 2 atan2(n, w)/n; Taylor for small n: 2/w (1 - n²/(3w²))
    factor = np.where(
        small,
        2.0 / safe_w * (1.0 - n * n / (3.0 * safe_w * safe_w)),
        2.0 * np.arctan2(n, w) / safe_n,
    )
    return factor[..., None] * v


def rotation_angle(R: ArrayLike) -> FloatArray:
    """Rotation angles (radians, in [0, π]) of rotation matrices, batched.

    Computed as ``atan2(|vee(R - Rᵀ)|, trace(R) - 1)``, i.e. from both sin θ and cos θ, which stays
    accurate near 0 and near π (unlike ``arccos((trace - 1)/2)``).

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (...), float64 (a 0-d array for a single matrix)
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"rotation matrices must have shape (..., 3, 3), got {R.shape}")
    s = np.linalg.norm(vee(R), axis=-1)  # sin θ
    c = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)  # cos θ
    return np.arctan2(s, c)


# ----------------------------------------------------------------------------------------------------
# Scalar coefficient helpers
# ----------------------------------------------------------------------------------------------------
# Power-series coefficients in θ² (|θ| < 1, 13 terms: truncation error < 1e-20):
#   C(θ) = (θ - sin θ)/θ³ = Σ (-θ²)^k / (2k+3)!
#   E(θ) = (2(1 - cos θ)/θ² - sin θ/θ)/θ² = Σ_{k≥1} (-1)^(k+1) 2k θ^(2k-2) / (2k+2)!
_C_SERIES = tuple((-1) ** k / math.factorial(2 * k + 3) for k in range(13))
_E_SERIES = tuple((-1) ** (k + 1) * 2 * k / math.factorial(2 * k + 2) for k in range(1, 14))
# In σ (|σ| < 1, 25 terms):  F(σ) = (expm1(σ) - σ e^σ)/σ² = -Σ (k+1) σ^k / (k+2)!
_F_SERIES = tuple(-(k + 1) / math.factorial(k + 2) for k in range(25))


def _poly(coeffs: tuple[float, ...], x: float) -> float:
    """``Σ coeffs[k] x^k`` by Horner's rule."""
    total = 0.0
    for c in reversed(coeffs):
        total = total * x + c
    return total


def _se3_v_coeffs(theta: float) -> tuple[float, float]:
    """``B = (1 - cos θ)/θ²`` and ``C = (θ - sin θ)/θ³`` of ``V = I + B ω^ + C ω^²``."""
    if theta == 0.0:
        return 0.5, 1.0 / 6.0
    h = math.sin(0.5 * theta) / theta
    b = 2.0 * h * h  # no cancellation
    if theta < 1.0:
        return b, _poly(_C_SERIES, theta * theta)
    return b, (theta - math.sin(theta)) / theta**3


def _se3_vinv_coeff(theta: float) -> float:
    """``D = (1 - (θ/2)·cot(θ/2))/θ²`` of ``V⁻¹ = I - ½ ω^ + D ω^²`` (θ ≤ π)."""
    if theta < 1.0:
        # D = (1 - A/(2B))/θ² = E/(2B) with A = sin θ/θ, B = (1 - cos θ)/θ²
        h = math.sin(0.5 * theta) / theta if theta > 0.0 else 0.5
        return _poly(_E_SERIES, theta * theta) / (4.0 * h * h)
    half = 0.5 * theta
    return (1.0 - half * math.cos(half) / math.sin(half)) / (theta * theta)


def _sim3_w_coeffs(sigma: float, theta: float) -> tuple[float, float, float]:
    """Coefficients of Sophus' ``W = A ω^ + B ω^² + C I`` (Sim(3) exp), robust for all (σ, θ).

    ``W = ∫₀¹ exp(s(ω^ + σI)) ds``, so with ``E(z) = (eᶻ - 1)/z`` and ``z = σ + iθ``:
    ``C = E(σ)``, ``A = Im E(z)/θ``, ``B = (E(σ) - Re E(z))/θ²``.  For ``|z| < 1`` the power series of
    ``E`` is summed (with polynomial recurrences for the divided parts); otherwise closed forms arranged
    to avoid catastrophic cancellation are used.
    """
    r = math.hypot(sigma, theta)
    if r < 1.0:
        # z^k = p_k + iθ q_k;  (σ^k - p_k)/θ² = r_k;  E(z) = Σ z^k/(k+1)!
        p, q, rk, sk = 1.0, 0.0, 0.0, 1.0
        t2 = theta * theta
        A = B = C = 0.0
        fact = 1.0  # (k+1)!
        for k in range(25):
            fact *= k + 1
            A += q / fact
            B += rk / fact
            C += sk / fact
            p, q, rk, sk = sigma * p - t2 * q, p + sigma * q, sigma * rk + q, sk * sigma
        return A, B, C
    es = math.exp(sigma)
    em1 = math.expm1(sigma)
    C = em1 / sigma if sigma != 0.0 else 1.0
    sinc = math.sin(theta) / theta if theta != 0.0 else 1.0
    half = math.sin(0.5 * theta) / theta if theta != 0.0 else 0.5
    h = 2.0 * half * half  # (1 - cos θ)/θ²
    one_minus_cos = h * theta * theta
    denom = sigma * sigma + theta * theta
    # A = (σ e^σ sinc θ - (e^σ cos θ - 1))/(σ² + θ²)
    A = (sigma * es * sinc - em1 * math.cos(theta) + one_minus_cos) / denom
    # B = (σ e^σ h(θ) + f1(σ) + e^σ g(θ))/(σ² + θ²), f1 = (expm1 σ - σ e^σ)/σ, g = 1 - sinc θ
    if abs(sigma) < 1.0:
        f1 = _poly(_F_SERIES, sigma) * sigma
    else:
        f1 = (em1 - sigma * es) / sigma
    if theta < 1.0:
        g = _poly(_C_SERIES, theta * theta) * theta * theta  # 1 - sinc θ = θ² C(θ)
    else:
        g = 1.0 - sinc
    B = (sigma * es * h + f1 + es * g) / denom
    return A, B, C


def _as_points(points: ArrayLike) -> FloatArray:
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1:] != (3,) or p.ndim > 2:
        raise ValueError(f"points must have shape (3,) or (N, 3), got {p.shape}")
    return p


def _vector(x: ArrayLike, n: int, name: str) -> FloatArray:
    v = np.asarray(x, dtype=np.float64)
    if v.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} has non-finite entries")
    return v


def _readonly(a: FloatArray) -> FloatArray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


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


class _Frozen:
    """Base class forbidding attribute assignment (instances are values)."""

    __slots__ = ()

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"{type(self).__name__} is immutable")

    def __delattr__(self, name: str) -> None:
        raise AttributeError(f"{type(self).__name__} is immutable")


# ----------------------------------------------------------------------------------------------------
# SO(3)
# ----------------------------------------------------------------------------------------------------
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


# ----------------------------------------------------------------------------------------------------
# SE(3)
# ----------------------------------------------------------------------------------------------------
def _rotation_arg(rotation: SO3 | ArrayLike) -> SO3:
    return rotation if isinstance(rotation, SO3) else SO3(rotation)


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
        if isinstance(other, Sim3):
            return Sim3.from_se3(self) @ other
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


# ----------------------------------------------------------------------------------------------------
# Sim(3)
# ----------------------------------------------------------------------------------------------------
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
