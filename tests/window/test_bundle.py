"""The window's photometric bundle adjustment (dmtrack.window): kernels against their numpy reference and finite
differences, the Schur solve against a dense solve, and convergence where the optimum is known (rendered keyframes
with exact depth; a focal length 10 % off)."""

from __future__ import annotations

import numpy as np
import pytest

from dmtrack.geometry.lie import SE3
from dmtrack.odometry.config import VOConfig, WindowConfig
from dmtrack.odometry.frame import build_frame
from dmtrack.window import PhotometricBundle, WindowKeyframe, sample_points
from dmtrack.window import _kernels as kern


def _frames(room, poses, channels=1):
    out = []
    for k, T in enumerate(poses):
        img, idepth = room.render(T)
        feat = img.astype(np.float32)[..., None]
        if channels > 1:  # a multichannel map: the image and smooth functions of it
            feat = np.concatenate([feat, 0.5 * feat + 20.0, np.sqrt(feat + 1.0) * 10.0][:channels], axis=2)
        out.append((build_frame(k, float(k), img, feat, room.camera, 5, True), idepth))
    return out


@pytest.fixture(scope="module")
def window(rendered_room):
    """Five keyframes 10 cm apart (turning 2° each), their exact inverse depths and poses."""
    poses = [rendered_room.pose(yaw_deg=2.0 * k, shift=(0.1 * k, 0.03 * k, 0.05 * k)) for k in range(5)]
    return rendered_room, poses, _frames(rendered_room, poses)


def _keyframes(window, config, hosts=4, perturb=True, seed=0):
    room, poses, frames = window
    rng = np.random.default_rng(seed)
    kfs = []
    for k, ((fr, idepth), T) in enumerate(zip(frames, poses, strict=True)):
        pts = sample_points(fr, idepth, np.full_like(idepth, 1e-4), config) if k < hosts else None
        kfs.append(WindowKeyframe(k, fr, np.linalg.inv(T), 1.0, pts))
    truth = [kf.T_cw.copy() for kf in kfs]
    depths = [None if kf.points is None else kf.points.d.copy() for kf in kfs]
    if perturb:
        for kf in kfs[1:]:
            xi = np.concatenate([rng.normal(0, 0.01, 3), rng.normal(0, 0.005, 3)])
            kf.T_cw = SE3.exp(xi).matrix() @ kf.T_cw
            if kf.points is not None:
                kf.points.d = kf.points.d * np.exp(rng.normal(0, 0.05, kf.points.count))
    return kfs, truth, depths


def _pose_errors(kfs, truth):
    return np.array([np.linalg.norm((kf.T_cw @ np.linalg.inv(T))[:3, 3]) for kf, T in zip(kfs, truth, strict=True)])


def _depth_errors(kfs, depths):
    return np.array([np.median(np.abs(kf.points.d / d - 1)) for kf, d in zip(kfs, depths, strict=True)
                     if kf.points is not None][1:])  # fmt: skip


def _pair_inputs(window, level=1, channels=1):
    room, poses, _ = window
    frames = _frames(room, poses[:2], channels) if channels > 1 else window[2][:2]
    (f0, id0), (f1, _) = frames
    pts = sample_points(f0, id0, np.full_like(id0, 1e-4), WindowConfig(size=2, points=300))
    xs, ys = pts.at_level(level)
    ref = kern.sample_values(f0.levels[level].packed, xs, ys)
    s = 0.5**level
    cam = room.camera
    camv = np.array([cam.fx * s, cam.fy * s, (cam.cx + 0.5) * s - 0.5, (cam.cy + 0.5) * s - 0.5, s])
    T_th = np.linalg.inv(poses[1]) @ poses[0]
    T_th[:3, 3] += 0.004  # off the optimum: non-zero residuals and gradients
    rows = np.arange(pts.count, dtype=np.int64)
    rows[::7] = -1  # some depths fixed
    return f1.levels[level].packed, xs, ys, pts.d * 1.01, ref, rows, T_th, camv


@pytest.mark.parametrize(("channels", "grad_c"), [(1, 0.0), (3, 0.0), (1, 50.0)])
def test_pair_kernel_equals_numpy_reference(window, channels, grad_c) -> None:
    packed, xs, ys, d, ref, rows, T_th, camv = _pair_inputs(window, channels=channels)
    n = 16
    cols = np.array([0, 1, 2, 3, 4, 5, -1, -1, -1, -1, -1, -1, 12, 13, 14, 15], np.int64)  # the target fixed
    cols[6:12] = np.arange(6, 12)  # … or not
    params = np.array([1.0 / channels, 1 / 16.0, 9.0, 40.0, grad_c**2])
    outs = []
    for fn in (kern.pair_normal_equations, kern.pair_normal_equations_numpy):
        H, b = np.zeros((n, n)), np.zeros(n)
        hpp, bp, Hcp, st = np.zeros(xs.size), np.zeros(xs.size), np.zeros((xs.size, n)), np.zeros(3)
        fn(packed, xs, ys, d, ref, rows, T_th, camv, cols, params, H, b, hpp, bp, Hcp, st, False)
        outs.append((H, b, hpp, bp, Hcp, st))
    assert outs[0][5][1] > 100 and outs[0][5][2] > 0  # inliers and outliers both present
    for a, b in zip(*outs, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * (np.abs(b).max() + 1e-300))
    assert np.all(outs[0][2][rows < 0] == 0)  # fixed depths get no row


def test_gradient_matches_finite_differences_on_a_smooth_image(window) -> None:
    """∂cost/∂(host pose, target pose, depth) = 2b, against central differences, on a bilinear image: its bilinear
    samples are exact and the sampled gradient is the interpolant's own derivative (a bilinear sample of a texture
    has no derivative to compare with)."""
    _, xs, ys, d, _, _, T_th, camv = _pair_inputs(window)
    hh, ww = 120, 160
    Y, X = np.mgrid[0:hh, 0:ww].astype(np.float64)
    F = 50.0 + 2.0 * X + 1.5 * Y + 0.03 * X * Y
    GX = 2.0 + 0.03 * Y
    GY = 1.5 + 0.03 * X
    packed = np.ascontiguousarray(np.stack([F, GX, GY], axis=-1)[..., None], dtype=np.float32)
    ref = (np.random.default_rng(2).normal(0, 5, (xs.size, 1)) + 50).astype(np.float32)
    rows = np.arange(xs.size, dtype=np.int64)
    params = np.array([1.0, 1.0, 1e4, 1e4, 0.0])  # no Huber, no outliers: a smooth cost (outside: a constant)
    cols = np.array(list(range(12)) + [-1] * 4, np.int64)
    T_h, T_t = np.eye(4), T_th

    def cost(Th, Tt, dd, out=None):
        H, b = np.zeros((12, 12)), np.zeros(12)
        hpp, bp, Hcp, st = np.zeros(xs.size), np.zeros(xs.size), np.zeros((xs.size, 12)), np.zeros(3)
        kern.pair_normal_equations(packed, xs, ys, dd, ref, rows, Tt @ np.linalg.inv(Th), camv, cols, params,
                                   H, b, hpp, bp, Hcp, st, False)  # fmt: skip
        if out is not None:
            out.extend([b, bp])
        return st[0]

    got: list = []
    cost(T_h, T_t, d, got)
    b, bp = got
    eps = 1e-6
    for k in range(12):
        xi = np.zeros(6)
        xi[k % 6] = eps
        up = [kern.se3_left_update(T_h, xi), T_t] if k < 6 else [T_h, kern.se3_left_update(T_t, xi)]
        dn = [kern.se3_left_update(T_h, -xi), T_t] if k < 6 else [T_h, kern.se3_left_update(T_t, -xi)]
        fd = (cost(*up, d) - cost(*dn, d)) / (2 * eps)
        assert fd == pytest.approx(2 * b[k], rel=1e-3, abs=1e-5 * np.abs(b).max())
    for p in (3, 10):
        dp = d.copy()
        dp[p] += eps
        dm = d.copy()
        dm[p] -= eps
        assert (cost(T_h, T_t, dp) - cost(T_h, T_t, dm)) / (2 * eps) == pytest.approx(2 * bp[p], rel=1e-3)


def test_schur_solve_equals_dense_solve() -> None:
    rng = np.random.default_rng(1)
    n, P = 14, 60
    Jc, Jp = rng.normal(size=(400, n)), np.zeros((400, P))
    for r in range(400):
        Jp[r, rng.integers(P)] = rng.normal()
    Jp[:, 5] = 0.0  # a point without information: no step
    J = np.hstack([Jc, Jp])
    r = rng.normal(size=400)
    A = J.T @ J
    g = J.T @ r
    H, Hcp, hpp = A[:n, :n].copy(), A[n:, :n].copy(), np.diag(A[n:, n:]).copy()
    assert np.allclose(A[n:, n:], np.diag(hpp))  # one depth per residual: a diagonal point block
    for lam in (0.0, 0.1):
        dc, dp, ok = kern.schur_solve(H, g[:n].copy(), hpp, g[n:].copy(), np.ascontiguousarray(Hcp), lam)
        assert ok
        D = A + lam * np.diag(np.diag(A))
        keep = np.r_[np.arange(n), n + np.nonzero(hpp > 0)[0]]
        dense = np.linalg.solve(D[np.ix_(keep, keep)], -g[keep])
        np.testing.assert_allclose(dc, dense[:n], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(dp[hpp > 0], dense[n:], rtol=1e-9, atol=1e-12)
        assert dp[5] == 0.0
    x, ok = kern.cholesky_solve(-np.eye(3), np.ones(3))
    assert not ok and not x.any()


def test_se3_update_is_the_exponential() -> None:
    rng = np.random.default_rng(3)
    T = SE3.exp(rng.normal(size=6)).matrix()
    for xi in (rng.normal(size=6) * 0.3, np.array([0.1, 0.2, 0.3, 0, 0, 0]), np.zeros(6)):
        np.testing.assert_allclose(kern.se3_left_update(T, xi), SE3.exp(xi).matrix() @ T, atol=1e-12)


def test_sample_points_are_strong_valid_and_deterministic(window) -> None:
    fr, idepth = window[2][0]
    cfg = WindowConfig(size=5, points=400)
    var = np.full_like(idepth, 1e-4)
    var[:, :160] = -1.0  # the left half has no depth
    a = sample_points(fr, idepth, var, cfg)
    b = sample_points(fr, idepth, var, cfg)
    assert a is not None and b is not None and a.count == 400
    assert np.array_equal(a.x0, b.x0) and np.array_equal(a.d, b.d)
    assert a.x0.min() >= 160  # only pixels with a depth
    assert np.all(a.d > 0)
    assert sample_points(fr, idepth, np.full_like(idepth, -1.0), cfg) is None


def test_window_converges_to_the_truth(window) -> None:
    """Rendered keyframes (exact depth, no noise), poses perturbed by about 1 cm and 0.3°, depths by 5 %: the
    optimisation brings the poses within 3 mm and halves the depth error (the renderer's own consistency,
    about one grey level, is the floor)."""
    cfg = WindowConfig(size=5, depth_prior=0.0, levels=(2, 1, 0), iterations=20)
    kfs, truth, depths = _keyframes(window, cfg)
    e0, d0 = _pose_errors(kfs, truth), _depth_errors(kfs, depths)
    cam = window[0].camera
    report = PhotometricBundle(cfg, (cam.fx, cam.fy, cam.cx, cam.cy), (cam.width, cam.height)).optimise(kfs)
    e1, d1 = _pose_errors(kfs, truth), _depth_errors(kfs, depths)
    assert e0[1:].min() > 0.006
    np.testing.assert_array_equal(kfs[0].T_cw, truth[0])  # the anchor does not move (compared as it is: T·T⁻¹ need
    # not give an exact 0 translation, it depends on the BLAS numpy brings)
    assert e1[1:].max() < 0.003
    assert np.all(d1 < 0.6 * d0)
    assert report.cost_after < report.cost_before and report.iterations > 3


def test_cost_before_and_after_are_taken_at_the_same_level(window) -> None:
    """The report's costs are both at the finest level (the levels' costs are not comparable): with no iteration
    allowed nothing moves and the two are equal; with iterations the cost after is the lower."""
    cam = window[0].camera
    for iterations in (0, 6):
        cfg = WindowConfig(size=5, depth_prior=0.0, levels=(2, 1), iterations=iterations)
        kfs, _, _ = _keyframes(window, cfg)
        report = PhotometricBundle(cfg, (cam.fx, cam.fy, cam.cx, cam.cy), (cam.width, cam.height)).optimise(kfs)
        if iterations == 0:
            assert report.iterations == 0 and report.cost_after == report.cost_before
        else:
            assert report.iterations > 0 and report.cost_after < report.cost_before


def test_focal_length_10_percent_off_is_recovered_within_1_percent(window) -> None:
    cfg = WindowConfig(size=5, depth_prior=0.0, levels=(4, 3, 2, 1, 0), iterations=20, refine_intrinsics=True)
    kfs, _, _ = _keyframes(window, cfg, perturb=False)
    cam = window[0].camera
    ba = PhotometricBundle(cfg, (1.1 * cam.fx, 1.1 * cam.fy, cam.cx, cam.cy), (cam.width, cam.height))
    report = ba.optimise(kfs)
    assert report.intrinsics is not None and report.intrinsics_sigma is not None
    assert abs(report.intrinsics[0] / cam.fx - 1) < 0.01
    assert report.intrinsics[1] / report.intrinsics[0] == pytest.approx(cam.fy / cam.fx)  # one focal length
    assert report.intrinsics[2] == cam.cx and report.intrinsics[3] == cam.cy  # the principal point kept
    assert 0 < report.intrinsics_sigma[0] < 0.01 * cam.fx


def test_config_is_checked() -> None:
    from dmtrack.errors import InputError

    for bad in ({"size": 1}, {"size": -1}, {"levels": (1, 2)}, {"leave": "drop"}, {"intrinsics_model": "k1"},
                {"points": 0}):  # fmt: skip
        with pytest.raises(InputError):
            WindowConfig(**bad)
    with pytest.raises(InputError, match="window.levels"):
        VOConfig(window=WindowConfig(size=5, levels=(6, 1)))
    assert VOConfig().with_overrides("window.size=6", "window.levels=[3,2]").window.levels == (3, 2)


def test_eliminating_variables_is_the_schur_complement() -> None:
    from dmtrack.window.bundle import _eliminate_first

    rng = np.random.default_rng(4)
    J = rng.normal(size=(50, 14))
    A, r = J.T @ J, rng.normal(size=14)
    got_A, got_r = _eliminate_first(A, r, 6)
    inv = np.linalg.inv(A[:6, :6])
    np.testing.assert_allclose(got_A, A[6:, 6:] - A[6:, :6] @ inv @ A[:6, 6:], rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(got_r, r[6:] - A[6:, :6] @ inv @ r[:6], rtol=1e-7, atol=1e-9)


def test_marginalised_keyframe_leaves_a_prior_that_holds_the_gauge(window) -> None:
    """With ``leave = "marginalise"`` the oldest keyframe's residuals become a prior on the others: the next window,
    without the old anchor and with nothing held fixed, still converges to the truth (the prior fixes where the
    keyframes are and the scale), where a window without the prior would be free to drift."""
    cfg = WindowConfig(size=4, depth_prior=0.0, levels=(2, 1, 0), iterations=20, leave="marginalise")
    kfs, truth, depths = _keyframes(window, cfg)
    cam = window[0].camera
    ba = PhotometricBundle(cfg, (cam.fx, cam.fy, cam.cx, cam.cy), (cam.width, cam.height))
    ba.optimise(kfs)
    assert ba.anchored()
    ba.marginalise(kfs)
    assert not ba.anchored() and ba.marginal is not None and ba.marginal.ids == [1, 2, 3, 4]
    w = np.linalg.eigvalsh(ba.marginal.H)
    assert w.min() > -1e-6 * w.max() and w.max() > 0  # a positive semi-definite prior
    rest, rest_truth = kfs[1:], truth[1:]
    rng = np.random.default_rng(7)
    for kf in rest:  # disturb again, the first of them too: nothing is fixed now
        kf.T_cw = SE3.exp(np.concatenate([rng.normal(0, 0.005, 3), rng.normal(0, 0.002, 3)])).matrix() @ kf.T_cw
    e0 = _pose_errors(rest, rest_truth)
    ba.optimise(rest)
    e1 = _pose_errors(rest, rest_truth)
    assert e0.max() > 0.006 and e1.max() < 0.004
