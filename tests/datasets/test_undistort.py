"""Camera models (FOV, radial-tangential, equidistant), the Undistorter and calibration-file parsing."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from dmtrack.datasets import Sequence, open_sequence
from dmtrack.datasets.undistort import UndistortedSequence, Undistorter, read_calibration_file
from dmtrack.errors import InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.geometry.distortion import EquidistantModel, FOVModel, PinholeModel, RadTanModel, model_from_dict

W, H = 200, 152
FOV = FOVModel(150.0, 152.0, 99.5, 75.5, W, H, omega=0.92)
RADTAN = RadTanModel(160.0, 158.0, 101.0, 74.0, W, H, k1=-0.28, k2=0.07, p1=2e-4, p2=-3e-4, k3=0.0)
EQUI = EquidistantModel(140.0, 141.0, 99.0, 76.0, W, H, k1=0.05, k2=-0.01, k3=0.002, k4=-0.0003)


def _points(rng: np.random.Generator, n: int, radius: float) -> np.ndarray:
    return rng.uniform(-radius, radius, size=(n, 2))


# -- models ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("model,radius", [(FOV, 1.5), (RADTAN, 0.9), (EQUI, 2.5)])
def test_distort_undistort_round_trip(model, radius: float) -> None:
    rng = np.random.default_rng(1)
    xy = _points(rng, 2000, radius)
    back = model.undistort(model.distort(xy))
    np.testing.assert_allclose(back, xy, atol=1e-9)
    xy_d = model.distort(xy)
    np.testing.assert_allclose(model.distort(model.undistort(xy_d)), xy_d, atol=1e-9)
    assert model_from_dict(model.to_dict()) == model


def test_fov_formula_and_limits() -> None:
    # r_d = atan(2 r tan(ω/2)) / ω  (Devernay–Faugeras, PTAM/LSD-SLAM/DSO convention)
    w = FOV.omega
    x = np.array([[0.3, -0.4]])  # r = 0.5
    rd = math.atan(2 * 0.5 * math.tan(w / 2)) / w
    np.testing.assert_allclose(FOV.distort(x), x * rd / 0.5, rtol=1e-12)
    # the centre: scale 2 tan(ω/2)/ω, continuous
    np.testing.assert_allclose(FOV.distort(np.array([[1e-14, 0.0]]))[0, 0] / 1e-14, 2 * math.tan(w / 2) / w)
    # radii at or beyond π/(2ω) have no undistorted ray
    far = np.array([[math.pi / (2 * w) + 0.01, 0.0]])
    assert np.isnan(FOV.undistort(far)).all()
    # ω = 0 is the pinhole model
    pin = FOVModel(1, 1, 0, 0, 2, 2, omega=0.0)
    np.testing.assert_array_equal(pin.distort(x), x)
    with pytest.raises(ValueError, match="omega"):
        FOVModel(1, 1, 0, 0, 2, 2, omega=-0.1)


def test_radtan_matches_opencv() -> None:
    rng = np.random.default_rng(2)
    xy = _points(rng, 500, 0.8)
    pts = np.column_stack([xy, np.ones(len(xy))])
    K = np.array([[RADTAN.fx, 0, RADTAN.cx], [0, RADTAN.fy, RADTAN.cy], [0, 0, 1]])
    uv_cv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, np.array(RADTAN.coefficients))
    np.testing.assert_allclose(RADTAN.project(pts), uv_cv[:, 0], atol=1e-9)
    # and our inverse agrees with OpenCV's iterative undistortPoints (which is itself approximate)
    und_cv = cv2.undistortPoints(uv_cv, K, np.array(RADTAN.coefficients),
                                 criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14))
    np.testing.assert_allclose(RADTAN.unproject_pixels(uv_cv[:, 0]), und_cv[:, 0], atol=1e-6)


def test_equidistant_matches_opencv_fisheye() -> None:
    rng = np.random.default_rng(3)
    xy = _points(rng, 500, 2.0)
    K = np.array([[EQUI.fx, 0, EQUI.cx], [0, EQUI.fy, EQUI.cy], [0, 0, 1]])
    D = np.array([EQUI.k1, EQUI.k2, EQUI.k3, EQUI.k4])
    uv_cv = cv2.fisheye.distortPoints(xy[None].astype(np.float64), K, D)[0]
    np.testing.assert_allclose(EQUI.normalised_to_pixel(EQUI.distort(xy)), uv_cv, atol=1e-8)


def test_radtan_turning_point_is_invalid() -> None:
    # k1 < 0 alone: r(1 + k1 r²) turns at r = 1/sqrt(-3 k1); beyond it undistortion would be ambiguous
    m = RadTanModel(100, 100, 50, 50, 100, 100, k1=-0.3)
    assert m.max_radius == pytest.approx(1 / math.sqrt(0.9), abs=1e-3)
    rd = m.distort(np.array([[1.5, 0.0]]))  # a ray past the turning point
    back = m.undistort(rd)
    assert not np.allclose(back, [[1.5, 0.0]], atol=1e-6)  # never reported as the (ambiguous) far ray


# -- undistorter ----------------------------------------------------------------------------------------
def _line_image(model, lines: list[tuple[float, float, float]], sigma: float = 0.008) -> np.ndarray:
    """A distorted image (float32) of straight lines a·x + b·y = c in normalised undistorted coordinates."""
    v, u = np.mgrid[0:model.height, 0:model.width].astype(np.float64)
    xy = model.unproject_pixels(np.stack([u, v], -1))
    img = np.zeros((model.height, model.width))
    for a, b, c in lines:
        d = (a * xy[..., 0] + b * xy[..., 1] - c) / math.hypot(a, b)
        img = np.maximum(img, 200.0 * np.exp(-0.5 * (d / sigma) ** 2))
    return np.nan_to_num(img).astype(np.float32)


@pytest.mark.parametrize("model", [FOV, RADTAN, EQUI], ids=["fov", "radtan", "equidistant"])
@pytest.mark.parametrize("axis", [0, 1], ids=["horizontal", "vertical"])
def test_undistorted_lines_are_straight(model, axis: int) -> None:
    # lines y = c (axis 0) or x = c (axis 1) in normalised undistorted coordinates
    consts = (0.25, -0.3) if axis == 0 else (0.35, -0.4)
    lines = [((0.0, 1.0) if axis == 0 else (1.0, 0.0)) + (c,) for c in consts]
    distorted = _line_image(model, lines)
    und = Undistorter.create(model, "crop")
    out = und(distorted)
    cam = und.camera
    if axis == 1:  # look at columns as rows
        out, distorted = out.T, distorted.T
    f, c0, n = (cam.fy, cam.cy, cam.width) if axis == 0 else (cam.fx, cam.cx, cam.height)
    for c in consts:
        row = f * c + c0  # the line's row (column) in the output pinhole camera
        lo, hi = int(row) - 6, int(row) + 7
        band = out[lo:hi].astype(np.float64)
        cols = np.flatnonzero(band.sum(0) > 100)
        assert cols.size > n * 0.9
        centroid = (band[:, cols] * np.arange(lo, hi)[:, None]).sum(0) / band[:, cols].sum(0)
        fit = np.polyfit(cols, centroid, 2)
        assert abs(fit[0]) * n**2 < 0.3  # no curvature left (pixels over the image width)
        np.testing.assert_allclose(centroid, row, atol=0.2)
        # in the distorted input the same line is visibly curved
        rows_in = distorted[lo - 20:hi + 20].argmax(0) if lo >= 20 else distorted[:hi + 20].argmax(0)
        strong = distorted[max(lo - 20, 0):hi + 20].max(0) > 100
        assert np.ptp(rows_in[strong]) >= 2


@pytest.mark.parametrize("model", [FOV, RADTAN, EQUI], ids=["fov", "radtan", "equidistant"])
def test_crop_and_full_modes(model) -> None:
    crop = Undistorter.create(model, "crop")
    assert crop.camera.width % 16 == 0 and crop.camera.height % 16 == 0
    assert (crop.camera.width, crop.camera.height) == (W - W % 16, H - H % 16)
    assert crop.valid.all()  # crop: no invalid pixel
    assert (crop.map_x > 0).all() and (crop.map_x < W - 1).all() and (crop.map_y < H - 1).all()
    img = np.full((H, W), 77, np.uint8)
    assert (crop(img) == 77).all()
    full = Undistorter.create(model, "full", size=(320, 240))
    assert (full.camera.width, full.camera.height) == (320, 240)
    assert not full.valid.all()  # corners outside the input image
    # every input pixel is seen: the undistorted input border lies inside the full output image
    border = np.array([[0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1], [W / 2, 0], [0, H / 2]], float)
    ray = model.unproject_pixels(border)
    uv = full.camera.project(np.column_stack([ray, np.ones(len(ray))]))
    assert full.camera.in_image(uv, border=-1e-6).all()
    # crop shows less of the scene than full: a smaller extent in normalised coordinates
    assert (crop.camera.width - 1) / crop.camera.fx < (full.camera.width - 1) / full.camera.fx
    assert (crop.camera.height - 1) / crop.camera.fy < (full.camera.height - 1) / full.camera.fy


def test_none_mode_and_given_camera() -> None:
    pin = PinholeModel(100, 100, 99.5, 75.5, W, H)
    none = Undistorter.create(pin, "none")
    assert none.map_x is None and (none.camera.width, none.camera.height) == (192, 144)
    img = np.arange(W * H, dtype=np.float32).reshape(H, W)
    np.testing.assert_array_equal(none(img), img[4:148, 4:196])
    given = Undistorter.create(RADTAN, PinholeCamera(120, 120, 80, 60, 170, 130))
    assert (given.camera.width, given.camera.height) == (160, 128)
    assert given.camera.cx == 75 and given.camera.cy == 59  # centre crop of the requested camera
    with pytest.raises(InputError, match="image is 10x10, the calibration is for 200x152"):
        given(np.zeros((10, 10), np.uint8))


# -- calibration files ------------------------------------------------------------------------------------
def test_dso_relative_fov_file(tmp_path: Path) -> None:
    p = tmp_path / "camera.txt"
    p.write_text("0.535719308086809 0.669566858850269 0.493248545285398 0.500408664348414 0.897966326944875\n"
                 "1280 1024\ncrop\n640 480\n")
    c = read_calibration_file(p, "dso")
    m = c.model
    assert isinstance(m, FOVModel) and c.relative and c.output == "crop" and c.output_size == (640, 480)
    assert m.fx == pytest.approx(0.535719308086809 * 1280)
    assert m.cx == pytest.approx(0.493248545285398 * 1280 - 0.5)  # DSO's −0.5 pixel-centre shift
    assert m.cy == pytest.approx(0.500408664348414 * 1024 - 0.5)
    p.write_text("RadTan 458.654 457.296 367.215 248.375 -0.28340811 0.07395907 0.00019359 1.76187114e-05\n"
                 "752 480\n0.6 0.9 0.5 0.5 0\n752 480\n")
    c = read_calibration_file(p, "dso")
    assert isinstance(c.model, RadTanModel) and not c.relative and c.model.k1 == pytest.approx(-0.28340811)
    assert isinstance(c.output, PinholeCamera) and c.output.fx == pytest.approx(0.6 * 752)
    assert c.output.cx == pytest.approx(0.5 * 752 - 0.5)
    p.write_text("KannalaBrandt 0.3 0.3 0.5 0.5 0.01 0.002 0 0\n100 80\nfull\n96 80\n")
    c = read_calibration_file(p, "dso")
    assert isinstance(c.model, EquidistantModel) and c.model.cx == pytest.approx(49.5)
    p.write_text("0.5 0.6 0.5 0.5 0\n100 80\nnone\n100 80\n")
    assert isinstance(read_calibration_file(p, "dso").model, PinholeModel)


def test_lsdslam_conventions(tmp_path: Path) -> None:
    p = tmp_path / "cameraCalibration.cfg"
    # FOV line: always relative (×size, −0.5) in LSD-SLAM
    p.write_text("0.527334 0.827306 0.473568 0.499436 0.928161\n752 480\ncrop\n640 480\n")
    c = read_calibration_file(p, "lsdslam")
    assert isinstance(c.model, FOVModel) and c.model.cx == pytest.approx(0.473568 * 752 - 0.5)
    # OpenCV line: pixels
    p.write_text("500 500 350 240 -0.1 0.01 0 0\n752 480\ncrop\n640 480\n")
    c = read_calibration_file(p, "lsdslam")
    assert isinstance(c.model, RadTanModel) and c.model.cx == 350 and not c.relative
    # OpenCV line with cx < 1: LSD-SLAM multiplies by the size without the −0.5 shift
    p.write_text("0.6 0.8 0.5 0.5 0 0 0 0\n100 80\nnone\n100 80\n")
    c = read_calibration_file(p, "lsdslam")
    assert c.model.cx == 50.0 and c.model.fy == pytest.approx(64.0)


@pytest.mark.parametrize(
    "text,match",
    [
        ("1 2 3\n10 10\ncrop\n10 10\n", r"camera.txt:1: expected 5 numbers"),
        ("Fisheye 1 2 3 4 5\n10 10\ncrop\n10 10\n", r"camera.txt:1: unknown camera model 'Fisheye'"),
        ("FOV 1 2 3 4\n10 10\ncrop\n10 10\n", r"camera.txt:1: FOV model needs 5 numbers, found 4"),
        ("0.5 0.5 0.5 0.5 0.9\n10 ten\ncrop\n10 10\n", r"camera.txt:2: input image size"),
        ("0.5 0.5 0.5 0.5 0.9\n10 10\nsquash\n10 10\n", r"camera.txt:3: output calibration"),
        ("0.5 0.5 0.5 0.5 0.9\n10 10\nnone\n12 10\n", r"camera.txt:4: 'none' \(no rectification\)"),
        ("0.5 0.5 0.5 0.5 0.9\n10 10\n", r"camera.txt: calibration file needs 4 lines"),
    ],
)
def test_calibration_errors(tmp_path: Path, text: str, match: str) -> None:
    p = tmp_path / "camera.txt"
    p.write_text(text)
    with pytest.raises(InputError, match=match):
        read_calibration_file(p, "dso")


def test_undistorted_sequence_wrapper(tmp_path: Path) -> None:
    root = tmp_path / "seq"
    (root / "images").mkdir(parents=True)
    lines = [(0.0, 1.0, 0.2), (1.0, 0.0, -0.3)]
    img = np.clip(_line_image(RADTAN, lines), 0, 255).astype(np.uint8)
    for i in range(3):
        cv2.imwrite(str(root / "images" / f"{i:03d}.png"), img)
    seq = open_sequence(root)
    und = UndistortedSequence(seq, Undistorter.create(RADTAN, "crop"))
    assert isinstance(und, Sequence)
    assert (und.width, und.height) == (192, 144) and und.camera.width == 192
    assert und.details["undistortion"] == "crop" and und.details["distortion_model"]["model"] == "radtan"
    f = und[1]
    assert f.image.shape == (144, 192) and f.index == 1
    np.testing.assert_array_equal(f.image, und.undistorter(img))
    assert len(und.slice(1, 3)) == 2
    with pytest.raises(InputError, match="calibration is for 100x80"):
        UndistortedSequence(seq, Undistorter.create(PinholeModel(50, 50, 50, 40, 100, 80), "crop"))


def test_radtan_text_reads_back_exactly(tmp_path: Path) -> None:
    """DSO's RadTan file as dmtrack writes it (the checkerboard calibration and calibrate-from-video share it): the
    model read back is the model written, to the last bit; a k3, which the format cannot hold, is refused."""
    from dmtrack.datasets.undistort import radtan_text

    (tmp_path / "cam.txt").write_text(radtan_text(RADTAN, "crop"))
    got = read_calibration_file(tmp_path / "cam.txt")
    assert got.model == RADTAN and (tmp_path / "cam.txt").read_text().splitlines()[1:] == [f"{W} {H}", "crop",
                                                                                             f"{W} {H}"]  # fmt: skip
    with pytest.raises(ValueError, match="k3"):
        radtan_text(RadTanModel(160.0, 158.0, 101.0, 74.0, W, H, k1=-0.2, k3=0.01), "crop")
