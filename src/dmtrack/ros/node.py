"""The ROS 2 node ``dmtrack`` (rclpy): images in, odometry out.

:class:`DmtrackNode` subscribes to

* ``image`` (``sensor_msgs/Image``: mono8, rgb8, bgr8, rgba8, bgra8) and ``image/compressed``
  (``sensor_msgs/CompressedImage``) — whichever delivers first is used, the other is then ignored (a camera driver
  with ``image_transport`` publishes both);
* ``camera_info`` (``sensor_msgs/CameraInfo``): the intrinsics, unless they are given on the command line;

with the sensor-data QoS (best effort, as camera drivers publish), and hands each image to a
:class:`~dmtrack.ros.source.TopicFrames` that the run loop reads. :class:`RosSink`, an ordinary output sink of the
odometry, publishes — each stamped with its image's header stamp —

* ``odometry`` (``nav_msgs/Odometry``) per tracked frame, and ``path`` (``nav_msgs/Path``, every pose so far);
* ``points`` (``sensor_msgs/PointCloud2``: x, y, z and PCL's packed ``rgb``) of each finished keyframe's semi-dense
  points in the world frame, stamped with the keyframe's image;
* ``/tf`` (``odom`` → ``camera``) when ``tf2_msgs`` can be imported (a sourced ROS 2 installation: there is no
  PyPI wheel of it; the node says so once at start);
* with ``--slam``, ``optimised_path`` (``nav_msgs/Path`` of the keyframes' optimised poses) after each optimisation.

The frame names are the node's parameters ``odom_frame`` and ``camera_frame``; every topic and the node's name are
remappable with ``--ros-args -r FROM:=TO``. Poses are dmtrack's ``T_wc`` (camera axes as OpenCV's: a ROS optical
frame). The odometry knows none of this: the node is a frame source and a sink at the outer layer.
"""

from __future__ import annotations

import array
import threading
from typing import Any

import numpy as np

from dmtrack.datasets.rosbag import COMPRESSED, IMAGE, decode_image
from dmtrack.errors import InputError
from dmtrack.io.rosbag import pose_fields
from dmtrack.odometry.sink import KeyframeSnapshot
from dmtrack.ros.source import TopicFrames

#: The wheels ``dmtrack ros2`` needs, and how to install them.
INSTALL_HINT = "pip install 'dmtrack[ros]'"
#: The PointCloud2 fields: x, y, z float32 and PCL's rgb (a uint32 0x00RRGGBB stored as float32).
POINT_STEP = 16


def ros_modules() -> Any:
    """``rclpy`` with the message packages the node uses, or an :class:`InputError` saying how to install them."""
    try:
        import geometry_msgs.msg  # noqa: F401
        import nav_msgs.msg  # noqa: F401
        import rclpy
        import sensor_msgs.msg  # noqa: F401
    except ImportError as e:
        raise InputError(f"dmtrack ros2 needs ROS 2's Python client library ({e}): {INSTALL_HINT}") from None
    return rclpy


def _time(stamp: tuple[int, int]) -> Any:
    from builtin_interfaces.msg import Time

    return Time(sec=int(stamp[0]), nanosec=int(stamp[1]))


def _pose_msg(T_wc: np.ndarray) -> Any:
    from geometry_msgs.msg import Point, Pose, Quaternion

    (x, y, z), (qx, qy, qz, qw) = pose_fields(T_wc)
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def pointcloud_message(points: np.ndarray, colours: np.ndarray, stamp: tuple[int, int], frame_id: str) -> Any:
    """A ``sensor_msgs/PointCloud2`` of ``(M, 3)`` world points with ``(M, 3)`` uint8 RGB colours."""
    from sensor_msgs.msg import PointCloud2, PointField

    n = int(points.shape[0])
    buf = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
    buf["x"], buf["y"], buf["z"] = points[:, 0], points[:, 1], points[:, 2]
    c = colours.astype(np.uint32)
    buf["rgb"] = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
    msg = PointCloud2()
    msg.header.stamp = _time(stamp)
    msg.header.frame_id = frame_id
    msg.height, msg.width = 1, n
    msg.fields = [PointField(name=name, offset=4 * k, datatype=PointField.FLOAT32, count=1)
                  for k, name in enumerate(("x", "y", "z", "rgb"))]
    msg.is_bigendian = False
    msg.point_step, msg.row_step = POINT_STEP, POINT_STEP * n
    msg.is_dense = True
    msg.data = array.array("B", buf.tobytes())
    return msg


def _tf_message_type() -> Any:
    try:
        from tf2_msgs.msg import TFMessage
    except ImportError:
        return None
    return TFMessage


class DmtrackNode:
    """The rclpy node (see the module docstring); ``node`` is the ``rclpy.node.Node``.

    Parameters
    ----------
    frames : where the received images go.
    need_camera_info : wait for ``camera_info`` (no intrinsics were given).
    slam : publish ``optimised_path`` too.
    context : the rclpy context (initialised by the caller).
    """

    def __init__(self, frames: TopicFrames, need_camera_info: bool, slam: bool = False, context: Any = None) -> None:
        ros_modules()
        from geometry_msgs.msg import TransformStamped  # noqa: F401  (the messages are ready before the run)
        from nav_msgs.msg import Odometry, Path
        from rclpy.node import Node
        from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
        from rclpy.qos_overriding_options import QoSOverridingOptions
        from sensor_msgs.msg import CameraInfo, CompressedImage, Image, PointCloud2

        self.frames = frames
        self.node = node = Node("dmtrack", context=context)
        self.odom_frame = node.declare_parameter("odom_frame", "odom").value
        self.camera_frame = node.declare_parameter("camera_frame", "camera").value
        self.log = node.get_logger()
        self._lock = threading.Lock()
        self._transport: str | None = None
        self.camera_info: Any = None
        self.rejected = 0
        # best effort, as camera drivers publish (a reliable publisher matches it too), and as deep as the frames'
        # queue: while this process is busy the middleware keeps the images for the callback. ROS's QoS overrides
        # apply: --ros-args -p qos_overrides./image.subscription.reliability:=reliable
        images = QoSProfile(depth=max(frames.queue_size, 10), reliability=ReliabilityPolicy.BEST_EFFORT)
        overrides = QoSOverridingOptions.with_default_policies()
        node.create_subscription(Image, "image", lambda m: self._on_image(m, IMAGE), images,
                                 qos_overriding_options=overrides)
        node.create_subscription(CompressedImage, "image/compressed", lambda m: self._on_image(m, COMPRESSED),
                                 images, qos_overriding_options=overrides)
        if need_camera_info:
            node.create_subscription(CameraInfo, "camera_info", self._on_camera_info, qos_profile_sensor_data,
                                     qos_overriding_options=overrides)
        reliable = QoSProfile(depth=100)
        self.pub_odometry = node.create_publisher(Odometry, "odometry", reliable)
        self.pub_path = node.create_publisher(Path, "path", reliable)
        self.pub_points = node.create_publisher(PointCloud2, "points", QoSProfile(depth=10))
        self.pub_optimised = node.create_publisher(Path, "optimised_path", QoSProfile(depth=10)) if slam else None
        tf = _tf_message_type()
        self.pub_tf = node.create_publisher(tf, "/tf", reliable) if tf is not None else None
        if tf is None:
            self.log.warning("/tf is not published: tf2_msgs cannot be imported (it has no PyPI wheel; source a ROS 2 "
                             "installation for it); odometry carries the same odom -> camera pose")

    def topic(self, name: str) -> str:
        """The resolved (remapped) name of one of the node's topics."""
        return self.node.resolve_topic_name(name)

    def _on_image(self, msg: Any, msgtype: str) -> None:
        with self._lock:
            if self._transport is None:
                self._transport = msgtype
                name = "image" if msgtype == IMAGE else "image/compressed"
                self.log.info(f"tracking the images of {self.topic(name)}")
            elif self._transport != msgtype:
                return  # the same camera through the other transport
        try:
            image = decode_image(msg, msgtype, self.topic("image"))
        except InputError as e:
            self.rejected += 1
            self.log.error(str(e), throttle_duration_sec=5.0)
            return
        if not self.frames.push(image, msg.header.stamp.sec, msg.header.stamp.nanosec) and not self.frames.closed:
            self.rejected += 1
            self.log.error(f"an image of {image.shape[1]}x{image.shape[0]} after {self.frames.width}x"
                           f"{self.frames.height} ones: dropped", throttle_duration_sec=5.0)

    def _on_camera_info(self, msg: Any) -> None:
        if self.camera_info is None:
            self.camera_info = msg

    def destroy(self) -> None:
        self.node.destroy_node()


class RosSink:
    """The odometry's output sink that publishes through a :class:`DmtrackNode` (see the module docstring).

    Attributes
    ----------
    published : odometry messages sent.
    keyframes : point clouds sent.
    """

    def __init__(self, node: DmtrackNode) -> None:
        from nav_msgs.msg import Path

        self._node = node
        self._stamp = node.frames.stamp
        self._path = Path()
        self._path.header.frame_id = node.odom_frame
        self.published = 0
        self.keyframes = 0

    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        from geometry_msgs.msg import PoseStamped, TransformStamped
        from nav_msgs.msg import Odometry

        n = self._node
        stamp = _time(self._stamp(timestamp))
        pose = _pose_msg(T_wc)
        odom = Odometry()
        odom.header.stamp, odom.header.frame_id = stamp, n.odom_frame
        odom.child_frame_id = n.camera_frame
        odom.pose.pose = pose
        n.pub_odometry.publish(odom)
        self.published += 1
        stamped = PoseStamped()
        stamped.header.stamp, stamped.header.frame_id = stamp, n.odom_frame
        stamped.pose = pose
        self._path.poses.append(stamped)
        self._path.header.stamp = stamp
        n.pub_path.publish(self._path)
        if n.pub_tf is not None:
            tf = TransformStamped()
            tf.header.stamp, tf.header.frame_id = stamp, n.odom_frame
            tf.child_frame_id = n.camera_frame
            p, q = pose.position, pose.orientation
            tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z = p.x, p.y, p.z
            tf.transform.rotation = q
            n.pub_tf.publish(_tf_message_type()(transforms=[tf]))

    def on_keyframe(self, keyframe_id: int, frame_index: int, timestamp: float, T_wc: np.ndarray,
                    depthmap_snapshot: KeyframeSnapshot) -> None:
        points, colours = depthmap_snapshot.points_world()
        msg = pointcloud_message(points, colours, self._stamp(timestamp), self._node.odom_frame)
        self._node.pub_points.publish(msg)
        self.keyframes += 1

    def on_lost(self, frame_index: int, reason: str) -> None:
        self._node.log.warning(f"tracking lost at frame {frame_index}: {reason}")

    def on_graph_optimised(self, graph: Any) -> None:
        """With ``--slam``: the keyframes' optimised poses as ``optimised_path``."""
        from geometry_msgs.msg import PoseStamped
        from nav_msgs.msg import Path

        pub = self._node.pub_optimised
        if pub is None or len(graph.timestamps) == 0:
            return
        path = Path()
        path.header.frame_id = self._node.odom_frame
        for t, T in zip(graph.timestamps, graph.poses, strict=True):
            p = PoseStamped()
            p.header.stamp, p.header.frame_id = _time(self._stamp(float(t))), self._node.odom_frame
            p.pose = _pose_msg(T)
            path.poses.append(p)
        path.header.stamp = path.poses[-1].header.stamp
        pub.publish(path)

    def close(self) -> None:
        """Nothing to flush: every message went out when it was made."""
