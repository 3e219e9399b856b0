"""The rotation gain (``dmtrack.evaluation.rotation_gain``): how much of the ground truth's turn an estimate shows per
camera axis, a check of the calibration (benchmarks/studies/2026-11-29-calibration)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmtrack.evaluation import evaluate, rotation_gain, rotation_gain_text
from dmtrack.geometry.lie import so3_log
from dmtrack.io.trajectory import Trajectory


def _trajectory(angles: np.ndarray, axis: int | None = None, n: int = 120) -> Trajectory:
    """Poses turning by ``angles`` (N,) about camera ``axis`` (or by (N, 3) rotation vectors), moving along a
    curve."""
    t = np.arange(n, dtype=float)
    T = np.repeat(np.eye(4)[None], n, 0)
    rv = np.zeros((n, 3))
    if axis is None:
        rv = angles
    else:
        rv[:, axis] = angles
    T[:, :3, :3] = Rotation.from_rotvec(rv).as_matrix()
    T[:, :3, 3] = np.stack([0.01 * t, 0.1 * np.sin(0.05 * t), 0.002 * t], axis=1)
    return Trajectory(t / 30.0, T)


def test_the_rotation_vectors_it_takes_are_scipys() -> None:
    R = Rotation.from_rotvec(np.random.default_rng(3).normal(size=(200, 3)) * 0.9).as_matrix()
    np.testing.assert_allclose(so3_log(R), Rotation.from_matrix(R).as_rotvec(), atol=1e-12)
    np.testing.assert_array_equal(so3_log(np.repeat(np.eye(3)[None], 2, 0)), np.zeros((2, 3)))


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_a_turn_read_as_smaller_has_that_gain_about_its_axis(axis: int) -> None:
    t = np.arange(120, dtype=float)
    theta = 0.01 * t + 0.2 * np.sin(0.05 * t)
    gt, est = _trajectory(theta, axis), _trajectory(0.8 * theta, axis)
    g = rotation_gain(gt, est)
    assert g.pairs == 105 and g.frames == 15
    assert g.gain[axis] == pytest.approx(0.8, abs=1e-12)
    others = [a for a in range(3) if a != axis]
    assert np.isnan(g.gain[others]).all()  # the camera does not turn about them: undefined, not 1 or 0
    assert g.rms_turn_deg[axis] > 5 and (g.rms_turn_deg[others] == 0).all()


def test_the_ground_truth_itself_and_a_similar_copy_have_gain_one() -> None:
    t = np.arange(150, dtype=float)
    rv = np.stack([0.3 * np.sin(0.04 * t), 0.2 * np.cos(0.03 * t), 0.005 * t], axis=1)
    gt = _trajectory(rv, None, 150)
    S = np.eye(4)
    S[:3, :3] = Rotation.from_rotvec([0.3, -1.0, 2.0]).as_matrix() * 2.5  # a similarity of the world
    S[:3, 3] = [1.0, -2.0, 3.0]
    moved = gt.poses.copy()
    moved[:, :3, :] = S[:3, :3] @ gt.poses[:, :3, :] / 2.5
    moved[:, :3, 3] = (S[:3, :3] @ gt.poses[:, :3, 3, None])[..., 0] + S[:3, 3]
    np.testing.assert_allclose(rotation_gain(gt, gt).gain, 1.0, atol=1e-12)
    np.testing.assert_allclose(rotation_gain(gt, Trajectory(gt.timestamps, moved)).gain, 1.0, atol=1e-9)
    # an estimate that turns about the wrong axis shows no gain about the right one
    swapped = _trajectory(rv[:, [1, 0, 2]], None, 150)
    assert abs(rotation_gain(gt, swapped).gain[0]) < 0.5


def test_a_camera_that_does_not_turn_has_no_gain() -> None:
    gt = _trajectory(np.zeros(60), 0, 60)
    assert np.isnan(rotation_gain(gt, gt).gain).all()
    assert np.isnan(rotation_gain(Trajectory(gt.timestamps[:10], gt.poses[:10]),
                                  Trajectory(gt.timestamps[:10], gt.poses[:10])).gain).all()  # fmt: skip
    result = evaluate(gt, gt)
    assert result["rotation_gain"] == [None, None, None] and result["rotation_gain_frames"] == 15
    json.dumps(result)
    assert rotation_gain_text(result["rotation_gain"]) == []
    with pytest.raises(ValueError, match="associated"):
        rotation_gain(gt, Trajectory(gt.timestamps[:5], gt.poses[:5]))
    with pytest.raises(ValueError, match="frames"):
        rotation_gain(gt, gt, frames=0)


def test_evaluate_reports_the_gain_and_the_text_names_the_calibration_signature() -> None:
    t = np.arange(120, dtype=float)
    rv = np.stack([0.2 * np.sin(0.05 * t), 0.15 * np.sin(0.04 * t + 1.0), 0.1 * np.sin(0.03 * t)], axis=1)
    result = evaluate(_trajectory(rv, None), _trajectory(rv * [0.8, 0.85, 1.0], None))
    x, y, z = result["rotation_gain"]
    assert 0.75 < x < 0.85 and 0.8 < y < 0.9 and 0.95 < z < 1.05
    (line,) = rotation_gain_text(result["rotation_gain"], result["rotation_gain_frames"])
    assert "x 0.8" in line and "over 15 poses" in line and "focal length may be too long" in line
    (line,) = rotation_gain_text([1.0, 0.99, None])
    assert line.endswith("x 1.00 y 0.99 z –")  # no hint when it turns as the camera did
    assert "focal" not in rotation_gain_text([0.8, 0.8, 1.5])[0]  # roll off too: not the calibration's signature


def test_a_focal_length_ten_percent_too_long_shows_as_a_gain_below_one(shared_dir, tmp_path) -> None:
    """Tsukuba (true f = 615 px, rendered): tracked at 676.5 px the estimate turns less about x and y."""
    from dmtrack.cli import main

    gains = {}
    for f in (615.0, 676.5):
        out = tmp_path / f"f{f:g}"
        assert main(["run", str(shared_dir / "data" / "tsukuba-150"), "--intrinsics", f"{f},{f},320,240",
                     "--max-frames", "80", "--out", str(out), "--no-progress", "--no-pointcloud",
                     "--no-depth-images"]) == 0  # fmt: skip
        gains[f] = json.loads((out / "metrics.json").read_text())["rotation_gain"]
    assert all(0.97 < g < 1.05 for g in gains[615.0])  # measured 1.01, 1.02, 0.99
    assert gains[676.5][0] < 0.95 and gains[676.5][1] < 0.95  # measured 0.92, 0.92
    assert 0.97 < gains[676.5][2] < 1.05  # roll does not depend on the focal length
