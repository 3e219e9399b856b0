"""The tracker's chunked N > 1 residual kernel (dmtrack.odometry._tracker_multi) and the vectorised reference
rebuild (idepth_downsample, make_points): the same bytes as the general kernels, on real feature maps.

Frames 0 and 8 of the demo sequence (real images, real rgb / Bit-Planes features), with an inverse depth on the
keyframe's high-gradient pixels. Both kernels inline one definition of a point's channel sums, whose order the
source fixes (dmtrack.odometry._lanes); these tests compare every output byte for byte, with each other and with
the numpy reference of that order.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dmtrack.geometry.lie import SE3
from dmtrack.odometry import _tracker_multi
from dmtrack.odometry._tracker_points import idepth_downsample, make_points, make_points_numpy
from dmtrack.odometry._tracker_residuals import BUF_COLS, eval_params, eval_pass_parallel, point_channel_sums_numpy
from dmtrack.odometry.frame import Frame, build_frame
from dmtrack.odometry.tracker import TrackingReference

POSES = (
    SE3.exp(np.r_[0.01, -0.005, 0.01, np.deg2rad([0.4, -0.5, 0.2])]).matrix(),  # small motion
    SE3.exp(np.r_[0.25, 0.0, 0.0, 0.0, 0.0, 0.0]).matrix(),  # shifted: many points leave the image
    SE3.exp(np.r_[0.0, 0.0, 0.0, 0.0, np.pi - 0.01, 0.0]).matrix(),  # turned around: points behind the camera
)


def _real_pair(sample_dir: Path, feature: str, channels: slice | None = None, tile: int = 1) -> tuple[Frame, Frame]:
    """Keyframe (frame 0) and frame 8 of the demo sequence with ``feature``'s maps (channels selected or tiled)."""
    from dmtrack.datasets import open_sequence
    from dmtrack.features import get_feature
    from dmtrack.geometry.camera import crop_image

    seq = open_sequence(str(sample_dir))
    cam, box = seq.camera.crop_to_multiple(16)
    feat = get_feature(feature)
    out = []
    for i in (0, 8):
        img = crop_image(seq[i].image, box)
        fmap = feat.compute(img)
        if channels is not None:
            fmap = fmap[:, :, channels]
        if tile > 1:  # more channels: copies, scaled per channel so that they differ
            fmap = np.concatenate([fmap] * tile, axis=2) * np.linspace(0.5, 1.5, tile * fmap.shape[2], dtype=np.float32)
        out.append(build_frame(i, float(i), img, np.ascontiguousarray(fmap, dtype=np.float32), cam))
    return out[0], out[1]


def _reference(kf: Frame) -> TrackingReference:
    """A smooth inverse depth (0.4–0.7 1/m) on the keyframe's 40 % highest-maxGrad pixels, variance 1e-3…4e-3."""
    lv = kf.levels[0]
    ys, xs = np.mgrid[0 : lv.height, 0 : lv.width].astype(np.float32)
    idepth = 0.55 + 0.15 * np.sin(xs / 37.0) * np.cos(ys / 29.0)
    var = 1e-3 * (2.5 + 1.5 * np.cos(xs / 11.0 + ys / 7.0))
    mask = lv.max_grad > np.quantile(lv.max_grad, 0.6)
    idepth = np.where(mask, idepth, -1).astype(np.float32)
    var = np.where(mask, var, -1).astype(np.float32)
    return TrackingReference.from_keyframe(kf, idepth, var)


def _args(ref: TrackingReference, frame: Frame, lvl: int, T: np.ndarray) -> list:
    rl, fl = ref.level(lvl), frame.levels[lvl]
    c = fl.camera
    prm = eval_params(c.fx, c.fy, c.cx, c.cy, 1.0, 0.0, 1.0, 16.0, 1.5, 3 * 1600.0, 0.25, 5.0)
    flags = np.ones(fl.width * fl.height, bool)
    buf = np.full((rl.n_points, BUF_COLS), np.nan)  # every row must be written
    placeholder = np.zeros((1, 1, 3, rl.values.shape[1]), np.float32)
    return [rl.points, rl.values, rl.variances, rl.pixel_index, fl.feat, placeholder, T, prm, False, flags, True, buf]


def _copy(args: list) -> list:
    return [a.copy() if isinstance(a, np.ndarray) else a for a in args]


@pytest.mark.parametrize(
    "feature,channels,tile",
    [
        ("bitplanes", None, 1),
        ("rgb", None, 1),
        ("bitplanes", slice(0, 5), 1),
        ("bitplanes", None, 2),
        ("rgb", None, 11),
    ],  # fmt: skip
    ids=["bitplanes-8", "rgb-3", "bitplanes-5", "bitplanes-16", "rgb-33(general)"],
)
def test_chunked_kernel_is_bit_identical_to_the_general_kernel(
    sample_dir: Path, feature: str, channels: slice | None, tile: int
) -> None:
    """Sums, flags and every buffer byte of the tracker's N > 1 kernels (serial and threaded) equal the general
    kernel's, at every level, with points outside the image and behind the camera."""
    kf, fr = _real_pair(sample_dir, feature, channels, tile)
    nch = kf.n_channels
    ref = _reference(kf)
    serial, threaded = _tracker_multi.tracker_eval_kernels(nch)
    if nch <= _tracker_multi.MAX_CHANNELS:
        assert (serial, threaded) == (_tracker_multi.eval_multi, _tracker_multi.eval_multi_threaded)
    else:
        assert threaded is eval_pass_parallel
    for T in POSES:
        for lvl in (1, 2, 3, 4):
            args = _args(ref, fr, lvl, T)
            want_args = _copy(args)
            want = eval_pass_parallel(*want_args)
            assert 0 < want[0] <= ref.level(lvl).n_points
            for fn in (serial, threaded, _tracker_multi.eval_multi_parallel):
                got_args = _copy(args)
                assert fn(*got_args) == want, (fn, lvl)
                assert got_args[-3].tobytes() == want_args[-3].tobytes()  # flags
                assert got_args[-1].tobytes() == want_args[-1].tobytes(), (fn, lvl)  # buffer
        if T is POSES[1]:
            assert want[0] < ref.level(1).n_points and not want_args[-3].all()
        if T is POSES[2]:
            assert (want_args[-1][:, 2] < 0).any()  # behind the camera, yet projected into the image


@pytest.mark.parametrize(
    "feature,channels,tile",
    [("bitplanes", None, 1), ("rgb", None, 1), ("bitplanes", slice(0, 2), 1), ("bitplanes", slice(0, 5), 1),
     ("bitplanes", None, 2), ("rgb", None, 11)],  # fmt: skip
    ids=["N=8", "N=3", "N=2", "N=5", "N=16", "N=33"],
)
def test_the_kernels_give_the_numpy_references_bits(sample_dir: Path, feature: str, channels, tile: int) -> None:  # noqa: ANN001
    """Every in-image point's buffer row (Sxx, Sxy, Syy, sx, sy) and the error of the general kernel — and so of the
    chunked ones, compared above — equal :func:`point_channel_sums_numpy` (float32 per channel, the lane order) bit
    for bit."""
    kf, fr = _real_pair(sample_dir, feature, channels, tile)
    ref = _reference(kf)
    args = _args(ref, fr, 1, POSES[0])
    points, vals, variances, feat, T, prm, buf = args[0], args[1], args[2], args[4], args[6], args[7], args[-1]
    got = eval_pass_parallel(*args)
    fx, fy, cx, cy = (float(prm[k]) for k in range(4))
    var_weight = float(prm[6])
    h, w = feat.shape[:2]
    # the kernel's projection (float64, the same operations)
    P = points.astype(np.float64)
    px, py, pz = P[:, 0], P[:, 1], P[:, 2]
    wx = T[0, 0] * px + T[0, 1] * py + T[0, 2] * pz + T[0, 3]
    wy = T[1, 0] * px + T[1, 1] * py + T[1, 2] * pz + T[1, 3]
    wz = T[2, 0] * px + T[2, 1] * py + T[2, 2] * pz + T[2, 3]
    iz = 1.0 / wz
    u = (wx * iz) * fx + cx
    v = (wy * iz) * fy + cy
    inside = (u > 1.0) & (v > 1.0) & (u < w - 2.0) & (v < h - 2.0)
    ix, iy = u[inside].astype(np.int64), v[inside].astype(np.int64)
    dx, dy = u[inside] - ix, v[inside] - iy
    dxdy = dx * dy
    zd = pz[inside] * iz[inside] * iz[inside]
    g0 = (T[0, 3] * wz[inside] - T[2, 3] * wx[inside]) * zd
    g1 = (T[1, 3] * wz[inside] - T[2, 3] * wy[inside]) * zd
    s2 = var_weight * variances[inside].astype(np.float64)
    bilinear = (1.0 - dx - dy + dxdy, dy - dxdy, dx - dxdy, dxdy)
    sums = point_channel_sums_numpy(feat, ix, iy, vals[inside], bilinear, g0, g1, s2, prm)
    assert inside.sum() > 1000 and got[0] == inside.sum()
    assert sums[:, 1:6].tobytes() == np.ascontiguousarray(buf[inside, 3:BUF_COLS]).tobytes()
    # the error: per-point sums added in point order within each block, blocks in order
    blocks = np.nonzero(inside)[0] // 1024
    err = sum(sum(sums[blocks == b, 0].tolist()) for b in np.unique(blocks))
    assert got[1] == err


def test_chunked_kernel_with_affine_sums_runs_the_general_kernel(sample_dir: Path) -> None:
    kf, fr = _real_pair(sample_dir, "rgb")
    ref = _reference(kf)
    args = _args(ref, fr, 2, POSES[0])
    args[5] = fr.levels[2].packed
    args[8] = True
    want_args = _copy(args)
    want = eval_pass_parallel(*want_args)
    assert want[9] > 0  # the affine sums are formed
    for fn in (_tracker_multi.eval_multi, _tracker_multi.eval_multi_threaded):
        got_args = _copy(args)
        assert fn(*got_args) == want
        assert got_args[-1].tobytes() == want_args[-1].tobytes()


def _idepth_downsample_point_by_point(idepth: np.ndarray, var: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The original loop: skip the invalid children (Python floats are IEEE doubles: the same roundings)."""
    h2, w2 = idepth.shape[0] // 2, idepth.shape[1] // 2
    out_d = np.empty((h2, w2), np.float32)
    out_v = np.empty((h2, w2), np.float32)
    d, v = idepth.astype(np.float64).tolist(), var.astype(np.float64).tolist()
    for y in range(h2):
        for x in range(w2):
            isum = dsum = 0.0
            num = 0
            for dy in range(2):
                for dx in range(2):
                    vv = v[2 * y + dy][2 * x + dx]
                    if vv > 0:
                        iv = 1.0 / vv
                        isum += iv
                        dsum += iv * d[2 * y + dy][2 * x + dx]
                        num += 1
            out_d[y, x] = dsum / isum if num else -1.0
            out_v[y, x] = num / isum if num else -1.0
    return out_d, out_v


def test_reference_rebuild_is_bit_identical_to_the_point_by_point_loops(sample_dir: Path) -> None:
    """idepth_downsample equals the point-by-point loop byte for byte (invalid children, ±0, tiny variances),
    make_points equals its numpy reference byte for byte, on a real Bit-Planes keyframe."""
    rng = np.random.default_rng(7)
    d = rng.uniform(-0.5, 2.0, (48, 66)).astype(np.float32)
    d[rng.random(d.shape) < 0.1] = 0.0
    d[rng.random(d.shape) < 0.05] = -0.0
    v = np.where(rng.random(d.shape) < 0.5, rng.uniform(1e-6, 0.1, d.shape), rng.choice([-1.0, 0.0], d.shape))
    v = v.astype(np.float32)
    v[rng.random(d.shape) < 0.02] = 1e-44  # subnormal: 1/v is large but finite in float64
    for a, b in zip(idepth_downsample(d, v), _idepth_downsample_point_by_point(d, v), strict=True):
        assert a.tobytes() == b.tobytes()
    kf, _ = _real_pair(sample_dir, "bitplanes")
    ref = _reference(kf)
    for lvl in (1, 2, 3):
        dl, vl = ref.idepth_pyramid[lvl]
        for a, b in zip(idepth_downsample(*ref.idepth_pyramid[lvl - 1]), (dl, vl), strict=True):
            assert a.tobytes() == b.tobytes()
        if lvl == 1:
            want = _idepth_downsample_point_by_point(*ref.idepth_pyramid[0])
            assert dl.tobytes() == want[0].tobytes() and vl.tobytes() == want[1].tobytes()
        kl = kf.levels[lvl]
        cam = kl.camera
        args = (dl, vl, kl.feat, float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy))
        got, want = make_points(*args), make_points_numpy(*args)
        assert len(got[0]) > 100
        for a, b in zip(got, want, strict=True):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
