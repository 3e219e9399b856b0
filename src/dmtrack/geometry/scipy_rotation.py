"""The few ``scipy.spatial.transform.Rotation`` operations the geometric start uses, in numpy, with scipy's arithmetic.

Importing ``scipy.spatial.transform`` imports all of ``scipy.spatial`` (about 0.2 s and 40 MB); the start needs four
small formulas of it. These functions evaluate scipy's own formulas (``scipy/spatial/transform/_rotation_xp.py``, the
same operations in the same order), so their results are scipy's to the last bit — ``tests/geometry`` compares them
with scipy on random and edge-case rotations. Where scipy would take another branch (a matrix that is not orthogonal
to 1e-12, which scipy projects by SVD first) the functions hand the call to scipy itself.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["magnitude_of_matrix", "matrix_from_rotvec", "slerp_from_identity"]


def _quat_from_rotvec(rotvec: np.ndarray) -> np.ndarray:
    angle = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    small = angle <= 1e-3
    angle2 = angle**2
    small_scale = 0.5 - angle2 / 48 + angle2**2 / 3840
    large_scale = np.sin(angle / 2) / (angle + small.astype(angle.dtype))
    scale = np.where(small, small_scale, large_scale)
    return np.concatenate([rotvec * scale, np.cos(angle / 2)], axis=-1)


def _matrix_from_quat(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    m = [x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw),
         2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw),
         2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2]  # fmt: skip
    return np.stack(m, axis=-1).reshape(*q.shape[:-1], 3, 3)


def _orthogonal(m: np.ndarray) -> bool:
    """scipy's test before it converts a matrix (positive determinant, RRᵀ within 1e-12 of I)."""
    if np.any(np.linalg.det(m) <= 0):
        return False
    gram = m @ np.swapaxes(m, -1, -2)
    return bool(np.all(np.isclose(gram, np.eye(3), atol=1e-12)))


def _quat_from_orthogonal_matrix(m: np.ndarray) -> np.ndarray:
    trace = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    choice = np.argmax(np.stack([m[..., 0, 0], m[..., 1, 1], m[..., 2, 2], trace], axis=-1), axis=-1)[..., None]
    q0 = np.stack([1 - trace + 2 * m[..., 0, 0], m[..., 1, 0] + m[..., 0, 1], m[..., 2, 0] + m[..., 0, 2],
                   m[..., 2, 1] - m[..., 1, 2]], axis=-1)  # fmt: skip
    q1 = np.stack([m[..., 1, 0] + m[..., 0, 1], 1 - trace + 2 * m[..., 1, 1], m[..., 2, 1] + m[..., 1, 2],
                   m[..., 0, 2] - m[..., 2, 0]], axis=-1)  # fmt: skip
    q2 = np.stack([m[..., 2, 0] + m[..., 0, 2], m[..., 2, 1] + m[..., 1, 2], 1 - trace + 2 * m[..., 2, 2],
                   m[..., 1, 0] - m[..., 0, 1]], axis=-1)  # fmt: skip
    q3 = np.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1],
                   1 + trace], axis=-1)  # fmt: skip
    return _normalised(np.where(choice == 0, q0, np.where(choice == 1, q1, np.where(choice == 2, q2, q3))))


def _rotvec_from_quat(q: np.ndarray) -> np.ndarray:
    """One quaternion's rotation vector, as scipy's compiled ``as_rotvec`` computes it (scalar libm calls)."""
    x, y, z, w = (float(v) for v in q)
    if w < 0 or (w == 0 and (x < 0 or (x == 0 and (y < 0 or (y == 0 and z < 0))))):
        x, y, z, w = -x, -y, -z, -w
    angle = 2 * math.atan2(math.sqrt(x * x + y * y + z * z), w)
    if angle <= 1e-3:
        scale = 2 + angle * angle / 12 + 7 * angle * angle * angle * angle / 2880
    else:
        scale = angle / math.sin(angle / 2)
    return np.array([scale * x, scale * y, scale * z])


def _normalised(q: np.ndarray) -> np.ndarray:
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def matrix_from_rotvec(rotvec: np.ndarray) -> np.ndarray:
    """``Rotation.from_rotvec(rotvec).as_matrix()`` for (..., 3) rotation vectors."""
    return _matrix_from_quat(_quat_from_rotvec(np.asarray(rotvec, dtype=np.float64)))


def magnitude_of_matrix(m: np.ndarray) -> float:
    """``Rotation.from_matrix(m).magnitude()`` (radians) of one 3×3 matrix."""
    m = np.asarray(m, dtype=np.float64)
    if not _orthogonal(m):
        from scipy.spatial.transform import Rotation

        return float(Rotation.from_matrix(m).magnitude())
    x, y, z, w = (float(v) for v in _quat_from_orthogonal_matrix(m))
    return 2 * math.atan2(math.sqrt(x * x + y * y + z * z), abs(w))


def slerp_from_identity(R: np.ndarray, fractions: np.ndarray) -> np.ndarray:
    """``Slerp([0, 1], Rotation.from_matrix([I, R]))(fractions).as_matrix()``: (n, 3, 3) for fractions in [0, 1]."""
    R = np.asarray(R, dtype=np.float64)
    f = np.asarray(fractions, dtype=np.float64)
    if not _orthogonal(R) or np.any((f < 0) | (f > 1)):
        from scipy.spatial.transform import Rotation, Slerp

        return Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([np.eye(3), R])))(f).as_matrix()
    # scipy: the rotation vector of I⁻¹·R, scaled by each fraction, composed after I; each product with the
    # identity quaternion is exact and scipy normalises its result
    rotvec = _rotvec_from_quat(_normalised(_quat_from_orthogonal_matrix(R)))
    return _matrix_from_quat(_normalised(_quat_from_rotvec(rotvec[None, :] * f[:, None])))
