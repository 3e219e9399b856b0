"""The geometric start (dmtrack.initialization) on the synthetic renderer: it recovers the first frame's depth up to
scale, refuses a pure rotation with a message that says so, is deterministic, and a run with it tracks every frame
and records what the start did; ``init="random"`` still gives the trajectories it gave before the start existed."""

from __future__ import annotations

import hashlib
import warnings

import numpy as np
import pytest

import dmtrack
from dmtrack.datasets.base import Frame as SequenceFrame
from dmtrack.datasets.synthetic.renderer import render
from dmtrack.datasets.synthetic.sequence import SyntheticConfig, SyntheticSequence
from dmtrack.geometry.lie import SO3
from dmtrack.initialization import GeometricInitializer
from dmtrack.io.trajectory import Trajectory
from dmtrack.odometry.config import VOConfig

GEOMETRIC = VOConfig(init="geometric")


@pytest.fixture(scope="module")
def moving() -> SyntheticSequence:
    return SyntheticSequence(SyntheticConfig(width=320, height=240, n_frames=40, seed=1))


def _feed(start: GeometricInitializer, frames: list) -> None:
    for f in frames:
        if start.add(f.index, f.timestamp, f.image):
            return


def test_the_first_map_is_the_true_depth_up_to_scale(moving: SyntheticSequence) -> None:
    start = GeometricInitializer(moving.camera, GEOMETRIC)
    _feed(start, list(moving))
    assert start.state == "accepted", start.reason
    m = start.initial_map
    assert m is not None and m.frame_index == 0 and m.accepted_frame == start.info["accepted_frame"] < 20
    est = m.idepth_smoothed
    use = m.valid & (est > 0)
    assert use.sum() > 0.5 * use.size  # semi-dense: the textured room has gradient almost everywhere
    true = moving.inverse_depth(0)[use]
    s = np.median(true / est[use])  # the map's scale is its own (mean inverse depth 1)
    rel = np.abs(s * est[use] - true) / true
    assert np.median(rel) < 0.02
    assert np.mean(rel < 0.10) > 0.9
    assert abs(float(np.mean(est[use])) - 1.0) < 1e-3  # the depth map's normalisation


def test_the_start_is_deterministic(moving: SyntheticSequence) -> None:
    maps = []
    for _ in range(2):
        start = GeometricInitializer(moving.camera, GEOMETRIC)
        _feed(start, list(moving))
        maps.append(start.initial_map)
    a, b = maps
    assert a is not None and b is not None and a.accepted_frame == b.accepted_frame
    for name in ("valid", "idepth", "idepth_var", "idepth_smoothed", "idepth_var_smoothed", "validity"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


class _Rotating:
    """A sequence (the dataset protocol, as far as dmtrack.track needs it) whose camera only turns about its centre:
    the renderer's scene seen from the synthetic sequence's first pose, yawing and pitching."""

    format = "synthetic"
    name = "rotation-only"
    has_depth = False
    details: dict = {}

    def __init__(self, base: SyntheticSequence, n: int = 40) -> None:
        self.camera = base.camera
        self._scene = base.scene
        T0 = base.poses[0]
        self._poses = []
        for i in range(n):
            R = SO3.exp([0.004 * i, 0.008 * i, 0.0]).matrix()
            T = T0.copy()
            T[:3, :3] = T0[:3, :3] @ R
            self._poses.append(T)
        self.timestamps = np.arange(n) / 30.0
        self.groundtruth = Trajectory(self.timestamps, np.array(self._poses))
        self.width, self.height = base.width, base.height

    def __len__(self) -> int:
        return len(self._poses)

    def __getitem__(self, i: int) -> SequenceFrame:
        radiance, _ = render(self._scene, self.camera, self._poses[i])
        image = np.clip(np.rint(radiance), 0, 255).astype(np.uint8)
        return SequenceFrame(i, float(self.timestamps[i]), image, self._poses[i].copy(), None)


def test_a_pure_rotation_is_refused_with_a_message_that_says_so(moving: SyntheticSequence) -> None:
    seq = _Rotating(moving)
    start = GeometricInitializer(seq.camera, GEOMETRIC.with_overrides("initializer.max_frames=30"))
    _feed(start, [seq[i] for i in range(len(seq))])
    assert start.state == "refused" and start.initial_map is None and start.info["frames_seen"] == 31
    assert "homography explains" in start.reason and "rotated without moving" in start.reason


def test_a_run_whose_start_refuses_begins_from_the_random_map_and_says_so(moving: SyntheticSequence) -> None:
    seq = _Rotating(moving, n=20)
    config = GEOMETRIC.with_overrides("initializer.max_frames=12")
    with pytest.warns(UserWarning, match="geometric start refused, starting from a random map"):
        res = dmtrack.track(seq, config=config)
    m = res.metrics
    assert m["init"] == "geometric" and m["init_fallback"] == "random" and m["init_accepted_frame"] is None
    assert "the camera has rotated without moving" in m["init_refused"]
    assert res.tracked_frames == 20  # every frame keeps a pose
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        random = dmtrack.track(seq, config=config.with_overrides("init=random"))
    assert np.array_equal(random.trajectory.poses, res.trajectory.poses)  # the same start as --init random


def test_a_run_with_the_geometric_start_tracks_every_frame_and_records_it() -> None:
    res = dmtrack.track("synthetic:n_frames=40,width=320,height=240,seed=1", config=GEOMETRIC)
    m = res.metrics
    assert res.tracked_frames == 40 and m["init"] == "geometric" and m["init_refused"] is None
    assert 0 < m["init_accepted_frame"] < 40 and m["init_info"]["ba_error_px"] < 0.2
    assert res.trajectory.timestamps[0] == 0.0 and len(res.trajectory.poses) == 40  # the window's frames too
    # the seed plays no part
    again = dmtrack.track("synthetic:n_frames=40,width=320,height=240,seed=1", config=GEOMETRIC, seed=7)
    assert np.array_equal(again.trajectory.poses, res.trajectory.poses)
    # and the start is better than a random one here
    random = dmtrack.track("synthetic:n_frames=40,width=320,height=240,seed=1", init="random", seed=0)
    assert m["ate_rmse"] < random.metrics["ate_rmse"]


def _digest(res: dmtrack.pipeline.RunResult) -> str:
    h = hashlib.sha256()
    for a in (res.trajectory.poses, res.trajectory.timestamps, res.keyframes.poses):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


# sha256 of the poses, timestamps and keyframe poses of these runs. Commit a4fcd61 (before the geometric start) gave
# 5cbc420e… / a96f747c… — but only where OpenBLAS ran its Haswell or Zen kernels: the odometry composed its poses with
# numpy's ``@``, and OpenBLAS's AVX-512 kernels gave 6597d836… for the first (issue 41). Since then the odometry's
# products are dmtrack.geometry.exact's, and these digests are the same for every numba kernel target and every
# OpenBLAS kernel (tests/faults/test_kernel_targets.py checks that across targets).
BEFORE = {
    "synthetic": "b6b4c54592f42a0dd8261ecbff9995fa2a6932c93a25370ce4eb53de17c41764",
    "sample": "cc47871fcae3ba61ee9cd2f09e9fbf2e64c6922c34604d483785e54bbb67ab71",
}


def test_the_random_start_is_byte_for_byte_what_it_was(sample_dir) -> None:  # noqa: ANN001
    config = VOConfig(init="random")
    syn = dmtrack.track("synthetic:n_frames=40,width=320,height=240,seed=2", feature="gray", config=config, seed=3)
    assert _digest(syn) == BEFORE["synthetic"]
    real = dmtrack.track(sample_dir, feature="gray", config=config, max_frames=60, seed=1)
    assert _digest(real) == BEFORE["sample"]


def test_the_odometry_alone_asks_for_the_first_map(moving: SyntheticSequence) -> None:
    from dmtrack.errors import InputError
    from dmtrack.odometry.vo import VisualOdometry

    f = moving[0]
    image = f.image.astype(np.float32)
    with pytest.raises(InputError, match="needs the first keyframe's map"):
        VisualOdometry(moving.camera, GEOMETRIC).process(0, f.timestamp, f.image, image)
    start = GeometricInitializer(moving.camera, GEOMETRIC)
    _feed(start, list(moving))
    vo = VisualOdometry(moving.camera, GEOMETRIC)
    vo.process(0, f.timestamp, f.image, image, initial_map=start.initial_map)
    dm, m = vo.depth_map, start.initial_map
    assert dm is not None and m is not None and dm.n_updates == 0
    assert np.array_equal(dm.idepth[dm.valid], m.idepth[dm.valid])  # taken as it is, where the keyframe can use it
    assert np.all(m.valid[dm.valid]) and dm.n_valid > 0.9 * m.n_valid


def _ba_problem(noise: float, seed: int = 0) -> tuple:
    """A well-conditioned window: 200 points 2–6 m in front, 5 frames moving 0.3 m sideways while turning."""
    from dmtrack.geometry.lie import SE3

    rng = np.random.default_rng(seed)
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    uv = rng.uniform([20, 20], [620, 460], size=(200, 2))
    rho = 1.0 / rng.uniform(2.0, 6.0, 200)
    f = np.c_[uv, np.ones(200)] @ np.linalg.inv(K).T
    poses = [SE3.exp([0.06 * i, 0.01 * i, 0.0, 0.0, -0.01 * i, 0.004 * i]).matrix() for i in range(1, 6)]
    obs = []
    for T in poses:
        Y = f @ T[:3, :3].T + rho[:, None] * T[:3, 3]
        obs.append(Y[:, :2] / Y[:, 2:] * 500.0 + [320, 240] + rng.normal(0, noise, (200, 2)))
    s = float(np.mean(rho))
    truth = np.array(poses)
    truth[:, :3, 3] *= s  # the gauge of the adjustment: mean inverse depth 1
    start = truth.copy()
    start[:, :3, 3] *= 1.3  # a wrong scale of motion and a rotation off by ~0.6°
    start[:, :3, :3] = SO3.exp([0.01, 0.0, 0.0]).matrix() @ start[:, :3, :3]
    return K, uv, obs, truth, start, rho / s


@pytest.mark.parametrize("solver", ["schur", "scipy"])
def test_the_bundle_adjustment_recovers_a_window(solver: str) -> None:
    from dmtrack.initialization import bundle_adjust

    K, uv, obs, truth, start, rho = _ba_problem(noise=0.2)
    guess = rho * np.random.default_rng(1).uniform(0.8, 1.25, len(rho))  # as a two-view triangulation gives
    res = bundle_adjust(K, uv, obs, start, guess, solver=solver)
    assert res.kept.all() and res.median_error_px < 0.3  # the noise's level (0.2 px a coordinate: 0.24)
    assert np.allclose(res.poses[:, :3, 3], truth[:, :3, 3], atol=0.02 * np.abs(truth[:, :3, 3]).max())
    for T, G in zip(res.poses, truth, strict=True):
        assert np.degrees(SO3.from_matrix(T[:3, :3] @ G[:3, :3].T).log().__abs__().max()) < 0.05
    assert np.median(np.abs(res.idepth - rho) / rho) < 0.02


def test_the_fast_adjustment_agrees_with_scipy_and_drops_outliers() -> None:
    from dmtrack.initialization import bundle_adjust

    K, uv, obs, truth, start, rho = _ba_problem(noise=0.3, seed=4)
    obs[2][:10] += 25.0  # ten corners tracked onto something else in one frame
    guess = rho * np.random.default_rng(1).uniform(0.8, 1.25, len(rho))
    a = bundle_adjust(K, uv, obs, start, guess, solver="schur")
    b = bundle_adjust(K, uv, obs, start, guess, solver="scipy")
    assert not a.kept[:10].any() and a.kept[10:].all() and np.array_equal(a.kept, b.kept)
    assert np.allclose(a.poses, b.poses, atol=2e-3) and np.allclose(a.idepth, b.idepth, rtol=0.03)
    assert abs(a.median_error_px - b.median_error_px) < 0.01 * b.median_error_px  # the same minimum
