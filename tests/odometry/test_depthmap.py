"""Tests of the semi-dense inverse-depth map (``dmtrack.odometry.depthmap`` and its kernels).

Scenes are textured planes rendered exactly (ray/plane intersection, bicubic texture lookup) from known
poses, so the true inverse depth of every keyframe pixel is known. Kernel-vs-reference comparisons use
64×48 images (the python references are slow); accuracy tests 128×96.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.odometry._depth_common import (
    PC_CREATED,
    PC_DROPPED_GOOD,
    PC_MERGED,
    PC_OCCLUDED,
    empty_state,
    make_params,
    stereo_geometry,
)
from dmtrack.odometry._depth_propagate import propagate_numba, propagate_reference
from dmtrack.odometry._depth_regularize import (
    fill_holes_numba,
    fill_holes_reference,
    regularize_numba,
    regularize_reference,
)
from dmtrack.odometry._epipolar_stereo import epl_check_reference, line_stereo_numba, line_stereo_reference
from dmtrack.odometry.config import DepthConfig
from dmtrack.odometry.depthmap import DepthMap
from dmtrack.odometry.frame import build_frame

# plane n·X = d in keyframe (= world) coordinates: depth ≈ 0.9 … 1.2 over the image
PLANE_N = np.array([0.1, -0.2, -1.0]) / np.linalg.norm([0.1, -0.2, -1.0])
PLANE_D = -1.0 / np.linalg.norm([0.1, -0.2, -1.0])


def _camera(w: int, h: int) -> PinholeCamera:
    f = 0.86 * w
    return PinholeCamera(f, f, (w - 1) / 2.0, (h - 1) / 2.0, w, h)


@functools.cache
def _texture(seed: int, size: int = 512) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.standard_normal((size, size)).astype(np.float32), (0, 0), 2.0)
    t = (t - t.mean()) / t.std()
    out = np.clip(128.0 + 50.0 * t, 0.0, 255.0).astype(np.float32)
    out.setflags(write=False)
    return out


def _pose(rvec, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, np.float64))[0]
    T[:3, 3] = t
    return T


def _motion(i: int, scale: float = 1.0) -> np.ndarray:
    """Camera-to-world pose of frame i of the test trajectory (keyframe = frame 0 = identity)."""
    return _pose((0.003 * i, -0.004 * i, 0.002 * i), (0.015 * i * scale, 0.006 * i * scale, 0.01 * i * scale))


def _render(cam: PinholeCamera, T_wc: np.ndarray, seeds: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Render the textured plane: (H, W, N) float32 feature map (0..255) and the (H, W) depth z."""
    a = np.cross(PLANE_N, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(PLANE_N, a)
    ys, xs = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float64)
    rays = np.stack([(xs - cam.cx) / cam.fx, (ys - cam.cy) / cam.fy, np.ones_like(xs)], -1)
    dirs = rays @ T_wc[:3, :3].T
    c = T_wc[:3, 3]
    lam = (PLANE_D - PLANE_N @ c) / (dirs @ PLANE_N)  # = z in the camera (rays have z = 1)
    X = c + lam[..., None] * dirs
    texel = 0.44 / cam.fx  # about two texels per pixel at depth 1
    chans = []
    for s in seeds:
        tex = _texture(s)
        tu = ((X @ a) / texel + tex.shape[1] / 2).astype(np.float32)
        tv = ((X @ b) / texel + tex.shape[0] / 2).astype(np.float32)
        chans.append(cv2.remap(tex, tu, tv, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT))
    return np.stack(chans, -1).astype(np.float32), lam


def _frame(index: int, cam: PinholeCamera, T_wc: np.ndarray, seeds: tuple[int, ...] = (1,)):
    feat, z = _render(cam, T_wc, seeds)
    img = np.clip(feat[..., 0], 0, 255).astype(np.uint8)
    return build_frame(index, float(index), img, feat, cam, n_levels=3), z


def _candidates(kf, geo, prm, cscale):
    """Keyframe pixels that pass the gradient gate and the epipolar checks: list of (x, y, epxn, epyn)."""
    lv = kf.levels[0]
    h, w = lv.max_grad.shape
    out = []
    for y in range(3, h - 3):
        for x in range(3, w - 3):
            if lv.max_grad[y, x] < 5.0:
                continue
            ok, ex, ey = epl_check_reference(lv.gx, lv.gy, x, y, geo, prm, cscale)
            if ok:
                out.append((x, y, ex, ey))
    return out


def _stereo_all(kf, fr, T_fk, cfg, cscale, fn=line_stereo_numba, ranges=None, info=1.0):
    cam = kf.camera
    geo = stereo_geometry(cam.fx, cam.fy, cam.cx, cam.cy, T_fk, 0.0)
    prm = make_params(cfg, info)
    lv = kf.levels[0]
    rows = []
    for x, y, ex, ey in _candidates(kf, geo, prm, cscale):
        lo, prior, hi = (0.0, 1.0, 20.0) if ranges is None else ranges(x, y)
        r = fn(lv.feat, fr.levels[0].feat, lv.gx, lv.gy, float(x), float(y), ex, ey, lo, prior, hi, geo, prm, cscale)
        rows.append((x, y, *r))
    return np.array(rows)


# ================================================================================== line stereo
@pytest.mark.parametrize("seeds", [(1,), (1, 2, 3)], ids=["N=1", "N=3"])
def test_line_stereo_recovers_plane_inverse_depth(seeds):
    cam = _camera(128, 96)
    kf, z0 = _frame(0, cam, np.eye(4), seeds)
    T_wc = _motion(6)
    fr, _ = _frame(6, cam, T_wc, seeds)
    res = _stereo_all(kf, fr, np.linalg.inv(T_wc), DepthConfig(), 1.0)
    ok = res[:, 2] >= 0
    # measured 0.46: on this small image many full-range (idepth 0 … 20) searches have their near end outside
    # the image, which LSD-SLAM counts as out of bounds
    assert ok.mean() > 0.4, f"only {ok.mean():.2f} of the stereo searches succeeded"
    xs, ys = res[ok, 0].astype(int), res[ok, 1].astype(int)
    truth = 1.0 / z0[ys, xs]
    err = res[ok, 3] - truth
    rel = np.abs(err) / truth
    assert np.median(rel) < 0.015, np.median(rel)
    assert np.mean(rel < 0.05) > 0.9, np.mean(rel < 0.05)
    # the variance model is not wildly over-confident: most errors within 3σ
    assert np.mean(np.abs(err) < 3.0 * np.sqrt(res[ok, 4])) > 0.8
    # the uncropped search length is the projection of idepth 0 … 20
    assert np.all(res[ok, 5] > 0)


def _grey_and_three_copies():
    """A grey keyframe/frame pair, the same pair as three identical channels, and the keyframe→frame motion."""
    cam = _camera(128, 96)
    T_wc = _motion(6)
    kf1, _ = _frame(0, cam, np.eye(4), (1,))
    fr1, _ = _frame(6, cam, T_wc, (1,))
    kf3, _ = _frame(0, cam, np.eye(4), (1, 1, 1))
    fr3, _ = _frame(6, cam, T_wc, (1, 1, 1))
    T_fk = np.linalg.inv(T_wc)
    return kf1, fr1, kf3, fr3, T_fk


def test_mean_reduction_over_identical_channels_equals_grey():
    """With the channel mean (cscale 1/N), three identical channels must behave exactly like one."""
    kf1, fr1, kf3, fr3, T_fk = _grey_and_three_copies()
    r1 = _stereo_all(kf1, fr1, T_fk, DepthConfig(), 1.0)
    r3 = _stereo_all(kf3, fr3, T_fk, DepthConfig(), 1.0 / 3.0)
    assert r1.shape == r3.shape
    code1 = np.minimum(r1[:, 2], 0)
    code3 = np.minimum(r3[:, 2], 0)
    assert np.mean(code1 == code3) > 0.995
    both = (r1[:, 2] >= 0) & (r3[:, 2] >= 0)
    np.testing.assert_allclose(r3[both, 3], r1[both, 3], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(r3[both, 4], r1[both, 4], rtol=1e-4)
    # with "sum" the SSD-type quantities triple, so the result differs (not a no-op option)
    # (the epipolar-gradient test also sums, so "sum" admits more pixels: compare the common ones)
    r3s = _stereo_all(kf3, fr3, T_fk, DepthConfig(), 1.0)
    assert len(r3s) > len(r1)
    index = {(int(x), int(y)): i for i, (x, y) in enumerate(r3s[:, :2])}
    r3s = r3s[[index[(int(x), int(y))] for x, y in r1[:, :2]]]
    both_s = (r1[:, 2] >= 0) & (r3s[:, 2] >= 0)
    assert both_s.sum() > 0.8 * (r1[:, 2] >= 0).sum()
    np.testing.assert_allclose(r3s[both_s, 2], 3.0 * r1[both_s, 2], rtol=1e-4)
    assert not np.allclose(r3s[both_s, 4], r1[both_s, 4], rtol=1e-3)


def test_information_factor_counts_channels_as_independent_observations():
    """Balanced rule: N identical channels with κ = N see the SSD of one channel and the information of N.

    Three copies of a grey frame with the channel mean (cscale 1/3) and information factor 3 must give grey's
    matches, with the photometric variance of grey at a third of the pixel noise (σ² / 3): the same stereo as
    grey with camera_pixel_noise2 = 16/3 wherever the gradient gates agree. Numba and reference agree.
    """
    kf1, fr1, kf3, fr3, T_fk = _grey_and_three_copies()
    r1 = _stereo_all(kf1, fr1, T_fk, DepthConfig(camera_pixel_noise2=16.0 / 3.0), 1.0)
    r3 = _stereo_all(kf3, fr3, T_fk, DepthConfig(), 1.0 / 3.0, info=3.0)
    r3_ref = _stereo_all(kf3, fr3, T_fk, DepthConfig(), 1.0 / 3.0, fn=line_stereo_reference, info=3.0)
    np.testing.assert_allclose(r3_ref, r3, rtol=1e-6, atol=1e-9, equal_nan=True)
    # the epipolar-gradient gate sees 3× the information: a superset of grey's candidates
    index = {(int(x), int(y)): i for i, (x, y) in enumerate(r3[:, :2])}
    assert len(r3) > len(r1) and all((int(x), int(y)) in index for x, y in r1[:, :2])
    r3 = r3[[index[(int(x), int(y))] for x, y in r1[:, :2]]]
    assert np.mean(np.minimum(r1[:, 2], 0) == np.minimum(r3[:, 2], 0)) > 0.995
    both = (r1[:, 2] >= 0) & (r3[:, 2] >= 0)
    np.testing.assert_allclose(r3[both, 3], r1[both, 3], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(r3[both, 4], r1[both, 4], rtol=1e-4)
    # and it is not a no-op: with information factor 1 the variances are larger
    r3m = _stereo_all(kf3, fr3, T_fk, DepthConfig(), 1.0 / 3.0)
    index = {(int(x), int(y)): i for i, (x, y) in enumerate(r3m[:, :2])}
    r3m = r3m[[index[(int(x), int(y))] for x, y in r1[:, :2]]]
    both = both & (r3m[:, 2] >= 0)
    assert np.all(r3m[both, 4] >= r1[both, 4]) and np.mean(r3m[both, 4] > 1.01 * r1[both, 4]) > 0.5


def test_channel_rule_reduces_to_grey_for_one_channel():
    from dmtrack.odometry.config import ChannelRule

    for cost in ("balanced", "sum", "mean"):
        for kappa, n_e in ((None, None), (0.5, 2.0), (19.0, 70.0)):
            assert ChannelRule.of(cost, 1, kappa, n_e) == ChannelRule(1.0, 1.0, 1.0)
    assert ChannelRule.of("sum", 8, 2.0, 1.5) == ChannelRule(1.0, 1.0, 8.0)
    assert ChannelRule.of("mean", 8, 2.0, 1.5) == ChannelRule(1.0 / 8, 1.0, 8.0)
    # balanced: SSD ÷ N_E; information Σg²/N_E·(κ N_E/N) = κ·mean(g²); good/bad constant N_E·40²
    assert ChannelRule.of("balanced", 8, 2.0, 1.5) == ChannelRule(1.0 / 1.5, 2.0 * 1.5 / 8, 1.5)
    assert ChannelRule.of("balanced", 8) == ChannelRule.of("mean", 8)  # unmeasured feature: the channel mean
    # the good/bad test's noise term: N_σ − N_E (balanced only; none for N = 1, "sum", "mean" or unknown N_σ)
    assert ChannelRule.of("balanced", 8, 2.0, 1.5, 41.5).noise_excess == 40.0
    assert ChannelRule.of("balanced", 1, 2.0, 1.5, 41.5).noise_excess == 0.0
    assert ChannelRule.of("sum", 8, 2.0, 1.5, 41.5).noise_excess == 0.0
    assert ChannelRule.of("mean", 8, 2.0, 1.5, 41.5).noise_excess == 0.0
    with pytest.raises(InputError):
        ChannelRule.of("max", 3)


@pytest.mark.parametrize("seeds", [(1,), (4, 5), tuple(range(4, 30))], ids=["N=1", "N=2", "N=26"])
def test_line_stereo_kernel_matches_reference(seeds):
    # N = 26 ≥ DOT_MIN_CHANNELS: the kernel forms the SSDs from per-sample dot products (with the channel-mean
    # cost, so that the grey thresholds let matches through)
    cscale = 1.0 if len(seeds) < 4 else 1.0 / len(seeds)
    cam = _camera(64, 48)
    kf, z0 = _frame(0, cam, np.eye(4), seeds)
    T_wc = _motion(5)
    fr, _ = _frame(5, cam, T_wc, seeds)
    T_fk = np.linalg.inv(T_wc)
    cfg = DepthConfig()
    for ranges in (None, lambda x, y: (0.8 / z0[y, x], 1.0 / z0[y, x], 1.2 / z0[y, x])):
        a = _stereo_all(kf, fr, T_fk, cfg, cscale, line_stereo_numba, ranges)
        b = _stereo_all(kf, fr, T_fk, cfg, cscale, line_stereo_reference, ranges)
        assert len(a) > 300
        np.testing.assert_array_equal(np.minimum(a[:, 2], 0), np.minimum(b[:, 2], 0))
        ok = a[:, 2] >= 0
        assert ok.sum() > 50
        np.testing.assert_allclose(a[ok, 2:], b[ok, 2:], rtol=1e-6, atol=1e-9)
        assert set(np.unique(np.minimum(a[:, 2], 0))) >= {-1.0, 0.0}


def test_single_channel_build_is_the_three_dimensional_build_bit_for_bit():
    """One channel runs a build of its own ((H, W) maps, the multichannel branches pruned at compile time): the
    line stereo and a whole observe pass give the bytes of the general (H, W, 1) build."""
    from dmtrack.odometry._depth_common import N_COUNTS
    from dmtrack.odometry._depth_update import _observe_rows, observe_numba

    cam = _camera(96, 64)
    kf, z0 = _frame(0, cam, np.eye(4))
    T_wc = _motion(4)
    fr, _ = _frame(4, cam, T_wc)
    T_fk = np.linalg.inv(T_wc)
    cfg = DepthConfig()

    def flat(fn):  # line_stereo_numba on (H, W) views of the same maps
        return lambda kf_, ref, gx, gy, *rest: fn(kf_[..., 0], ref[..., 0], gx[..., 0], gy[..., 0], *rest)

    for ranges in (None, lambda x, y: (0.8 / z0[y, x], 1.0 / z0[y, x], 1.2 / z0[y, x])):
        a = _stereo_all(kf, fr, T_fk, cfg, 1.0, line_stereo_numba, ranges)
        b = _stereo_all(kf, fr, T_fk, cfg, 1.0, flat(line_stereo_numba), ranges)
        assert (a[:, 2] >= 0).sum() > 100
        assert a.tobytes() == b.tobytes()

    dm = DepthMap()
    dm.initialize_random(kf, seed=2)
    dm.valid[np.random.default_rng(0).random(dm.valid.shape) < 0.3] = False  # creations too
    lv, geo, prm = kf.levels[0], stereo_geometry(cam.fx, cam.fy, cam.cx, cam.cy, T_fk, 0.2), make_params(cfg)
    good = np.random.default_rng(1).random((32, 48)) > 0.1
    two = tuple(x.copy() for x in dm.state)
    counts2 = observe_numba(two, lv.feat, lv.gx, lv.gy, lv.max_grad, fr.levels[0].feat, good, geo, prm, 1.0, 4, 1.0)
    three = tuple(x.copy() for x in dm.state)
    counts3 = np.zeros((64, N_COUNTS), np.int64)
    _observe_rows(0, 1, *three, lv.feat, lv.gx, lv.gy, lv.max_grad, fr.levels[0].feat, good, True, geo, prm, 1.0, 4,
                  1.0, counts3)  # fmt: skip
    assert lv.feat.ndim == 3 and counts2[4] > 100  # updated
    assert counts2.tobytes() == counts3.sum(axis=0).tobytes()
    for x, y in zip(two, three, strict=True):
        assert x.tobytes() == y.tobytes()


@pytest.mark.parametrize("seeds", [(1, 2, 3), tuple(range(4, 30))], ids=["N=3", "N=26"])
def test_observe_without_gradient_maps_is_bit_identical(seeds):
    """N > 1: the observe kernel given no gradient maps forms each keyframe pixel's gradients itself (the depth map
    keeps no (H, W, N) gradients): the same counters and states, byte for byte, as with the maps."""
    from dmtrack.odometry._depth_update import observe_numba

    cscale = 1.0 / len(seeds)
    cam = _camera(96, 64)
    kf, _ = _frame(0, cam, np.eye(4), seeds)
    T_wc = _motion(4)
    fr, _ = _frame(4, cam, T_wc, seeds)
    dm = DepthMap()
    dm.initialize_random(kf, seed=2)
    dm.valid[np.random.default_rng(0).random(dm.valid.shape) < 0.3] = False  # creations too
    lv = kf.levels[0]
    geo = stereo_geometry(cam.fx, cam.fy, cam.cx, cam.cy, np.linalg.inv(T_wc), 0.2)
    prm = make_params(DepthConfig())
    good = np.random.default_rng(1).random((32, 48)) > 0.1
    results = []
    for gx, gy in ((lv.gx, lv.gy), (None, None)):
        state = tuple(x.copy() for x in dm.state)
        counts = observe_numba(state, lv.feat, gx, gy, lv.max_grad, fr.levels[0].feat, good, geo, prm, cscale, 4, 1.0)
        results.append((counts, state))
    (c_maps, s_maps), (c_fly, s_fly) = results
    assert c_maps[4] > 50  # updated
    assert c_maps.tobytes() == c_fly.tobytes()
    for x, y in zip(s_maps, s_fly, strict=True):
        assert x.tobytes() == y.tobytes()


def test_multichannel_keyframe_keeps_no_gradient_maps():
    """The depth map of an N > 1 keyframe reads only max_grad: the (H, W, N) gradients are never built."""
    cam = _camera(64, 48)
    kf, _ = _frame(0, cam, np.eye(4), (1, 2, 3))
    fr, _ = _frame(5, cam, _motion(5), (1, 2, 3))
    dm = DepthMap()
    dm.initialize_random(kf, seed=1)
    dm.update(fr, np.linalg.inv(_motion(5)))
    dm.create_keyframe(fr, np.linalg.inv(_motion(5)))
    assert dm.n_valid > 0
    for frame in (kf, fr):
        assert frame.levels[0]._gx is None and frame.levels[0]._gy is None


# ================================================================================== random init
def test_random_init_is_seeded_and_feature_independent():
    cam = _camera(64, 48)
    kf, _ = _frame(0, cam, np.eye(4), (1,))
    kf3, _ = _frame(0, cam, np.eye(4), (1, 2, 3))
    a, b, c, d = DepthMap(), DepthMap(), DepthMap(), DepthMap()
    a.initialize_random(kf, seed=7)
    b.initialize_random(kf, seed=7)
    c.initialize_random(kf, seed=8)
    d.initialize_random(kf3, seed=7)
    for x, y in zip(a.state, b.state, strict=True):
        np.testing.assert_array_equal(x, y)
    mg = kf.levels[0].max_grad
    expect = np.zeros_like(a.valid)
    expect[1:-1, 1:-1] = mg[1:-1, 1:-1] > 5.0
    np.testing.assert_array_equal(a.valid, expect)
    v = a.valid
    assert v.sum() > 100
    assert np.all((a.idepth[v] >= 0.5) & (a.idepth[v] <= 1.5))
    np.testing.assert_array_equal(a.idepth_smoothed[v], a.idepth[v])
    assert np.all(a.idepth_var[v] == np.float32(0.125)) and np.all(a.idepth_var_smoothed[v] == np.float32(0.125))
    assert np.all(a.validity_counter[v] == 20)
    assert not np.array_equal(a.idepth[v], c.idepth[v])
    # the same seed gives the same value at every pixel whatever the feature
    both = a.valid & d.valid
    assert both.sum() > 100
    np.testing.assert_array_equal(a.idepth[both], d.idepth[both])
    # roughly uniform on [0.5, 1.5]
    assert abs(float(np.mean(a.idepth[v])) - 1.0) < 0.05


# ================================================================================== full update vs reference
def _assert_states_equal(a: DepthMap, b: DepthMap):
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_array_equal(a.blacklisted, b.blacklisted)
    np.testing.assert_array_equal(a.next_stereo_frame_min_id, b.next_stereo_frame_min_id)
    np.testing.assert_array_equal(a.validity_counter, b.validity_counter)
    v = a.valid
    for name in ("idepth", "idepth_var", "idepth_smoothed", "idepth_var_smoothed"):
        np.testing.assert_allclose(getattr(a, name)[v], getattr(b, name)[v], rtol=2e-5, atol=1e-7, err_msg=name)


def _as_reference(dm: DepthMap) -> DepthMap:
    ref = dm.copy()
    ref.use_numba = False
    return ref


@pytest.mark.parametrize("seeds", [(1,), (4, 5)], ids=["N=1", "N=2"])
def test_update_and_keyframe_pipeline_matches_reference(seeds):
    """Every update (observe, fill holes, regularize) and the keyframe creation (finalize, propagate,
    regularize(true), fill, regularize(false), scale) agree with the python references, step by step from
    the same input state. (Comparing two independently run pipelines is not meaningful over several frames:
    LSD-SLAM's parity dither ``int(eplLength·10000) % 2`` amplifies float rounding.)"""
    cam = _camera(64, 48)
    kf, _ = _frame(0, cam, np.eye(4), seeds)
    dm = DepthMap()
    dm.initialize_random(kf, seed=3)
    rng = np.random.default_rng(0)
    dm.valid[rng.random(dm.valid.shape) < 0.4] = False  # exercise creation (and its blacklisting) too
    totals: dict[str, int] = {}
    for i in (2, 4, 6):
        T_wc = _motion(i)
        fr, _ = _frame(i, cam, T_wc, seeds)
        good = rng.random((24, 32)) > 0.1
        ref = _as_reference(dm)
        c_fast = dm.update(fr, np.linalg.inv(T_wc), good, initial_tracked_residual=0.3)
        c_ref = ref.update(fr, np.linalg.inv(T_wc), good, initial_tracked_residual=0.3)
        assert c_fast == c_ref
        assert c_fast["updated"] > 100
        totals = {k: totals.get(k, 0) + v for k, v in c_fast.items()}
        _assert_states_equal(dm, ref)
    print(totals)
    for key in ("created", "blacklisted", "inconsistent", "skip_not_good", "skip_scheduled"):
        assert totals[key] > 0, key
    new_kf, _ = _frame(8, cam, _motion(8), seeds)
    good = rng.random((24, 32)) > 0.05
    ref = _as_reference(dm)
    child = dm.create_keyframe(new_kf, np.linalg.inv(_motion(8)), good)
    ref_child = ref.create_keyframe(new_kf, np.linalg.inv(_motion(8)), good)
    _assert_states_equal(dm, ref)  # the finalised old map
    _assert_states_equal(child, ref_child)
    assert child.last_counts == ref_child.last_counts
    assert child.scale_from_parent == pytest.approx(ref_child.scale_from_parent, rel=1e-6)
    assert child.n_valid > 0.3 * child.valid.size


def test_parallel_observe_is_identical():
    cam = _camera(64, 48)
    kf, _ = _frame(0, cam, np.eye(4))
    fr, _ = _frame(5, cam, _motion(5))
    maps = []
    for par in (False, True):
        dm = DepthMap(parallel=par)
        dm.initialize_random(kf, seed=1)
        dm.update(fr, np.linalg.inv(_motion(5)))
        maps.append(dm)
    for x, y in zip(maps[0].state, maps[1].state, strict=True):
        np.testing.assert_array_equal(x, y)


def test_parallel_update_and_keyframe_are_bit_identical():
    """A few updates and a keyframe switch: the parallel depth map (observe, fill, regularize) equals serial."""
    cam = _camera(96, 64)
    kf, _ = _frame(0, cam, np.eye(4))
    frames = [_frame(i, cam, _motion(i))[0] for i in range(1, 5)]
    maps = []
    for par in (False, True):
        dm = DepthMap(parallel=par)
        dm.initialize_random(kf, seed=3)
        for i, fr in enumerate(frames, start=1):
            dm.update(fr, np.linalg.inv(_motion(i)))
        child = dm.create_keyframe(frames[-1], np.linalg.inv(_motion(4)))
        maps.append((dm, child))
    (a, ca), (b, cb) = maps
    assert a.n_valid > 0 and ca.n_valid > 0
    for x, y in zip(a.state + ca.state, b.state + cb.state, strict=True):
        assert x.tobytes() == y.tobytes()
    assert ca.scale_from_parent == cb.scale_from_parent


# ================================================================================== convergence
@pytest.mark.parametrize("seeds", [(1,), (1, 2, 3)], ids=["N=1", "N=3"])
def test_updates_converge_to_true_inverse_depth(seeds):
    """Random init + 8 frames of known motion: most semi-dense pixels end near the true inverse depth."""
    cam = _camera(128, 96)
    kf, z0 = _frame(0, cam, np.eye(4), seeds)
    dm = DepthMap()
    dm.initialize_random(kf, seed=0)
    init = dm.idepth.copy()
    for i in range(1, 9):
        T_wc = _motion(i)
        fr, _ = _frame(i, cam, T_wc, seeds)
        dm.update(fr, np.linalg.inv(T_wc))
    assert dm.n_updates == 8
    v = dm.valid
    truth = 1.0 / z0[v]
    est = dm.idepth_smoothed[v].astype(np.float64)
    scale = float(np.median(truth / est))  # the poses are metric, so this should be ≈ 1
    rel = np.abs(est * scale - truth) / truth
    # pixels whose raw idepth was set by stereo at least once (the others were never observable: image
    # border, search segment out of the image, epipolar line along an edge)
    observed = (dm.idepth != init)[v]
    frac10 = float(np.mean(rel < 0.10))
    med = float(np.median(rel))
    print(
        f"\n{len(seeds)} channel(s): {v.sum()} valid, scale {scale:.4f}, median rel. error {med:.4f}, "
        f"within 10%: {frac10:.3f}; observed {observed.sum()}: median {np.median(rel[observed]):.4f}, "
        f"within 10%: {np.mean(rel[observed] < 0.1):.3f}"
    )
    assert v.sum() > 0.5 * v.size
    assert abs(scale - 1.0) < 0.02
    assert med < 0.01
    assert frac10 > 0.75
    assert observed.mean() > 0.5
    assert np.median(rel[observed]) < 0.005
    assert np.mean(rel[observed] < 0.1) > 0.97


# ================================================================================== regularize
def _random_state(h: int, w: int, seed: int, density: float = 0.7, max_validity: int = 40):
    """A plausible state: two depth layers, random validity / variances."""
    rng = np.random.default_rng(seed)
    st = empty_state((h, w))
    valid, bl, nx, val, d, v, ds, vs = st
    valid[:] = rng.random((h, w)) < density
    layer = (np.arange(w)[None, :] + 3 * np.sin(np.arange(h)[:, None] / 4.0)) > w / 2
    d[:] = np.where(layer, 0.5, 1.2) + 0.05 * rng.standard_normal((h, w))
    v[:] = rng.uniform(0.001, 0.05, (h, w))
    val[:] = rng.integers(0, max_validity, (h, w))
    bl[:] = rng.integers(-3, 1, (h, w))
    ds[:] = d
    vs[:] = v
    return st


def _copy(st):
    return tuple(a.copy() for a in st)


@pytest.mark.parametrize("remove_occlusions", [False, True])
def test_regularize_kernel_matches_reference(remove_occlusions):
    st = _random_state(48, 64, 5, density=0.5, max_validity=10)
    a, b = _copy(st), _copy(st)
    regularize_numba(a, remove_occlusions, 24.0, 0.075**2)
    regularize_reference(b, remove_occlusions, 24.0, 0.075**2)
    for i in (0, 1, 2, 3, 4, 5):
        np.testing.assert_array_equal(a[i], b[i])
    v = a[0]
    assert 0.2 * v.size < v.sum() < np.count_nonzero(st[0])  # some dropped, many kept
    np.testing.assert_allclose(a[6][v], b[6][v], rtol=1e-5)
    np.testing.assert_allclose(a[7][v], b[7][v], rtol=1e-5)


def _regularize_float32_passes(st, remove_occlusions, validity_th, reg_dist_var):
    """LSD-SLAM's regularisation as 25 float32 passes, one per offset (dy outer, dx inner), in numpy: the
    arithmetic and order of additions the kernel must keep, whatever its loop structure."""
    valid, blacklisted, _nx, validity, idepth, var, idepth_s, var_s = st
    h, w = valid.shape
    vr = valid.copy()
    one, zero, fac = np.float32(1.0), np.float32(0.0), np.float32(1.0)
    acc = {k: np.zeros((h - 4, w - 4), np.float32) for k in ("v", "s", "i", "occ", "ok")}
    d0, v0 = idepth[2:-2, 2:-2], var[2:-2, 2:-2]
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            sl = (slice(2 + dy, h - 2 + dy), slice(2 + dx, w - 2 + dx))
            c = np.float32((dx * dx + dy * dy) * reg_dist_var)
            di, vi = idepth[sl], var[sl]
            diff = di - d0
            incons = fac * diff * diff > vi + v0
            use = vr[sl] & ~incons
            with np.errstate(divide="ignore"):
                iv = one / (vi + c)
            acc["v"] += np.where(use, validity[sl], zero)
            acc["s"] += np.where(use, di * iv, zero)
            acc["i"] += np.where(use, iv, zero)
            acc["occ"] += np.where(vr[sl] & incons & (di > d0), one, zero)
            acc["ok"] += np.where(use, one, zero)
    target = vr[2:-2, 2:-2]
    drop = target & (acc["v"] < np.float32(validity_th))
    occl = target & ~drop & (acc["occ"] > acc["ok"]) if remove_occlusions else np.zeros_like(target)
    keep = target & ~drop & ~occl
    si = acc["i"].astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        m = acc["s"].astype(np.float64) / si
        m = np.where(m < 0, np.minimum(m, -1e-10), np.maximum(m, 1e-10))
        inv = 1.0 / si
    inner = (slice(2, h - 2), slice(2, w - 2))
    idepth_s[inner][keep] = m[keep]
    var_s[inner][keep] = inv[keep]
    blacklisted[inner][drop] -= 1
    valid[inner][drop | occl] = False


@pytest.mark.parametrize("remove_occlusions", [False, True])
def test_regularize_kernel_keeps_the_float32_order_of_the_25_passes(remove_occlusions):
    """Bit for bit: the kernel's fused passes add in LSD-SLAM's (dy, dx) order, in float32."""
    for seed in (5, 6):
        st = _random_state(48, 64, seed, density=0.5, max_validity=10)
        st[0][20:23, :] = False  # rows without a valid pixel
        a, b = _copy(st), _copy(st)
        regularize_numba(a, remove_occlusions, 24.0, 0.075**2)
        _regularize_float32_passes(b, remove_occlusions, 24.0, 0.075**2)
        assert (a[0] != st[0]).any() and (a[6] != st[6]).any()
        for x, y in zip(a, b, strict=True):
            assert x.tobytes() == y.tobytes()


@pytest.mark.parametrize("remove_occlusions", [False, True])
def test_parallel_regularize_and_fill_holes_are_identical(remove_occlusions):
    """The row-parallel (prange) regularize / fill-holes kernels give the serial kernels' bits."""
    import numba

    st = _random_state(48, 64, 5, density=0.5, max_validity=10)
    mg = np.random.default_rng(1).uniform(0, 12, (48, 64)).astype(np.float32)
    prm = make_params(DepthConfig())
    a, b = _copy(st), _copy(st)
    regularize_numba(a, remove_occlusions, 24.0, 0.075**2, parallel=False)
    regularize_numba(b, remove_occlusions, 24.0, 0.075**2, parallel=True)
    fill_holes_numba(a, mg, prm, parallel=False)
    fill_holes_numba(b, mg, prm, parallel=True)
    prev = numba.get_num_threads()
    c = _copy(st)
    try:
        numba.set_num_threads(1)  # one thread through the parallel build
        regularize_numba(c, remove_occlusions, 24.0, 0.075**2, parallel=True)
        fill_holes_numba(c, mg, prm, parallel=True)
    finally:
        numba.set_num_threads(prev)
    assert (a[0] != st[0]).any()  # the passes changed something
    for x, y, z in zip(a, b, c, strict=True):
        assert x.tobytes() == y.tobytes() == z.tobytes()


def test_regularize_semantics():
    h, w = 20, 20
    st = empty_state((h, w))
    valid, bl, _nx, val, d, v, ds, vs = st
    # a 7×7 block of constant inverse depth 0.8, var 0.01, validity 5
    valid[5:12, 5:12] = True
    d[5:12, 5:12] = 0.8
    v[5:12, 5:12] = 0.01
    val[5:12, 5:12] = 5
    # an isolated hypothesis with validity 20 (< 24)
    valid[16, 16] = True
    d[16, 16] = 0.5
    v[16, 16] = 0.01
    val[16, 16] = 20
    regularize_numba(st, False, 24.0, 0.075**2)
    assert not valid[16, 16] and bl[16, 16] == -1
    assert valid[8, 8] and ds[8, 8] == pytest.approx(0.8, rel=1e-6)
    expect = 1.0 / sum(1.0 / (0.01 + (dx * dx + dy * dy) * 0.075**2) for dx in range(-2, 3) for dy in range(-2, 3))
    assert vs[8, 8] == pytest.approx(expect, rel=1e-5)
    # a corner pixel of the block sees 9 valid neighbours (45 ≥ 24): kept
    assert valid[5, 5]

    # occlusion: a far pixel surrounded by (inconsistent) closer ones
    st = empty_state((h, w))
    valid, bl, _nx, val, d, v, ds, vs = st
    valid[5:12, 5:12] = True
    d[5:12, 5:12] = 1.0
    v[5:12, 5:12] = 0.001
    val[5:12, 5:12] = 10
    d[8, 8] = 0.3
    val[8, 8] = 30
    st2 = _copy(st)
    regularize_numba(st, True, 24.0, 0.075**2)
    assert not st[0][8, 8] and st[1][8, 8] == 0  # occluded: invalid, not blacklisted
    regularize_numba(st2, False, 24.0, 0.075**2)
    assert st2[0][8, 8] and st2[6][8, 8] == pytest.approx(0.3, rel=1e-6)  # kept, not smeared


# ================================================================================== fill holes
def test_fill_holes_kernel_matches_reference():
    st = _random_state(48, 64, 9)
    mg = np.random.default_rng(1).uniform(0, 12, (48, 64)).astype(np.float32)
    prm = make_params(DepthConfig())
    a, b = _copy(st), _copy(st)
    fill_holes_numba(a, mg, prm)
    fill_holes_reference(b, mg, prm)
    for i in range(6):
        np.testing.assert_array_equal(a[i], b[i])
    filled = a[0] & ~st[0]
    assert filled.sum() > 50
    np.testing.assert_allclose(a[4][filled], b[4][filled], rtol=1e-6)
    assert np.all(a[3][filled] == 0) and np.all(a[5][filled] == np.float32(0.125))


def test_fill_holes_reads_a_copy():
    """Holes are filled from the hypotheses that existed before the pass (no cascading)."""
    h, w = 16, 24
    st = empty_state((h, w))
    valid, bl, _nx, val, d, v, _ds, _vs = st
    valid[4:11, 3:9] = True  # block, columns 3..8, idepth varying per column
    d[4:11, 3:9] = np.linspace(0.5, 1.0, 6)[None, :]
    v[4:11, 3:9] = 0.01
    val[4:11, 3:9] = 5
    bl[7, 11] = -2  # blacklisted: needs a sum > 100
    mg = np.full((h, w), 10.0, np.float32)
    mg[4, 9] = 1.0  # too little gradient: never filled
    fill_holes_numba(st, mg, make_params(DepthConfig()))
    # (7, 9): window columns 7..10 → 2 valid columns × 5 rows × 5 = 50 > 30: filled with the
    # inverse-variance mean of the original hypotheses only (not of (7, 9)'s filled neighbours)
    assert valid[7, 9] and val[7, 9] == 0 and v[7, 9] == np.float32(0.125)
    assert d[7, 9] == pytest.approx(np.mean(np.linspace(0.5, 1.0, 6)[4:6]), rel=1e-6)
    # (7, 10): one valid column (25 ≤ 30): a cascading fill would have used (7, 9); must stay empty
    assert not valid[7, 10]
    assert not valid[4, 9]
    assert not valid[7, 11]  # blacklisted, sum 0
    st2 = empty_state((h, w))
    st2[0][2:13, 5:12] = True
    st2[3][2:13, 5:12] = 5
    st2[4][2:13, 5:12] = 0.7
    st2[5][2:13, 5:12] = 0.01
    st2[0][7, 8] = False
    st2[1][7, 8] = -5
    fill_holes_numba(st2, mg, make_params(DepthConfig()))
    assert st2[0][7, 8] and st2[1][7, 8] == 0  # 5×5 sum 120 > 100: filled and un-blacklisted


# ================================================================================== propagation
def test_propagation_of_known_depth_to_new_keyframe():
    cam = _camera(128, 96)
    kf, z0 = _frame(0, cam, np.eye(4))
    T_wc1 = _motion(4)
    new_kf, z1 = _frame(4, cam, T_wc1)
    dm = DepthMap()
    dm.initialize_from_depth(kf, 1.0 / z0, var=1e-4)
    good = np.ones((48, 64), bool)
    child = dm.create_keyframe(new_kf, np.linalg.inv(T_wc1), good)
    rho = child.scale_from_parent
    v = child.valid
    assert v.mean() > 0.8
    truth = 1.0 / z1[v]
    rel_raw = np.abs(child.idepth[v] / rho - truth) / truth
    rel_smooth = np.abs(child.idepth_smoothed[v] / rho - truth) / truth
    assert np.median(rel_raw) < 0.003 and np.mean(rel_raw < 0.01) > 0.97
    assert np.median(rel_smooth) < 0.003
    assert child.last_counts["attempts"] == dm.n_valid
    assert child.last_counts["created"] > 0.8 * v.sum()
    # mean inverse depth normalised to 1
    assert float(np.mean(child.idepth_smoothed[v], dtype=np.float64)) == pytest.approx(1.0, rel=1e-5)
    assert rho == pytest.approx(1.0 / np.mean(truth), rel=0.01)
    np.testing.assert_allclose(child.T_new_old, np.linalg.inv(T_wc1))
    assert child.n_updates == 0 and child.keyframe is new_kf


def _two_pixel_state(h, w, pixels):
    st = empty_state((h, w))
    for (x, y), d, var, val in pixels:
        st[0][y, x] = True
        st[4][y, x] = d
        st[6][y, x] = d
        st[5][y, x] = var
        st[3][y, x] = val
    return st


def test_propagation_variance_and_collisions():
    cam = _camera(64, 48)
    fx, fy, cx, cy = cam.fx, cam.fy, cam.cx, cam.cy
    prm = make_params(DepthConfig())
    mg = np.full((48, 64), 10.0, np.float32)
    feat = np.zeros((48, 64, 1), np.float32)
    # single pixel, move 0.25 forward: z 2 → 1.75, idepth 0.5 → 1/1.75, var × (d_new/d_old)^4
    st = _two_pixel_state(48, 64, [((20, 30), 0.5, 0.01, 17.0)])
    T = np.eye(4)
    T[2, 3] = -0.25
    new, counts = propagate_numba(st, mg, None, feat, feat, T, fx, fy, cx, cy, prm, 1.0)
    u = (20 - cx) * 2.0 / 1.75 + cx
    v = (30 - cy) * 2.0 / 1.75 + cy
    ny, nx = int(v + 0.5), int(u + 0.5)
    assert new[0].sum() == 1 and new[0][ny, nx]
    assert new[4][ny, nx] == pytest.approx(1 / 1.75, rel=1e-6)
    assert new[5][ny, nx] == pytest.approx(0.01 * (2.0 / 1.75) ** 4, rel=1e-6)
    assert new[3][ny, nx] == 17.0 and new[6][ny, nx] == -1.0
    assert counts[PC_CREATED] == 1
    # the flags are indexed by the OLD pixel at level 1
    good = np.ones((24, 32), bool)
    good[15, 10] = False
    new, counts = propagate_numba(st, mg, good, feat, feat, T, fx, fy, cx, cy, prm, 1.0)
    assert new[0].sum() == 0 and counts[PC_DROPPED_GOOD] == 1

    # collisions under a sideways move: u_new = u + fx·tx·idepth
    def side(tx, pixels):
        T = np.eye(4)
        T[0, 3] = tx
        st = _two_pixel_state(48, 64, pixels)
        return propagate_numba(st, mg, None, feat, feat, T, fx, fy, cx, cy, prm, 1.0)

    y = 20
    # consistent pair (same idepth, pure x shift keeps both) → separate pixels, no collision
    new, counts = side(2.0 / fx, [((20, y), 1.0, 0.01, 5.0), ((21, y), 1.0, 0.02, 5.0)])
    assert counts[PC_CREATED] == 2
    # inconsistent, the second (in raster order) is farther: dropped
    new, counts = side(2.0 / fx, [((20, y), 1.0, 0.001, 5.0), ((21, y), 0.5, 0.001, 6.0)])
    assert new[0].sum() == 1 and new[0][y, 22] and new[4][y, 22] == pytest.approx(1.0)
    assert counts[PC_OCCLUDED] == 1
    # inconsistent, the second is closer: replaces the first
    new, counts = side(-2.0 / fx, [((20, y), 0.5, 0.001, 5.0), ((21, y), 1.0, 0.001, 6.0)])
    assert new[0].sum() == 1 and new[0][y, 19] and new[4][y, 19] == pytest.approx(1.0)
    assert new[3][y, 19] == 6.0
    # consistent collision: fused (inverse-variance), validity summed
    new, counts = side(2.0 / fx, [((20, y), 1.0, 0.5, 200.0), ((21, y), 0.5, 0.5, 100.0)])
    assert counts[PC_MERGED] == 1 and new[0].sum() == 1
    assert new[4][y, 22] == pytest.approx(0.75, rel=1e-6)  # equal variances: plain mean
    assert new[5][y, 22] == pytest.approx(0.25, rel=1e-6)
    assert new[3][y, 22] == 255.0  # 300 capped at VALIDITY_COUNTER_MAX + MAX_VARIABLE


@pytest.mark.parametrize("with_flags", [True, False])
def test_propagation_kernel_matches_reference(with_flags):
    cam = _camera(64, 48)
    kf, z0 = _frame(0, cam, np.eye(4), (4, 5))
    T_wc = _motion(5)
    new_kf, _ = _frame(5, cam, T_wc, (4, 5))
    rng = np.random.default_rng(2)
    st = empty_state((48, 64))
    st[0][:] = rng.random((48, 64)) < 0.8
    st[4][:] = (1.0 / z0) * (1.0 + 0.02 * rng.standard_normal((48, 64)))
    st[6][:] = st[4] * (1.0 + 0.01 * rng.standard_normal((48, 64)))
    st[5][:] = rng.uniform(1e-5, 1e-3, (48, 64))
    st[3][:] = rng.integers(0, 100, (48, 64))
    good = rng.random((24, 32)) > 0.2 if with_flags else None
    prm = make_params(DepthConfig())
    new_feat = new_kf.levels[0].feat.copy()
    new_feat[10:30, 20:40] += 60.0  # a "lighting change": fails the colour test where there are no flags
    args = (
        new_kf.levels[0].max_grad,
        good,
        kf.levels[0].feat,
        new_feat,
        np.linalg.inv(T_wc),
        cam.fx,
        cam.fy,
        cam.cx,
        cam.cy,
        prm,
        0.5,
    )
    a, ca = propagate_numba(st, *args)
    b, cb = propagate_reference(st, *args)
    np.testing.assert_array_equal(ca, cb)
    assert ca[PC_CREATED] > 500 and ca[PC_MERGED] > 0 and ca[PC_DROPPED_GOOD] > 0
    for i in range(4):
        np.testing.assert_array_equal(a[i], b[i])
    np.testing.assert_allclose(a[4], b[4], rtol=1e-6)
    np.testing.assert_allclose(a[5], b[5], rtol=1e-6)


# ================================================================================== outputs, errors
def test_tracking_depth_and_mean_idepth():
    cam = _camera(64, 48)
    kf, _ = _frame(0, cam, np.eye(4))
    dm = DepthMap()
    dm.initialize_random(kf, seed=0)
    dm.idepth_smoothed[10, 10] = -0.2
    dm.valid[10, 10] = True
    d, v = dm.tracking_depth()
    assert d.dtype == np.float32 and v.dtype == np.float32
    use = dm.valid & (dm.idepth_smoothed >= -0.05)
    assert not use[10, 10]
    np.testing.assert_array_equal(d[use], dm.idepth_smoothed[use])
    np.testing.assert_array_equal(v[use], dm.idepth_var_smoothed[use])
    assert np.all(d[~use] == -1) and np.all(v[~use] == -1)
    assert dm.mean_idepth == pytest.approx(float(np.mean(dm.idepth_smoothed[use], dtype=np.float64)))


def test_scale_normalisation_scales_variances_by_rho_squared():
    cam = _camera(64, 48)
    kf, z0 = _frame(0, cam, np.eye(4))
    T_wc = _motion(3)
    new_kf, _ = _frame(3, cam, T_wc)
    dm = DepthMap()
    dm.initialize_from_depth(kf, 0.25 / z0, var=1e-4)  # mean inverse depth ≈ 0.25
    ref = dm.copy()
    child = dm.create_keyframe(new_kf, np.linalg.inv(T_wc), None)
    # redo the steps without the normalisation
    ref.finalize()
    cam0 = kf.camera
    new_state, _ = propagate_numba(
        ref.state,
        new_kf.levels[0].max_grad,
        None,
        kf.levels[0].feat,
        new_kf.levels[0].feat,
        np.linalg.inv(T_wc),
        cam0.fx,
        cam0.fy,
        cam0.cx,
        cam0.cy,
        make_params(DepthConfig()),
        1.0,
    )
    raw = DepthMap()
    raw.keyframe = new_kf
    raw._set_state(new_state)
    raw.regularize(True)
    raw.fill_holes()
    raw.regularize(False)
    v = raw.valid
    np.testing.assert_array_equal(child.valid, v)
    rho = child.scale_from_parent
    assert rho == pytest.approx(v.sum() / np.sum(raw.idepth_smoothed[v], dtype=np.float64), rel=1e-9)
    assert rho == pytest.approx(4.0, rel=0.15)
    np.testing.assert_allclose(child.idepth_smoothed[v], raw.idepth_smoothed[v] * rho, rtol=1e-6)
    np.testing.assert_allclose(child.idepth[v], raw.idepth[v] * rho, rtol=1e-6)
    np.testing.assert_allclose(child.idepth_var[v], raw.idepth_var[v] * rho**2, rtol=1e-6)
    np.testing.assert_allclose(child.idepth_var_smoothed[v], raw.idepth_var_smoothed[v] * rho**2, rtol=1e-6)
    assert child.mean_idepth == pytest.approx(1.0, rel=1e-5)


def test_input_errors():
    cam = _camera(64, 48)
    kf, _ = _frame(0, cam, np.eye(4))
    dm = DepthMap()
    with pytest.raises(RuntimeError):
        dm.update(kf, np.eye(4))
    dm.initialize_random(kf, seed=0)
    other, _ = _frame(1, _camera(32, 32), np.eye(4))
    with pytest.raises(InputError):
        dm.update(other, np.eye(4))
    three, _ = _frame(1, cam, np.eye(4), (1, 2, 3))
    with pytest.raises(InputError):
        dm.update(three, np.eye(4))
    with pytest.raises(InputError):
        dm.update(kf, np.eye(4), np.ones((48, 64), bool))
    with pytest.raises(InputError):
        DepthMap(channel_cost="max")


# ================================================================================== LSD-SLAM oracle
GOLDEN = Path(__file__).parent / "data" / "lsd_stereo_golden.json"


def test_line_stereo_matches_lsd_slam_release_build(sample_dir):
    """500 line-stereo searches recorded from LSD-SLAM itself (tools/lsd_oracle, release build) on the shipped
    7-Scenes frames 0 (keyframe) and 31, each pixel searched around its hypothesis as ``observeDepthUpdate``
    does: successes (unpadded, uncropped segments, whose step count is not decided by rounding), ambiguous
    (−2), not found (−3) and out-of-bounds (−1) results, the last mostly at the image border where a near
    end outside the image makes the pixel out of bounds. dmtrack must give the same outcome, and the same
    inverse depth and variance where both succeed. (About 3 % of the failures sit on a rounding coin flip —
    whether a padded 3-px segment ends with its 6th step — and may differ.)"""
    g = json.loads(GOLDEN.read_text())
    cam = PinholeCamera(585.0, 585.0, 320.0, 240.0, 640, 480)

    def load(i):
        img = cv2.imread(str(sample_dir / f"frame-{i:06d}.color.jpg"), cv2.IMREAD_GRAYSCALE)
        return build_frame(i, float(i), img, img.astype(np.float32)[..., None], cam, n_levels=1)

    kf, fr = load(g["keyframe"]), load(g["frame"])
    T_kf = np.eye(4)
    T_kf[:3, :] = np.array(g["T_frame_to_keyframe"])
    geo = stereo_geometry(585.0, 585.0, 320.0, 240.0, np.linalg.inv(T_kf), g["initial_tracked_residual"])
    prm = make_params(DepthConfig())
    lv = kf.levels[0]
    same = close = both = 0
    codes = {}
    for p in g["pixels"]:
        x, y = p["x"], p["y"]
        ok, ex, ey = epl_check_reference(lv.gx, lv.gy, x, y, geo, prm, 1.0)
        assert ok, (x, y)
        sv = float(np.sqrt(np.float32(p["var_s"])))
        lo = max(0.0, float(np.float32(p["idepth_s"]) - 2 * sv))
        hi = min(20.0, float(np.float32(p["idepth_s"]) + 2 * sv))
        err, idepth, var, _ = line_stereo_numba(
            lv.feat, fr.levels[0].feat, lv.gx, lv.gy, float(x), float(y), ex, ey, lo, p["idepth_s"], hi, geo, prm, 1.0
        )
        lsd_code = p["err"] if p["err"] < 0 else 0.0
        code = err if err < 0 else 0.0
        same += lsd_code == code
        codes[lsd_code] = codes.get(lsd_code, 0) + 1
        if p["err"] >= 0 and err >= 0:
            both += 1
            close += abs(idepth - p["idepth"]) <= 1e-3 * abs(p["idepth"]) and abs(var - p["var"]) <= 1e-3 * p["var"]
    assert codes == {0.0: 150, -1.0: 150, -2.0: 100, -3.0: 100}
    assert same >= 0.95 * len(g["pixels"]), same  # measured 484 / 500
    assert both >= 0.97 * codes[0.0] and close == both, (both, close)


def test_near_end_outside_the_image_is_out_of_bounds():
    """LSD-SLAM (release build): when the near end of the search segment lies beyond the 7-px border, its
    move-back-and-re-test cannot pass, so the search is out of bounds (−1) — even where a moved segment would
    still have been long enough. Same search away from the border succeeds."""
    cam = _camera(128, 96)
    kf, _ = _frame(0, cam, np.eye(4))
    T_wc = _pose((0.0, 0.0, 0.0), (-0.04, 0.0, 0.0))  # camera moves left: matches move right in the frame
    fr, _ = _frame(1, cam, T_wc)
    geo = stereo_geometry(cam.fx, cam.fy, cam.cx, cam.cy, np.linalg.inv(T_wc), 0.0)
    prm = make_params(DepthConfig())
    lv = kf.levels[0]
    results = {}
    for x, y, ex, ey in _candidates(kf, geo, prm, 1.0):
        args = (lv.feat, fr.levels[0].feat, lv.gx, lv.gy, float(x), float(y), ex, ey, 0.0, 1.0, 20.0, geo, prm, 1.0)
        results[(x, y)] = line_stereo_numba(*args)[0]
        if x > cam.width - 7 - 29:
            assert line_stereo_reference(*args)[0] == -1.0
    # the segment is cropped to 30 px from the far end (idepth 0 = the pixel itself, pure translation): from
    # x ≥ w − 7 − 31 (30 px + the one-step extension) its near end leaves the image
    near_border = [e for (x, _), e in results.items() if x > cam.width - 7 - 29]
    inside = [e for (x, y), e in results.items() if 10 < x < cam.width - 7 - 34 and 10 < y < cam.height - 10]
    assert near_border and all(e == -1.0 for e in near_border)
    assert inside and np.mean([e != -1.0 for e in inside]) > 0.95


def test_update_variance_modes():
    """``depth.update_variance``: a map 10 % off in inverse depth whose smoothed variance is over-confident
    (σ_smoothed = 0.01, raw σ = 0.22). "smoothed" (LSD-SLAM) searches only ±2σ_smoothed (padded to 3 px)
    around the wrong value: part of the pixels match inside that window, pass the consistency test and are
    fused, reinforcing the error; "raw-search" searches ±2σ_raw, finds the true match more often and flags it
    inconsistent instead (fewer reinforcing updates); "raw" also tests with σ_raw and moves the estimates to
    the truth. Kernel and reference agree in every mode."""
    cam = _camera(64, 48)
    kf, z0 = _frame(0, cam, np.eye(4))
    T_wc = _motion(6)
    fr, _ = _frame(6, cam, T_wc)
    truth = (1.0 / z0).astype(np.float32)
    out = {}
    for mode in ("smoothed", "raw-search", "raw"):
        dm = DepthMap(DepthConfig(update_variance=mode))
        dm.initialize_from_depth(kf, 1.1 * truth, var=0.05, validity=20.0)
        dm.idepth_var_smoothed[dm.valid] = 1e-4
        ref = _as_reference(dm)
        counts = dm.observe(fr, np.linalg.inv(T_wc))
        assert counts == ref.observe(fr, np.linalg.inv(T_wc))
        _assert_states_equal(dm, ref)
        updated = dm.valid & (dm.idepth_var < 0.05)
        rel = np.abs(dm.idepth[updated] / truth[updated] - 1.0)
        out[mode] = (counts, int(updated.sum()), float(np.median(rel)))
    (c_s, n_s, e_s), (c_rs, n_rs, e_rs), (c_r, n_r, e_r) = out["smoothed"], out["raw-search"], out["raw"]
    assert c_s["inconsistent"] > 0.2 * c_s["update_attempted"] and c_rs["inconsistent"] >= c_s["inconsistent"]
    assert n_rs < 0.9 * n_s and e_rs <= e_s  # measured 317 vs 414 fused, median error 2.9 % vs 3.3 %
    assert c_r["inconsistent"] == 0 and n_r > 2 * n_s and e_r < 0.02  # measured 933 fused, error 1.3 %
    with pytest.raises(InputError, match="update_variance"):
        DepthConfig(update_variance="median")


def test_tracking_select_is_the_numpy_expression_bit_for_bit():
    """The one-pass kernel behind tracking_snapshot gives the bytes of the numpy mask / where / mean it replaced,
    including values at the float32-rounded threshold (NumPy 2 compares float32 with a Python float in float32)."""
    from dmtrack.odometry._depth_common import tracking_select

    rng = np.random.default_rng(5)
    valid = rng.random((48, 64)) < 0.4
    ids = (rng.random((48, 64)) * 2 - 0.3).astype(np.float32)
    ids[::7, ::5] = np.float32(-0.05)  # exactly the float32 threshold: selected
    ids[1::9, ::3] = np.nextafter(np.float32(-0.05), np.float32(-1))  # just below: not selected
    ids[2, :5] = np.nan
    var = rng.random((48, 64)).astype(np.float32)
    d, v, mean = tracking_select(valid, ids, var, -0.05)
    m = valid & (ids >= -0.05)
    assert d.tobytes() == np.where(m, ids, np.float32(-1.0)).astype(np.float32).tobytes()
    assert v.tobytes() == np.where(m, var, np.float32(-1.0)).astype(np.float32).tobytes()
    assert mean == float(np.mean(ids[m], dtype=np.float64))
    assert (ids == np.float32(-0.05))[m].sum() > 10  # the tie case was exercised
    _, _, none = tracking_select(np.zeros_like(valid), ids, var, -0.05)
    assert np.isnan(none)
