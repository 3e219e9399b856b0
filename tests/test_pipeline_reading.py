"""A run reads only what it needs: the ground-truth depth maps of a sequence (7-Scenes ships one per frame) are
decoded by ``seq[i]`` for whoever wants them, never by a run (``read_frame(i, depth=False)``)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from dmtrack.datasets import open_sequence
from dmtrack.errors import InputError
from dmtrack.pipeline import track

N = 12
# a mild radial distortion in DSO's format: frames are undistorted (an UndistortedSequence around the reader)
CALIBRATION = "585 585 320 240 -0.01 0 0 0\n640 480\ncrop\n640 480\n"


@pytest.fixture
def damaged_depth(tmp_path: Path, sample_dir: Path) -> Path:
    """The first frames of the sample with a depth map each that cannot be decoded."""
    root = tmp_path / "seq"
    root.mkdir()
    shutil.copy(sample_dir / "camera-intrinsics.txt", root)
    for i in range(N):
        for kind in ("color.jpg", "pose.txt"):
            shutil.copy(sample_dir / f"frame-{i:06d}.{kind}", root)
        (root / f"frame-{i:06d}.depth.png").write_bytes(b"not a PNG file")
    (tmp_path / "camera.txt").write_text(CALIBRATION)
    return root


@pytest.mark.parametrize("undistorted", [False, True], ids=["reader", "undistorted"])
def test_a_run_does_not_decode_the_depth_maps(damaged_depth: Path, undistorted: bool) -> None:
    intrinsics = damaged_depth.parent / "camera.txt" if undistorted else None
    seq = open_sequence(damaged_depth, intrinsics=intrinsics)
    assert seq.has_depth and (type(seq).__name__ == "UndistortedSequence") == undistorted
    with pytest.raises(InputError, match=r"frame-000003\.depth\.png"):  # seq[i] decodes the depth map
        seq[3]
    frame = seq.read_frame(3, depth=False)
    assert frame.depth is None and frame.image.shape == (480, 640, 3) and frame.pose is not None
    result = track(damaged_depth, intrinsics=intrinsics, max_frames=N)  # a run never does
    assert result.tracked_frames == N
