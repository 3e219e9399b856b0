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

Layout: ``_rotation`` (hat, vee, quaternions, ``so3_exp``/``so3_log``, ``rotation_angle``, batched), ``so3``,
``se3`` and ``sim3`` (the value classes), ``_coeffs`` (the scalar series of the SE(3)/Sim(3) exp and log) and
``_common`` (the immutable base class and argument helpers).
"""

from dmtrack.geometry.lie._rotation import (
    hat,
    matrix_to_quaternion,
    quaternion_to_matrix,
    rotation_angle,
    so3_exp,
    so3_log,
    vee,
)
from dmtrack.geometry.lie.se3 import SE3
from dmtrack.geometry.lie.sim3 import Sim3
from dmtrack.geometry.lie.so3 import SO3

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
