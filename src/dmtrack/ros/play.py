"""Play a sequence to ROS 2 topics and listen to what ``dmtrack ros2`` sends back (:class:`Player`).

The test of the node and ``benchmarks/ros_node.py`` use it: a real rclpy publisher sends a sequence's images as
``sensor_msgs/Image`` (``bgr8``, as a camera driver does) or ``CompressedImage`` (JPEG), each with a
``sensor_msgs/CameraInfo`` of the same stamp, at a fixed rate; a subscription collects the node's ``odometry``.
Stamps are ``epoch + timestamp`` of each frame (:func:`frame_stamp`), so that a receiver can check them exactly.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterable
from typing import Any

import numpy as np

from dmtrack.ros.node import ros_modules

#: The stamps a player sends: seconds since the epoch of a day in 2023 plus the frame's own timestamp.
EPOCH = 1_700_000_000


def frame_stamp(timestamp: float) -> tuple[int, int]:
    """``(sec, nanosec)`` of a frame's timestamp (seconds) sent by a :class:`Player`."""
    ns = round(float(timestamp) * 1e9)
    return EPOCH + ns // 1_000_000_000, ns % 1_000_000_000


class Player:
    """A node (``dmtrack_player``) that publishes images and listens to odometry.

    Parameters
    ----------
    domain_id : the ROS domain (isolate tests from other ROS traffic on the machine).
    image_topic, info_topic, odometry_topic : where to publish and what to listen to.
    compressed : publish ``CompressedImage`` (JPEG) instead of ``Image`` (bgr8).

    Attributes
    ----------
    odometry : ``[(sec, nanosec, position (3,))]`` received, in order.
    """

    def __init__(self, domain_id: int, image_topic: str = "/image", info_topic: str = "/camera_info",
                 odometry_topic: str = "/odometry", compressed: bool = False) -> None:
        rclpy = ros_modules()
        from nav_msgs.msg import Odometry
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.qos import QoSProfile
        from rclpy.signals import SignalHandlerOptions
        from sensor_msgs.msg import CameraInfo, CompressedImage, Image

        self.context = rclpy.Context()
        rclpy.init(args=[], context=self.context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node("dmtrack_player", context=self.context)
        self.compressed = compressed
        qos = QoSProfile(depth=10)
        self.pub_image = self.node.create_publisher(CompressedImage if compressed else Image, image_topic, qos)
        self.pub_info = self.node.create_publisher(CameraInfo, info_topic, qos)
        self.odometry: list[tuple[int, int, np.ndarray]] = []
        self._lock = threading.Lock()
        self.node.create_subscription(Odometry, odometry_topic, self._on_odometry, QoSProfile(depth=1000))
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._spin = threading.Thread(target=self.executor.spin, name="dmtrack-player", daemon=True)
        self._spin.start()

    def _on_odometry(self, msg: Any) -> None:
        p = msg.pose.pose.position
        with self._lock:
            self.odometry.append((msg.header.stamp.sec, msg.header.stamp.nanosec, np.array([p.x, p.y, p.z])))

    def received(self) -> int:
        with self._lock:
            return len(self.odometry)

    def wait_for_node(self, timeout: float) -> bool:
        """Wait until the node subscribes to the images and publishes odometry (discovery)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.pub_image.get_subscription_count() > 0 and self.node.count_publishers(
                    self.node.resolve_topic_name("/odometry")) > 0:
                return True
            time.sleep(0.05)
        return False

    def _image(self, image: np.ndarray, stamp: tuple[int, int]) -> Any:
        import array

        import cv2
        from sensor_msgs.msg import CompressedImage, Image

        bgr = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        if self.compressed:
            msg = CompressedImage(format="jpeg")
            msg.data = array.array("B", cv2.imencode(".jpg", bgr)[1].tobytes())
        else:
            msg = Image(height=bgr.shape[0], width=bgr.shape[1], encoding="mono8" if bgr.ndim == 2 else "bgr8",
                        is_bigendian=0, step=bgr.strides[0])
            msg.data = array.array("B", np.ascontiguousarray(bgr).tobytes())
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
        msg.header.frame_id = "camera"
        return msg

    def _info(self, camera: Any, size: tuple[int, int], stamp: tuple[int, int]) -> Any:
        from sensor_msgs.msg import CameraInfo

        msg = CameraInfo(width=size[0], height=size[1], distortion_model="plumb_bob", d=[0.0] * 5)
        msg.k = [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0]
        msg.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        msg.p = [camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
        msg.header.frame_id = "camera"
        return msg

    def play(self, frames: Iterable[tuple[float, np.ndarray]], camera: Any, rate_hz: float) -> list[tuple[int, int]]:
        """Publish ``(timestamp, RGB or grey image)`` at ``rate_hz`` with their camera_info; the stamps sent."""
        sent = []
        t0 = time.monotonic()
        for k, (t, image) in enumerate(frames):
            stamp = frame_stamp(t)
            size = (image.shape[1], image.shape[0])
            msg = self._image(image, stamp)  # made before the wait: the rate is that of the sending
            delay = t0 + k / rate_hz - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            self.pub_info.publish(self._info(camera, size, stamp))
            self.pub_image.publish(msg)
            sent.append(stamp)
        return sent

    def wait_quiet(self, expected: int, timeout: float, quiet: float = 3.0) -> int:
        """Wait until ``expected`` odometry messages came, or none came for ``quiet`` seconds, or ``timeout``."""
        end = time.monotonic() + timeout
        last, since = -1, time.monotonic()
        while time.monotonic() < end:
            n = self.received()
            if n >= expected:
                return n
            if n != last:
                last, since = n, time.monotonic()
            elif time.monotonic() - since > quiet:
                break
            time.sleep(0.05)
        return self.received()

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        self.context.try_shutdown()
        self._spin.join(2.0)
