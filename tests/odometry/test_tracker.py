"""SE(3) tracker (dmtrack.odometry.tracker and its kernels: _tracker_points, _tracker_residuals,
_tracker_normal_equations).

Synthetic data: a textured plane rendered by ray casting (exact depth) from a keyframe pose and from a frame
pose a known small motion away.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.geometry.lie import SE3
from dmtrack.odometry._tracker_normal_equations import (
    se3_exp,
    solve_damped,
    warp_update,
    warp_update_numpy,
    warp_update_parallel,
)
from dmtrack.odometry._tracker_points import idepth_downsample, idepth_downsample_numpy, make_points, make_points_numpy
from dmtrack.odometry._tracker_residuals import (
    BUF_COLS,
    _eval_grey,
    _eval_grey_parallel,
    eval_params,
    eval_pass,
    eval_pass_numpy,
    eval_pass_parallel,
)
from dmtrack.odometry.config import TrackerConfig
from dmtrack.odometry.frame import Frame, build_frame
from dmtrack.odometry.tracker import Tracker, TrackingReference

CAM = PinholeCamera(200.0, 200.0, 127.5, 95.5, 256, 192)
MOTION = np.r_[0.02, -0.01, 0.015, np.deg2rad([0.6, -0.8, 0.3])]  # ~2.7 cm and ~1.0° (υ, ω)


# ---------------------------------------------------------------------------------------------- synthetic
def make_texture(seed: int, size: int = 768) -> np.ndarray:
    """Smooth multi-scale random texture, 0..255 float32."""
    rng = np.random.default_rng(seed)
    t = np.zeros((size, size), np.float32)
    for sigma, amp in ((1.5, 1.0), (4.0, 1.5), (12.0, 2.0)):
        n = cv2.GaussianBlur(rng.standard_normal((size, size)).astype(np.float32), (0, 0), sigma)
        t += amp * n / n.std()
    t = (t - t.mean()) / t.std()
    return np.clip(128 + 45 * t, 0, 255).astype(np.float32)


def render_plane(
    tex: np.ndarray,
    cam: PinholeCamera,
    T_wc: np.ndarray,
    normal: tuple[float, float, float] = (0.15, -0.2, 1.0),
    dist: float = 1.5,
    px_per_m: float = 140.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Image (H, W) float32 and exact depth z (H, W) of the textured plane n·X = dist (world frame)."""
    n = np.asarray(normal, float)
    n /= np.linalg.norm(n)
    ys, xs = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float64)
    rays = np.stack([(xs - cam.cx) / cam.fx, (ys - cam.cy) / cam.fy, np.ones_like(xs)], -1)
    R, o = T_wc[:3, :3], T_wc[:3, 3]
    rw = rays @ R.T
    s = (dist - n @ o) / (rw @ n)
    X = o + s[..., None] * rw
    e1 = np.cross(n, [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    mx = (X @ e1 * px_per_m + tex.shape[1] / 2).astype(np.float32)
    my = (X @ e2 * px_per_m + tex.shape[0] / 2).astype(np.float32)
    img = cv2.remap(tex, mx, my, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
    return img.astype(np.float32), s.astype(np.float32)


class Pair:
    """Keyframe (identity pose) and frame rendered MOTION away; features may have several channels."""

    def __init__(self, n_extra: int = 0, gain: float = 1.0, offset: float = 0.0):
        self.T_wk = np.eye(4)
        self.T_wf = self.T_wk @ SE3.exp(MOTION).matrix()
        self.T_fk = np.linalg.inv(self.T_wf) @ self.T_wk
        chans1, chans2 = [], []
        for k in range(1 + n_extra):
            tex = make_texture(k)
            a, self.depth = render_plane(tex, CAM, self.T_wk)
            b, _ = render_plane(tex, CAM, self.T_wf)
            chans1.append(a)
            chans2.append(gain * b + offset)
        self.feat_k = np.stack(chans1, -1)
        self.feat_f = np.stack(chans2, -1)

    def frames(self, copies: int = 1) -> tuple[Frame, Frame]:
        fk = np.concatenate([self.feat_k] * copies, axis=-1)
        ff = np.concatenate([self.feat_f] * copies, axis=-1)
        return build_frame(0, 0.0, None, fk, CAM), build_frame(1, 1.0, None, ff, CAM)

    def depth_for(self, keyframe: Frame) -> tuple[np.ndarray, np.ndarray]:
        """Semi-dense exact inverse depth where maxGrad > 5 (var 1e-3), −1 elsewhere."""
        mask = keyframe.levels[0].max_grad > 5
        idepth = np.where(mask, 1.0 / self.depth, -1).astype(np.float32)
        var = np.where(mask, 1e-3, -1).astype(np.float32)
        return idepth, var


@pytest.fixture(scope="module")
def grey() -> Pair:
    return Pair()


def pose_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(translation error in metres, rotation error in degrees)."""
    E = np.linalg.inv(T_true) @ T_est
    ang = np.degrees(np.arccos(np.clip((np.trace(E[:3, :3]) - 1) / 2, -1.0, 1.0)))
    return float(np.linalg.norm(E[:3, 3])), float(ang)


def track(
    pair: Pair,
    config: TrackerConfig | None = None,
    copies: int = 1,
    use_numba: bool = True,
    init=None,
    channel_cost: str = "balanced",
    **rule: float,
):
    fk, ff = pair.frames(copies)
    ref = TrackingReference.from_keyframe(fk, *pair.depth_for(fk), use_numba=use_numba)
    tracker = Tracker(config or TrackerConfig(), use_numba=use_numba, channel_cost=channel_cost, **rule)
    return tracker.track(ref, ff, np.eye(4) if init is None else init)


# ---------------------------------------------------------------------------------------------- kernels
def test_idepth_downsample_semantics_and_numba_equals_numpy() -> None:
    d = np.array([[1.0, 2.0, 5.0, 5.0], [3.0, 4.0, 5.0, 5.0]], np.float32)
    v = np.array([[0.5, 0.25, -1.0, -1.0], [-1.0, 0.0, -1.0, -1.0]], np.float32)
    for fn in (idepth_downsample, idepth_downsample_numpy):
        od, ov = fn(d, v)
        assert od.shape == (1, 2)
        # children 1 (var .5) and 2 (var .25) valid: (1/.5 + 2/.25) / (1/.5 + 1/.25) = 10/6; var = 2/6
        assert od[0, 0] == pytest.approx(10.0 / 6.0, rel=1e-6)
        assert ov[0, 0] == pytest.approx(2.0 / 6.0, rel=1e-6)
        assert od[0, 1] == -1.0 and ov[0, 1] == -1.0
    rng = np.random.default_rng(1)
    d = rng.uniform(0.2, 2.0, (48, 64)).astype(np.float32)
    v = np.where(rng.random((48, 64)) < 0.5, rng.uniform(1e-4, 0.1, (48, 64)), -1).astype(np.float32)
    a, b = idepth_downsample(d, v), idepth_downsample_numpy(d, v)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


def test_make_points_numba_equals_numpy_and_backprojects() -> None:
    rng = np.random.default_rng(2)
    h, w = 24, 32
    d = rng.uniform(0.3, 2.0, (h, w)).astype(np.float32)
    d[rng.random((h, w)) < 0.2] = 0.0
    v = np.where(rng.random((h, w)) < 0.6, 0.01, -1).astype(np.float32)
    feat = rng.random((h, w, 3)).astype(np.float32)
    args = (d, v, feat, 30.0, 32.0, 15.5, 11.5)
    out_nb, out_np = make_points(*args), make_points_numpy(*args)
    for a, b in zip(out_nb, out_np, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-6)
    pts, vals, vrs, idx = out_nb
    ys, xs = idx // w, idx % w
    assert np.all((xs >= 1) & (xs <= w - 2) & (ys >= 1) & (ys <= h - 2))
    assert np.all(v[ys, xs] > 0) and np.all(d[ys, xs] != 0)
    expected = int(((v[1:-1, 1:-1] > 0) & (d[1:-1, 1:-1] != 0)).sum())
    assert len(idx) == expected and np.all(np.diff(idx) > 0)  # row-major order
    np.testing.assert_allclose(pts[:, 2], 1.0 / d[ys, xs], rtol=1e-6)
    np.testing.assert_allclose(30.0 * pts[:, 0] / pts[:, 2] + 15.5, xs, atol=1e-4)
    np.testing.assert_allclose(32.0 * pts[:, 1] / pts[:, 2] + 11.5, ys, atol=1e-4)
    np.testing.assert_array_equal(vals, feat[ys, xs])


def _eval_args(pair: Pair, lvl: int, T: np.ndarray, copies: int = 1, affine_sums: bool = True):
    fk, ff = pair.frames(copies)
    ref = TrackingReference.from_keyframe(fk, *pair.depth_for(fk))
    rl, fl = ref.level(lvl), ff.levels[lvl]
    c = fl.camera
    flags = np.ones(fl.width * fl.height, bool)
    buf = np.zeros((rl.n_points, BUF_COLS))
    prm = eval_params(c.fx, c.fy, c.cx, c.cy, 1.1, -3.0, 1.0, 16.0, 1.5, 1600.0, 0.25, 5.0)
    nch = rl.values.shape[1]
    packed = fl.packed if (affine_sums or nch == 1) else np.zeros((1, 1, 3, nch), np.float32)  # placeholder
    args = [rl.points, rl.values, rl.variances, rl.pixel_index, fl.feat, packed, T, prm, affine_sums, flags, True, buf]
    return args, rl, fl


@pytest.mark.parametrize("copies,affine_sums", [(1, True), (1, False), (3, True), (3, False), (16, False)])
def test_eval_pass_numba_equals_numpy(copies: int, affine_sums: bool) -> None:
    """Grey and multichannel; N > 1 without affine sums takes the vectorised (fast-math) channel loop."""
    pair = Pair(n_extra=1)
    T = SE3.exp(0.5 * MOTION).matrix() @ np.linalg.inv(SE3.exp(np.r_[0.3, 0, 0, 0, 0, 0]).matrix())
    args, rl, _ = _eval_args(pair, 1, T, copies, affine_sums)
    args2 = list(args)
    args2[-3] = args[-3].copy()
    args2[-1] = args[-1].copy()
    args3 = list(args)
    args3[-3] = args[-3].copy()
    args3[-1] = args[-1].copy()
    out_nb = eval_pass(*args)
    out_np = eval_pass_numpy(*args2)
    out_par = eval_pass_parallel(*args3)
    n_in = out_nb[0]
    assert 0 < n_in < rl.n_points  # the shifted pose pushes some points out of the image
    assert out_nb[0] == out_np[0] and out_nb[2] == out_np[2] and out_nb[3] == out_np[3]
    # N > 1 without affine sums runs the float32 vectorised channel loop: float32 rounding, else float64
    fast = args[1].shape[1] > 1 and not affine_sums
    rtol = 2e-5 if fast else 1e-9
    np.testing.assert_allclose(out_nb[1:], out_np[1:], rtol=rtol)
    np.testing.assert_array_equal(args[-3], args2[-3])  # flags
    assert not args[-3].all()
    atol = rtol * np.abs(args2[-1]).max(axis=0) if fast else 1e-12
    assert np.all(np.abs(args[-1] - args2[-1]) <= atol + rtol * np.abs(args2[-1]))
    assert np.count_nonzero(args[-1][:, 2]) == n_in  # z' = 0 marks the points outside the image
    # the parallel kernel is bit-identical to the serial one
    assert out_par == out_nb
    assert args3[-1].tobytes() == args[-1].tobytes() and args3[-3].tobytes() == args[-3].tobytes()
    A, b = warp_update(args[-1])
    Ap, bp = warp_update_parallel(args[-1])
    assert A.tobytes() == Ap.tobytes() and b.tobytes() == bp.tobytes()
    An, bn = warp_update_numpy(args2[-1])
    np.testing.assert_allclose(A, An, rtol=rtol, atol=rtol * np.abs(An).max() if fast else 0)
    np.testing.assert_allclose(b, bn, rtol=rtol, atol=rtol * np.abs(bn).max())


@pytest.mark.parametrize("affine_sums", [False, True])
def test_grey_kernel_is_bit_identical_to_the_point_by_point_kernel(affine_sums: bool) -> None:
    """The vectorised grey kernel does the general kernel's per-point arithmetic (whose N = 1 branch is the
    original point-by-point loop): the same bytes for the sums, the flags and the buffer, at every level, with
    points outside the image and behind the camera, serial and threaded."""
    pair = Pair()
    poses = [
        SE3.exp(0.5 * MOTION).matrix() @ np.linalg.inv(SE3.exp(np.r_[0.3, 0, 0, 0, 0, 0]).matrix()),
        SE3.exp(np.r_[0.0, 0.0, 0.0, 0.0, np.pi - 0.01, 0.0]).matrix(),  # turned around: points behind the camera
    ]
    for T in poses:
        for lvl in (1, 2, 3, 4):
            args, rl, _ = _eval_args(pair, lvl, T, 1, affine_sums)
            want_args = [x.copy() if isinstance(x, np.ndarray) else x for x in args]
            want = eval_pass_parallel(*want_args)
            assert 0 < want[0] <= rl.n_points
            for fn in (_eval_grey, _eval_grey_parallel):
                got_args = [x.copy() if isinstance(x, np.ndarray) else x for x in args]
                got_args[-1][:] = np.nan  # every row must be written
                assert fn(*got_args) == want
                assert got_args[-3].tobytes() == want_args[-3].tobytes()  # flags
                assert got_args[-1].tobytes() == want_args[-1].tobytes()  # buffer
        if T is poses[1]:  # points behind the camera project into the image (the kernel does not test z' > 0)
            assert (want_args[-1][:, 2] < 0).any()
        else:
            assert want[0] < rl.n_points and not want_args[-3].all()


def _warp_update_point_by_point(buf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The normal equations as the original kernel formed them: per block of 1024 rows, skip z' = 0, add each
    point's terms to 27 sums in row order (Python floats are IEEE doubles: the same roundings)."""
    tot = [0.0] * 27
    for i0 in range(0, len(buf), 1024):
        s = [0.0] * 27
        for x, y, z, sxx, sxy, syy, bx, by in buf[i0 : i0 + 1024].tolist():
            if z == 0.0:
                continue
            iz = 1.0 / z
            xz, yz = x * iz, y * iz
            jx = (iz, 0.0, -xz * iz, -xz * yz, 1.0 + xz * xz, -yz)
            jy = (0.0, iz, -yz * iz, -(1.0 + yz * yz), xz * yz, xz)
            u = [sxx * jx[0], sxy * jy[1]] + [sxx * jx[k] + sxy * jy[k] for k in range(2, 6)]
            q = [0.0, syy * jy[1]] + [sxy * jx[k] + syy * jy[k] for k in range(2, 6)]
            k = 0
            for i in range(6):
                for j in range(i, 6):
                    # rows 0 and 1 of M have a single non-zero entry in columns 0 and 1
                    s[k] += jx[0] * u[j] if i == 0 else jy[1] * q[j] if i == 1 else jx[i] * u[j] + jy[i] * q[j]
                    k += 1
            for i, t in enumerate((jx[0] * bx, jy[1] * by)):
                s[21 + i] += t
            for i in range(2, 6):
                s[21 + i] += jx[i] * bx + jy[i] * by
        tot = [a + b for a, b in zip(tot, s, strict=True)]
    A = np.empty((6, 6))
    A[np.triu_indices(6)] = tot[:21]
    A.T[np.triu_indices(6)] = tot[:21]
    return A, np.array(tot[21:])


def test_warp_update_is_bit_identical_to_the_point_by_point_sums() -> None:
    """The two-pass (vectorised terms, ordered sums) normal equations give the bytes of the point-by-point sums:
    sizes around the chunk and block lengths, points outside the image (z' = 0), signed zeros."""
    rng = np.random.default_rng(11)
    for n in (1, 63, 64, 65, 1023, 1024, 1025, 2500):
        buf = rng.normal(size=(n, BUF_COLS)) * np.array([1, 1, 0, 1e3, 1e3, 1e3, 50, 50])
        buf[:, 2] = rng.uniform(0.5, 4.0, n)
        buf[rng.random(n) < 0.3] = 0.0
        buf[rng.random(n) < 0.1, 6] = -0.0
        want = _warp_update_point_by_point(buf)
        for fn in (warp_update, warp_update_parallel):
            A, b = fn(buf)
            assert A.tobytes() == want[0].tobytes() and b.tobytes() == want[1].tobytes(), (n, fn)


def test_warp_update_numba_equals_numpy_and_explicit_jacobian() -> None:
    """A = Σ_p Σ_c W J_cᵀJ_c with J_c = g_cᵀM equals the 2×2-sum accumulation; M matches finite differences."""
    rng = np.random.default_rng(5)
    n, nch = 40, 3
    X = np.c_[rng.uniform(-1, 1, (n, 2)), rng.uniform(1, 3, n)]
    G = rng.normal(size=(n, nch, 2)) * 50  # fx·∂F/∂x, fy·∂F/∂y per channel
    W = rng.uniform(0.01, 1, (n, nch))
    r = rng.normal(size=(n, nch)) * 5
    buf = np.zeros((n, BUF_COLS))
    buf[:, :3] = X
    buf[:, 3] = np.sum(W * G[..., 0] ** 2, 1)
    buf[:, 4] = np.sum(W * G[..., 0] * G[..., 1], 1)
    buf[:, 5] = np.sum(W * G[..., 1] ** 2, 1)
    buf[:, 6] = np.sum(W * r * G[..., 0], 1)
    buf[:, 7] = np.sum(W * r * G[..., 1], 1)
    A_nb, b_nb = warp_update(buf)
    A_np, b_np = warp_update_numpy(buf)
    np.testing.assert_allclose(A_nb, A_np, rtol=1e-10)
    np.testing.assert_allclose(b_nb, b_np, rtol=1e-10, atol=1e-9)
    # explicit (N·n)×6 Jacobian with M from finite differences of the normalised projection
    A_ex = np.zeros((6, 6))
    b_ex = np.zeros(6)
    eps = 1e-6
    for p in range(n):
        M = np.zeros((2, 6))
        for k in range(6):
            d = np.zeros(6)
            d[k] = eps
            q1 = SE3.exp(d).act(X[p])
            q0 = SE3.exp(-d).act(X[p])
            M[:, k] = ((q1[:2] / q1[2]) - (q0[:2] / q0[2])) / (2 * eps)
        for c in range(nch):
            J = G[p, c] @ M
            A_ex += W[p, c] * np.outer(J, J)
            b_ex += W[p, c] * r[p, c] * J
    np.testing.assert_allclose(A_nb, A_ex, rtol=1e-5, atol=1e-6 * np.abs(A_ex).max())
    np.testing.assert_allclose(b_nb, b_ex, rtol=1e-5, atol=1e-6 * np.abs(b_ex).max())


def test_solve_damped_and_se3_exp() -> None:
    rng = np.random.default_rng(3)
    B = rng.normal(size=(6, 6))
    A = B @ B.T + 0.1 * np.eye(6)
    b = rng.normal(size=6)
    for lam in (0.0, 0.2, 3.0):
        x, ok = solve_damped(A, b, lam)
        Ad = A.copy()
        Ad[np.diag_indices(6)] *= 1 + lam
        assert ok
        np.testing.assert_allclose(x, np.linalg.solve(Ad, b), rtol=1e-9)
    x, ok = solve_damped(np.zeros((6, 6)), b, 0.0)
    assert not ok and not x.any()
    for xi in (np.zeros(6), 1e-7 * rng.normal(size=6), rng.normal(size=6), np.r_[0.1, 0.2, 0.3, 0, 0, 1e-6]):
        np.testing.assert_allclose(se3_exp(xi), SE3.exp(xi).matrix(), atol=1e-12)


# ---------------------------------------------------------------------------------------------- tracking
def test_recovers_known_motion_grey(grey: Pair) -> None:
    res = track(grey)
    dt, dr = pose_error(res.T_fk, grey.T_fk)
    assert dt < 1.5e-3 and dr < 0.04, (dt, dr)  # motion was 27 mm, 1.0°
    assert res.good and not res.diverged and res.reason is None
    assert res.good_count > 0.9 * (res.good_count + res.bad_count)
    assert 0.8 < res.point_usage <= 1.0
    assert res.initial_tracked_residual == pytest.approx(res.last_residual / res.point_usage)
    assert res.ref_pixel_was_good.shape == (CAM.height // 2, CAM.width // 2)
    assert res.affine == (1.0, 0.0)
    assert set(res.iterations) == {1, 2, 3, 4}
    # the identity start is far worse than the result
    assert pose_error(np.eye(4), grey.T_fk)[0] > 0.02


def test_numba_equals_numpy_tracker(grey: Pair) -> None:
    a = track(grey, use_numba=True)
    b = track(grey, use_numba=False)
    np.testing.assert_allclose(a.T_fk, b.T_fk, atol=1e-9)
    assert a.iterations == b.iterations and a.evaluations == b.evaluations
    assert a.good_count == b.good_count and a.bad_count == b.bad_count
    np.testing.assert_array_equal(a.ref_pixel_was_good, b.ref_pixel_was_good)
    assert a.last_residual == pytest.approx(b.last_residual, rel=1e-9)


def test_deterministic_and_parallel_identical(grey: Pair) -> None:
    a = track(grey)
    b = track(grey)
    assert a.T_fk.tobytes() == b.T_fk.tobytes()
    assert a.ref_pixel_was_good.tobytes() == b.ref_pixel_was_good.tobytes()
    assert a.last_residual == b.last_residual
    fk, ff = grey.frames()
    ref = TrackingReference.from_keyframe(fk, *grey.depth_for(fk))
    # parallel kernels on every level (parallel_min_points=0), on the finest only, and on none
    for min_pts in (0, ref.level(1).n_points, 10**9):
        c = Tracker(parallel=True, parallel_min_points=min_pts).track(ref, ff, np.eye(4))
        assert c.T_fk.tobytes() == a.T_fk.tobytes() and c.last_residual == a.last_residual
        assert c.ref_pixel_was_good.tobytes() == a.ref_pixel_was_good.tobytes()
        assert c.iterations == a.iterations and c.evaluations == a.evaluations


def test_tracking_decision_adds_the_features_extra_noise(grey: Pair) -> None:
    """balanced: the decision "tracking good" counts Σ_c r_c² < N_E·g² + (N_σ − N_E)·σ² + ¼Σ_c|∇F_c|² (g =
    good_residual, σ² = camera_pixel_noise2 = 16); the per-pixel flags keep N_E·g². Three copies of grey with
    N_E = 3 and N_σ = 3 + 6 have the decision constant 3·g² + 96 = 3·(g² + 32): the counts of grey with
    good_residual² = g² + 32, and grey's own flags and pose. With N_σ = N_E (or none) it is grey's test. g = 4
    makes the test bite."""
    tight = TrackerConfig(good_residual=4.0)
    one = track(grey, tight)
    assert one.bad_count > 100
    three = track(grey, tight, copies=3, energy_channels=3.0)
    same = track(grey, tight, copies=3, energy_channels=3.0, noise_energy_channels=3.0)
    for t in (three, same):
        assert (t.good_count, t.bad_count) == (one.good_count, one.bad_count)
        assert t.ref_pixel_was_good.tobytes() == three.ref_pixel_was_good.tobytes()
    wider_grey = track(grey, TrackerConfig(good_residual=48**0.5))
    noisy = track(grey, tight, copies=3, energy_channels=3.0, noise_energy_channels=9.0)
    # (N = 3 sums in float32, grey in float64: a point or two on the border may fall either way)
    assert abs(noisy.good_count - wider_grey.good_count) <= 2
    assert noisy.good_count + noisy.bad_count == wider_grey.good_count + wider_grey.bad_count
    assert noisy.good_count > one.good_count + 100  # the decision's test changed: more points pass
    # ... and nothing else did: the flags, the pose and the iterations are those without the term
    assert noisy.ref_pixel_was_good.tobytes() == three.ref_pixel_was_good.tobytes()
    assert noisy.T_fk.tobytes() == three.T_fk.tobytes() and noisy.iterations == three.iterations
    assert noisy.evaluations[1] == three.evaluations[1] + 1  # one more count at the final pose
    # the decision follows the counts: a good ratio that fails without the term passes with it
    strict = TrackerConfig(good_residual=4.0, min_good_ratio=one.good_count / (one.good_count + one.bad_count))
    assert not track(grey, strict, copies=3, energy_channels=3.0).good
    assert track(grey, strict, copies=3, energy_channels=3.0, noise_energy_channels=9.0).good
    # "sum" and "mean" keep the channel mean whatever N_σ
    for cost in ("sum", "mean"):
        a = track(grey, tight, copies=3, channel_cost=cost, energy_channels=3.0, noise_energy_channels=9.0)
        b = track(grey, tight, copies=3, channel_cost=cost)
        assert (a.good_count, a.bad_count) == (b.good_count, b.bad_count)


def test_three_copies_of_grey_give_the_grey_pose(grey: Pair) -> None:
    # N = 3 runs the float32 vectorised channel loop (grey the float64 scalar one): equal up to float32 rounding
    one = track(grey)
    # the default ("balanced") and "mean" average the error over channels: the per-channel residual of grey
    for cost in ("balanced", "mean"):
        three = track(grey, copies=3, channel_cost=cost)
        np.testing.assert_allclose(three.T_fk, one.T_fk, atol=1e-6)
        assert three.iterations == one.iterations
        assert three.last_residual == pytest.approx(one.last_residual, rel=1e-6)
        assert (three.good_count, three.bad_count) == (one.good_count, one.bad_count)
    # the paper's sum triples it (same step: LM is invariant to a common factor of A and b)
    summed = track(grey, copies=3, channel_cost="sum")
    np.testing.assert_allclose(summed.T_fk, one.T_fk, atol=1e-6)
    assert summed.last_residual == pytest.approx(3 * one.last_residual, rel=1e-6)
    # for N = 1 every rule is the same computation, bit for bit
    for cost in ("sum", "mean"):
        other = track(grey, channel_cost=cost)
        assert other.T_fk.tobytes() == one.T_fk.tobytes() and other.last_residual == one.last_residual
    with pytest.raises(InputError):
        Tracker(channel_cost="median")


def test_genuinely_multichannel() -> None:
    pair = Pair(n_extra=2)  # three independent textures on the plane
    res = track(pair)
    dt, dr = pose_error(res.T_fk, pair.T_fk)
    assert dt < 1.5e-3 and dr < 0.04, (dt, dr)
    assert res.good
    # a frame whose other channels disagree (channel 1 shuffled) is penalised: larger residual
    bad = Pair(n_extra=2)
    bad.feat_f = bad.feat_f.copy()
    bad.feat_f[..., 1] = np.roll(bad.feat_f[..., 1], 17, axis=1)
    worse = track(bad)
    assert worse.last_residual > 2 * res.last_residual


def test_gray_a_recovers_gain_and_offset() -> None:
    pair = Pair(gain=1.3, offset=12.0)
    plain = track(pair)
    assert pose_error(plain.T_fk, pair.T_fk)[0] > 5e-3  # without the affine model tracking fails
    res = track(pair, TrackerConfig(affine=True, affine_compose=True))
    dt, dr = pose_error(res.T_fk, pair.T_fk)
    assert dt < 1.5e-3 and dr < 0.04, (dt, dr)
    a, b = res.affine
    assert a == pytest.approx(1.3, rel=0.04) and b == pytest.approx(12.0, abs=6.0)
    # LSD-SLAM's own update (replace instead of compose) still runs and returns a gain estimate
    lsd = track(pair, TrackerConfig(affine=True))
    assert not lsd.diverged and 1.0 < lsd.affine[0] < 1.4
    # and on a pair without brightness change it tracks accurately
    same = Pair()
    dt, dr = pose_error(track(same, TrackerConfig(affine=True)).T_fk, same.T_fk)
    assert dt < 2e-3 and dr < 0.06


def test_divergence_and_out_of_image_flags(grey: Pair) -> None:
    far = np.eye(4)
    far[0, 3] = 50.0  # everything projects far outside
    res = track(grey, init=far)
    assert res.diverged and not res.good and "diverged at level 4" in res.reason
    # a moderate sideways shift: part of the keyframe leaves the image → those pixels are not good
    shift = SE3.exp(np.r_[0.3, 0, 0, 0, 0, 0]).matrix() @ grey.T_fk
    fk, ff = grey.frames()
    idepth, var = grey.depth_for(fk)
    ref = TrackingReference.from_keyframe(fk, idepth, var)
    cfg = TrackerConfig(max_its=(0, 0, 0, 0, 0))  # evaluate only: keep the shifted pose
    r2 = Tracker(cfg).track(ref, ff, shift)
    flags = r2.ref_pixel_was_good
    rl = ref.level(1)
    ys, xs = rl.pixel_index // rl.width, rl.pixel_index % rl.width
    assert not flags[ys, xs].all() and flags[ys, xs].any()
    # pixels without a reference point stay True
    no_point = np.ones(flags.shape, bool)
    no_point[ys, xs] = False
    assert flags[no_point].all()


def test_input_errors(grey: Pair) -> None:
    fk, ff = grey.frames(copies=2)
    ref = TrackingReference.from_keyframe(fk, *grey.depth_for(fk))
    with pytest.raises(InputError, match="Gray-A"):
        Tracker(TrackerConfig(affine=True)).track(ref, ff, np.eye(4))
    _, ff1 = grey.frames(copies=1)
    with pytest.raises(InputError, match="channels"):
        Tracker().track(ref, ff1, np.eye(4))
    with pytest.raises(InputError, match="match"):
        TrackingReference.from_keyframe(fk, np.zeros((4, 4), np.float32), np.zeros((4, 4), np.float32))


def test_level_4_only_evaluates_by_default(grey: Pair) -> None:
    """LSD-SLAM's SlamSystem sets maxItsPerLvl to 0 from level 4 up: the coarsest level is evaluated (for the
    divergence test and Gray-A's first estimate) but not optimised."""
    res = track(grey)
    assert res.iterations[4] == 0 and res.evaluations[4] == 1
    assert all(res.iterations[lv] > 0 for lv in (3, 2, 1))
