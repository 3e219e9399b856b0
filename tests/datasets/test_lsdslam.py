"""LSD-SLAM sample-sequence reader: images/ + cameraCalibration.cfg (FOV relative or OpenCV pixels)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from dmtrack.cli import main
from dmtrack.datasets import detect_format, open_sequence
from dmtrack.datasets.undistort import UndistortedSequence
from dmtrack.errors import InputError
from dmtrack.geometry.distortion import FOVModel, RadTanModel

W, H = 160, 120


def _dots(model, pts: np.ndarray) -> np.ndarray:
    uv = model.project(pts)
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    img = np.full((H, W), 15.0)
    for x, y in uv:
        img += 220.0 * np.exp(-((u - x) ** 2 + (v - y) ** 2) / (2 * 1.3**2))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _centroid(img: np.ndarray, x: float, y: float, r: int = 4) -> np.ndarray:
    xi, yi = int(round(x)), int(round(y))
    p = np.clip(img[yi - r:yi + r + 1, xi - r:xi + r + 1].astype(float) - 15.0, 0, None)
    vv, uu = np.mgrid[yi - r:yi + r + 1, xi - r:xi + r + 1]
    return np.array([(p * uu).sum() / p.sum(), (p * vv).sum() / p.sum()])


def _scene() -> np.ndarray:
    g = np.stack(np.meshgrid(np.linspace(-1.0, 1.0, 5), np.linspace(-0.7, 0.7, 4)), -1).reshape(-1, 2)
    return np.column_stack([g * 3.0, np.full(len(g), 3.0)])


def write_lsd(root: Path, cfg: str, model, n: int = 4, in_folder: bool = False) -> None:
    folder = root if in_folder else root / "images"
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        cv2.imwrite(str(folder / f"{i:05d}.png"), _dots(model, _scene() + [0.02 * i, 0, 0]))
    (root / "cameraCalibration.cfg").write_text(cfg)


def test_fov_relative_crop(tmp_path: Path) -> None:
    rel = (0.527334, 0.827306, 0.473568, 0.499436, 0.928161)  # LSD-SLAM's FOV example calibration
    model = FOVModel(rel[0] * W, rel[1] * H, rel[2] * W - 0.5, rel[3] * H - 0.5, W, H, omega=rel[4])
    root = tmp_path / "LSD_room"
    write_lsd(root, " ".join(map(str, rel)) + f"\n{W} {H}\ncrop\n{W} {H}\n", model)
    assert detect_format(root) == "lsd-slam"
    seq = open_sequence(root)
    assert isinstance(seq, UndistortedSequence)
    assert (seq.width, seq.height) == (160, 112)  # 120 → multiple of 16
    assert seq.width % 16 == 0 and seq.height % 16 == 0
    assert not seq.has_groundtruth and seq.groundtruth is None
    np.testing.assert_allclose(seq.timestamps, np.arange(4) / 50.0)  # 50 fps (paper, Table 1)
    # the undistorted image shows each scene point where the output pinhole camera projects it
    f = seq[2]
    uv = seq.camera.project(_scene() + [0.04, 0, 0])
    inside = seq.camera.in_image(uv, border=6)
    assert inside.sum() >= 8
    err = [np.hypot(*(_centroid(f.image, x, y) - (x, y))) for x, y in uv[inside]]
    assert max(err) < 0.3


def test_opencv_model_and_times(tmp_path: Path) -> None:
    model = RadTanModel(140.0, 140.0, 80.0, 60.0, W, H, -0.2, 0.05, 0.0, 0.0)
    root = tmp_path / "LSD_machine"
    write_lsd(root, f"140 140 80 60 -0.2 0.05 0 0\n{W} {H}\nfull\n{W} {H}\n", model, in_folder=True)
    (root / "times.txt").write_text("\n".join(f"{10 + 0.02 * i:.3f}" for i in range(4)) + "\n")
    seq = open_sequence(root)
    assert seq.details["distortion_model"]["model"] == "radtan" and seq.details["undistortion"] == "full"
    np.testing.assert_allclose(seq.timestamps, 10 + 0.02 * np.arange(4))
    assert not seq.undistorter.valid.all()  # 'full' keeps the black corners
    f = seq[0]
    uv = seq.camera.project(_scene())
    inside = seq.camera.in_image(uv, border=6)
    err = [np.hypot(*(_centroid(f.image, x, y) - (x, y))) for x, y in uv[inside]]
    assert inside.sum() >= 5 and max(err) < 0.35


def test_pinhole_none_passthrough(tmp_path: Path) -> None:
    root = tmp_path / "seq"
    model = FOVModel(0.5 * W, 0.6 * H, 0.5 * W - 0.5, 0.5 * H - 0.5, W, H, omega=0.0)
    write_lsd(root, f"0.5 0.6 0.5 0.5 0\n{W} {H}\nnone\n{W} {H}\n", model)
    seq = open_sequence(root, fps=25.0)
    assert seq.camera.fx == 80.0 and seq.camera.cx == 79.5  # relative ×width − 0.5
    assert (seq.width, seq.height) == (160, 112)  # 'none' crops the centre to a multiple of 16
    np.testing.assert_allclose(seq.timestamps, np.arange(4) / 25.0)


def test_errors_and_info(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "LSD_eccv"
    model = FOVModel(80, 96, 79.5, 59.5, W, H, omega=0.9)
    write_lsd(root, f"0.5 0.8 0.5 0.5 0.9\n{W} {H}\ncrop\n{W} {H}\n", model)
    assert main(["info", str(root), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "lsd-slam" and info["frames"] == 4 and (info["width"], info["height"]) == (160, 112)
    assert info["details"]["undistortion"] == "crop" and not info["has_groundtruth"]
    (root / "cameraCalibration.cfg").write_text(f"0.5 0.8 0.5 0.5 0.9 1 2\n{W} {H}\ncrop\n{W} {H}\n")
    with pytest.raises(InputError, match=r"cameraCalibration.cfg:1: expected 5 numbers \(FOV"):
        open_sequence(root)
    (root / "cameraCalibration.cfg").write_text(f"0.5 0.8 0.5 0.5 0.9\n{W} {H}\ncrop\n{W} {H}\n")
    (root / "times.txt").write_text("1\n2\n")
    with pytest.raises(InputError, match=r"times.txt: 2 timestamps for 4 images"):
        open_sequence(root)
    (root / "times.txt").unlink()
    (root / "cameraCalibration.cfg").write_text(f"0.5 0.8 0.5 0.5 0.9\n{W + 2} {H}\ncrop\n{W} {H}\n")
    with pytest.raises(InputError,
                       match=r"cameraCalibration.cfg: the calibration is for 162x120 images, 00000.png is 160x120"):
        open_sequence(root)
