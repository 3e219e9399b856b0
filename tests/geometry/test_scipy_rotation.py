"""The start's rotation formulas give scipy's results to the last bit (so its maps did not change when it stopped
importing scipy.spatial), on random rotations, small and large angles, and the branches scipy handles itself."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from dmtrack.geometry.scipy_rotation import magnitude_of_matrix, matrix_from_rotvec, slerp_from_identity

FRACTIONS = np.array([0.0, 0.1, 1 / 3, 0.5, 6 / 7, 1.0])


def _rotations() -> np.ndarray:
    rng = np.random.default_rng(7)
    big = Rotation.random(300, random_state=3).as_matrix()
    small = Rotation.from_rotvec(rng.normal(size=(300, 3)) * 0.01).as_matrix()
    tiny = Rotation.from_rotvec(rng.normal(size=(100, 3)) * 1e-4).as_matrix()  # the Taylor branch
    near_pi = Rotation.from_rotvec(rng.normal(size=(50, 3)) * 1e-3 + [np.pi, 0, 0]).as_matrix()
    return np.concatenate([big, small, tiny, near_pi, np.eye(3)[None]])


@pytest.mark.parametrize("scale", [0.0, 1e-8, 1e-4, 1e-3, 2e-3, 0.05, 0.5, 3.1])
def test_matrix_from_rotvec_is_scipys(scale):
    rv = np.random.default_rng(1).normal(size=(2000, 3)) * scale
    np.testing.assert_array_equal(matrix_from_rotvec(rv), Rotation.from_rotvec(rv).as_matrix())


def test_magnitude_and_slerp_are_scipys():
    for R in _rotations():
        assert magnitude_of_matrix(R) == Rotation.from_matrix(R).magnitude()
        expected = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([np.eye(3), R])))(FRACTIONS).as_matrix()
        np.testing.assert_array_equal(slerp_from_identity(R, FRACTIONS), expected)


def test_matrices_scipy_would_project_go_to_scipy():
    R = Rotation.from_rotvec([0.3, -0.2, 0.1]).as_matrix() * (1 + 1e-9)  # not orthogonal to 1e-12
    assert magnitude_of_matrix(R) == Rotation.from_matrix(R).magnitude()
    expected = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([np.eye(3), R])))(FRACTIONS).as_matrix()
    np.testing.assert_array_equal(slerp_from_identity(R, FRACTIONS), expected)
