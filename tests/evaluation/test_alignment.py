"""Tests of dmtrack.evaluation.alignment (Umeyama)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmtrack.evaluation import align_trajectory, apply_sim3, umeyama
from dmtrack.io.trajectory import Trajectory


def random_trajectory(rng: np.random.Generator, n: int) -> Trajectory:
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.05, (n, 3)), axis=0)).as_matrix()
    poses[:, :3, 3] = np.cumsum(rng.normal(0, 0.3, (n, 3)), axis=0)
    return Trajectory(np.arange(n, dtype=float), poses)


def cost(src, dst, s, R, t):
    return float(np.sum((dst - (s * src @ R.T + t)) ** 2))


def test_recovers_known_similarity():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(50, 3))
    R0 = Rotation.from_rotvec([0.3, -1.2, 2.0]).as_matrix()
    s0, t0 = 3.7, np.array([1.0, -2.0, 5.0])
    s, R, t = umeyama(src, s0 * src @ R0.T + t0)
    assert s == pytest.approx(s0, rel=1e-12)
    np.testing.assert_allclose(R, R0, atol=1e-12)
    np.testing.assert_allclose(t, t0, atol=1e-12)


def test_rigid_without_scale():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(20, 3))
    R0 = Rotation.from_rotvec([-2.5, 0.1, 0.4]).as_matrix()
    t0 = np.array([0.5, 0.0, -1.0])
    s, R, t = umeyama(src, src @ R0.T + t0, with_scale=False)
    assert s == 1.0
    np.testing.assert_allclose(R, R0, atol=1e-12)
    np.testing.assert_allclose(t, t0, atol=1e-12)


@pytest.mark.parametrize("with_scale", [True, False])
def test_reflection_gives_a_proper_rotation_and_matches_evo(with_scale):
    from evo.core.geometry import umeyama_alignment

    rng = np.random.default_rng(2)
    src = rng.normal(size=(30, 3))
    dst = src * np.array([1.0, 1.0, -1.0]) * 2.0 + 0.01 * rng.normal(size=(30, 3))  # a mirror image
    s, R, t = umeyama(src, dst, with_scale=with_scale)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    r_e, t_e, s_e = umeyama_alignment(src.T, dst.T, with_scale)
    assert s == pytest.approx(s_e, rel=1e-12)
    np.testing.assert_allclose(R, r_e, atol=1e-10)
    np.testing.assert_allclose(t, t_e, atol=1e-10)


def test_noisy_solution_is_a_minimum():
    rng = np.random.default_rng(3)
    src = rng.normal(size=(40, 3))
    dst = (
        0.5 * src @ Rotation.from_rotvec([1.0, 2.0, 0.5]).as_matrix().T + 3.0 + 0.1 * rng.normal(size=(40, 3))
    )
    s, R, t = umeyama(src, dst)
    c0 = cost(src, dst, s, R, t)
    for _ in range(50):
        dR = Rotation.from_rotvec(rng.normal(0, 1e-3, 3)).as_matrix()
        assert cost(src, dst, s * (1 + rng.normal(0, 1e-3)), dR @ R, t + rng.normal(0, 1e-3, 3)) > c0


def test_collinear_points_are_accepted():
    src = np.column_stack([np.arange(6.0), np.zeros(6), np.zeros(6)])
    R0 = Rotation.from_rotvec([0.2, 0.3, -0.1]).as_matrix()
    dst = 2.0 * src @ R0.T + 1.0
    s, R, t = umeyama(src, dst)
    assert s == pytest.approx(2.0, rel=1e-12)
    assert cost(src, dst, s, R, t) < 1e-20


def test_degenerate_inputs_raise():
    p = np.random.default_rng(4).normal(size=(5, 3))
    with pytest.raises(ValueError, match="at least 3"):
        umeyama(p[:2], p[:2])
    with pytest.raises(ValueError, match="identical"):
        umeyama(np.ones((5, 3)), p)
    with pytest.raises(ValueError, match="identical"):
        umeyama(p, np.tile(p[0], (5, 1)))
    with pytest.raises(ValueError, match="shape"):
        umeyama(p, p[:4])
    with pytest.raises(ValueError, match="finite"):
        umeyama(np.where(p > 1, np.nan, p), p)


def test_align_trajectory_modes():
    rng = np.random.default_rng(5)
    gt = random_trajectory(rng, 30)
    R0 = Rotation.from_rotvec([0.4, -0.3, 1.1]).as_matrix()
    est = apply_sim3(gt, 0.25, R0, np.array([4.0, 5.0, 6.0]))
    aligned, T = align_trajectory(est, gt, "sim3")
    np.testing.assert_allclose(aligned.positions, gt.positions, atol=1e-10)
    np.testing.assert_allclose(aligned.rotations, gt.rotations, atol=1e-10)  # rotations stay orthonormal
    assert np.cbrt(np.linalg.det(T[:3, :3])) == pytest.approx(4.0, rel=1e-12)
    np.testing.assert_allclose(T[3], [0, 0, 0, 1])

    aligned, T = align_trajectory(est, gt, "se3")
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)  # no scale
    assert np.abs(aligned.positions - gt.positions).max() > 0.1

    aligned, T = align_trajectory(est, gt, "none")
    np.testing.assert_array_equal(T, np.eye(4))
    np.testing.assert_array_equal(aligned.poses, est.poses)

    aligned, T = align_trajectory(est, gt, "scale")
    np.testing.assert_allclose(T, np.diag([4.0, 4.0, 4.0, 1.0]), atol=1e-10)
    np.testing.assert_allclose(aligned.positions, 4.0 * est.positions, atol=1e-10)
    np.testing.assert_array_equal(aligned.rotations, est.rotations)

    with pytest.raises(ValueError, match="unknown alignment mode"):
        align_trajectory(est, gt, "sim2")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="associated"):
        align_trajectory(est[np.arange(5)], gt, "sim3")


@pytest.mark.parametrize("mode", ["sim3", "se3", "scale"])
def test_align_trajectory_matches_evo(mode):
    from evo.core.trajectory import PoseTrajectory3D

    rng = np.random.default_rng(6)
    gt = random_trajectory(rng, 40)
    noisy = gt.poses.copy()
    noisy[:, :3, 3] += rng.normal(0, 0.2, (40, 3))
    est = apply_sim3(Trajectory(gt.timestamps, noisy), 0.3, Rotation.from_rotvec([1, 2, 3]).as_matrix(), 1.0)
    aligned, _ = align_trajectory(est, gt, mode)
    e = PoseTrajectory3D(poses_se3=list(est.poses), timestamps=est.timestamps)
    r = PoseTrajectory3D(poses_se3=list(gt.poses), timestamps=gt.timestamps)
    e = copy.deepcopy(e)
    e.align(r, correct_scale=mode == "sim3", correct_only_scale=mode == "scale")
    np.testing.assert_allclose(aligned.poses, np.array(e.poses_se3), atol=1e-10)
