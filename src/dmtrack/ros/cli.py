"""``dmtrack ros2``: run the node ``dmtrack`` until Ctrl-C (:mod:`dmtrack.ros.node`).

The node waits for its first image (and, without ``--intrinsics``, its first ``camera_info``), then tracks every
image it receives with the run loop of ``dmtrack run`` on a live source: the odometry goes on after a loss and finds
the camera again, the geometric start reads the first frames, ``--slam`` adds the keyframe graph, ``--out DIR``
writes the usual run folder. Ctrl-C (or SIGTERM, as ``ros2 launch`` sends) stops it between frames; what was
finished is published and saved, and the command exits 0.

Everything after ``--ros-args`` goes to ROS (``-r image:=/camera/image_raw``, ``-p odom_frame:=map``,
``-r __node:=vo``); the rest is dmtrack's.
"""

from __future__ import annotations

import argparse
import sys
import threading
from pathlib import Path
from typing import Any

from dmtrack.errors import InputError


def add_ros2_parser(sub: Any, feature_options: Any, add_device_arg: Any) -> None:
    """The ``ros2`` subcommand; ``feature_options`` and ``add_device_arg`` are the CLI's own helpers."""
    p = sub.add_parser(
        "ros2", help="run the ROS 2 node `dmtrack`: images in, odometry, path, points and /tf out (Ctrl-C stops)",
        description="Subscribes to image, image/compressed and camera_info; publishes odometry, path, points (each "
        "finished keyframe's semi-dense points), /tf and, with --slam, optimised_path, each stamped with its image's "
        "stamp. Remap names after --ros-args, e.g. `dmtrack ros2 --ros-args -r image:=/camera/image_raw -r "
        "camera_info:=/camera/camera_info -p odom_frame:=odom -p camera_frame:=camera`. Needs pip install "
        "'dmtrack[ros]'.",
    )
    p.add_argument("--feature", default="gray", help="feature name (see `dmtrack features`; default gray)")
    p.add_argument("--feature-opt", action="append", metavar="KEY=VALUE", help="feature option (repeatable)")
    add_device_arg(p)
    group = p.add_mutually_exclusive_group()
    group.add_argument("--intrinsics", metavar="FX,FY,CX,CY|FILE",
                       help="the camera's intrinsics instead of camera_info's (numbers, or a calibration file as for "
                            "dmtrack run)")
    group.add_argument("--calibration", metavar="FILE",
                       help="a calibration file (fx fy cx cy, a 3x3 K, or the DSO file calibrate-camera writes: the "
                            "frames are undistorted with it) instead of camera_info")
    p.add_argument("--slam", action="store_true",
                   help="keyframe graph with loop closures (gtsam; pip install 'dmtrack[slam]'): also publishes "
                        "optimised_path after each optimisation")
    p.add_argument("--out", metavar="DIR", help="also write the run folder of dmtrack run (trajectory.txt, …)")
    p.add_argument("--config", metavar="YAML", help="odometry parameters")
    p.add_argument("--set", action="append", metavar="KEY=VALUE", help="override one parameter (repeatable)")
    p.add_argument("--init", choices=("random", "geometric"), help="how the first keyframe's map is made")
    p.add_argument("--queue", type=int, default=30, metavar="N",
                   help="images that may wait for the odometry (default 30); when one more comes the oldest is "
                        "dropped and counted. 1: always the newest image, as dmtrack run --realtime")
    p.add_argument("--max-frames", type=int, metavar="N", help="stop after N frames")
    p.add_argument("--wait", type=float, metavar="S",
                   help="give up when no image (or camera_info) has come after S seconds (default: wait)")
    p.add_argument("--threads", type=int, metavar="N", help="threads of the kernels and features (default: all)")
    p.add_argument("--no-depth-images", action="store_true", help="with --out: do not write depth/*.png")
    p.add_argument("--no-pointcloud", action="store_true", help="with --out: do not write pointcloud.ply")
    p.set_defaults(func=lambda args: cmd_ros2(args, feature_options), ros_args=[])


def _config(args: argparse.Namespace) -> Any:
    from dmtrack.odometry.config import VOConfig

    config = VOConfig.from_yaml(args.config) if args.config else VOConfig()
    if args.set:
        config = config.with_overrides(*args.set)
    if args.init:
        config = config.with_overrides(f"init={args.init}")
    return config


def _wait(what: str, ready: Any, timeout: float | None) -> None:
    from dmtrack.ros.source import wait_until

    if not wait_until(ready, timeout):
        raise InputError(f"dmtrack ros2: no {what} after {timeout:g} s")


def _sequence(args: argparse.Namespace, node: Any, frames: Any) -> Any:
    """The live sequence with its camera: from the command line, or from the first camera_info."""
    from dmtrack.datasets.registry import apply_intrinsics
    from dmtrack.datasets.rosbag import camera_from_info
    from dmtrack.datasets.undistort import CalibrationFile, undistort_sequence

    intrinsics = args.intrinsics or args.calibration
    if intrinsics is not None:
        return apply_intrinsics(frames, intrinsics)
    topic = node.topic("camera_info")
    print(f"dmtrack ros2: waiting for {topic} (or pass --intrinsics)", file=sys.stderr)
    _wait(f"message on {topic}", lambda: node.camera_info is not None, args.wait)
    size = (frames.width, frames.height)
    camera, distortion = camera_from_info(node.camera_info, size, Path(topic), topic)
    if camera is None:
        raise InputError(f"{topic}: the camera is not calibrated (K is zero); pass --intrinsics")
    frames.camera = camera
    frames.details["intrinsics_source"] = topic
    if distortion is None:
        return frames
    return undistort_sequence(frames, CalibrationFile(distortion, "crop", size, Path(topic), False))


def cmd_ros2(args: argparse.Namespace, feature_options: Any) -> int:
    from dmtrack.ros.node import DmtrackNode, RosSink, ros_modules

    rclpy = ros_modules()
    if args.threads is not None:
        import os

        from dmtrack.experiments.task import limit_threads

        if args.threads < 1:
            raise InputError(f"--threads must be ≥ 1, got {args.threads}")
        os.environ["DMTRACK_FEATURE_THREADS"] = str(args.threads)
        limit_threads(args.threads)
    if args.queue < 1:
        raise InputError(f"--queue must be ≥ 1, got {args.queue}")
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from dmtrack.features import get_feature
    from dmtrack.ros.source import TopicFrames

    config = _config(args)
    feature = get_feature(args.feature, **feature_options(args.feature_opt, args.device))
    context = rclpy.Context()
    # dmtrack's own Ctrl-C handling stops the run between frames; rclpy must not take SIGINT
    rclpy.init(args=["dmtrack", *args.ros_args], context=context, signal_handler_options=SignalHandlerOptions.NO)
    frames = TopicFrames("ros2", queue_size=args.queue)
    node = executor = spinner = None
    try:
        node = DmtrackNode(frames, need_camera_info=args.intrinsics is None and args.calibration is None,
                           slam=args.slam, context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node.node)
        spinner = threading.Thread(target=executor.spin, name="dmtrack-ros-spin", daemon=True)
        spinner.start()
        image = node.topic("image")
        print(f"dmtrack ros2: node {node.node.get_fully_qualified_name()} waiting for {image} "
              f"(or {image}/compressed)", file=sys.stderr)
        _wait(f"image on {image}", lambda: frames.wait_first(0.0), args.wait)
        frames.name = frames.root = image.strip("/").replace("/", "-") or "ros2"
        seq = _sequence(args, node, frames)
        sink = RosSink(node)
        _summary(_run(args, seq, feature, config, sink), frames, sink, node, args.out)
    except KeyboardInterrupt:  # before the run began (waiting for images); during it, _run saves and returns
        print("dmtrack ros2: stopped", file=sys.stderr)
    finally:
        frames.close()
        if executor is not None:
            executor.shutdown(timeout_sec=2.0)
        if node is not None:
            node.destroy()
        if context.ok():
            context.try_shutdown()
        if spinner is not None:
            spinner.join(2.0)
    return 0


def _run(args: argparse.Namespace, seq: Any, feature: Any, config: Any, sink: Any) -> dict[str, Any]:
    """Track the node's frames until Ctrl-C; the run's metrics (also of a run stopped by Ctrl-C)."""
    from dmtrack.pipeline import _track, run_to_directory

    common = {"max_frames": args.max_frames, "slam": args.slam or None, "progress": False}
    if args.out:
        try:
            result = run_to_directory(seq, args.out, feature=feature, config=config, extra_sinks=(sink,),
                                    depth_images=not args.no_depth_images, pointcloud=not args.no_pointcloud,
                                    **common)
        except KeyboardInterrupt:  # Ctrl-C: the run folder is complete, the metrics of the finished frames too
            import json

            return json.loads((Path(args.out) / "metrics.json").read_text(encoding="utf-8"))
        return result.metrics
    # the result of a run stopped by Ctrl-C (track() would raise it after saving): stopping is how a node ends
    return _track(seq, feature, config, sink=sink, **common).metrics


def _summary(m: dict[str, Any], frames: Any, sink: Any, node: Any, out: str | None) -> None:
    line = (f"dmtrack ros2: {frames.received} images received, {frames.dropped} dropped (queue full); "
            f"{sink.published} poses published on {node.topic('odometry')}, {sink.keyframes} keyframe clouds; "
            f"tracked {m['tracked_frames']}/{m['total_frames']} frames at {m['fps']:.1f} fps")
    print(line, file=sys.stderr)
    if out:
        print(f"outputs: {out}/", file=sys.stderr)
