"""Live sources (``camera:N``) and ``--realtime`` runs, on a real video of the 7-Scenes sample.

The "camera" is an OpenCV ``VideoCapture`` over a video file written here (real MJPG encoding and decoding),
handed in through the capture factory that :func:`dmtrack.datasets.open_sequence` passes to the stream reader.
Where a test needs a camera that delivers at a camera's pace, the video's frames are released at 30 fps.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from dmtrack.datasets import open_sequence
from dmtrack.datasets.stream import StreamSequence, stream_name
from dmtrack.errors import InputError
from dmtrack.odometry.config import VOConfig
from dmtrack.pipeline import run_to_directory

INTRINSICS = "585,585,320,240"  # the sample's camera-intrinsics.txt
N = 60


def _write_video(path: Path, sample: Path, n: int, fps: float) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (640, 480))
    assert writer.isOpened()
    writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
    for i in range(n):
        writer.write(cv2.imread(str(sample / f"frame-{i:06d}.color.jpg")))
    writer.release()
    return path


@pytest.fixture(scope="module")
def fast_video(tmp_path_factory: pytest.TempPathFactory, sample_dir: Path) -> Path:
    """60 frames at 200 fps: 0.3 s of video, faster than the odometry can follow."""
    return _write_video(tmp_path_factory.mktemp("video") / "kitchen.avi", sample_dir, N, 200.0)


def _lines(path: Path) -> list[str]:
    return [ln for ln in path.read_text().splitlines() if ln and not ln.startswith("#")]


class Devices:
    """A capture factory whose device is the video file; remembers what it was asked to open and what it opened."""

    def __init__(self, video: Path, fps: float | None = None) -> None:
        self.video, self.fps = video, fps
        self.targets: list[Any] = []
        self.opened: list[Any] = []

    def __call__(self, target: Any) -> Any:
        self.targets.append(target)
        cap = cv2.VideoCapture(str(self.video)) if self.fps is None else _Paced(self.video, self.fps)
        self.opened.append(cap)
        return cap


class _Paced:
    """A real ``VideoCapture`` over the file whose ``read`` returns frames at ``fps``, as a camera does."""

    def __init__(self, video: Path, fps: float) -> None:
        self.cap = cv2.VideoCapture(str(video))
        self.period = 1.0 / fps
        self.due: float | None = None

    def isOpened(self) -> bool:  # noqa: N802 - OpenCV's name
        return self.cap.isOpened()

    def read(self) -> tuple[bool, np.ndarray | None]:
        now = time.monotonic()
        if self.due is not None and now < self.due:
            time.sleep(self.due - now)
        self.due = max(now, self.due or now) + self.period
        return self.cap.read()

    def release(self) -> None:
        self.cap.release()


def test_realtime_video_drops_the_frames_it_cannot_follow(fast_video: Path, tmp_path: Path) -> None:
    out = tmp_path / "rt"
    config = VOConfig().with_overrides("stop_on_loss=false")  # run to the end whatever the frame gaps do
    t0 = time.monotonic()
    result = run_to_directory(fast_video, out, config=config, realtime=True, intrinsics=INTRINSICS,
                              depth_images=False)
    wall = time.monotonic() - t0
    m = json.loads((out / "metrics.json").read_text())
    assert m["realtime"] is True and m["interrupted"] is None
    assert m["total_frames"] == N and m["dropped_frames"] > 0
    assert m["processed_frames"] + m["dropped_frames"] == N  # every frame was either tracked or dropped
    assert m["processed_frames"] >= 2 and m["tracked_frames"] == len(_lines(out / "trajectory.txt"))
    assert wall >= (N - 1) / 200.0  # played at its speed, not faster
    # the poses are those of frames of the video, at the video's times, in order, with gaps where frames dropped
    idx = result.frame_indices
    assert (np.diff(idx) > 0).all() and idx[0] == 0
    np.testing.assert_allclose(result.trajectory.timestamps, idx / 200.0, atol=1e-6)
    assert len(_lines(out / "keyframes.txt")) == m["keyframes"] >= 1
    # without realtime: every frame, nothing dropped
    plain = run_to_directory(fast_video, tmp_path / "plain", max_frames=8, intrinsics=INTRINSICS, depth_images=False)
    assert plain.metrics["realtime"] is False and plain.metrics["dropped_frames"] == 0
    assert plain.metrics["processed_frames"] == plain.metrics["tracked_frames"] == 8


def test_fake_camera_end_to_end(fast_video: Path, tmp_path: Path) -> None:
    devices = Devices(fast_video)
    before = time.time()
    seq = open_sequence("camera:0", intrinsics=INTRINSICS, capture=devices)
    assert isinstance(seq, StreamSequence) and seq.format == "stream" and seq.name == "camera0"
    assert devices.targets == [0] and (seq.width, seq.height) == (640, 480)
    assert seq.camera is not None and seq.camera.fx == 585.0 and not seq.has_groundtruth
    r = run_to_directory(seq, tmp_path / "cam", max_frames=20, depth_images=False)
    after = time.time()
    m = r.metrics
    assert m["format"] == "stream" and m["sequence"] == "camera0"
    assert m["total_frames"] == m["processed_frames"] == m["tracked_frames"] == 20 and m["lost_at"] is None
    ts = r.trajectory.timestamps  # wall clock when each frame was read
    assert before <= ts[0] and ts[-1] <= after and (np.diff(ts) > 0).all()
    assert not devices.opened[0].isOpened()  # the run released the device
    assert "groundtruth.txt" not in os.listdir(tmp_path / "cam")

    # realtime to the end of the "stream": the camera delivers as fast as it decodes
    seq = open_sequence("camera:0", intrinsics=INTRINSICS, capture=devices)
    r = run_to_directory(seq, tmp_path / "rt", realtime=True, depth_images=False,
                         config=VOConfig().with_overrides("stop_on_loss=false"))
    m = r.metrics
    assert m["total_frames"] == N and m["processed_frames"] + m["dropped_frames"] == N and m["dropped_frames"] > 0
    assert not devices.opened[1].isOpened()


def test_camera_needs_intrinsics_and_must_open(tmp_path: Path, fast_video: Path) -> None:
    devices = Devices(fast_video)
    with pytest.raises(InputError, match=r"camera:0: a live source has no intrinsics: .*dmtrack calibrate-camera"):
        open_sequence("camera:0", capture=devices)
    with pytest.raises(InputError, match="calibrate-camera"):
        run_to_directory("camera:0", tmp_path / "x")
    assert devices.targets == []  # refused before any device was opened

    # a device that is not there (real OpenCV, an index no machine running the tests has)
    with pytest.raises(InputError, match=r"cannot open camera:97 \(camera 97\): no such device"):
        open_sequence("camera:97", intrinsics=INTRINSICS)
    with pytest.raises(InputError, match=r"cannot open rtsp://example\.invalid/live"):
        open_sequence("rtsp://example.invalid/live", intrinsics=INTRINSICS,
                      capture=lambda target: cv2.VideoCapture(str(tmp_path / "absent.avi")))
    with pytest.raises(InputError, match="expected camera:N"):
        open_sequence("camera:front", intrinsics=INTRINSICS)
    # wrong intrinsics release the device that was opened
    with pytest.raises(InputError, match="expected four numbers"):
        open_sequence("camera:0", intrinsics="585,585", capture=devices)
    assert len(devices.opened) == 1 and not devices.opened[0].isOpened()
    assert stream_name("rtsp://192.168.1.10:554/live?x=1") == "rtsp-192.168.1.10-554-live"


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_ctrl_c_during_a_realtime_run_keeps_the_results(sample_dir: Path, tmp_path: Path) -> None:
    video = _write_video(tmp_path / "slow.avi", sample_dir, 90, 30.0)
    devices = Devices(video, fps=30.0)  # 3 s of frames at a camera's pace
    out = tmp_path / "run"
    seen: list[int] = []

    def press_ctrl_c() -> None:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if (out / "trajectory.txt").exists() and len(_lines(out / "trajectory.txt")) >= 3:
                seen.append(len(_lines(out / "trajectory.txt")))
                os.kill(os.getpid(), signal.SIGINT)
                return
            time.sleep(0.01)

    handler = signal.getsignal(signal.SIGINT)
    seq = open_sequence("camera:0", intrinsics=INTRINSICS, capture=devices)
    presser = threading.Thread(target=press_ctrl_c, daemon=True)
    presser.start()
    with pytest.raises(KeyboardInterrupt):
        run_to_directory(seq, out, realtime=True, depth_images=False)
    presser.join(5)
    assert seen, "the run ended before Ctrl-C"
    m = json.loads((out / "metrics.json").read_text())
    assert m["interrupted"] == "SIGINT" and m["realtime"] is True
    assert m["tracked_frames"] == len(_lines(out / "trajectory.txt")) >= seen[0]  # no finished frame lost
    assert m["processed_frames"] + m["dropped_frames"] <= m["total_frames"] < 90
    assert (out / "pointcloud.ply").stat().st_size > 0
    assert not [t for t in threading.enumerate() if t.name.startswith(("dmtrack-grabber", "dmtrack-prefetch"))]
    assert not devices.opened[0].isOpened()  # the camera is released
    assert signal.getsignal(signal.SIGINT) is handler
