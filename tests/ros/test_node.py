"""The ROS 2 node with real components: ``dmtrack ros2`` in a subprocess, fed by an rclpy publisher on a ROS domain of
its own (a seeded pick, discovery limited to this machine); what comes back on ``odometry`` is checked against the
images' stamps and against the offline run of the same frames. Skipped, with the reason, where the ROS 2 wheels
cannot be imported."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dmtrack.datasets.stream import EndOfStream
from dmtrack.ros.source import TopicFrames

N = 40  # the geometric start accepts at frame ~35 of the sample: the node starts it and tracks on


def _ros_or_skip() -> None:
    for module in ("rclpy", "sensor_msgs.msg", "nav_msgs.msg", "geometry_msgs.msg"):
        pytest.importorskip(module, reason=f"ROS 2 wheels not importable ({module}): pip install 'dmtrack[ros]'")


@pytest.fixture
def ros_domain(monkeypatch: pytest.MonkeyPatch) -> int:
    """A ROS domain for this test alone: seeded by the process id (two test runs at once pick apart), discovery
    on this machine only."""
    _ros_or_skip()
    domain = random.Random(f"dmtrack-{os.getpid()}").randrange(100, 200)
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
    return domain


def _start_node(tmp_path: Path, *args: str) -> subprocess.Popen:
    log = open(tmp_path / "node.log", "w")  # noqa: SIM115 - the child writes it
    return subprocess.Popen([sys.executable, "-m", "dmtrack", "ros2", *args], stdout=log, stderr=subprocess.STDOUT)


def _stop(node: subprocess.Popen, tmp_path: Path) -> tuple[int, str]:
    node.send_signal(signal.SIGINT)  # Ctrl-C
    try:
        code = node.wait(60)
    except subprocess.TimeoutExpired:
        node.kill()
        code = node.wait()
    return code, (tmp_path / "node.log").read_text()


def _sample_frames(sample_dir: Path, n: int) -> tuple[list[tuple[float, np.ndarray]], object]:
    from dmtrack.datasets import open_sequence

    seq = open_sequence(sample_dir)
    return [(seq[i].timestamp, seq[i].image) for i in range(n)], seq.camera


def test_the_node_tracks_a_publishers_images(ros_domain: int, sample_dir: Path, tmp_path: Path) -> None:
    import dmtrack
    from dmtrack.io.trajectory import read_tum
    from dmtrack.ros.play import EPOCH, Player

    out = tmp_path / "run"
    node = _start_node(tmp_path, "--out", str(out), "--no-depth-images", "--no-pointcloud",
                       "--ros-args", "-p", "qos_overrides./image.subscription.reliability:=reliable")
    player = Player(ros_domain)
    try:
        assert player.wait_for_node(120.0), (tmp_path / "node.log").read_text()
        frames, camera = _sample_frames(sample_dir, N)
        sent = player.play(frames, camera, rate_hz=10.0)
        received = player.wait_quiet(N, timeout=60.0)
    finally:
        code, log = _stop(node, tmp_path)
        player.close()
    assert code == 0, log
    assert received == N, log
    stamps = [(s, n) for s, n, _ in player.odometry]
    assert stamps == sent  # each image's own stamp, exactly, in order
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["total_frames"] == N and metrics["tracked_frames"] == N and metrics["dropped_frames"] == 0
    assert f"{N} images received, 0 dropped" in log and f"{N} poses published on /odometry" in log
    # every frame came and none was dropped: the trajectory is the offline run's
    traj = read_tum(out / "trajectory.txt")
    offline = dmtrack.track(sample_dir, "gray", max_frames=N)
    np.testing.assert_allclose(traj.timestamps - EPOCH, offline.trajectory.timestamps, atol=1e-6)
    np.testing.assert_allclose(traj.poses, offline.trajectory.poses, atol=1e-6)
    positions = np.array([p for _, _, p in player.odometry])
    np.testing.assert_allclose(positions, traj.poses[:, :3, 3], atol=1e-6)


def test_compressed_images_remapped_with_given_intrinsics(ros_domain: int, sample_dir: Path, tmp_path: Path) -> None:
    from dmtrack.ros.play import Player

    n = 12
    node = _start_node(tmp_path, "--intrinsics", "585,585,320,240", "--init", "random", "--no-depth-images",
                       "--ros-args", "-r", "image/compressed:=/cam/image_raw/compressed", "-r", "odometry:=/vo/odom",
                       "-p", "qos_overrides./cam/image_raw/compressed.subscription.reliability:=reliable",
                       "-p", "odom_frame:=map")
    player = Player(ros_domain, image_topic="/cam/image_raw/compressed", info_topic="/unused/camera_info",
                    odometry_topic="/vo/odom", compressed=True)
    try:
        deadline = time.monotonic() + 120.0
        while player.pub_image.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        frames, camera = _sample_frames(sample_dir, n)
        sent = player.play(frames, camera, rate_hz=10.0)
        received = player.wait_quiet(n, timeout=60.0)
    finally:
        code, log = _stop(node, tmp_path)
        player.close()
    assert code == 0, log
    assert received == n and [(s, ns) for s, ns, _ in player.odometry] == sent, log
    assert "tracking the images of /cam/image_raw/compressed" in log and "waiting for /camera_info" not in log


def test_ctrl_c_while_waiting_for_images(ros_domain: int, tmp_path: Path) -> None:
    from dmtrack.ros.play import Player

    node = _start_node(tmp_path)
    player = Player(ros_domain)
    try:
        assert player.wait_for_node(120.0), (tmp_path / "node.log").read_text()
    finally:
        t0 = time.monotonic()
        code, log = _stop(node, tmp_path)
        player.close()
    assert code == 0 and "dmtrack ros2: stopped" in log and time.monotonic() - t0 < 10.0, log


def test_topic_frames_queue_drops_the_oldest_and_counts() -> None:
    frames = TopicFrames("t", queue_size=2)
    img = np.zeros((4, 6), np.uint8)
    for k in range(5):
        assert frames.push(img + k, 1_700_000_000, 10 * k)
    assert not frames.push(np.zeros((5, 6), np.uint8), 1, 0)  # another size: refused
    assert (frames.received, frames.dropped, frames.width, frames.height) == (5, 3, 6, 4)
    f0, f1 = frames[0], frames[1]
    assert int(f0.image[0, 0]) == 3 and int(f1.image[0, 0]) == 4  # the newest two waited
    assert frames.stamp(f1.timestamp) == (1_700_000_000, 40) and frames[1] is f1
    with pytest.raises(IndexError):
        frames[5]
    stop = []
    frames.watch_stop(lambda: bool(stop))
    stop.append(1)
    with pytest.raises(EndOfStream):  # Ctrl-C while the run waits for a frame
        frames[2]
    frames.close()
    assert not frames.push(img, 2, 0)
