"""The ROS 2 node against the offline run (issue 40), and bags against the image folder.

Usage::

    python benchmarks/ros_node.py [--frames 150] [--rate 10] [--feature gray] [--compressed] [--json FILE]
    python benchmarks/ros_node.py --bags [--frames 300]

Node: ``dmtrack ros2 --out DIR`` runs in a subprocess on its own ROS domain (a seeded pick among 100–199, discovery
limited to this machine); an rclpy publisher (:class:`dmtrack.ros.play.Player`) sends the sample's first FRAMES
frames (bgr8 as OpenCV decodes the JPEGs, with camera_info) at RATE Hz, stamped ``EPOCH + the frame's timestamp``,
and counts the ``odometry`` messages that come back and checks their stamps; then Ctrl-C stops the node. Reported:
messages received and whether each stamp is one that was sent, the node's dropped frames, and the ATE (Sim(3),
against the sample's ground truth) of the node's trajectory beside the offline ``dmtrack.track`` of the same frames.
Targets: ≥ 140 of 150 messages with the images' stamps; ATE within 20 % of the offline run's.

``--bags``: the sample's first FRAMES frames written as a ROS 2 bag and a ROS 1 bag (bgr8, camera_info) and as a
ROS 2 bag of JPEG CompressedImages, each run with ``dmtrack.track``; reported: the largest difference of the bag runs'
poses from the image folder's (target 1e-4), and the frames the compressed bag tracked.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import dmtrack
from dmtrack.datasets import open_sequence
from dmtrack.evaluation.metrics import evaluate
from dmtrack.io.trajectory import Trajectory, read_tum

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "data" / "7scenes-redkitchen-0000-0299"


def ros_environment(seed: int) -> dict[str, str]:
    """The environment of an isolated ROS domain: a seeded domain id in 100–199, discovery on this machine only."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(random.Random(seed).randrange(100, 200))
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_LOCALHOST_ONLY", None)  # the older setting; Kilted warns when both are set
    return env


def run_node(frames: int, rate: float, feature: str, compressed: bool, work: Path, seed: int = 40,
             extra: tuple[str, ...] = ()) -> dict:
    from dmtrack.ros.play import EPOCH, Player

    env = ros_environment(seed)
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
    out = work / "node"
    cmd = [sys.executable, "-m", "dmtrack", "ros2", "--feature", feature, "--out", str(out), "--no-depth-images",
           *extra, "--ros-args", "-p", f"qos_overrides./image{'/compressed' if compressed else ''}.subscription."
           "reliability:=reliable"]
    log = open(work / "node.log", "w")  # noqa: SIM115
    node = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
    player = Player(int(env["ROS_DOMAIN_ID"]), compressed=compressed)
    try:
        if not player.wait_for_node(120.0):
            raise RuntimeError(f"the node did not come up: {(work / 'node.log').read_text()}")
        seq = open_sequence(SAMPLE)
        images = [(seq[i].timestamp, seq[i].image) for i in range(frames)]
        t0 = time.perf_counter()
        sent = player.play(images, seq.camera, rate)
        play_s = time.perf_counter() - t0
        received = player.wait_quiet(len(sent), timeout=120.0)
    finally:
        node.send_signal(signal.SIGINT)
        try:
            code = node.wait(60)
        except subprocess.TimeoutExpired:
            node.kill()
            code = node.wait()
        player.close()
        log.close()
        print((work / "node.log").read_text(), file=sys.stderr)  # the node's own account
    stamps = {(s, n) for s, n in sent}
    got = [(s, n) for s, n, _ in player.odometry]
    traj = read_tum(out / "trajectory.txt")
    traj = Trajectory(traj.timestamps - EPOCH, traj.poses)
    gt = seq.groundtruth
    node_eval = evaluate(gt, traj)
    offline = dmtrack.track(SAMPLE, feature, max_frames=frames)
    metrics = json.loads((out / "metrics.json").read_text())
    return {
        "frames_sent": len(sent), "rate_hz": rate, "play_s": play_s, "compressed": compressed, "feature": feature,
        "odometry_received": received, "stamps_all_sent": all(g in stamps for g in got),
        "stamps_in_order": got == sorted(got), "node_exit_code": code,
        "node_tracked_frames": metrics["tracked_frames"], "node_total_frames": metrics["total_frames"],
        "node_dropped_frames": metrics["dropped_frames"], "node_fps": metrics["fps"],
        "node_ate_rmse": node_eval["ate_rmse"], "offline_ate_rmse": offline.metrics["ate_rmse"],
        "offline_tracked_frames": offline.tracked_frames,
        "first_frame_tracked": int(round(float(traj.timestamps[0]) * 30)) if len(traj) else None,
        "ate_ratio": node_eval["ate_rmse"] / offline.metrics["ate_rmse"],
    }


def run_bags(frames: int, work: Path) -> dict:
    from dmtrack.io.rosbag import write_image_bag

    seq = open_sequence(SAMPLE)
    images = [(seq[i].timestamp, seq[i].image) for i in range(frames)]
    bags = {
        "ros2": write_image_bag(work / "ros2", images, camera=seq.camera, encoding="bgr8"),
        "ros1": write_image_bag(work / "ros1.bag", images, camera=seq.camera, encoding="bgr8", ros1=True),
        "compressed": write_image_bag(work / "jpeg", images, camera=seq.camera, encoding="jpeg",
                                      topic="/camera/image_raw/compressed"),
    }
    folder = dmtrack.track(SAMPLE, "gray", max_frames=frames)
    report: dict = {"frames": frames, "folder_tracked": folder.tracked_frames, "folder_ate": folder.metrics["ate_rmse"]}
    for name, bag in bags.items():
        run = dmtrack.track(bag, "gray")
        report[f"{name}_tracked"] = run.tracked_frames
        if name != "compressed":
            report[f"{name}_max_pose_difference"] = float(np.abs(run.trajectory.poses - folder.trajectory.poses).max())
            report[f"{name}_max_time_difference"] = float(
                np.abs(run.trajectory.timestamps - folder.trajectory.timestamps).max())
        else:
            gt = seq.groundtruth
            report["compressed_ate"] = evaluate(gt, run.trajectory)["ate_rmse"]
    return report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--rate", type=float, default=10.0)
    ap.add_argument("--feature", default="gray")
    ap.add_argument("--compressed", action="store_true", help="publish JPEG CompressedImages")
    ap.add_argument("--bags", action="store_true", help="bags against the image folder instead of the node")
    ap.add_argument("--seed", type=int, default=40, help="seed of the ROS domain id")
    ap.add_argument("--json", metavar="FILE", help="also write the report here")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="dmtrack-ros-") as tmp:
        if args.bags:
            report = run_bags(args.frames, Path(tmp))
        else:
            report = run_node(args.frames, args.rate, args.feature, args.compressed, Path(tmp), args.seed)
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(text + "\n")


if __name__ == "__main__":
    main()
