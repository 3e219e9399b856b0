"""Video reader: lazy decoding with seeking, container timestamps, sidecar intrinsics, clear decode errors."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from dmtrack.cli import main
from dmtrack.datasets import Sequence, detect_format, open_sequence
from dmtrack.datasets.undistort import UndistortedSequence
from dmtrack.errors import DatasetError, InputError

W, H = 96, 64
N = 8


def _frame(i: int) -> np.ndarray:
    """A frame whose content encodes its index: a bright square whose position moves with i."""
    img = np.full((H, W, 3), 30, np.uint8)
    x = 8 + 9 * i
    img[20:36, x:x + 12] = (40, 200, 240)  # BGR
    return img


def write_video(path: Path, fps: float = 25.0, fourcc: str = "MJPG") -> None:
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (W, H))
    assert w.isOpened()
    w.set(cv2.VIDEOWRITER_PROP_QUALITY, 100)
    for i in range(N):
        w.write(_frame(i))
    w.release()


def _square_x(img: np.ndarray) -> float:
    mask = img[:, :, 0] > 150 if img.ndim == 3 else img > 150  # RGB: the square's red channel is 240
    cols = np.flatnonzero(mask.any(0))
    return float(cols.mean())


def test_frames_timestamps_and_seeking(tmp_path: Path) -> None:
    path = tmp_path / "walk.avi"
    write_video(path)
    assert detect_format(path) == "video"
    seq = open_sequence(path)
    assert isinstance(seq, Sequence)
    assert seq.format == "video" and len(seq) == N and (seq.width, seq.height) == (W, H)
    np.testing.assert_allclose(seq.timestamps, np.arange(N) / 25.0, atol=1e-6)  # container times (ms)
    assert seq.details["timestamps"].startswith("container")
    assert seq.camera is None and not seq.has_groundtruth
    sequential = [seq[i].image for i in range(N)]
    assert sequential[0].shape == (H, W, 3)
    assert abs(_square_x(sequential[0]) - 13.5) < 1.0 and sequential[0][28, 10, 0] > 200  # RGB, not BGR
    for i in (5, 1, 7, 2, 2, 3):  # random access seeks and gives the same frames
        f = seq[i]
        assert f.index == i and f.timestamp == pytest.approx(i / 25.0)
        assert abs(_square_x(f.image) - (13.5 + 9 * i)) < 1.0
        np.testing.assert_array_equal(f.image, sequential[i])
    part = seq.slice(2, 5)
    assert len(part) == 3 and abs(_square_x(part[0].image) - (13.5 + 18)) < 1.0
    fixed = open_sequence(path, fps=10.0)
    np.testing.assert_allclose(fixed.timestamps, np.arange(N) / 10.0)
    quick = open_sequence(path, scan=False)
    assert len(quick) == N and quick.details["timestamps"].startswith("index / 25")


def test_sidecar_intrinsics_and_info(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "clip.mp4"
    write_video(path, fourcc="mp4v")
    (tmp_path / "clip.mp4.camera.txt").write_text("80 81 47.5 31.5\n")
    seq = open_sequence(path)
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx) == (80.0, 81.0, 47.5)
    assert main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "video" and info["frames"] == N and info["fx"] == 80.0
    assert info["details"]["intrinsics_source"] == "clip.mp4.camera.txt"
    assert main(["info", str(path), "--json", "--intrinsics", "70,70,48,32"]) == 0
    assert json.loads(capsys.readouterr().out)["fx"] == 70.0
    # a 4-line DSO calibration with distortion undistorts the frames
    (tmp_path / "clip.mp4.camera.txt").write_text(f"RadTan 80 80 47.5 31.5 -0.1 0.01 0 0\n{W} {H}\ncrop\n{W} {H}\n")
    und = open_sequence(path)
    assert isinstance(und, UndistortedSequence) and (und.width, und.height) == (96, 64)
    assert und[3].image.shape == (64, 96, 3)


def test_decode_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"\x00\x00\x00\x18ftypmp42" + b"garbage" * 100)
    with pytest.raises(InputError, match=r"broken.mp4: OpenCV cannot (open|decode)"):
        open_sequence(bad)
    assert main(["info", str(bad)]) == 1
    assert "broken.mp4: OpenCV cannot" in capsys.readouterr().err
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    with pytest.raises(DatasetError, match=r"notes.txt: a sequence is a folder or a video file"):
        open_sequence(text)
    path = tmp_path / "short.avi"
    write_video(path)
    seq = open_sequence(path, scan=False)
    with pytest.raises(IndexError):
        seq[N]
