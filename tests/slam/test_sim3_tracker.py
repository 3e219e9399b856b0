"""Sim(3) alignment of keyframes on the synthetic renderer: the true relative pose and scale come back."""

from __future__ import annotations

import numpy as np
import pytest

from dmtrack.datasets.synthetic.sequence import SyntheticConfig, SyntheticSequence
from dmtrack.geometry.lie import SE3, Sim3
from dmtrack.odometry.config import TrackerConfig
from dmtrack.odometry.frame import build_frame
from dmtrack.odometry.tracker import TrackingReference
from dmtrack.slam.sim3_tracker import Sim3Tracker

W, H = 320, 240


@pytest.fixture(scope="module")
def seq() -> SyntheticSequence:
    return SyntheticSequence(SyntheticConfig(width=W, height=H, n_frames=40, seed=3, texel=0.02))


def _keyframe(seq: SyntheticSequence, i: int, norm: float, channels: int = 1):
    """Keyframe ``i`` with its exact inverse depth × ``norm`` (keyframe units) and a small variance."""
    image = seq[i].image.astype(np.float32)
    feat = np.repeat(image[:, :, None], channels, axis=2)
    frame = build_frame(i, float(i), seq[i].image, feat, seq.camera, n_levels=5, use_numba=False)
    idepth = (norm * seq.inverse_depth(i)).astype(np.float32)
    var = np.full_like(idepth, 1e-4 * norm**2)
    ref = TrackingReference.from_keyframe(frame, idepth, var, levels=(), use_numba=False)
    return frame, ref


def _truth(seq: SyntheticSequence, a: int, b: int, c_a: float, c_b: float) -> Sim3:
    """reference (a) → frame (b) in keyframe units: p_b = (c_a/c_b) R p_a + t/c_b."""
    T_ba = SE3.from_matrix(np.linalg.inv(seq[b].pose) @ seq[a].pose, orthonormalize=True)
    return Sim3(T_ba.rotation, T_ba.translation / c_b, c_a / c_b)


def _errors(S: Sim3, truth: Sim3) -> tuple[float, float, float]:
    d = S.inverse() @ truth
    return (float(np.degrees(d.rotation.angle())), float(np.linalg.norm(S.translation - truth.translation)
            / np.linalg.norm(truth.translation)), abs(S.scale / truth.scale - 1))


def test_recovers_pose_and_scale_from_a_perturbed_start(seq: SyntheticSequence):
    c_a, c_b = 0.7, 1.6  # the two keyframes' maps have different scales, as normalised keyframes do
    _, ref_a = _keyframe(seq, 0, c_a)
    frame_b, ref_b = _keyframe(seq, 12, c_b)
    truth = _truth(seq, 0, 12, c_a, c_b)
    start = Sim3.exp([0.02, -0.01, 0.01, 0.01, -0.015, 0.01, 0.1]) @ truth  # ~1.1°, 10 % scale off
    assert _errors(start, truth)[0] > 0.9 and _errors(start, truth)[1] > 0.2 and _errors(start, truth)[2] > 0.09
    res = Sim3Tracker().track(ref_a, frame_b, ref_b.idepth_pyramid, start)
    assert not res.diverged, res.reason
    rot, trans, scale = _errors(res.S, truth)
    assert rot < 0.1 and trans < 0.05 and scale < 0.005, (rot, trans, scale)  # from 1.1°, 30 %, 10 %
    info = res.hessian
    assert np.allclose(info, info.T) and np.all(np.linalg.eigvalsh(info) > 0)
    assert res.n_depth > 0.5 * res.n_in


def test_without_the_depth_residual_the_scale_is_not_observed(seq: SyntheticSequence):
    # the photometric residual alone does not see the scale (its σ row of the normal equations is zero): the
    # inverse-depth residual is what fixes it, and without it the alignment says so instead of returning a scale
    _, ref_a = _keyframe(seq, 0, 1.0)
    frame_b, _ = _keyframe(seq, 12, 1.0)
    no_depth = [(np.zeros((H >> lv, W >> lv), np.float32), -np.ones((H >> lv, W >> lv), np.float32))
                for lv in range(5)]
    res = Sim3Tracker().track(ref_a, frame_b, no_depth, _truth(seq, 0, 12, 1.0, 1.0))
    assert res.diverged and res.n_depth == 0
    assert "singular normal equations" in res.reason


def test_n_channels_follow_the_channel_rule(seq: SyntheticSequence):
    # three copies of grey under the "mean" rule are grey: the same alignment
    truth = _truth(seq, 0, 12, 1.0, 1.0)
    start = Sim3.exp([0.01, 0, 0, 0, 0.01, 0, 0.05]) @ truth
    out = []
    for n in (1, 3):
        _, ref_a = _keyframe(seq, 0, 1.0, channels=n)
        frame_b, ref_b = _keyframe(seq, 12, 1.0, channels=n)
        out.append(Sim3Tracker(channel_cost="mean").track(ref_a, frame_b, ref_b.idepth_pyramid, start))
    assert np.allclose(out[0].S.matrix(), out[1].S.matrix(), atol=1e-9)
    assert out[0].residual == pytest.approx(out[1].residual, rel=1e-9)


def test_a_start_far_off_diverges_or_is_told_apart(seq: SyntheticSequence):
    _, ref_a = _keyframe(seq, 0, 1.0)
    frame_b, ref_b = _keyframe(seq, 12, 1.0)
    truth = _truth(seq, 0, 12, 1.0, 1.0)
    good = Sim3Tracker().track(ref_a, frame_b, ref_b.idepth_pyramid, truth)
    bad = Sim3Tracker(TrackerConfig()).track(ref_a, frame_b, ref_b.idepth_pyramid,
                                             Sim3.exp([0, 0, 0, 0, 1.2, 0, 0]) @ truth)  # 69° off
    assert bad.diverged or bad.residual > 5 * good.residual


def test_the_kernel_equals_the_numpy_reference(seq: SyntheticSequence):
    _, ref_a = _keyframe(seq, 0, 0.7, channels=3)
    frame_b, ref_b = _keyframe(seq, 12, 1.6, channels=3)
    S = Sim3.exp([0.02, -0.01, 0.01, 0.01, -0.015, 0.01, 0.1]) @ _truth(seq, 0, 12, 0.7, 1.6)
    fast, slow = Sim3Tracker(channel_cost="mean"), Sim3Tracker(channel_cost="mean", use_numba=False)
    for lvl in (3, 1):
        d, v = ref_b.idepth_pyramid[lvl]
        a = fast._terms(ref_a.level(lvl), frame_b.levels[lvl], d, v, S, 0.5)
        b = slow._terms(ref_a.level(lvl), frame_b.levels[lvl], d, v, S, 0.5)
        assert (a.n_in, a.n_depth) == (b.n_in, b.n_depth) and a.n_in > 100
        assert np.allclose(a.A, b.A, rtol=1e-9, atol=1e-9 * np.abs(b.A).max())
        assert np.allclose(a.b, b.b, rtol=1e-9, atol=1e-9 * np.abs(b.b).max())
        assert a.error == pytest.approx(b.error, rel=1e-9) and a.usage == pytest.approx(b.usage, rel=1e-9)
    res_fast = fast.track(ref_a, frame_b, ref_b.idepth_pyramid, S)
    res_slow = slow.track(ref_a, frame_b, ref_b.idepth_pyramid, S)
    assert res_fast.S.allclose(res_slow.S, atol=1e-6)
