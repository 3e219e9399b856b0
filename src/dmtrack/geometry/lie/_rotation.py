"""Batched rotation helpers: hat/vee, quaternions ``(x, y, z, w)``, ``so3_exp``/``so3_log``, rotation angles."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from dmtrack.geometry.lie._common import FloatArray

# Below these magnitudes closed-form coefficients are replaced by Taylor series.
_SMALL_ANGLE = 1e-4  # so3_exp coefficients: truncation error ~θ⁶/5040


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
