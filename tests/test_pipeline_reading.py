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


@pytest.mark.parametrize(("channels", "ahead"), [(1, 2), (128, 0)], ids=["grey", "dense-SIFT-sized"])
def test_frames_are_read_ahead_within_a_memory_budget(channels: int, ahead: int) -> None:
    """The background reader keeps PREFETCH frames in flight while their feature maps fit PREFETCH_BYTES (grey), and
    none for 640×480×128 float32 maps (157 MB each: dense SIFT would otherwise hold three more of them)."""
    import numpy as np

    from dmtrack.datasets.prefetch import PrefetchedFrames

    def load(i: int) -> tuple:
        return float(i), None, np.zeros((480, 640, channels), np.float32), 0.0, 0.0, None

    frames = PrefetchedFrames(load, 0, 8)
    in_flight = []
    try:
        for i, item in frames:
            assert item[0] == float(i)  # in order
            in_flight.append(len(frames._pending))
    finally:
        frames.close()
    assert len(in_flight) == 8 and frames.delivered == 8
    assert in_flight[0] == 0  # the first frame alone: its size is not known before
    assert in_flight[1:6] == [ahead] * 5
    assert in_flight[-1] == 0
