"""Tests of dmtrack.evaluation.metrics (ATE, the paper's RPE, evo-style RPE, evaluate)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from dmtrack.errors import InputError
from dmtrack.evaluation import UNDEFINED_ANGLE_DEG, apply_sim3, ate, evaluate, rpe, rpe_paper
from dmtrack.io.trajectory import Trajectory, read_kitti, read_tum

# evo's Sim(3)-aligned ATE RMSE on the shared trajectories (evo 1.38.1: evo_ape ... -as)
EVO_ATE_KITTI_00_ORB = 0.937709074
EVO_ATE_FR1_XYZ_RGBDSLAM = 0.013389385


def random_trajectory(rng: np.random.Generator, n: int, step: float = 0.3) -> Trajectory:
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.05, (n, 3)), axis=0)).as_matrix()
    poses[:, :3, 3] = np.cumsum(rng.normal(0, step, (n, 3)), axis=0)
    return Trajectory(np.arange(n, dtype=float), poses)


def straight_line(n: int) -> Trajectory:
    """n poses, identity rotations, 1 unit apart along x (path length n − 1)."""
    positions = np.column_stack([np.arange(n, dtype=float), np.zeros((n, 2))])
    return Trajectory.from_positions(np.arange(n, dtype=float), positions)


def perturbed(gt: Trajectory, rng: np.random.Generator, sigma: float = 0.05) -> Trajectory:
    poses = gt.poses.copy()
    poses[:, :3, :3] = Rotation.from_rotvec(rng.normal(0, sigma, (len(gt), 3))).as_matrix() @ poses[:, :3, :3]
    poses[:, :3, 3] += rng.normal(0, sigma, (len(gt), 3))
    return Trajectory(gt.timestamps.copy(), poses)


def rpe_paper_bruteforce(gt: Trajectory, est: Trajectory, r_l: float):
    """The paper's definition, written with loops, matrix inverses and arccos."""
    d = gt.distances()
    lengths = [k / 8 * r_l * d[-1] for k in range(1, 9)]
    rot_means, trans_means = [], []
    for L in lengths:
        rots, transs = [], []
        for i in range(len(gt)):
            js = [j for j in range(len(gt)) if d[j] >= d[i] + L]
            if not js:
                continue
            j = js[0]
            P = np.linalg.inv(est.poses[i]) @ est.poses[j]
            Q = np.linalg.inv(gt.poses[i]) @ gt.poses[j]
            dR = Q[:3, :3].T @ P[:3, :3]
            rots.append(np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))) / L)
            c = Q[:3, 3] @ P[:3, 3] / (np.linalg.norm(Q[:3, 3]) * np.linalg.norm(P[:3, 3]))
            transs.append(np.degrees(np.arccos(np.clip(c, -1, 1))) / L)
        if rots:
            rot_means.append(np.mean(rots))
            trans_means.append(np.mean(transs))
    return np.mean(rot_means), np.mean(trans_means), np.array(rot_means), np.array(trans_means)


# -- ATE ---------------------------------------------------------------------------------------------
def test_ate_hand_computed_without_alignment():
    gt = Trajectory.from_positions(np.arange(4.0), np.zeros((4, 3)))
    est = Trajectory.from_positions(np.arange(4.0), [[3, 4, 0], [0, 0, 0], [0, 0, 1], [0, 2, 0]])
    a = ate(gt, est, align="none")
    np.testing.assert_allclose(a.errors, [5, 0, 1, 2])
    assert a.rmse == pytest.approx(np.sqrt(30 / 4))
    assert a.mean == pytest.approx(2.0)
    assert a.median == pytest.approx(1.5)
    assert a.std == pytest.approx(np.std([5, 0, 1, 2]))
    assert a.max == 5.0
    assert a.scale == 1.0


def test_ate_zero_for_a_similar_copy():
    rng = np.random.default_rng(10)
    gt = random_trajectory(rng, 60)
    est = apply_sim3(gt, 3.0, Rotation.from_rotvec([0.5, -2.0, 1.0]).as_matrix(), np.array([10.0, -3.0, 2.0]))
    a = ate(gt, est, "sim3")
    assert a.rmse < 1e-10
    assert a.scale == pytest.approx(1 / 3, rel=1e-12)
    assert ate(gt, est, "se3").rmse > 0.1  # without scale the copy does not fit
    with pytest.raises(ValueError, match="associated"):
        ate(gt, est[np.arange(10)])


# -- the paper's RPE: hand-computed cases -------------------------------------------------------------
def test_rpe_constant_rotation_rate_gives_that_angle_per_length():
    # straight line 16 units long, r_l = 1/2 → L_k = k exactly; the estimate's orientation turns
    # by alpha about a fixed axis per unit of path, so every pair (i, i+k) is off by k·alpha
    n, alpha = 17, 0.7
    gt = straight_line(n)
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    est_poses = gt.poses.copy()
    est_poses[:, :3, :3] = Rotation.from_rotvec(np.radians(alpha) * np.arange(n)[:, None] * axis).as_matrix()
    est = Trajectory(gt.timestamps, est_poses)
    r = rpe_paper(gt, est, r_l=0.5)
    np.testing.assert_array_equal(r.lengths, np.arange(1.0, 9.0))
    np.testing.assert_array_equal(r.pairs_per_length, n - np.arange(1, 9))
    np.testing.assert_allclose(r.per_length_rot, alpha, rtol=1e-10)
    assert r.rot_deg_per_unit == pytest.approx(alpha, rel=1e-10)


def test_rpe_translation_at_known_angle():
    n, beta = 17, 25.0
    gt = straight_line(n)
    b = np.radians(beta)
    est = Trajectory.from_positions(gt.timestamps, 0.3 * np.arange(n)[:, None] * [np.cos(b), np.sin(b), 0.0])
    r = rpe_paper(gt, est, r_l=0.5)
    np.testing.assert_allclose(r.per_length_trans * r.lengths, beta, rtol=1e-12)
    assert r.trans_angle_deg_per_unit == pytest.approx(np.mean(beta / np.arange(1, 9)), rel=1e-12)
    np.testing.assert_array_equal(r.per_length_rot, 0.0)
    assert r.undefined_trans_pairs == 0


def test_rpe_and_ate_zero_for_scaled_rotated_translated_copy():
    rng = np.random.default_rng(11)
    gt = random_trajectory(rng, 80)
    est = apply_sim3(gt, 3.0, Rotation.from_rotvec([2.0, 0.1, -0.7]).as_matrix(), np.array([-5.0, 1.0, 0.5]))
    r = rpe_paper(gt, est)
    assert r.rot_deg_per_unit < 1e-9
    assert r.trans_angle_deg_per_unit < 1e-9
    assert ate(gt, est).rmse < 1e-10


def test_rpe_stationary_estimate_counts_90_degrees():
    gt = straight_line(17)
    est = Trajectory.from_positions(gt.timestamps, np.tile([1.0, 2.0, 3.0], (17, 1)))
    r = rpe_paper(gt, est, r_l=0.5)
    assert r.undefined_trans_pairs == int(r.pairs_per_length.sum())
    np.testing.assert_allclose(r.per_length_trans * r.lengths, UNDEFINED_ANGLE_DEG)


def test_rpe_matches_bruteforce_definition():
    rng = np.random.default_rng(12)
    gt = random_trajectory(rng, 70)
    gt.poses[:, :3, 3] *= rng.uniform(0.2, 3.0, (70, 1))  # uneven steps: non-trivial pair selection
    est = perturbed(gt, rng)
    for r_l in (1 / 3, 1 / 20, 1.0):
        r = rpe_paper(gt, est, r_l=r_l)
        rot, trans, per_rot, per_trans = rpe_paper_bruteforce(gt, est, r_l)
        assert r.rot_deg_per_unit == pytest.approx(rot, rel=1e-7)
        assert r.trans_angle_deg_per_unit == pytest.approx(trans, rel=1e-7)
        np.testing.assert_allclose(r.per_length_rot, per_rot, rtol=1e-7)
        np.testing.assert_allclose(r.per_length_trans, per_trans, rtol=1e-7)
        assert (r.pairs_per_length > 0).all()


def test_rpe_bad_arguments():
    gt = straight_line(5)
    with pytest.raises(ValueError, match="r_l"):
        rpe_paper(gt, gt, r_l=0.0)
    with pytest.raises(ValueError, match="does not move"):
        rpe_paper(Trajectory.from_positions(np.arange(3.0), np.zeros((3, 3))), gt[np.arange(3)])


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    scale=st.floats(1e-2, 1e2),
    rotvec=st.tuples(*[st.floats(-3.0, 3.0)] * 3),
    t=st.tuples(*[st.floats(-100.0, 100.0)] * 3),
)
def test_rpe_invariant_to_global_sim3_of_estimate(seed, scale, rotvec, t):
    rng = np.random.default_rng(seed)
    gt = random_trajectory(rng, 40)
    est = perturbed(gt, rng, sigma=0.1)
    moved = apply_sim3(est, scale, Rotation.from_rotvec(rotvec).as_matrix(), np.array(t))
    r0, r1 = rpe_paper(gt, est), rpe_paper(gt, moved)
    assert r1.rot_deg_per_unit == pytest.approx(r0.rot_deg_per_unit, rel=1e-7)
    assert r1.trans_angle_deg_per_unit == pytest.approx(r0.trans_angle_deg_per_unit, rel=1e-7)
    np.testing.assert_array_equal(r1.pairs_per_length, r0.pairs_per_length)
    # and the Sim(3)-aligned ATE, measured in the ground truth's frame, does not change either
    assert ate(gt, moved).rmse == pytest.approx(ate(gt, est).rmse, rel=1e-6, abs=1e-12)


# -- evo cross-checks -----------------------------------------------------------------------------------
def _evo_traj(traj: Trajectory):
    from evo.core.trajectory import PoseTrajectory3D

    return PoseTrajectory3D(poses_se3=list(traj.poses), timestamps=traj.timestamps)


def test_ate_equals_evo_on_kitti(shared_dir):
    from evo.core import metrics

    d = shared_dir / "data" / "trajectories"
    gt, est = read_kitti(d / "KITTI_00_gt.txt"), read_kitti(d / "KITTI_00_ORB.txt")
    a = ate(gt, est, "sim3")
    assert a.rmse == pytest.approx(EVO_ATE_KITTI_00_ORB, abs=1e-6)
    ref, e = _evo_traj(gt), copy.deepcopy(_evo_traj(est))
    _, _, s = e.align(ref, correct_scale=True)
    m = metrics.APE(metrics.PoseRelation.translation_part)
    m.process_data((ref, e))
    stats = m.get_all_statistics()
    for key in ("rmse", "mean", "median", "std", "max"):
        assert getattr(a, key) == pytest.approx(stats[key], rel=1e-9), key
    assert a.scale == pytest.approx(s, rel=1e-9)


def test_ate_equals_evo_on_tum(shared_dir):
    from evo.core import metrics, sync
    from evo.tools import file_interface

    d = shared_dir / "data" / "trajectories"
    gt_path, est_path = d / "freiburg1_xyz-groundtruth.txt", d / "freiburg1_xyz-rgbdslam.txt"
    res = evaluate(read_tum(gt_path), read_tum(est_path), max_diff=0.01)
    assert res["matched_poses"] == 785
    assert res["ate_rmse"] == pytest.approx(EVO_ATE_FR1_XYZ_RGBDSLAM, abs=1e-6)
    ref, e = sync.associate_trajectories(
        file_interface.read_tum_trajectory_file(str(gt_path)),
        file_interface.read_tum_trajectory_file(str(est_path)),
        max_diff=0.01,
    )
    e.align(ref, correct_scale=True)
    m = metrics.APE(metrics.PoseRelation.translation_part)
    m.process_data((ref, e))
    assert res["ate_rmse"] == pytest.approx(m.get_statistic(metrics.StatisticsType.rmse), rel=1e-9)


@pytest.mark.parametrize(
    ("delta", "unit", "relation", "all_pairs", "from_ref"),
    [
        (1, "frames", "trans", False, False),
        (10, "frames", "rot_deg", True, False),
        (7, "frames", "trans", False, False),
        (0.2, "m", "trans", False, False),
        (0.2, "m", "rot_deg", True, False),
        (0.1, "m", "trans", True, True),
    ],
)
def test_standard_rpe_equals_evo(shared_dir, delta, unit, relation, all_pairs, from_ref):
    from evo.core import metrics

    d = shared_dir / "data" / "trajectories"
    gt, est = read_tum(d / "freiburg1_xyz-groundtruth.txt"), read_tum(d / "freiburg1_xyz-rgbdslam.txt")
    from dmtrack.io.association import associate_trajectories

    gt, est = associate_trajectories(gt, est, 0.01)
    ours = rpe(gt, est, delta, unit, relation, all_pairs=all_pairs, pairs_from_reference=from_ref)
    m = metrics.RPE(
        metrics.PoseRelation.translation_part
        if relation == "trans"
        else metrics.PoseRelation.rotation_angle_deg,
        delta=delta,
        delta_unit=metrics.Unit.frames if unit == "frames" else metrics.Unit.meters,
        all_pairs=all_pairs,
        pairs_from_reference=from_ref,
    )
    m.process_data((_evo_traj(gt), _evo_traj(est)))
    assert ours.pairs[:, 1].tolist() == m.delta_ids
    np.testing.assert_allclose(ours.errors, m.error, rtol=1e-9, atol=1e-9)
    assert ours.rmse == pytest.approx(m.get_statistic(metrics.StatisticsType.rmse), rel=1e-9)


# -- evaluate -------------------------------------------------------------------------------------------
def test_evaluate_with_gaps_and_keys():
    rng = np.random.default_rng(13)
    full = random_trajectory(rng, 100)
    full.timestamps[:] = 0.1 * np.arange(100)
    keep = np.r_[0:30, 70:100]  # ground truth only at the start and the end
    gt = full[keep]
    est = apply_sim3(perturbed(full, rng, 0.01), 2.0, np.eye(3), np.zeros(3))
    est.timestamps[:] += 0.003
    res = evaluate(gt, est, max_diff=0.01)
    for key in ("ate_rmse", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "matched_poses", "ate_scale"):
        assert key in res
    assert res["matched_poses"] == 60
    assert res["est_poses"] == 100
    assert res["max_matched_time_gap"] == pytest.approx(4.1)
    assert res["gt_path_length"] == pytest.approx(gt.path_length())
    assert res["ate_scale"] == pytest.approx(0.5, rel=0.05)
    assert len(res["rpe_lengths"]) == 8
    # the same numbers as computing on the matched poses by hand
    r = rpe_paper(gt, est[keep])
    assert res["rpe_rot_deg_per_m"] == pytest.approx(r.rot_deg_per_unit, rel=1e-12)


def test_evaluate_too_few_matches():
    gt = random_trajectory(np.random.default_rng(14), 10)
    est = Trajectory(gt.timestamps + 1000.0, gt.poses)
    with pytest.raises(InputError, match="need at least 3"):
        evaluate(gt, est)
    with pytest.raises(InputError, match="only 2 pose"):
        evaluate(gt, gt[np.arange(2)])
