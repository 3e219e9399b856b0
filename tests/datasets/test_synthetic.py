"""Tests of the synthetic textured-room sequence (dmtrack.datasets.synthetic)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from dmtrack.datasets.base import Frame, Sequence
from dmtrack.datasets.synthetic import (
    SyntheticConfig,
    SyntheticSequence,
    make_scene,
    make_trajectory,
    render,
    render_numpy,
    world_points,
)
from dmtrack.errors import InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.geometry.lie import rotation_angle
from dmtrack.io.trajectory import Trajectory

SMALL = {"width": 160, "height": 120, "n_frames": 90}


@pytest.fixture(scope="module")
def seq() -> SyntheticSequence:
    return SyntheticSequence(SyntheticConfig(**SMALL))


@pytest.fixture(scope="module")
def seq_colour() -> SyntheticSequence:
    return SyntheticSequence(SyntheticConfig(**SMALL, colour=True))


def _bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    u0 = np.floor(u).astype(int)
    v0 = np.floor(v).astype(int)
    au, av = u - u0, v - v0
    return (
        img[v0, u0] * (1 - au) * (1 - av)
        + img[v0, u0 + 1] * au * (1 - av)
        + img[v0 + 1, u0] * (1 - au) * av
        + img[v0 + 1, u0 + 1] * au * av
    )


def _grad_mag(img: np.ndarray) -> np.ndarray:
    """LSD-SLAM gradient magnitude: halved central differences, interior pixels only."""
    f = img.astype(np.float64)
    gx = 0.5 * (f[1:-1, 2:] - f[1:-1, :-2])
    gy = 0.5 * (f[2:, 1:-1] - f[:-2, 1:-1])
    return np.hypot(gx, gy)


def _box_down(img: np.ndarray) -> np.ndarray:
    h, w = img.shape[0] // 2 * 2, img.shape[1] // 2 * 2
    f = img[:h, :w].astype(np.float64)
    return 0.25 * (f[0::2, 0::2] + f[1::2, 0::2] + f[0::2, 1::2] + f[1::2, 1::2])


# ---------------------------------------------------------------------------------------- the protocol
def test_frames_have_the_right_types_and_shapes(seq: SyntheticSequence, seq_colour: SyntheticSequence) -> None:
    assert isinstance(seq, Sequence)
    assert seq.format == "synthetic" and seq.name == "synthetic-seed0"
    assert (seq.width, seq.height, len(seq)) == (160, 120, 90)
    cam = seq.camera
    assert isinstance(cam, PinholeCamera)
    assert (cam.width, cam.height) == (160, 120)
    assert cam.fx == pytest.approx(525.0 / 4) and (cam.cx, cam.cy) == (79.5, 59.5)
    np.testing.assert_allclose(seq.timestamps, np.arange(90) / 30.0)
    gt = seq.groundtruth
    assert isinstance(gt, Trajectory) and seq.has_groundtruth and len(gt) == 90

    f = seq[3]
    assert isinstance(f, Frame)
    assert f.index == 3 and f.timestamp == pytest.approx(0.1)
    assert f.image.dtype == np.uint8 and f.image.shape == (120, 160)
    assert f.depth is not None and f.depth.dtype == np.float32 and f.depth.shape == (120, 160)
    assert f.pose is not None and f.pose.dtype == np.float64 and f.pose.shape == (4, 4)
    np.testing.assert_array_equal(f.pose, gt.poses[3])
    np.testing.assert_array_equal(seq[-87].image, f.image)
    assert seq[-1].index == 89

    c = seq_colour[3]
    assert c.image.dtype == np.uint8 and c.image.shape == (120, 160, 3)
    np.testing.assert_array_equal(c.depth, f.depth)

    with pytest.raises(IndexError):
        seq[90]
    with pytest.raises(IndexError):
        seq[-91]
    assert [fr.index for fr in seq.slice(0, 3)] == [0, 1, 2]


def test_slice_keeps_frames_timestamps_and_poses(seq: SyntheticSequence) -> None:
    sub = seq.slice(10, 20)
    assert len(sub) == 10 and isinstance(sub, SyntheticSequence)
    np.testing.assert_array_equal(sub.timestamps, seq.timestamps[10:20])
    np.testing.assert_array_equal(sub.groundtruth.poses, seq.groundtruth.poses[10:20])
    a, b = sub[2], seq[12]
    assert a.index == 2 and a.timestamp == b.timestamp
    np.testing.assert_array_equal(a.image, b.image)
    assert len(seq.slice(85)) == 5 and len(seq.slice(80, 1000)) == 10
    with pytest.raises(InputError):
        seq.slice(90)
    with pytest.raises(InputError):
        seq.slice(5, 5)


def test_invalid_settings_raise_input_error(seq: SyntheticSequence) -> None:
    with pytest.raises(InputError):
        SyntheticSequence(SyntheticConfig(width=0))
    with pytest.raises(InputError):
        SyntheticSequence(SyntheticConfig(**SMALL, noise_sigma=-1.0))
    with pytest.raises(InputError):
        make_scene(0, room_size=(2.0, 2.0, 2.0))
    assert seq.camera is not None
    with pytest.raises(InputError):
        render(seq.scene, seq.camera, np.eye(3))


# ---------------------------------------------------------------------------------------- determinism
def test_frames_are_deterministic_and_independent_of_access_order() -> None:
    cfg = SyntheticConfig(**SMALL, noise_sigma=2.0, global_illumination=0.2, local_illumination=0.4)
    first = SyntheticSequence(cfg)[40]
    other = SyntheticSequence(cfg)
    for i in (0, 39, 41, 7):
        other[i]
    again = other[40]
    np.testing.assert_array_equal(first.image, again.image)
    np.testing.assert_array_equal(first.depth, again.depth)
    np.testing.assert_array_equal(first.pose, again.pose)
    # a different seed gives a different scene, trajectory and image
    diff = SyntheticSequence(SyntheticConfig(**SMALL, seed=1))[40]
    assert np.abs(diff.image.astype(int) - first.image.astype(int)).mean() > 10
    assert not np.allclose(diff.pose, first.pose)


def test_scene_generation_is_deterministic_by_seed() -> None:
    kw = {"room_size": (3.4, 3.2, 2.2), "n_boxes": 2, "n_planes": 1, "texel": 0.03}
    uncached = make_scene.__wrapped__  # bypass the lru cache: really generate twice
    a, b, c = uncached(7, **kw), uncached(7, **kw), uncached(8, **kw)
    np.testing.assert_array_equal(a.tex, b.tex)
    np.testing.assert_array_equal(a.face_origin, b.face_origin)
    assert a.tex.shape != c.tex.shape or not np.array_equal(a.tex, c.tex)
    assert not np.allclose(a.box_centre, c.box_centre)
    # the geometry does not depend on the texture resolution (separate random streams)
    d = uncached(7, **{**kw, "texel": 0.06})
    np.testing.assert_array_equal(a.face_origin, d.face_origin)
    assert a.n_faces == 6 + 6 * 2 + 1


# ---------------------------------------------------------------------------------------- rendering
@pytest.mark.parametrize("colour", [False, True])
def test_numba_kernel_matches_numpy_reference(colour: bool) -> None:
    sq = SyntheticSequence(SyntheticConfig(**SMALL, colour=colour))
    assert sq.camera is not None
    for k in (0, 45, 89):
        img, depth = render(sq.scene, sq.camera, sq.groundtruth.poses[k])
        ref_img, ref_depth = render_numpy(sq.scene, sq.camera, sq.groundtruth.poses[k])
        assert img.shape == ref_img.shape == ((120, 160, 3) if colour else (120, 160))
        np.testing.assert_allclose(depth, ref_depth, rtol=1e-5)
        err = np.abs(img - ref_img)
        # identical up to rounding, except possibly a few pixels exactly on a box edge (face choice tie)
        assert np.mean(err > 1e-2) < 1e-3 and np.median(err) < 1e-4


def test_numba_kernel_matches_numpy_reference_next_to_a_box(seq: SyntheticSequence) -> None:
    """Camera inside a box's bounding sphere: the kernel's sphere culling must not drop the box.

    The camera sits 5 cm off a box face, beyond the box centre along the face, looking along the face
    with a wide field of view: some rays hit the face although the box centre is behind them.
    """
    scene = seq.scene
    cam = PinholeCamera(25.0, 25.0, 31.5, 23.5, 64, 48)
    b, k, j = max(
        ((b, k, j) for b in range(len(scene.box_half)) for k in range(3) for j in range(3) if k != j),
        key=lambda t: scene.box_half[t[0], t[2]] / scene.box_half[t[0], t[1]],
    )
    c, R, h = scene.box_centre[b], scene.box_rot[b], scene.box_half[b]
    off = np.zeros(3)
    off[k], off[j] = h[k] + 0.05, 0.6 * h[j]
    eye = c + R @ off
    assert np.sum((eye - c) ** 2) < np.sum(h**2)  # inside the bounding sphere, outside the box
    assert not scene.inside_boxes(eye).any() and scene.inside_room(eye).all()
    z = R[:, j]
    x = -R[:, k]  # image right = towards the face
    T = np.eye(4)
    T[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    T[:3, 3] = eye
    img, depth = render(scene, cam, T)
    ref_img, ref_depth = render_numpy(scene, cam, T)
    np.testing.assert_allclose(depth, ref_depth, rtol=1e-5)
    assert np.mean(np.abs(img - ref_img) > 1e-2) < 1e-3
    # the case is really exercised: pixels on this box whose ray points away from the box centre
    pts = world_points(ref_depth, cam, T)
    on_box = np.all(np.abs((pts - c) @ R) <= h + 1e-6, axis=-1)
    away = (pts - eye) @ (c - eye) <= 0.0
    assert np.sum(on_box & away) >= 5


def test_depth_is_exact(seq: SyntheticSequence) -> None:
    """Every back-projected pixel lies on a surface; looking straight at a wall gives its distance."""
    assert seq.camera is not None
    for k in (0, 60):
        T = seq.groundtruth.poses[k]
        _, depth = render(seq.scene, seq.camera, T)
        pts = world_points(depth, seq.camera, T).reshape(-1, 3)
        assert seq.scene.clearance(pts).max() < 1e-5  # float32 depth: ~1e-7 relative
    # room only; camera at the centre looking along +x (OpenCV axes: x_c = -y_w, y_c = -z_w, z_c = +x_w)
    scene = make_scene(3, n_boxes=0, n_planes=0, texel=0.05)
    cam = PinholeCamera(100.0, 100.0, 40.0, 30.0, 81, 61)
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    T[:3, 3] = (0.5, 0.2, 1.4)
    _, depth = render(scene, cam, T)
    wall = scene.room_hi[0] - 0.5
    # the wall fills every pixel whose ray leaves the room through x = hi: all pixels here (the room is
    # 6 x 5 x 2.8 m, the field of view ±22°), and z on a fronto-parallel plane is constant
    np.testing.assert_allclose(depth, wall, rtol=1e-6)


def test_warp_with_depth_and_pose_is_photo_consistent(seq: SyntheticSequence) -> None:
    """Unproject frame i with its depth and pose, reproject into frame j: intensities agree there."""
    cam = seq.camera
    assert cam is not None
    poses = seq.groundtruth.poses
    i, j = 20, 32
    img_i, depth_i = render(seq.scene, cam, poses[i])
    img_j, depth_j = render(seq.scene, cam, poses[j])

    def warp(T_j: np.ndarray, depth_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixel coordinates in j and depths there of every pixel of i (flattened)."""
        pw = world_points(depth_i * depth_scale, cam, poses[i]).reshape(-1, 3)
        T_jw = np.linalg.inv(T_j)
        uv, z = cam.project_with_depth(pw @ T_jw[:3, :3].T + T_jw[:3, 3])
        return uv[:, 0], uv[:, 1], z

    # pixels of i visible in j (not occluded, inside, away from depth discontinuities of j)
    u, v, z = warp(poses[j])
    ok = cam.in_image(np.stack([u, v], axis=1), border=3.0)
    ui, vi = np.rint(u[ok]).astype(int), np.rint(v[ok]).astype(int)
    near = np.stack([depth_j[vi + dv, ui + du] for dv in (-1, 0, 1) for du in (-1, 0, 1)])
    smooth = (near.max(axis=0) - near.min(axis=0)) < 0.05 * z[ok]
    visible = np.abs(_bilinear(depth_j, u[ok], v[ok]) - z[ok]) < 0.01 * z[ok]
    keep = np.flatnonzero(ok)[smooth & visible]
    assert keep.size > 0.5 * u.size

    def error(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        uc = np.clip(u[keep], 0.0, cam.width - 1.001)
        vc = np.clip(v[keep], 0.0, cam.height - 1.001)
        return np.abs(_bilinear(img_j, uc, vc) - img_i.reshape(-1)[keep])

    baseline = np.linalg.norm(poses[j][:3, 3] - poses[i][:3, 3])
    flow = np.hypot(u[keep] - np.arange(u.size)[keep] % cam.width, v[keep] - np.arange(u.size)[keep] // cam.width)
    assert baseline > 0.08 and np.median(flow) > 3.0  # a real motion, several pixels of flow
    err = error(u, v)
    print(
        f"\nwarp {i}->{j} (baseline {baseline:.3f} m, median flow {np.median(flow):.1f} px): median |err| "
        f"{np.median(err):.2f}, mean {err.mean():.2f}, p95 {np.percentile(err, 95):.2f} grey levels"
    )
    assert np.median(err) < 1.2 and err.mean() < 2.0
    # the test can fail: a 3 cm pose error or a 20 % depth error (≈ 1–2 px) makes the warp inconsistent
    T_bad = poses[j].copy()
    T_bad[:3, 3] += 0.03 * T_bad[:3, 0]  # along the camera's x axis
    bad_pose = error(*warp(T_bad)[:2])
    bad_depth = error(*warp(poses[j], depth_scale=1.2)[:2])
    print(f"median |err| with a 3 cm pose error {np.median(bad_pose):.2f}, 20 % depth error {np.median(bad_depth):.2f}")
    assert np.median(bad_pose) > 3 * np.median(err) and np.median(bad_depth) > 3 * np.median(err)


def test_vga_render_speed_and_validity() -> None:
    sq = SyntheticSequence(SyntheticConfig(n_frames=30))
    assert sq.camera is not None
    render(sq.scene, sq.camera, sq.groundtruth.poses[0])  # warm-up (numba compile / cache load)
    times = []
    for k in range(1, 6):
        t0 = time.perf_counter()
        img, depth = render(sq.scene, sq.camera, sq.groundtruth.poses[k])
        times.append(time.perf_counter() - t0)
    print(f"\nVGA render: median {1e3 * np.median(times):.1f} ms, min {1e3 * min(times):.1f} ms per frame")
    assert img.shape == (480, 640) and depth.shape == (480, 640)
    assert np.isfinite(depth).all() and depth.min() > 0.3
    frame = sq[5]
    assert frame.image.shape == (480, 640) and frame.image.dtype == np.uint8
    # LSD-SLAM's minUseGrad: a decent share of pixels has |∇I| > 5 (0..255), at VGA and coarser levels
    level = frame.image.astype(np.float64)
    for lvl in range(4):
        share = float(np.mean(_grad_mag(level) > 5.0))
        print(f"level {lvl}: {100 * share:.0f} % of pixels with |grad| > 5")
        assert share > 0.25
        level = _box_down(level)


# ---------------------------------------------------------------------------------------- texture
def test_image_gradients_at_several_scales(seq: SyntheticSequence) -> None:
    for k in (0, 45, 89):
        level = seq[k].image.astype(np.float64)
        for _ in range(3):  # 160x120, 80x60, 40x30
            assert np.mean(_grad_mag(level) > 5.0) > 0.25
            level = _box_down(level)


def test_texture_is_multiscale_natural_and_not_periodic(seq: SyntheticSequence) -> None:
    scene = seq.scene
    tex = scene.face_texture(4, 0)[..., 0].astype(np.float64)  # the floor, 1 cm texels
    tex = tex[:400, :400] - tex[:400, :400].mean()
    n = tex.shape[0]
    # autocorrelation without wrap-around (zero padding)
    spec = np.fft.rfft2(tex, s=(2 * n, 2 * n))
    ac = np.fft.irfft2(np.abs(spec) ** 2, s=(2 * n, 2 * n))
    ac = np.fft.fftshift(ac) / ac[0, 0]
    overlap = np.fft.fftshift(
        np.fft.irfft2(np.abs(np.fft.rfft2(np.ones((n, n)), s=(2 * n, 2 * n))) ** 2, s=(2 * n, 2 * n))
    )
    ac = ac * (n * n) / np.maximum(overlap, 1.0)  # unbiased estimate per shift
    yy, xx = np.mgrid[-n:n, -n:n]
    r = np.hypot(yy, xx)
    # spatially correlated (not white noise) at 1 texel, no strong repeat beyond 15 cm (no checkerboard)
    assert ac[r == 1].mean() > 0.8
    far = (r > 15) & (np.abs(yy) < n // 2) & (np.abs(xx) < n // 2)
    assert ac[far].max() < 0.6
    # radially averaged power spectrum falls like 1/f^α with α in the range of natural images
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n)))
    power = np.abs(np.fft.fft2(tex * np.outer(np.hanning(n), np.hanning(n)))) ** 2
    bins = np.geomspace(2.0 / n, 0.3, 12)
    idx = np.digitize(f.ravel(), bins)
    p = np.array([power.ravel()[idx == b].mean() for b in range(1, len(bins))])
    fc = np.sqrt(bins[1:] * bins[:-1])
    alpha = -np.polyfit(np.log(fc), np.log(p), 1)[0]
    print(f"\nfloor texture power spectrum slope alpha = {alpha:.2f}")
    assert 1.2 < alpha < 3.5
    # every band carries power close to the fitted power law (no gap or spike between scales)
    resid = np.log(p) - np.polyval(np.polyfit(np.log(fc), np.log(p), 1), np.log(fc))
    assert np.abs(resid).max() < np.log(4.0)
    # mid-grey on average, with strong contrast, within the 8-bit range
    assert 100.0 < float(scene.tex.mean()) < 160.0 and float(scene.tex.std()) > 25.0
    assert scene.tex.min() >= 0.0 and scene.tex.max() <= 255.0


# ---------------------------------------------------------------------------------------- trajectory
@pytest.mark.parametrize("seed", range(8))
def test_camera_stays_in_free_space(seed: int) -> None:
    scene = make_scene(seed, texel=0.2)  # geometry does not depend on the texel size
    _, poses = make_trajectory(seed, 900, 30.0, 0.5, scene)
    c = poses[:, :3, 3]
    assert scene.inside_room(c).all() and not scene.inside_boxes(c).any()
    assert scene.clearance(c).min() > 0.4
    assert np.hypot(c[:, 0], c[:, 1]).max() < scene.free_radius


def test_camera_sees_valid_depth_everywhere(seq: SyntheticSequence) -> None:
    cam = PinholeCamera(40.0, 40.0, 39.5, 29.5, 80, 60)
    poses = make_trajectory(0, 600, 30.0, 0.3, seq.scene)[1]
    for T in poses[::25]:
        _, depth = render(seq.scene, cam, T)
        assert np.isfinite(depth).all() and depth.min() > 0.3 and depth.max() < 8.0
        # it looks at the objects, not only at walls: some depth variation in every view
        assert np.percentile(depth, 90) - np.percentile(depth, 10) > 0.1


def test_trajectory_is_smooth_with_the_requested_speed() -> None:
    scene = make_scene(0, texel=0.2)
    fps = 30.0
    for speed in (0.3, 0.6):
        t, poses = make_trajectory(0, 1800, fps, speed, scene)
        np.testing.assert_allclose(t, np.arange(1800) / fps)
        R = poses[:, :3, :3]
        np.testing.assert_allclose(np.swapaxes(R, 1, 2) @ R, np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
        np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
        c = poses[:, :3, 3]
        v = np.diff(c, axis=0) * fps
        a = np.diff(c, 2, axis=0) * fps**2
        sp = np.linalg.norm(v, axis=1)
        assert 0.6 * speed < sp.mean() < 1.4 * speed
        assert sp.max() < 2.5 * speed
        assert np.linalg.norm(a, axis=1).max() < 10.0 * speed**2  # m/s² (∝ speed² for a fixed path)
        rel = np.einsum("nji,njk->nik", R[:-1], R[1:])
        w = rotation_angle(rel) * fps  # rad/s
        assert w.max() < 2.0 * speed  # ≤ 35°/s at 0.3 m/s
        dw = np.diff(w) * fps
        assert np.abs(dw).max() < 10.0 * speed**2
        # the camera looks roughly horizontally (slightly down), the image stays upright (small roll)
        fwd = R[:, :, 2]
        assert np.all(np.abs(fwd[:, 2]) < 0.5)
        assert np.all(R[:, 2, 1] < -0.8)  # camera y (down) points down in the world
    static = make_trajectory(0, 10, fps, 0.0, scene)[1]
    np.testing.assert_array_equal(static, np.broadcast_to(static[0], static.shape))


# ---------------------------------------------------------------------------------------- photometry
def test_global_illumination_is_a_smooth_gain_and_offset(seq: SyntheticSequence) -> None:
    lit = SyntheticSequence(SyntheticConfig(**SMALL, global_illumination=0.3))
    go = np.array([lit.gain_offset(k) for k in range(90)])
    assert np.all(np.abs(go[:, 0] - 1.0) <= 0.3) and np.all(np.abs(go[:, 1]) <= 12.0)
    assert np.ptp(go[:, 0]) > 0.05  # it really changes over 3 s
    assert np.abs(np.diff(go[:, 0])).max() < 0.02 and np.abs(np.diff(go[:, 1])).max() < 1.0  # smooth
    assert seq.gain_offset(10) == (1.0, 0.0)
    for k in (0, 50):
        base, d0 = seq.radiance(k)
        img, d1 = lit.radiance(k)
        gain, offset = lit.gain_offset(k)
        np.testing.assert_allclose(img, gain * base + offset, rtol=1e-5, atol=1e-3)
        np.testing.assert_array_equal(d0, d1)
        np.testing.assert_array_equal(lit[k].pose, seq[k].pose)
        assert np.abs(lit[k].image.astype(int) - seq[k].image.astype(int)).mean() > 1.0


def test_local_illumination_is_a_spatially_varying_gain(seq: SyntheticSequence) -> None:
    amp = 0.6
    lit = SyntheticSequence(SyntheticConfig(**SMALL, local_illumination=amp))
    ratios = []
    for k in (0, 45, 89):
        base, d0 = seq.radiance(k)
        img, d1 = lit.radiance(k)
        np.testing.assert_array_equal(d0, d1)
        ratio = img / base
        assert ratio.min() >= 1.0 - amp / 2 - 1e-5 and ratio.max() <= 1.0 + amp / 2 + 1e-5
        assert ratio.std() > 0.05  # not a global gain
        # smooth: neighbouring pixels on the same surface get nearly the same gain
        same = np.abs(np.diff(d0, axis=1)) < 0.01
        assert np.abs(np.diff(ratio, axis=1))[same].max() < 0.05
        ratios.append(ratio)
    assert np.abs(ratios[0] - ratios[1]).mean() > 0.02  # the light moves: no fixed vignetting pattern
    np.testing.assert_array_equal(lit.groundtruth.poses, seq.groundtruth.poses)


def test_noise_is_gaussian_seeded_per_frame(seq: SyntheticSequence) -> None:
    sigma = 3.0
    noisy = SyntheticSequence(SyntheticConfig(**SMALL, noise_sigma=sigma))
    d5 = noisy.radiance(5)[0] - seq.radiance(5)[0]
    d6 = noisy.radiance(6)[0] - seq.radiance(6)[0]
    assert abs(d5.std() - sigma) < 0.15 * sigma and abs(d5.mean()) < 0.1 * sigma
    assert abs(np.corrcoef(d5.ravel(), d6.ravel())[0, 1]) < 0.05  # new noise every frame
    np.testing.assert_array_equal(noisy.radiance(5)[0], noisy.radiance(5)[0])
    u8 = noisy[5].image.astype(float) - seq[5].image.astype(float)
    assert abs(u8.std() - math.sqrt(sigma**2 + 1 / 6)) < 0.2 * sigma
    np.testing.assert_array_equal(noisy[5].depth, seq[5].depth)
    np.testing.assert_array_equal(noisy.slice(4)[1].image, noisy[5].image)  # a slice keeps each frame's noise


def test_colour_frames_have_chroma_and_grey_luma(seq: SyntheticSequence, seq_colour: SyntheticSequence) -> None:
    grey, _ = seq.radiance(30)
    rgb, _ = seq_colour.radiance(30)
    luma = rgb @ np.array([0.299, 0.587, 0.114])
    unclipped = np.all((rgb > 5) & (rgb < 250), axis=-1)
    assert unclipped.mean() > 0.9
    assert np.abs(luma - grey)[unclipped].mean() < 0.5  # luma of the colour scene = grey scene
    assert (rgb[..., 0] - rgb[..., 1]).std() > 5 and (rgb[..., 2] - rgb[..., 1]).std() > 5
    img = seq_colour[30].image
    assert img.shape == (120, 160, 3) and img.dtype == np.uint8


def test_inverse_depth(seq: SyntheticSequence) -> None:
    inv = seq.inverse_depth(7)
    assert inv.dtype == np.float32 and inv.shape == (120, 160)
    np.testing.assert_allclose(inv, 1.0 / seq[7].depth, rtol=1e-6)


def test_forward_motion_drives_down_a_hall() -> None:
    """``motion=forward``: the camera moves along +x at the given speed, looking ahead, in an empty 30 m hall."""
    from dmtrack.datasets import open_sequence
    from dmtrack.errors import InputError

    seq = open_sequence("synthetic:motion=forward,fps=10,speed=2,n_frames=30,width=64,height=48,seed=3")
    P = seq.poses
    step = np.diff(P[:, :3, 3], axis=0)
    assert np.allclose(step[:, 0], 0.2) and np.all(np.abs(step[:, 1:]) < 0.02)  # 2 m/s at 10 Hz, forward
    fwd = P[:, :3, 2]  # the optical axis stays within a few degrees of the direction of motion
    assert np.all(np.degrees(np.arccos(np.clip(fwd[:, 0], -1, 1))) < 5.0)
    assert seq.config.setting("room_size") == (30.0, 5.0, 3.0) and seq.config.setting("n_boxes") == 0
    assert seq.scene.room_hi[0] - seq.scene.room_lo[0] == 30.0
    img = seq[10].image
    assert img.shape == (48, 64) and img.std() > 10  # textured walls
    with pytest.raises(InputError, match="longer than"):
        open_sequence("synthetic:motion=forward,fps=10,speed=10,n_frames=40,width=64,height=48")
    with pytest.raises(InputError, match="motion must be one of"):
        open_sequence("synthetic:motion=sideways")


def test_intrinsics_change_what_the_odometry_is_told_not_the_images() -> None:
    """``--intrinsics`` on a ``synthetic:`` source replaces ``camera`` (what the odometry assumes) and leaves the
    rendering camera ``lens`` and so the images and depths as they were: a wrong calibration can be tried on them.
    A slice keeps the replaced camera."""
    from dmtrack.datasets import open_sequence

    spec = "synthetic:n_frames=4,width=160,height=120,seed=3"
    true = open_sequence(spec)
    told = open_sequence(spec, intrinsics="150,150,79.5,59.5")
    assert told.camera.fx == 150.0 and told.lens == true.lens == true.camera and true.lens.fx != 150.0
    assert np.array_equal(np.asarray(told[2].image), np.asarray(true[2].image))
    assert np.array_equal(told.depth(2), true.depth(2))
    part = told.slice(1, 3)
    assert part.camera.fx == 150.0 and part.lens == true.lens
    assert np.array_equal(np.asarray(part[1].image), np.asarray(true[2].image))
