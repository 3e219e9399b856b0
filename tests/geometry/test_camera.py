"""Tests of dmtrack.geometry.camera: intrinsics, pyramid levels, projection, crops."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dmtrack.geometry import PinholeCamera, crop_image

SETTINGS = settings(max_examples=100, deadline=None)
TUM = PinholeCamera(fx=525.0, fy=525.0, cx=319.5, cy=239.5, width=640, height=480)
KITTI = PinholeCamera(fx=718.856, fy=718.856, cx=607.1928, cy=185.2157, width=1226, height=370)

cameras = st.builds(
    PinholeCamera,
    fx=st.floats(50.0, 2000.0),
    fy=st.floats(50.0, 2000.0),
    cx=st.floats(-50.0, 700.0),
    cy=st.floats(-50.0, 500.0),
    width=st.integers(1, 2000),
    height=st.integers(1, 2000),
)


def test_level_intrinsics_follow_lsd_slam() -> None:
    # c_1 = (c_0 + 0.5)/2 - 0.5: the centre 319.5 of a 640-wide image stays the centre 159.5 of 320 pixels.
    c1 = TUM.level(1)
    assert (c1.fx, c1.fy, c1.cx, c1.cy) == (262.5, 262.5, 159.5, 119.5)
    off = PinholeCamera(500.0, 400.0, 100.0, 50.25, 641, 479).level(1)
    assert (off.fx, off.fy, off.cx, off.cy, off.width, off.height) == (250.0, 200.0, 49.75, 24.875, 320, 239)
    assert c1.size == (320, 240)
    c3 = TUM.level(3)
    assert c3.fx == 525.0 / 8
    assert c3.cx == pytest.approx((319.5 + 0.5) / 8 - 0.5)
    assert c3.cy == pytest.approx((239.5 + 0.5) / 8 - 0.5)
    assert c3.size == (80, 60)
    assert TUM.level(0) == TUM
    # odd sizes are truncated like w >> l
    assert KITTI.level(1).size == (613, 185)
    assert KITTI.level(2).size == (306, 92)


@SETTINGS
@given(cameras, st.integers(0, 4), st.integers(0, 4))
def test_levels_compose(cam: PinholeCamera, a: int, b: int) -> None:
    if (cam.width >> (a + b)) == 0 or (cam.height >> (a + b)) == 0:
        with pytest.raises(ValueError, match="empty"):
            cam.level(a + b)
        return
    direct, chained = cam.level(a + b), cam.level(a).level(b)
    assert direct.size == chained.size
    np.testing.assert_allclose(direct.K, chained.K, rtol=1e-14, atol=1e-12)


def test_level_matches_block_average_of_a_projected_point() -> None:
    # A point on the image plane at pixel (u, v) of level 0 sits, after 2x2 block averaging, at
    # ((u + 0.5)/2 - 0.5, (v + 0.5)/2 - 0.5): the level camera must project it there.
    p = np.array([0.3, -0.2, 2.0])
    u0 = TUM.project(p[None])[0]
    u1 = TUM.level(1).project(p[None])[0]
    np.testing.assert_allclose(u1, (u0 + 0.5) / 2 - 0.5, rtol=1e-14)


def test_pyramid() -> None:
    pyr = TUM.pyramid(5)
    assert len(pyr) == 5
    assert pyr[0] == TUM
    assert [c.size for c in pyr] == [(640, 480), (320, 240), (160, 120), (80, 60), (40, 30)]
    assert all(pyr[i] == TUM.level(i) for i in range(5))
    with pytest.raises(ValueError):
        TUM.pyramid(0)
    with pytest.raises(ValueError):
        TUM.level(-1)
    with pytest.raises(ValueError, match="empty"):
        TUM.level(10)


def test_K_and_K_inv() -> None:
    K = KITTI.K
    np.testing.assert_array_equal(K, [[718.856, 0, 607.1928], [0, 718.856, 185.2157], [0, 0, 1]])
    np.testing.assert_allclose(K @ KITTI.K_inv, np.eye(3), atol=1e-13)
    np.testing.assert_allclose(KITTI.K_inv, np.linalg.inv(K), rtol=1e-14, atol=1e-16)
    assert PinholeCamera.from_K(K, 1226, 370) == KITTI
    assert KITTI.shape == (370, 1226)
    K[0, 0] = 1.0  # K is a fresh array each time
    assert KITTI.fx == 718.856


@SETTINGS
@given(
    cameras,
    st.integers(0, 2**32 - 1),
)
def test_project_unproject_round_trip(cam: PinholeCamera, seed: int) -> None:
    rng = np.random.default_rng(seed)
    uv = rng.uniform(-10, 2000, (50, 2))
    depth = rng.uniform(0.01, 100.0, 50)
    pts = cam.unproject(uv, depth)
    assert pts.shape == (50, 3)
    np.testing.assert_allclose(pts[:, 2], depth)
    np.testing.assert_allclose(cam.project(pts), uv, rtol=1e-12, atol=1e-9)
    uv2, z = cam.project_with_depth(pts)
    np.testing.assert_allclose(uv2, uv, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(z, depth)
    # against the matrix form K p / z
    h = pts @ cam.K.T
    np.testing.assert_allclose(cam.project(pts), h[:, :2] / h[:, 2:], rtol=1e-12, atol=1e-9)


def test_project_behind_camera_is_nan_and_shapes_broadcast() -> None:
    pts = np.array([[0.0, 0.0, 1.0], [1.0, 1.0, 0.0], [1.0, 2.0, -3.0], [0.1, 0.2, np.nan]])
    uv = TUM.project(pts)
    np.testing.assert_array_equal(uv[0], [319.5, 239.5])
    assert np.all(np.isnan(uv[1:]))
    assert not TUM.in_image(uv[1:]).any()
    grid = np.ones((4, 5, 3))
    assert TUM.project(grid).shape == (4, 5, 2)
    assert TUM.project(np.array([0.0, 0.0, 2.0])).shape == (2,)
    assert TUM.unproject(np.zeros((4, 5, 2)), 2.0).shape == (4, 5, 3)
    with pytest.raises(ValueError):
        TUM.project(np.zeros((3, 2)))
    with pytest.raises(ValueError):
        TUM.unproject(np.zeros((3, 3)), np.ones(3))


def test_pixel_grid_rays() -> None:
    cam = TUM.level(3)
    rays = cam.pixel_grid_rays()
    assert rays.shape == (60, 80, 3)
    np.testing.assert_array_equal(rays[..., 2], 1.0)
    vv, uu = np.mgrid[0:60, 0:80]
    np.testing.assert_allclose(cam.project(rays), np.stack([uu, vv], axis=-1), atol=1e-12)
    np.testing.assert_allclose(rays[7, 11], cam.K_inv @ [11.0, 7.0, 1.0], rtol=1e-15)


def test_in_image() -> None:
    cam = PinholeCamera(100.0, 100.0, 4.5, 2.5, 10, 6)
    uv = np.array([[0.0, 0.0], [9.0, 5.0], [9.01, 1.0], [-0.01, 1.0], [4.0, 5.5], [2.0, 2.0], [np.nan, 1.0]])
    np.testing.assert_array_equal(cam.in_image(uv), [True, True, False, False, False, True, False])
    inside_border_2 = [False, False, False, False, False, True, False]
    np.testing.assert_array_equal(cam.in_image(uv, border=2), inside_border_2)
    assert cam.in_image(np.array([7.0, 3.0]), border=2)
    assert not cam.in_image(np.array([7.01, 3.0]), border=2)


def test_crop_to_multiple_of_kitti() -> None:
    cam, box = KITTI.crop_to_multiple(16)
    assert box == (5, 1, 1216, 368)
    assert cam.size == (1216, 368)
    assert cam.cx == pytest.approx(KITTI.cx - 5)
    assert cam.cy == pytest.approx(KITTI.cy - 1)
    assert (cam.fx, cam.fy) == (KITTI.fx, KITTI.fy)
    image = np.arange(370 * 1226, dtype=np.float32).reshape(370, 1226)
    cropped = crop_image(image, box)
    assert cropped.shape == (368, 1216)
    assert cropped.flags.c_contiguous and cropped.dtype == np.float32
    np.testing.assert_array_equal(cropped, image[1:369, 5:1221])
    rgb = np.zeros((370, 1226, 3), dtype=np.uint8)
    assert crop_image(rgb, box).shape == (368, 1216, 3)
    # already a multiple: nothing is cropped
    cam_same, box_same = TUM.crop_to_multiple(16)
    assert cam_same == TUM and box_same == (0, 0, 640, 480)


@SETTINGS
@given(cameras, st.integers(1, 64), st.integers(0, 2**32 - 1))
def test_crop_to_multiple_is_minimal_centred_and_consistent(cam: PinholeCamera, m: int, seed: int) -> None:
    if cam.width < m or cam.height < m:
        with pytest.raises(ValueError):
            cam.crop_to_multiple(m)
        return
    cropped, (left, top, w, h) = cam.crop_to_multiple(m)
    assert w % m == 0 and h % m == 0
    assert 0 <= cam.width - w < m and 0 <= cam.height - h < m
    assert left == (cam.width - w) // 2 and top == (cam.height - h) // 2
    assert cropped.size == (w, h)
    # The same 3D point lands on the same image content: uv_cropped = uv - (left, top).
    rng = np.random.default_rng(seed)
    pts = cam.unproject(rng.uniform(0, 100, (10, 2)), rng.uniform(1, 5, 10))
    np.testing.assert_allclose(cropped.project(pts), cam.project(pts) - [left, top], atol=1e-9)


def test_crop_validation() -> None:
    assert TUM.crop(10, 20, 100, 50) == PinholeCamera(525.0, 525.0, 309.5, 219.5, 100, 50)
    for box in [(-1, 0, 10, 10), (0, 0, 641, 10), (600, 0, 41, 10), (0, 0, 0, 10), (0, 471, 10, 10)]:
        with pytest.raises(ValueError):
            TUM.crop(*box)
    with pytest.raises(ValueError):
        crop_image(np.zeros((10, 10)), (5, 5, 6, 1))
    with pytest.raises(ValueError):
        crop_image(np.zeros(10), (0, 0, 1, 1))
    with pytest.raises(ValueError):
        crop_image(np.zeros((10, 10)), (0, 0, 1))  # type: ignore[arg-type]


def test_scaled_and_resized() -> None:
    assert TUM.scaled(0.5) == TUM.level(1)  # both are the image-border-preserving map
    s2 = TUM.scaled(2.0)
    assert s2.size == (1280, 960)
    assert (s2.fx, s2.cx, s2.cy) == (1050.0, 639.5, 479.5)
    # a 3D point projects to the resized pixel u' = (u + 0.5)·s - 0.5 (cv2.resize's pixel mapping)
    r = KITTI.resized(613, 200)
    p = np.array([[0.4, -0.3, 3.0]])
    u0, u1 = KITTI.project(p)[0], r.project(p)[0]
    np.testing.assert_allclose(u1, (u0 + 0.5) * [613 / 1226, 200 / 370] - 0.5, rtol=1e-14)
    for bad in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError):
            TUM.scaled(bad)


def test_dict_round_trip_through_json() -> None:
    d = json.loads(json.dumps(KITTI.to_dict()))
    assert PinholeCamera.from_dict(d) == KITTI
    assert set(d) == {"fx", "fy", "cx", "cy", "width", "height"}
    del d["cy"]
    with pytest.raises(ValueError, match="cy"):
        PinholeCamera.from_dict(d)


def test_validation() -> None:
    good = {"fx": 500.0, "fy": 500.0, "cx": 10.0, "cy": 10.0, "width": 20, "height": 20}
    for key, bad in [
        ("fx", 0.0),
        ("fy", -1.0),
        ("fx", np.nan),
        ("cx", np.inf),
        ("cy", "a"),
        ("width", 0),
        ("height", -3),
        ("width", 10.5),
        ("height", True),
    ]:
        with pytest.raises(ValueError):
            PinholeCamera(**{**good, key: bad})
    cam = PinholeCamera(**{**good, "width": np.int64(20), "fx": np.float32(500.0)})
    assert type(cam.width) is int and type(cam.fx) is float
    with pytest.raises(dataclasses.FrozenInstanceError):
        cam.fx = 1.0  # type: ignore[misc]
    with pytest.raises(ValueError):
        PinholeCamera.from_K(np.eye(4), 10, 10)
    skewed = TUM.K
    skewed[0, 1] = 0.5
    with pytest.raises(ValueError):
        PinholeCamera.from_K(skewed, 640, 480)
