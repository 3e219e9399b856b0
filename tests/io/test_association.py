"""Tests of dmtrack.io.association (greedy one-to-one timestamp matching)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dmtrack.io.association import associate, associate_trajectories
from dmtrack.io.trajectory import Trajectory, read_kitti, read_tum


def greedy_reference(t_a: np.ndarray, t_b: np.ndarray, max_diff: float, offset: float = 0.0):
    """TUM associate.py's algorithm, written plainly: all candidate pairs sorted by
    (difference, rank of t_a, rank of t_b), taken greedily when both stamps are free."""
    t_b = t_b + offset
    rank_a = np.empty(t_a.size, dtype=int)
    rank_a[np.argsort(t_a, kind="stable")] = np.arange(t_a.size)
    rank_b = np.empty(t_b.size, dtype=int)
    rank_b[np.argsort(t_b, kind="stable")] = np.arange(t_b.size)
    cand = [
        (abs(t_a[i] - t_b[j]), rank_a[i], rank_b[j], i, j)
        for i in range(t_a.size)
        for j in range(t_b.size)
        if abs(t_a[i] - t_b[j]) <= max_diff
    ]
    cand.sort()
    used_a, used_b, pairs = set(), set(), []
    for _, _, _, i, j in cand:
        if i not in used_a and j not in used_b:
            used_a.add(i)
            used_b.add(j)
            pairs.append((i, j))
    pairs.sort(key=lambda p: (rank_a[p[0]], p[0]))
    return [p[0] for p in pairs], [p[1] for p in pairs]


def test_hand_computed_pairs():
    t_a = np.array([0.0, 1.0, 2.0, 3.0])
    t_b = np.array([0.005, 1.02, 1.999, 3.0101])
    ia, ib = associate(t_a, t_b, max_diff=0.01)
    assert ia.tolist() == [0, 2]
    assert ib.tolist() == [0, 2]


def test_each_stamp_used_once_and_closest_wins():
    # b=0.003 is within 0.01 of both a's; the closer a (0.004) gets it, a=0.0 stays unmatched
    ia, ib = associate(np.array([0.0, 0.004]), np.array([0.003]), max_diff=0.01)
    assert ia.tolist() == [1] and ib.tolist() == [0]
    # evo's nearest-neighbour matching would give b=0.003 to both a's when a is the shorter side
    ia, ib = associate(np.array([0.003]), np.array([0.0, 0.004]), max_diff=0.01)
    assert ia.tolist() == [0] and ib.tolist() == [1]


def test_chain_needs_several_rounds():
    # spacings grow geometrically: greedy resolves the chain one pair at a time from the left
    gaps = 0.001 * 1.5 ** np.arange(12)
    t = np.concatenate([[0.0], np.cumsum(gaps)])
    t_a, t_b = t[0::2], t[1::2]
    ia, ib = associate(t_a, t_b, max_diff=1.0)
    ra, rb = greedy_reference(t_a, t_b, 1.0)
    assert ia.tolist() == ra and ib.tolist() == rb
    assert len(ia) == 6  # every a matched to its right neighbour


def test_offset_and_unsorted_input():
    t_a = np.array([3.0, 1.0, 2.0])
    t_b = np.array([11.002, 12.001, 13.0])  # t_b - 10 ≈ t_a
    ia, ib = associate(t_a, t_b, max_diff=0.01, offset=-10.0)
    assert ia.tolist() == [1, 2, 0]  # sorted by t_a
    assert ib.tolist() == [0, 1, 2]


def test_frame_indices_match_exactly():
    t_a = np.arange(10, dtype=float)
    t_b = np.array([2.0, 3.0, 5.0, 20.0, 9.0])
    ia, ib = associate(t_a, t_b, max_diff=0.0)
    np.testing.assert_array_equal(t_a[ia], t_b[ib])
    assert ia.tolist() == [2, 3, 5, 9]


def test_empty_and_bad_arguments():
    ia, ib = associate(np.zeros(0), np.array([1.0]), max_diff=0.1)
    assert ia.size == 0 and ib.size == 0 and ia.dtype == np.int64
    with pytest.raises(ValueError, match="max_diff"):
        associate(np.array([1.0]), np.array([1.0]), max_diff=-1.0)
    with pytest.raises(ValueError, match="finite"):
        associate(np.array([np.nan]), np.array([1.0]), max_diff=0.1)


@settings(max_examples=150, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_a=st.integers(0, 25),
    n_b=st.integers(0, 25),
    max_diff=st.sampled_from([0.0, 0.5, 1.0, 2.0, 3.7, 100.0]),
    integer=st.booleans(),
)
def test_matches_plain_greedy(seed, n_a, n_b, max_diff, integer):
    rng = np.random.default_rng(seed)
    if integer:  # many exact ties: exercises the tie-breaking order
        t_a = rng.integers(0, 15, n_a).astype(float)
        t_b = rng.integers(0, 15, n_b).astype(float)
    else:
        t_a = rng.uniform(0, 15, n_a)
        t_b = rng.uniform(0, 15, n_b)
    ia, ib = associate(t_a, t_b, max_diff)
    ra, rb = greedy_reference(t_a, t_b, max_diff)
    assert ia.tolist() == ra
    assert ib.tolist() == rb


def test_associate_trajectories_keeps_order_and_stamps():
    gt = Trajectory.from_positions(np.arange(5.0), np.arange(15.0).reshape(5, 3))
    est = Trajectory.from_positions(np.array([4.001, 0.002, 2.0]), -np.arange(9.0).reshape(3, 3))
    g, e = associate_trajectories(gt, est, max_diff=0.01)
    assert g.timestamps.tolist() == [0.0, 2.0, 4.0]
    assert e.timestamps.tolist() == [0.002, 2.0, 4.001]
    np.testing.assert_array_equal(e.positions, -np.arange(9.0).reshape(3, 3)[[1, 2, 0]])


def test_against_evo_on_real_tum_files(shared_dir):
    from evo.core import sync
    from evo.tools import file_interface

    d = shared_dir / "data" / "trajectories"
    gt_path, est_path = d / "freiburg1_xyz-groundtruth.txt", d / "freiburg1_xyz-rgbdslam.txt"
    gt, est = read_tum(gt_path), read_tum(est_path)
    g, e = associate_trajectories(gt, est, max_diff=0.01)
    eg, ee = sync.associate_trajectories(
        file_interface.read_tum_trajectory_file(str(gt_path)),
        file_interface.read_tum_trajectory_file(str(est_path)),
        max_diff=0.01,
    )
    assert len(g) == eg.num_poses == 785
    np.testing.assert_allclose(g.timestamps, eg.timestamps, rtol=0, atol=1e-6)
    np.testing.assert_allclose(e.timestamps, ee.timestamps, rtol=0, atol=1e-6)
    assert np.abs(g.timestamps - e.timestamps).max() <= 0.01


def test_against_evo_on_kitti_frame_indices(shared_dir):
    from evo.core import sync
    from evo.core.trajectory import PoseTrajectory3D

    d = shared_dir / "data" / "trajectories"
    gt, est = read_kitti(d / "KITTI_00_gt.txt"), read_kitti(d / "KITTI_00_ORB.txt")
    est = est[np.arange(0, len(est), 3)]  # a sparse estimate with frame-index stamps
    g, e = associate_trajectories(gt, est, max_diff=0.01)
    eg, _ = sync.associate_trajectories(
        PoseTrajectory3D(poses_se3=list(gt.poses), timestamps=gt.timestamps),
        PoseTrajectory3D(poses_se3=list(est.poses), timestamps=est.timestamps),
        max_diff=0.01,
    )
    assert len(g) == eg.num_poses == len(est)
    np.testing.assert_array_equal(g.timestamps, e.timestamps)
