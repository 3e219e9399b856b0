"""Frame pyramid and gradients (dmtrack.odometry.frame) against plain numpy definitions."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from dmtrack.errors import InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.odometry.frame import (
    build_frame,
    downsample,
    downsample_numpy,
    gradients,
    gradients_numpy,
    max_gradient,
    pack,
    pack_numpy,
)


def _random_feat(h: int, w: int, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.random((h, w, n)) * 255).astype(np.float32)


@pytest.mark.parametrize("n", [1, 3, 8])
def test_gradients_numba_equals_numpy(n: int) -> None:
    f = _random_feat(24, 40, n, seed=n)
    (gx, gy, mg), (gx_r, gy_r, mg_r) = gradients(f), gradients_numpy(f)
    for a, b in ((gx, gx_r), (gy, gy_r), (mg, mg_r)):
        assert a.dtype == np.float32 and b.dtype == np.float32
    np.testing.assert_array_equal(gx, gx_r)
    np.testing.assert_array_equal(gy, gy_r)
    if n == 1:
        np.testing.assert_array_equal(mg, mg_r)
    else:  # the kernel sums the N magnitudes in a vectorised order: equal up to float32 rounding
        np.testing.assert_allclose(mg, mg_r, rtol=1e-6)
        assert np.array_equal(mg == 0, mg_r == 0)


@pytest.mark.parametrize("n", [1, 3, 8, 128])
def test_max_gradient_is_that_of_gradients_bit_for_bit(n: int) -> None:
    """max_grad without the gradient arrays (what a multichannel keyframe's depth map reads) has the bytes of the
    one :func:`gradients` computes with them."""
    f = _random_feat(24, 40, n, seed=10 + n)
    f[5:9, 10:20] = 17.0  # flat patches: zero magnitudes and ties in the 3×3 maximum
    a, b = max_gradient(f), gradients(f)[2]
    assert a.dtype == np.float32 and a.shape == (24, 40)
    assert a.tobytes() == b.tobytes()
    cam = PinholeCamera(30.0, 30.0, 15.5, 7.5, 32, 16)
    level = build_frame(0, 0.0, np.zeros((16, 32), np.uint8), f[:16, :32], cam, n_levels=1).levels[0]
    assert level.max_grad.tobytes() == gradients(f[:16, :32])[2].tobytes()
    assert (level._gx is None) == (n > 1)  # N > 1: no (h, w, N) gradients were kept for it
    np.testing.assert_array_equal(level.gx, gradients(f[:16, :32])[0])  # still there on request


@pytest.mark.parametrize("n", [1, 3, 8])
def test_pack_numba_equals_numpy_and_gradients(n: int) -> None:
    """The tracker's (h, w, 3, N) layout: values, then the x- and y-gradients of :func:`gradients_numpy`."""
    f = _random_feat(24, 40, n, seed=20 + n)
    p = pack(f)
    assert p.shape == (24, 40, 3, n) and p.dtype == np.float32 and p.flags.c_contiguous
    np.testing.assert_array_equal(p, pack_numpy(f))
    gx, gy, _ = gradients_numpy(f)
    np.testing.assert_array_equal(p[:, :, 0], f)
    np.testing.assert_array_equal(p[:, :, 1], gx)
    np.testing.assert_array_equal(p[:, :, 2], gy)


@pytest.mark.parametrize("n", [1, 4])
def test_downsample_numba_equals_numpy_and_box_mean(n: int) -> None:
    f = _random_feat(32, 48, n, seed=10 + n)
    a = downsample(f)
    np.testing.assert_array_equal(a, downsample_numpy(f))
    box = f.astype(np.float64).reshape(16, 2, 24, 2, n).mean(axis=(1, 3))
    np.testing.assert_allclose(a, box, rtol=0, atol=1e-4)


@pytest.mark.parametrize("h,w", [(1, 1), (2, 2), (2, 5), (3, 3), (5, 2), (7, 9), (33, 17)])
def test_grey_kernels_equal_numpy_on_small_and_odd_sizes(h: int, w: int) -> None:
    """Grey (N = 1) has its own vectorised kernels: the same bits as the references, borders included."""
    f = _random_feat(h, w, 1, seed=h * 100 + w)
    np.testing.assert_array_equal(pack(f), pack_numpy(f))
    for a, b in zip(gradients(f), gradients_numpy(f), strict=True):
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
    if h % 2 == 0 and w % 2 == 0:
        d = downsample(f)
        assert d.tobytes() == downsample_numpy(f).tobytes() and d.shape == (h // 2, w // 2, 1)


def test_gradient_definition_against_explicit_formula() -> None:
    f = _random_feat(20, 30, 3, seed=3)
    gx, gy, mg = gradients_numpy(f)
    f64 = f.astype(np.float64)
    exp_gx = np.zeros_like(f64)
    exp_gy = np.zeros_like(f64)
    exp_gx[1:-1, 1:-1] = 0.5 * (f64[1:-1, 2:] - f64[1:-1, :-2])
    exp_gy[1:-1, 1:-1] = 0.5 * (f64[2:, 1:-1] - f64[:-2, 1:-1])
    np.testing.assert_allclose(gx, exp_gx, atol=1e-4)
    np.testing.assert_allclose(gy, exp_gy, atol=1e-4)
    # border rows/columns are exactly zero
    for g in (gx, gy):
        assert not g[0].any() and not g[-1].any() and not g[:, 0].any() and not g[:, -1].any()
    mag_mean = np.sqrt(exp_gx**2 + exp_gy**2).mean(axis=2)
    exp_mg = ndimage.maximum_filter(mag_mean, size=3, mode="constant", cval=0.0)
    exp_mg[0, :] = exp_mg[-1, :] = 0
    exp_mg[:, 0] = exp_mg[:, -1] = 0
    np.testing.assert_allclose(mg, exp_mg, atol=1e-3)


def test_linear_ramp_gradients() -> None:
    h, w = 16, 24
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    f = np.stack([3.0 * xs - 2.0 * ys, 0.5 * ys], axis=-1).astype(np.float32)
    gx, gy, mg = gradients(f)
    np.testing.assert_allclose(gx[1:-1, 1:-1, 0], 3.0)
    np.testing.assert_allclose(gy[1:-1, 1:-1, 0], -2.0)
    np.testing.assert_allclose(gx[1:-1, 1:-1, 1], 0.0)
    np.testing.assert_allclose(gy[1:-1, 1:-1, 1], 0.5)
    # channel mean of |∇F_c| = (sqrt(13) + 0.5)/2; interior pixels next to the border see zeros only beyond it
    expected = (np.sqrt(13.0) + 0.5) / 2.0
    np.testing.assert_allclose(mg[1:-1, 1:-1], expected, rtol=1e-6)


def test_build_frame_pyramid_and_cameras() -> None:
    cam = PinholeCamera(100.0, 110.0, 31.5, 23.5, 64, 48)
    feat = _random_feat(48, 64, 2, seed=7)
    image = feat[..., 0].astype(np.uint8)
    fr = build_frame(5, 0.25, image, feat, cam, n_levels=4)
    assert fr.index == 5 and fr.timestamp == 0.25 and fr.n_channels == 2
    assert fr.camera == cam and fr.width == 64 and fr.height == 48
    assert len(fr.levels) == 4
    ref = feat
    for lv, level in enumerate(fr.levels):
        assert level.feat.shape == (48 >> lv, 64 >> lv, 2)
        assert level.feat.flags["C_CONTIGUOUS"] and level.feat.dtype == np.float32
        if lv > 0:
            ref = downsample_numpy(ref)
        np.testing.assert_array_equal(level.feat, ref)
        gx, gy, mg = gradients_numpy(ref)
        np.testing.assert_array_equal(level.gx, gx)
        np.testing.assert_array_equal(level.gy, gy)
        np.testing.assert_allclose(level.max_grad, mg, rtol=1e-6)  # N = 2: vectorised magnitude sum
        c = level.camera
        assert c.fx == pytest.approx(100.0 / 2**lv) and c.fy == pytest.approx(110.0 / 2**lv)
        assert c.cx == pytest.approx((31.5 + 0.5) / 2**lv - 0.5)
        assert c.cy == pytest.approx((23.5 + 0.5) / 2**lv - 0.5)
        assert (c.width, c.height) == (64 >> lv, 48 >> lv)
        packed = level.packed
        assert packed.shape == (48 >> lv, 64 >> lv, 3, 2)
        np.testing.assert_array_equal(packed[:, :, 0], level.feat)
        np.testing.assert_array_equal(packed[:, :, 1], level.gx)
        np.testing.assert_array_equal(packed[:, :, 2], level.gy)
    # the numpy path builds the same frame
    fr2 = build_frame(5, 0.25, image, feat, cam, n_levels=4, use_numba=False)
    for a, b in zip(fr.levels, fr2.levels, strict=True):
        np.testing.assert_array_equal(a.feat, b.feat)
        np.testing.assert_allclose(a.max_grad, b.max_grad, rtol=1e-6)  # N = 2: vectorised magnitude sum


def test_build_frame_grey_2d_input() -> None:
    cam = PinholeCamera(50.0, 50.0, 15.5, 15.5, 32, 32)
    img = (np.arange(32 * 32).reshape(32, 32) % 251).astype(np.uint8)
    fr = build_frame(0, 0.0, img, img, cam, n_levels=3)
    assert fr.n_channels == 1
    np.testing.assert_array_equal(fr.levels[0].feat[..., 0], img.astype(np.float32))


def test_build_frame_rejects_bad_input() -> None:
    cam = PinholeCamera(50.0, 50.0, 15.5, 15.5, 32, 32)
    with pytest.raises(InputError, match="divisible"):
        build_frame(0, 0.0, None, np.zeros((32, 24, 1), np.float32), PinholeCamera(50, 50, 10, 10, 24, 32), 5)
    with pytest.raises(InputError, match="camera"):
        build_frame(0, 0.0, None, np.zeros((16, 32, 1), np.float32), cam, 3)
    with pytest.raises(InputError):
        build_frame(0, 0.0, None, np.zeros((32, 32, 1, 1), np.float32), cam, 3)


def test_build_frame_with_recomputed_levels() -> None:
    """The "recompute" pyramid policy: every level's map is given and used as is."""
    from dmtrack.errors import InputError
    from dmtrack.features import get_feature
    from dmtrack.geometry.camera import PinholeCamera
    from dmtrack.odometry.frame import build_frame

    rng = np.random.default_rng(3)
    image = (rng.random((64, 96)) * 255).astype(np.uint8)
    feat = get_feature("bitplanes")
    maps = feat.compute_pyramid(image, 3)
    cam = PinholeCamera(80.0, 80.0, 47.5, 31.5, 96, 64)
    frame = build_frame(0, 0.0, image, maps, cam, n_levels=3)
    for lv in range(3):
        np.testing.assert_array_equal(frame.levels[lv].feat, maps[lv])
        assert frame.levels[lv].camera == cam.level(lv)
    # the down-sampled map differs from the recomputed one: the list was really used
    assert not np.array_equal(build_frame(0, 0.0, image, maps[0], cam, n_levels=3).levels[2].feat, maps[2])
    with pytest.raises(InputError, match="2 feature maps given for a 3-level pyramid"):
        build_frame(0, 0.0, image, maps[:2], cam, n_levels=3)
