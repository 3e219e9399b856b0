"""dmtrack.geometry: Lie groups (SO3, SE3, Sim3), quaternion/rotation helpers and the pinhole camera.

See :mod:`dmtrack.geometry.lie` for the conventions: tangent order (υ, ω) for SE(3) and (υ, ω, σ) for
Sim(3), left perturbation, quaternions in (x, y, z, w) order.
"""

from __future__ import annotations

from dmtrack.geometry.camera import PinholeCamera, crop_image
from dmtrack.geometry.lie import (
    SE3,
    SO3,
    Sim3,
    hat,
    matrix_to_quaternion,
    quaternion_to_matrix,
    rotation_angle,
    so3_exp,
    so3_log,
    vee,
)

__all__ = [
    "SE3",
    "SO3",
    "PinholeCamera",
    "Sim3",
    "crop_image",
    "hat",
    "matrix_to_quaternion",
    "quaternion_to_matrix",
    "rotation_angle",
    "so3_exp",
    "so3_log",
    "vee",
]
