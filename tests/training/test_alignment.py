"""The torch re-implementation of the tracker's objective (dmtrack.training.alignment) against the tracker's own numba
kernels, on a real synthetic pair (renderer: exact depth and pose).

Per feature (grey: N = 1, the kernels' packed float64 path; rgb: N = 3 and Bit-Planes: N = 8, the kernels' float32
channel loop, with the balanced rule's N_E) and per level 3, 2, 1, at a pose ~1 cm / 0.6° off the truth:

* the evaluation — which points are in the image, n_in, good/bad counts, point usage, the error E and the per-point
  buffer rows (x', y', z', Σ_c W ĝĝᵀ, Σ_c W r ĝ) of ``eval_pass`` — agree to 1e-4 (relative to each column's largest
  magnitude; the float64 torch side differs from the float32 channel sums by ~1e-7, from grey's by ~1e-14);
* the normal equations: (H, b) from the torch side's explicit (N·m)×6 Jacobian agree with ``warp_update``'s
  per-point 2×2 accumulation (÷ n_in × ρ, as the tracker scales them) to 1e-4;
* one damped step: ``solve_damped`` + ``se3_exp`` (numba) and the torch solve + exp agree to 1e-4 for λ = 0 and 0.2,
  and a one-iteration ``Tracker.track`` on the level ends at the torch step's pose with the torch error there.

The Jacobian's projection part is also checked against autograd of the warp through the torch ``se3_exp``.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from dmtrack.datasets.synthetic import SyntheticConfig, SyntheticSequence  # noqa: E402
from dmtrack.features import get_feature  # noqa: E402
from dmtrack.odometry._tracker_normal_equations import se3_exp, solve_damped, warp_update  # noqa: E402
from dmtrack.odometry._tracker_residuals import BUF_COLS, eval_params, eval_pass  # noqa: E402
from dmtrack.odometry.config import ChannelRule, TrackerConfig  # noqa: E402
from dmtrack.odometry.frame import build_frame  # noqa: E402
from dmtrack.odometry.tracker import Tracker, TrackingReference  # noqa: E402
from dmtrack.training import alignment as al  # noqa: E402

TOL = 1e-4
D = torch.float64
XI = np.r_[0.006, -0.004, 0.005, 0.006, -0.005, 0.004]  # initial pose error (υ in m, ω in rad)


def rel(a: np.ndarray, b: np.ndarray) -> float:
    """max |a − b| / max |b| (per column when 2-D)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.ndim == 2:
        return max(rel(a[:, j], b[:, j]) for j in range(a.shape[1]))
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


@pytest.fixture(scope="module")
def scene():
    seq = SyntheticSequence(SyntheticConfig(width=320, height=240, seed=3, colour=True, n_frames=8))
    return seq, seq[0], seq[5]


def setup(scene, name: str):
    seq, f0, f1 = scene
    feat = get_feature(name)
    n_levels = 5

    def maps(img):
        return feat.compute_pyramid(img, n_levels) if feat.pyramid == "recompute" else feat.compute(img)

    fk = build_frame(0, 0.0, f0.image, maps(f0.image), seq.camera, n_levels)
    ff = build_frame(1, 1.0, f1.image, maps(f1.image), seq.camera, n_levels)
    mask = fk.levels[0].max_grad > 5
    rng = np.random.default_rng(1)
    idepth = np.where(mask, 1.0 / f0.depth, -1).astype(np.float32)
    var = np.where(mask, 10.0 ** rng.uniform(-4, -2, mask.shape), -1).astype(np.float32)
    ref = TrackingReference.from_keyframe(fk, idepth, var)
    T_true = np.linalg.inv(f1.pose) @ f0.pose
    T0 = se3_exp(XI) @ T_true
    return feat, ref, ff, T0


def numba_level(ref, ff, lvl, T, rule, cfg):
    rl, fl = ref.level(lvl), ff.levels[lvl]
    cam = fl.camera
    prm = eval_params(cam.fx, cam.fy, cam.cx, cam.cy, 1.0, 0.0, cfg.var_weight, cfg.camera_pixel_noise2,
                      cfg.huber_d / 2, rule.good * cfg.good_residual**2, cfg.good_grad_weight**2, cfg.affine_huber)
    buf = np.empty((rl.n_points, BUF_COLS))
    flags = np.ones(fl.width * fl.height, bool)
    nch = rl.values.shape[1]
    packed = fl.packed if nch == 1 else np.zeros((1, 1, 3, nch), np.float32)  # N > 1 reads the map itself
    n_in, err, good, bad, usage, *_ = eval_pass(rl.points, rl.values, rl.variances, rl.pixel_index, fl.feat, packed,
                                                 T, prm, False, flags, False, buf)
    A, b = warp_update(buf)
    return n_in, err * rule.residual / n_in, good, bad, usage, buf, A / n_in * rule.residual, b / n_in * rule.residual


def torch_level(ref, ff, lvl, T, feat, cfg):
    rl, fl = ref.level(lvl), ff.levels[lvl]
    prm = al.AlignParams.of(fl.camera, cfg, feat.channels, "balanced", feat.energy_channels)
    t = lambda a: torch.tensor(np.asarray(a), dtype=D)  # noqa: E731
    return al.evaluate(t(rl.points), t(rl.values), t(rl.variances), t(fl.feat), t(T), prm)


@pytest.mark.parametrize("name", ["gray", "rgb", "bitplanes"])
def test_evaluation_normal_equations_and_step_match_the_numba_kernels(scene, name: str) -> None:
    feat, ref, ff, T0 = setup(scene, name)
    cfg = TrackerConfig()
    rule = ChannelRule.of("balanced", feat.channels, None, feat.energy_channels)
    if feat.channels > 1:
        assert rule.residual != 1.0 / feat.channels  # N_E is measured, not N: the factor is exercised
    for lvl in (3, 2, 1):
        n_in, err, good, bad, usage, buf, A, b = numba_level(ref, ff, lvl, T0, rule, cfg)
        ev = torch_level(ref, ff, lvl, T0, feat, cfg)
        # the same points, counts and error
        inside = ev.inside.numpy()
        np.testing.assert_array_equal(inside, buf[:, 2] != 0)
        assert ev.n_in == n_in > 500
        assert (ev.good, ev.bad) == (good, bad)
        assert ev.usage == pytest.approx(usage, rel=1e-9)
        assert float(ev.error) == pytest.approx(err, rel=TOL)
        # per-point sums of the buffer
        assert rel(ev.point_sums().numpy(), buf[inside]) < TOL
        # normal equations: explicit Jacobians (torch) vs per-point 2×2 accumulation (numba)
        H, bt = al.normal_equations(ev)
        assert rel(H.numpy(), A) < TOL
        assert rel(bt.numpy(), b) < TOL
        # one damped step and the pose after it
        for lam in (0.0, 0.2):
            step_n, ok_n = solve_damped(A, b, lam)
            step_t, ok_t = al.solve_damped(H, bt, lam)
            assert ok_n and ok_t
            assert np.linalg.norm(step_t.numpy() - step_n) < TOL * np.linalg.norm(step_n)
            T_n = se3_exp(step_n) @ T0
            T_t = (al.se3_exp(step_t) @ torch.tensor(T0)).numpy()
            assert np.abs(T_t - T_n).max() < TOL * 1e-2
        # lm_step is evaluate + normal_equations + solve + exp
        t = lambda a: torch.tensor(np.asarray(a), dtype=D)  # noqa: E731
        rl, fl = ref.level(lvl), ff.levels[lvl]
        prm = al.AlignParams.of(fl.camera, cfg, feat.channels, "balanced", feat.energy_channels)
        T1, delta, _, ok = al.lm_step(t(rl.points), t(rl.values), t(rl.variances), t(fl.feat), t(T0), prm, 0.0)
        assert ok
        step_n = solve_damped(A, b, 0.0)[0]
        np.testing.assert_allclose(delta.numpy(), step_n, rtol=0, atol=TOL * float(delta.abs().max()))


@pytest.mark.parametrize("name", ["gray", "bitplanes"])
def test_one_tracker_iteration_ends_at_the_torch_step(scene, name: str) -> None:
    """Tracker.track with one LM iteration on level 2 (λ = 0: a Gauss–Newton step, accepted because the error
    drops) ends at exp(δ)·T0 with δ from the torch normal equations, and its final error is the torch error there."""
    feat, ref, ff, T0 = setup(scene, name)
    cfg = TrackerConfig(levels=(2,), max_its=(0, 0, 1, 0, 0))
    res = Tracker(cfg, energy_channels=feat.energy_channels).track(ref, ff, T0)
    assert res.iterations[2] == 1 and not res.diverged
    ev0 = torch_level(ref, ff, 2, T0, feat, cfg)
    H, b = al.normal_equations(ev0)
    delta, _ = al.solve_damped(H, b, 0.0)
    T1 = (al.se3_exp(delta) @ torch.tensor(T0)).numpy()
    np.testing.assert_allclose(res.T_fk, T1, rtol=0, atol=1e-6)
    ev1 = torch_level(ref, ff, 2, T1, feat, cfg)
    assert res.final_error[2] == pytest.approx(float(ev1.error), rel=TOL)
    assert res.final_error[2] < float(ev0.error)


def test_projection_jacobian_is_the_derivative_of_the_warp(scene) -> None:
    """m_x, m_y (the Jacobian's geometric part) = autograd of (x/z, y/z) of exp(ξ)·T·p at ξ = 0."""
    _, ref, _, T0 = setup(scene, "gray")
    pts = torch.tensor(ref.level(2).points[::50], dtype=D)
    T = torch.tensor(T0, dtype=D)

    def proj(xi):
        M = al.se3_exp(xi) @ T
        X = pts @ M[:3, :3].T + M[:3, 3]
        return torch.stack([X[:, 0] / X[:, 2], X[:, 1] / X[:, 2]], 1)

    J = torch.autograd.functional.jacobian(proj, torch.zeros(6, dtype=D))  # (m, 2, 6)
    mx, my = al.projection_jacobian(pts @ T[:3, :3].T + T[:3, 3])
    np.testing.assert_allclose(J[:, 0].numpy(), mx.numpy(), rtol=0, atol=1e-9)
    np.testing.assert_allclose(J[:, 1].numpy(), my.numpy(), rtol=0, atol=1e-9)


def test_se3_exp_matches_the_tracker_and_is_differentiable_at_zero() -> None:
    rng = np.random.default_rng(0)
    for xi in [np.zeros(6), 1e-7 * rng.standard_normal(6), rng.standard_normal(6) * [0.1, 0.1, 0.1, 0.5, 0.5, 0.5]]:
        np.testing.assert_allclose(al.se3_exp(torch.tensor(xi, dtype=D)).numpy(), se3_exp(xi), rtol=0, atol=1e-12)
    x = torch.zeros(6, dtype=D, requires_grad=True)
    al.se3_exp(x).sum().backward()
    assert torch.isfinite(x.grad).all()


def test_gradients_reach_the_feature_maps(scene) -> None:
    """A loss on the pose after a step back-propagates into both feature maps (what training relies on)."""
    feat, ref, ff, T0 = setup(scene, "rgb")
    rl, fl = ref.level(2), ff.levels[2]
    key = torch.tensor(ref.keyframe.levels[2].feat, dtype=D, requires_grad=True)
    frame = torch.tensor(fl.feat, dtype=D, requires_grad=True)
    vals = key.reshape(-1, key.shape[2])[torch.from_numpy(rl.pixel_index.astype(np.int64))]
    prm = al.AlignParams.of(fl.camera, TrackerConfig(), 3, "balanced", feat.energy_channels)
    T1, _, _, ok = al.lm_step(torch.tensor(rl.points, dtype=D), vals, torch.tensor(rl.variances, dtype=D), frame,
                              torch.tensor(T0), prm)
    assert ok
    T1[:3, 3].square().sum().backward()
    for g in (key.grad, frame.grad):
        assert g is not None and torch.isfinite(g).all() and float(g.abs().sum()) > 0
