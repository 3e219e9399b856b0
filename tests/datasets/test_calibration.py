"""Camera calibration (``dmtrack calibrate-camera``) on rendered views of a board seen by a known camera.

The views are rendered, not faked: every pixel of a 640×480 image with known K and radial-tangential distortion is
traced back (``cv2.undistortPoints``, 3×3 supersamples per pixel) to the board's plane and coloured by the square it
hits; then blurred and given noise.  The calibration must recover K to 0.5 % and k1 to ±0.01, reject a view rendered
through a different lens, write a DSO file that reads back exactly, and that file must straighten the board's lines
and drive ``dmtrack run``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from dmtrack.datasets import open_sequence, read_calibration_file
from dmtrack.datasets.calibration import Board, calibrate_camera, parse_board, write_calibration
from dmtrack.datasets.cli_calibrate import add_calibrate_parser
from dmtrack.datasets.undistort import UndistortedSequence
from dmtrack.errors import InputError
from dmtrack.geometry.distortion import RadTanModel

W, H = 640, 480
K_TRUE = np.array([[500.0, 0.0, 320.0], [0.0, 502.0, 240.0], [0.0, 0.0, 1.0]])
DIST_TRUE = np.array([-0.1, 0.02, 0.0005, -0.0003, 0.0])
COLS, ROWS, SQ = 9, 6, 0.025
SS = 3  # supersamples per pixel side (anti-aliasing)
# board poses: rotation vector (rad), distance of the board's centre (m), its offset from the optical axis (m)
POSES = [
    ((0, 0, 0), 0.30, (0, 0)), ((0.5, 0, 0), 0.33, (0, 0)), ((-0.5, 0, 0.1), 0.33, (0, 0)),
    ((0, 0.5, 0), 0.33, (0, 0)), ((0, -0.5, -0.1), 0.33, (0, 0)), ((0.2, 0.2, 0.1), 0.32, (0.06, 0.045)),
    ((-0.2, 0.2, -0.1), 0.32, (-0.06, 0.045)), ((0.2, -0.2, 0.15), 0.32, (0.06, -0.045)),
    ((-0.2, -0.2, 0), 0.32, (-0.06, -0.045)), ((0.15, -0.15, 0.8), 0.30, (0, 0)), ((0.1, 0.3, -0.3), 0.25, (0, 0)),
]


def _rays(K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Normalised undistorted coordinates (H·SS, W·SS, 2) of every supersample of the distorted image."""
    uu, vv = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    pts = np.stack([uu.ravel(), vv.ravel()], -1).reshape(-1, 1, 2)
    xy = cv2.undistortPoints(pts, K, dist, None, None, None,
                             (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 1e-12)).reshape(H, W, 2)
    back = cv2.projectPoints(np.c_[xy.reshape(-1, 2), np.ones(H * W)], np.zeros(3), np.zeros(3), K, dist)[0]
    assert np.abs(back.reshape(-1, 2) - pts.reshape(-1, 2)).max() < 1e-6  # the inverse is exact
    # a smooth field: bilinear resampling puts supersample k of pixel u at u + (k + 0.5) / SS − 0.5
    return cv2.resize(xy, (W * SS, H * SS), interpolation=cv2.INTER_LINEAR)


def _board_coordinates(rays: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each ray meets the board's plane z = 0 (board units)."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    Hinv = np.linalg.inv(np.column_stack([R[:, 0], R[:, 1], tvec]))
    x, y = rays[..., 0], rays[..., 1]
    z = Hinv[2, 0] * x + Hinv[2, 1] * y + Hinv[2, 2]
    return (Hinv[0, 0] * x + Hinv[0, 1] * y + Hinv[0, 2]) / z, (Hinv[1, 0] * x + Hinv[1, 1] * y + Hinv[1, 2]) / z


def _finish(values: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    img = values.reshape(H, SS, W, SS).mean(axis=(1, 3))  # box filter over the supersamples
    img = cv2.GaussianBlur(img, (0, 0), 0.6) + rng.normal(0.0, 1.5, img.shape)
    return np.clip(img.round(), 0, 255).astype(np.uint8)


def _pose(rotation: tuple, distance: float, offset: tuple, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Board pose putting board point ``centre`` at ``(offset, distance)`` in the camera."""
    R, _ = cv2.Rodrigues(np.asarray(rotation, np.float64))
    return cv2.Rodrigues(R)[0].ravel(), np.array([offset[0], offset[1], distance]) - R @ centre


def render_checkerboard(rays: np.ndarray, rotation: tuple, distance: float, offset: tuple,
                        rng: np.random.Generator) -> np.ndarray:
    """A COLS×ROWS-inner-corner checkerboard (first inner corner at the board origin) with a white margin."""
    rvec, tvec = _pose(rotation, distance, offset, np.array([(COLS - 1) * SQ / 2, (ROWS - 1) * SQ / 2, 0.0]))
    X, Y = _board_coordinates(rays, rvec, tvec)
    i, j = np.floor(X / SQ), np.floor(Y / SQ)
    squares = (i >= -1) & (i <= COLS - 1) & (j >= -1) & (j <= ROWS - 1)
    margin = (X >= -2 * SQ) & (X <= (COLS + 1) * SQ) & (Y >= -2 * SQ) & (Y <= (ROWS + 1) * SQ)
    values = np.full(X.shape, 90.0)
    values[margin] = 235.0
    values[squares & ((i + j) % 2 == 0)] = 25.0
    return _finish(values, rng)


def render_texture(rays: np.ndarray, texture: np.ndarray, px_per_unit: float, rotation: tuple, distance: float,
                   offset: tuple, rng: np.random.Generator) -> np.ndarray:
    """A flat board printed from ``texture`` (its top-left edge at the board origin), e.g. a ChArUco board."""
    size = np.array([texture.shape[1], texture.shape[0], 0.0]) / px_per_unit
    rvec, tvec = _pose(rotation, distance, offset, size / 2)
    X, Y = _board_coordinates(rays, rvec, tvec)
    mx, my = (X * px_per_unit - 0.5).astype(np.float32), (Y * px_per_unit - 0.5).astype(np.float32)
    values = cv2.remap(texture, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=90)
    return _finish(values.astype(np.float64), rng)


@pytest.fixture(scope="module")
def rays() -> np.ndarray:
    return _rays(K_TRUE, DIST_TRUE)


@pytest.fixture(scope="module")
def views(tmp_path_factory: pytest.TempPathFactory, rays: np.ndarray) -> Path:
    """11 views of the checkerboard, plus view11.png seen through another lens (k1 = +0.25): an outlier."""
    folder = tmp_path_factory.mktemp("views")
    rng = np.random.default_rng(0)
    for k, pose in enumerate(POSES):
        cv2.imwrite(str(folder / f"view{k:02d}.png"), render_checkerboard(rays, *pose, rng))
    other = _rays(K_TRUE, np.array([0.25, 0.0, 0.0, 0.0, 0.0]))
    cv2.imwrite(str(folder / "view11.png"), render_checkerboard(other, (0.3, -0.3, 0.2), 0.30, (0, 0), rng))
    return folder


def _check_intrinsics(calib, tol: float = 0.005, k1_tol: float = 0.01) -> None:  # noqa: ANN001
    for got, want in ((calib.fx, 500.0), (calib.fy, 502.0), (calib.cx, 320.0), (calib.cy, 240.0)):
        assert abs(got / want - 1) < tol, (got, want)
    assert abs(calib.coefficients[0] - DIST_TRUE[0]) < k1_tol, calib.coefficients


def test_recovers_a_known_camera_and_rejects_the_outlier_view(views: Path) -> None:
    calib = calibrate_camera(views, Board(COLS, ROWS, SQ))
    _check_intrinsics(calib)
    assert calib.image_size == (W, H)
    assert list(calib.rejected) == ["view11.png"] and calib.rejected["view11.png"] > 1.0  # pixels
    assert sorted(calib.view_errors) == [f"view{k:02d}.png" for k in range(11)]
    assert calib.rms < 0.3 and max(calib.view_errors.values()) < 0.3
    assert calib.detected == 12 and calib.frames == 12
    # the square size scales the board poses, not the intrinsics
    in_mm = calibrate_camera(views, Board(COLS, ROWS, 25.0))
    np.testing.assert_allclose(in_mm.K, calib.K, rtol=1e-6)


def test_cli_writes_a_calibration_that_round_trips_and_undistorts(views: Path, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser(prog="dmtrack")
    add_calibrate_parser(parser.add_subparsers())
    out = tmp_path / "cam" / "camera.txt"
    args = parser.parse_args(["calibrate-camera", str(views), "--board", "9x6", "--square", "0.025", "--out", str(out)])
    assert args.func(args) == 0
    printed = capsys.readouterr().out
    assert "RMS reprojection error" in printed and "view11.png" in printed and str(out) in printed

    result = json.loads((tmp_path / "cam" / "camera.json").read_text())
    assert result["views_used"] == 11 and list(result["rejected_views_px"]) == ["view11.png"]
    assert result["image_size"] == [W, H] and result["board"]["inner_corners"] == [9, 6]
    cal = read_calibration_file(out)
    # "crop" written out as its output camera (DSO's own crop folds a k1 < 0 lens): the camera dmtrack's crop gives
    crop = read_calibration_file(out).model
    from dmtrack.datasets.undistort import Undistorter
    expected = Undistorter.create(crop, "crop", (W, H), multiple=1).camera
    assert isinstance(cal.model, RadTanModel) and cal.output_size == (W, H) and not isinstance(cal.output, str)
    assert [cal.output.fx, cal.output.fy, cal.output.cx, cal.output.cy] == pytest.approx(
        [expected.fx, expected.fy, expected.cx, expected.cy], abs=1e-6)
    m = cal.model
    assert (m.fx, m.fy, m.cx, m.cy, m.k1, m.k2, m.p1, m.p2) == tuple(
        result[k] for k in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"))  # exactly: the numbers round-trip
    assert abs(m.fx / 500 - 1) < 0.005 and abs(m.k1 + 0.1) < 0.01

    # --intrinsics FILE: the frames are undistorted with it, so the board's rows and columns become straight
    raw = open_sequence(views)
    seq = open_sequence(views, intrinsics=str(out))
    assert isinstance(seq, UndistortedSequence) and seq.details["intrinsics_source"] == str(out)
    assert seq.camera is not None and (seq.width, seq.height) == (seq.camera.width, seq.camera.height)

    def bend(image: np.ndarray) -> float:
        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        found, corners = cv2.findChessboardCorners(grey, (COLS, ROWS))
        assert found
        grid = cv2.cornerSubPix(grey, corners, (5, 5), (-1, -1), (3, 50, 1e-4)).reshape(ROWS, COLS, 2)
        residuals = []
        for line in [*grid, *grid.transpose(1, 0, 2)]:
            centred = line - line.mean(axis=0)
            normal = np.linalg.svd(centred)[2][1]
            residuals.append(np.sqrt(np.mean((centred @ normal) ** 2)))
        return float(np.mean(residuals))

    before = np.mean([bend(raw[i].image) for i in (5, 6, 7, 8, 10)])
    after = np.mean([bend(seq[i].image) for i in (5, 6, 7, 8, 10)])
    assert after < before / 3, (before, after)


def test_run_reads_the_calibration_file(views: Path, sample_dir: Path, tmp_path: Path) -> None:
    """``run_to_directory(..., intrinsics=FILE)``: fx fy cx cy files give the same bytes as the string, and the
    file calibrate-camera wrote undistorts the frames the odometry gets (the sample is 640×480 as the views)."""
    from dmtrack.pipeline import run_to_directory

    plain = tmp_path / "k.txt"
    plain.write_text("585 585 320 240\n")
    a = run_to_directory(sample_dir, tmp_path / "a", max_frames=6, intrinsics="585,585,320,240", depth_images=False)
    b = run_to_directory(sample_dir, tmp_path / "b", max_frames=6, intrinsics=str(plain), depth_images=False)
    assert (tmp_path / "a" / "trajectory.txt").read_bytes() == (tmp_path / "b" / "trajectory.txt").read_bytes()
    assert a.metrics["tracked_frames"] == b.metrics["tracked_frames"] == 6

    camera_txt = tmp_path / "camera.txt"
    write_calibration(calibrate_camera(views, Board(COLS, ROWS, SQ)), camera_txt)
    seq = open_sequence(sample_dir, intrinsics=camera_txt)
    r = run_to_directory(sample_dir, tmp_path / "c", max_frames=4, intrinsics=str(camera_txt), depth_images=False)
    assert r.metrics["total_frames"] == 4 and r.metrics["processed_frames"] == 4
    assert isinstance(seq, UndistortedSequence) and seq.camera is not None
    assert (r.metrics["width"], r.metrics["height"]) == (seq.camera.width, seq.camera.height) == (W, H)
    assert seq.camera.fx < 0.97 * 499  # "crop": the largest valid rectangle, stretched to 640×480
    raw = open_sequence(sample_dir)[0].image.astype(float)
    assert np.abs(seq[0].image.astype(float) - raw).mean() > 5  # the odometry got resampled frames

    with pytest.raises(InputError, match="neither four numbers"):
        open_sequence(sample_dir, intrinsics=str(tmp_path / "missing.txt"))
    bad = tmp_path / "bad.txt"
    bad.write_text("RadTan 500 500 320 240 -0.1 0 0\n640 480\ncrop\n640 480\n")
    with pytest.raises(InputError, match=r"bad\.txt:1: RadTan model needs 8 numbers"):
        open_sequence(sample_dir, intrinsics=str(bad))
    other = tmp_path / "other.txt"
    other.write_text(camera_txt.read_text().replace("640 480", "1280 960"))
    with pytest.raises(InputError, match=r"other\.txt: the calibration is for 1280x960 images, the sequence has 640"):
        open_sequence(sample_dir, intrinsics=str(other))


def test_charuco_board(tmp_path: Path, rays: np.ndarray) -> None:
    aruco = cv2.aruco
    board = aruco.CharucoBoard((COLS + 1, ROWS + 1), SQ, 0.75 * SQ, aruco.getPredefinedDictionary(aruco.DICT_5X5_100))
    texture = board.generateImage(((COLS + 1) * 100, (ROWS + 1) * 100), marginSize=0, borderBits=1)  # 100 px/square
    texture = cv2.copyMakeBorder(texture, 50, 50, 50, 50, cv2.BORDER_CONSTANT, value=235)
    rng = np.random.default_rng(1)
    for k, pose in enumerate(POSES[:8]):
        cv2.imwrite(str(tmp_path / f"c{k}.png"), render_texture(rays, texture, 100 / SQ, *pose, rng))
    calib = calibrate_camera(tmp_path, Board(COLS, ROWS, SQ, charuco="DICT_5X5_100"))
    _check_intrinsics(calib)
    assert len(calib.view_errors) == 8 and calib.rms < 0.3
    # the same images are no plain checkerboard of another size, and an unknown dictionary is named
    with pytest.raises(InputError, match="unknown ArUco dictionary"):
        calibrate_camera(tmp_path, Board(COLS, ROWS, SQ, charuco="DICT_9X9_1"))


def test_from_a_camera_every_nth_frame(views: Path, tmp_path: Path) -> None:
    """``camera:0`` whose device is a video of the views (each held for 3 frames): real OpenCV decoding."""
    video = tmp_path / "views.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (W, H))
    writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 100)
    for k in range(11):
        frame = cv2.cvtColor(cv2.imread(str(views / f"view{k:02d}.png"), cv2.IMREAD_GRAYSCALE), cv2.COLOR_GRAY2BGR)
        for _ in range(3):
            writer.write(frame)
    writer.release()
    opened: list[tuple[object, cv2.VideoCapture]] = []

    def device(target: object) -> cv2.VideoCapture:
        cap = cv2.VideoCapture(str(video))
        opened.append((target, cap))
        return cap

    found: list[str] = []
    calib = calibrate_camera("camera:0", Board(COLS, ROWS, SQ), every=3, max_views=20, capture=device,
                             on_view=lambda name, n: found.append(name))
    assert opened[0][0] == 0 and not opened[0][1].isOpened()  # the device index; released afterwards
    assert found == [f"camera:0 frame {3 * k}" for k in range(11)] and calib.frames == 11
    _check_intrinsics(calib, tol=0.01, k1_tol=0.02)  # through JPEG compression
    # a live source stops at max_views
    first = calibrate_camera("camera:0", Board(COLS, ROWS, SQ), every=3, max_views=4, capture=device)
    assert first.frames == 4 and len(first.view_errors) + len(first.rejected) == 4
    assert not opened[1][1].isOpened()
    # the same video as a file, every 6th frame
    assert calibrate_camera(video, Board(COLS, ROWS, SQ), every=6).frames == 6


def test_clear_errors(tmp_path: Path, views: Path) -> None:
    blank = tmp_path / "blank"
    blank.mkdir()
    for k in range(3):
        cv2.imwrite(str(blank / f"{k}.png"), np.full((H, W), 128, np.uint8))
    with pytest.raises(InputError, match=r"blank: no 9x6 checkerboard \(inner corners\) found in any of the 3 frames"):
        calibrate_camera(blank, Board(COLS, ROWS, SQ))

    mixed = tmp_path / "mixed"
    mixed.mkdir()
    (mixed / "a.png").write_bytes((views / "view00.png").read_bytes())
    cv2.imwrite(str(mixed / "b.png"), np.full((240, 320), 128, np.uint8))
    with pytest.raises(InputError, match=r"mixed/b\.png: image is 320x240, the first one \(a\.png\) is 640x480"):
        calibrate_camera(mixed, Board(COLS, ROWS, SQ))

    few = tmp_path / "few"
    few.mkdir()
    for k in (0, 1):
        (few / f"v{k}.png").write_bytes((views / f"view0{k}.png").read_bytes())
    with pytest.raises(InputError, match=r"few: only 2 usable views \(at least 3"):
        calibrate_camera(few, Board(COLS, ROWS, SQ))

    with pytest.raises(InputError, match="expected COLUMNSxROWS"):
        parse_board("9by6")
    assert parse_board("9x6") == (9, 6)
    with pytest.raises(InputError, match="square size"):
        Board(9, 6, 0.0)
    with pytest.raises(InputError, match="no such folder or video file"):
        calibrate_camera(tmp_path / "nowhere", Board(COLS, ROWS, SQ))
    with pytest.raises(InputError, match="cannot open camera:0"):
        calibrate_camera("camera:0", Board(COLS, ROWS, SQ), capture=lambda t: cv2.VideoCapture(str(tmp_path / "x.avi")))
