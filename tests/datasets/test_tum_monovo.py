"""TUM monoVO reader on a small sequence written here in the official layout (images.zip, relative FOV camera.txt,
times.txt with exposures, photometric calibration, groundtruthSync.txt with NaN rows)."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmtrack.cli import main
from dmtrack.datasets import detect_format, open_sequence
from dmtrack.datasets.tum_monovo import open_tum_monovo
from dmtrack.errors import InputError
from dmtrack.geometry.distortion import FOVModel

W_IN, H_IN = 160, 128
REL = (0.62, 0.78, 0.497, 0.502, 0.85)  # fx/w fy/h cx/w cy/h omega, as the dataset's camera.txt
MODEL = FOVModel(REL[0] * W_IN, REL[1] * H_IN, REL[2] * W_IN - 0.5, REL[3] * H_IN - 0.5, W_IN, H_IN, omega=REL[4])
N = 6
T0 = 1433184983.043186


def _points() -> np.ndarray:
    g = np.stack(np.meshgrid(np.linspace(-1.2, 1.2, 6), np.linspace(-0.9, 0.9, 5)), -1).reshape(-1, 2)
    z = 4.0 + 0.3 * np.sin(3 * g[:, 0]) + 0.2 * g[:, 1]
    return np.column_stack([g * z[:, None] / 3.0, z])


def _poses(n: int = N) -> np.ndarray:
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.from_rotvec(np.linspace(0, 0.06, n)[:, None] * np.array([0.3, 1.0, 0.1])).as_matrix()
    T[:, :3, 3] = np.linspace(0, 0.25, n)[:, None] * np.array([1.0, -0.2, 0.3])
    return T


def _render(uv: np.ndarray, w: int, h: int, sigma: float = 1.3) -> np.ndarray:
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    img = np.full((h, w), 20.0)
    for x, y in uv:
        if np.isfinite(x):
            img += 210.0 * np.exp(-((u - x) ** 2 + (v - y) ** 2) / (2 * sigma**2))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _centroid(img: np.ndarray, x: float, y: float, r: int = 4) -> tuple[float, float]:
    xi, yi = int(round(x)), int(round(y))
    patch = img[yi - r:yi + r + 1, xi - r:xi + r + 1].astype(np.float64) - 20.0
    patch = np.clip(patch, 0, None)
    vv, uu = np.mgrid[yi - r:yi + r + 1, xi - r:xi + r + 1]
    return float((patch * uu).sum() / patch.sum()), float((patch * vv).sum() / patch.sum())


def write_monovo(root: Path, camera_txt: str | None = None, images: list[np.ndarray] | None = None,
                 unzipped: bool = False) -> np.ndarray:
    """Write sequence_NN in the official layout; returns the true camera-to-world poses."""
    root.mkdir(parents=True)
    poses = _poses()
    X = _points()
    if images is None:
        images = []
        for T in poses:
            Xc = (np.linalg.inv(T) @ np.column_stack([X, np.ones(len(X))]).T).T[:, :3]
            images.append(_render(MODEL.project(Xc), W_IN, H_IN))
    if unzipped:
        (root / "images").mkdir()
        for i, img in enumerate(images):
            cv2.imwrite(str(root / "images" / f"{i:05d}.png"), img)
    else:
        with zipfile.ZipFile(root / "images.zip", "w") as z:
            for i in range(len(images)):  # stored out of order: the reader sorts by name
                j = len(images) - 1 - i
                z.writestr(f"{j:05d}.jpg", cv2.imencode(".jpg", images[j], [cv2.IMWRITE_JPEG_QUALITY, 100])[1])
    stamps = T0 + np.arange(N) * 0.05
    (root / "times.txt").write_text("".join(f"{i:05d} {t:.6f} {10.0 + i:.4f}\n" for i, t in enumerate(stamps)))
    if camera_txt is None:
        camera_txt = " ".join(f"{v}" for v in REL) + f"\n{W_IN} {H_IN}\ncrop\n128 96\n"
    (root / "camera.txt").write_text(camera_txt)
    lines = []
    for i, (t, T) in enumerate(zip(stamps, poses, strict=True)):
        if i in (2, 3):  # the motion capture only sees the start and end segments
            lines.append(f"{t:.6f} " + " ".join(["NaN"] * 7))
        else:
            q = Rotation.from_matrix(T[:3, :3]).as_quat()
            lines.append(f"{t:.6f} " + " ".join(f"{v:.9f}" for v in (*T[:3, 3], *q)))
    (root / "groundtruthSync.txt").write_text("\n".join(lines) + "\n")
    return poses


def test_layout_zip_and_groundtruth(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    root = tmp_path / "sequence_07"
    true_poses = write_monovo(root)
    # the reader must never unpack the archive
    monkeypatch.setattr(zipfile.ZipFile, "extractall", lambda *a, **k: pytest.fail("extractall called"))
    monkeypatch.setattr(zipfile.ZipFile, "extract", lambda *a, **k: pytest.fail("extract called"))
    assert detect_format(root) == "tum-monovo"
    seq = open_sequence(root)
    assert len(seq) == N and (seq.width, seq.height) == (128, 96)
    np.testing.assert_allclose(seq.timestamps, T0 + np.arange(N) * 0.05)
    np.testing.assert_allclose(seq.exposures, 10.0 + np.arange(N))
    assert seq.details["undistortion"] == "crop" and seq.details["images"] == "images.zip"
    # ground truth only at the start and end segments
    assert seq.has_groundtruth and len(seq.groundtruth) == 4
    assert seq[2].pose is None and seq[3].pose is None
    np.testing.assert_allclose(seq[5].pose, true_poses[5], atol=1e-8)
    np.testing.assert_allclose(seq.groundtruth.poses, true_poses[[0, 1, 4, 5]], atol=1e-8)
    assert not (root / "images").exists()


def test_projected_points_land_on_the_dots(tmp_path: Path) -> None:
    """The undistorted frames, the output camera and the ground truth agree: projecting the scene points with
    the reader's pose and camera hits the dots drawn in the (distorted) recorded images."""
    root = tmp_path / "sequence_01"
    true_poses = write_monovo(root)
    seq = open_sequence(root)
    cam = seq.camera
    X = np.column_stack([_points(), np.ones(len(_points()))])
    errors = []
    for i in (0, 1, 4, 5):
        f = seq[i]
        uv = cam.project((np.linalg.inv(f.pose) @ X.T).T[:, :3])
        inside = cam.in_image(uv, border=6)
        assert inside.sum() >= 10
        for x, y in uv[inside]:
            cx, cy = _centroid(f.image, x, y)
            errors.append(np.hypot(cx - x, cy - y))
    errors = np.asarray(errors)
    assert errors.max() < 0.35 and errors.mean() < 0.12
    # a camera without DSO's −0.5 pixel-centre shift is visibly worse: the convention matters here
    shifted = type(cam)(cam.fx, cam.fy, cam.cx + 0.5, cam.cy + 0.5, cam.width, cam.height)
    f = seq[0]
    uv = shifted.project((np.linalg.inv(true_poses[0]) @ X.T).T[:, :3])
    inside = shifted.in_image(uv, border=6)
    bad = [np.hypot(*np.subtract(_centroid(f.image, x, y), (x, y))) for x, y in uv[inside]]
    assert np.mean(bad) > 0.3


def test_photometric_calibration(tmp_path: Path) -> None:
    root = tmp_path / "sequence_02"
    rng = np.random.default_rng(5)
    images = [rng.integers(0, 256, (H_IN, W_IN), dtype=np.uint8) for _ in range(N)]
    write_monovo(root, camera_txt=f"Pinhole 100 100 79.5 63.5 0\n{W_IN} {H_IN}\nnone\n{W_IN} {H_IN}\n",
                 images=images, unzipped=True)
    G = 1000.0 * (np.arange(256) / 255.0) ** 2.2 + 3.0 * np.arange(256)  # strictly increasing
    (root / "pcalib.txt").write_text(" ".join(f"{g:.6f}" for g in G) + "\n")
    v, u = np.mgrid[0:H_IN, 0:W_IN]
    vig = 1.0 - 0.6 * (((u - 80) / 80.0) ** 2 + ((v - 64) / 64.0) ** 2) / 2
    cv2.imwrite(str(root / "vignette.png"), np.rint(vig * 50000).astype(np.uint16))
    plain = open_tum_monovo(root)
    assert (plain.width, plain.height) == (W_IN, H_IN) and plain.details["photometric"] == "off"
    np.testing.assert_array_equal(plain[3].image, images[3])
    seq = open_tum_monovo(root, photometric=True)
    Gn = 255.0 * (G - G[0]) / (G[-1] - G[0])
    V = np.rint(vig * 50000) / np.rint(vig * 50000).max()
    expected = np.clip(np.rint(Gn[images[3]] / V), 0, 255).astype(np.uint8)
    got = seq[3].image
    assert np.abs(got.astype(int) - expected.astype(int)).max() <= 1  # float32 rounding
    assert (got != images[3]).mean() > 0.5
    # malformed calibration files are named
    (root / "pcalib.txt").write_text(" ".join(["1"] * 256) + "\n")
    with pytest.raises(InputError, match=r"pcalib.txt:1: .*strictly increasing"):
        open_tum_monovo(root, photometric=True)
    (root / "vignette.png").unlink()
    with pytest.raises(InputError, match=r"vignette.png: photometric calibration requested"):
        open_tum_monovo(root, photometric=True)


def test_malformed_inputs(tmp_path: Path) -> None:
    root = tmp_path / "sequence_03"
    write_monovo(root)
    (root / "times.txt").write_text("00000 1.0 10\n00001 1.05 10\n")
    with pytest.raises(InputError, match=r"times.txt: 2 lines for 6 images in images.zip"):
        open_sequence(root)
    write_times = "".join(f"{i:05d} {1 + i * 0.05:.6f} 10\n" for i in range(N))
    (root / "times.txt").write_text(write_times.replace("00003 ", "three "))
    with pytest.raises(InputError, match=r"times.txt:4: cannot read"):
        open_sequence(root)
    (root / "times.txt").write_text(write_times)
    (root / "camera.txt").write_text("0.5 0.5 0.5\n160 128\ncrop\n128 96\n")
    with pytest.raises(InputError, match=r"camera.txt:1: expected 5 numbers"):
        open_sequence(root)
    (root / "camera.txt").write_text("0.5 0.6 0.5 0.5 0.9\n160 128\ncrop\n128 96\n")
    (root / "groundtruthSync.txt").write_text("1.0 0 0 0 0 0 0\n")
    with pytest.raises(InputError, match=r"groundtruthSync.txt:1: expected 8 numbers"):
        open_sequence(root)
    (root / "images.zip").write_bytes(b"not a zip")
    with pytest.raises(InputError, match=r"images.zip: not a readable zip file"):
        open_sequence(root)


def test_info_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "sequence_04"
    write_monovo(root)
    assert main(["info", str(root), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "tum-monovo" and info["frames"] == N
    assert (info["width"], info["height"]) == (128, 96)
    assert info["has_groundtruth"] and info["groundtruth_frames"] == 4
    assert info["details"]["distortion_model"]["model"] == "fov"
    assert info["crop16"]["width"] == 128  # already a multiple of 16
