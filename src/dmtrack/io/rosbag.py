"""ROS bags written with ``rosbags`` (pure Python, ``pip install 'dmtrack[ros]'``): a run's trajectory as a ROS 2 bag,
and a sequence's images as a ROS 1 or ROS 2 bag.

* :func:`write_trajectory_bag` — ``dmtrack run … --rosbag-out DIR``: ``nav_msgs/Odometry`` per tracked frame on
  ``/odometry``, the same transform on ``/tf`` (``tf2_msgs/TFMessage``, ``odom`` → ``camera``), and the whole
  ``nav_msgs/Path`` once, at the last pose's time, on ``/path``; for rviz and PlotJuggler.
* :func:`write_image_bag` — the images of a sequence as ``sensor_msgs/Image`` (``mono8``, ``rgb8``, ``bgr8``) or
  ``sensor_msgs/CompressedImage`` (``jpeg``, ``png``), with a ``sensor_msgs/CameraInfo`` per image on the camera's
  ``camera_info`` topic: the bags the tests and ``benchmarks/ros_node.py`` read back.

Stamps: a timestamp ``t`` (seconds, float64) becomes ``sec = floor(t)``, ``nanosec = round((t − sec)·1e9)``
(:func:`stamp_of`); the bag's own time of each message is the same instant. Poses follow the ROS conventions the
messages carry: position ``(x, y, z)`` and orientation ``(x, y, z, w)`` of the camera in the ``odom`` frame
(dmtrack's ``T_wc``; camera axes are OpenCV's, which ROS calls an optical frame).

``rosbags`` is imported when a function here is called: without it, :func:`rosbags_modules` raises one
:class:`~dmtrack.errors.InputError` line saying how to install it.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack.errors import InputError, OutputError
from dmtrack.geometry.lie._rotation import matrix_to_quaternion
from dmtrack.io.atomic import output_error, prepare_folder

#: What every message about a missing ``rosbags`` says.
INSTALL_HINT = "pip install 'dmtrack[ros]'"
#: Image encodings :func:`write_image_bag` writes: raw ``sensor_msgs/Image`` ones and compressed ones.
RAW_ENCODINGS = ("mono8", "rgb8", "bgr8")
COMPRESSED_FORMATS = ("jpeg", "png")


def rosbags_modules(what: str = "reading or writing a ROS bag") -> Any:
    """The ``rosbags`` package, or an :class:`InputError` naming the extra that installs it."""
    try:
        import rosbags.highlevel  # noqa: F401
        import rosbags.rosbag1  # noqa: F401
        import rosbags.rosbag2  # noqa: F401
        import rosbags.typesys  # noqa: F401
    except ImportError as e:
        raise InputError(f"{what} needs the rosbags package ({e}): {INSTALL_HINT}") from None
    import rosbags

    return rosbags


def typestore(ros1: bool = False) -> Any:
    """The message definitions of ROS 1 Noetic or ROS 2 Kilted (``rosbags.typesys``)."""
    rosbags_modules()
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_KILTED)


def stamp_of(t: float) -> tuple[int, int]:
    """``(sec, nanosec)`` of a timestamp in seconds (rounded to the nanosecond)."""
    ns = round(float(t) * 1e9)
    return ns // 1_000_000_000, ns % 1_000_000_000


def stamp_ns(t: float) -> int:
    """Nanoseconds of a timestamp in seconds (the bag's time of a message)."""
    return round(float(t) * 1e9)


def camera_info_topic(image_topic: str) -> str:
    """The ``camera_info`` topic of the camera publishing ``image_topic`` (``/cam/image_raw[/compressed]`` →
    ``/cam/camera_info``), as ``image_transport`` names them."""
    topic = image_topic.rstrip("/")
    if topic.endswith("/compressed"):
        topic = topic[: -len("/compressed")]
    ns = topic.rpartition("/")[0]
    return f"{ns}/camera_info"


def _header(ts: Any, t: float, frame_id: str, ros1: bool = False, seq: int = 0) -> Any:
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    sec, nanosec = stamp_of(t)
    if ros1:
        return Header(seq=seq, stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id)
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id)


def pose_fields(T_wc: np.ndarray) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """Position and orientation quaternion ``(x, y, z, w)`` of a camera-to-world pose."""
    T = np.asarray(T_wc, dtype=np.float64)
    q = matrix_to_quaternion(T[:3, :3])
    return (float(T[0, 3]), float(T[1, 3]), float(T[2, 3])), (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def _pose(ts: Any, T_wc: np.ndarray) -> Any:
    (x, y, z), (qx, qy, qz, qw) = pose_fields(T_wc)
    return ts.types["geometry_msgs/msg/Pose"](
        position=ts.types["geometry_msgs/msg/Point"](x=x, y=y, z=z),
        orientation=ts.types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
    )


def _replace_bag_folder(tmp: Path, out: Path) -> None:
    """Move the bag written in ``tmp`` to ``out``, replacing an earlier ROS 2 bag there (never anything else)."""
    if out.exists():
        if not out.is_dir() or not (out / "metadata.yaml").is_file():
            raise OutputError("exists and is not a ROS 2 bag folder (no metadata.yaml); not replacing it", out)
        shutil.rmtree(out)
    try:
        tmp.rename(out)
    except OSError as e:
        raise output_error(out, e) from None


def write_trajectory_bag(
    out_dir: str | Path,
    timestamps: np.ndarray,
    poses: np.ndarray,
    *,
    odom_frame: str = "odom",
    camera_frame: str = "camera",
    odometry_topic: str = "/odometry",
    path_topic: str = "/path",
    tf_topic: str = "/tf",
) -> Path:
    """Write a trajectory as a ROS 2 bag folder (sqlite3) at ``out_dir``; an earlier bag there is replaced.

    Parameters
    ----------
    timestamps : (N,) seconds of the poses.
    poses : (N, 4, 4) camera-to-world ``T_wc``.
    odom_frame, camera_frame : ``header.frame_id`` and ``child_frame_id`` of the messages.
    odometry_topic, path_topic, tf_topic : where the messages go.

    Returns
    -------
    The bag folder.

    Raises
    ------
    InputError
        ``rosbags`` is not installed.
    OutputError
        ``out_dir`` cannot be written, or is something else than a ROS 2 bag folder.
    """
    rosbags_modules("--rosbag-out")
    from rosbags.rosbag2 import Writer

    out = Path(out_dir)
    prepare_folder(out.parent if str(out.parent) else Path("."))
    ts = typestore()
    types = ts.types
    timestamps = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    try:
        bag = tmp / "bag"
        with Writer(bag, version=9) as writer:
            c_odom = writer.add_connection(odometry_topic, "nav_msgs/msg/Odometry", typestore=ts)
            c_tf = writer.add_connection(tf_topic, "tf2_msgs/msg/TFMessage", typestore=ts)
            c_path = writer.add_connection(path_topic, "nav_msgs/msg/Path", typestore=ts)
            zero6 = np.zeros(36, dtype=np.float64)
            stamped = []
            for t, T in zip(timestamps, poses, strict=True):
                pose = _pose(ts, T)
                odom = types["nav_msgs/msg/Odometry"](
                    header=_header(ts, t, odom_frame),
                    child_frame_id=camera_frame,
                    pose=types["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=zero6),
                    twist=types["geometry_msgs/msg/TwistWithCovariance"](
                        twist=types["geometry_msgs/msg/Twist"](
                            linear=types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                            angular=types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                        ),
                        covariance=zero6,
                    ),
                )
                writer.write(c_odom, stamp_ns(t), ts.serialize_cdr(odom, "nav_msgs/msg/Odometry"))
                (x, y, z), (qx, qy, qz, qw) = pose_fields(T)
                tf = types["geometry_msgs/msg/TransformStamped"](
                    header=_header(ts, t, odom_frame),
                    child_frame_id=camera_frame,
                    transform=types["geometry_msgs/msg/Transform"](
                        translation=types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
                        rotation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
                    ),
                )
                msg = types["tf2_msgs/msg/TFMessage"](transforms=[tf])
                writer.write(c_tf, stamp_ns(t), ts.serialize_cdr(msg, "tf2_msgs/msg/TFMessage"))
                stamped.append(types["geometry_msgs/msg/PoseStamped"](header=_header(ts, t, odom_frame), pose=pose))
            if len(timestamps):
                last = float(timestamps[-1])
                path = types["nav_msgs/msg/Path"](header=_header(ts, last, odom_frame), poses=stamped)
                writer.write(c_path, stamp_ns(last), ts.serialize_cdr(path, "nav_msgs/msg/Path"))
        _replace_bag_folder(bag, out)
    except OSError as e:
        raise output_error(out, e) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out


def _camera_info(ts: Any, t: float, frame_id: str, camera: Any, size: tuple[int, int], ros1: bool, seq: int,
                 distortion: tuple[float, ...] = ()) -> Any:
    w, h = size
    K = np.array([camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0])
    R = np.eye(3).reshape(-1)
    P = np.array([camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    D = np.zeros(5)
    D[: len(distortion)] = distortion
    roi = ts.types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    fields = {"D": D, "K": K, "R": R, "P": P} if ros1 else {"d": D, "k": K, "r": R, "p": P}
    return ts.types["sensor_msgs/msg/CameraInfo"](
        header=_header(ts, t, frame_id, ros1, seq), height=h, width=w, distortion_model="plumb_bob",
        binning_x=0, binning_y=0, roi=roi, **fields,
    )


def image_message(ts: Any, t: float, image: np.ndarray, encoding: str, frame_id: str = "camera",
                  ros1: bool = False, seq: int = 0) -> tuple[str, Any]:
    """``(msgtype, message)`` of an RGB or grey uint8 image as ``sensor_msgs/Image`` (``encoding`` one of
    :data:`RAW_ENCODINGS`) or ``sensor_msgs/CompressedImage`` (``jpeg``, ``png``; OpenCV encodes)."""
    import cv2

    header = _header(ts, t, frame_id, ros1, seq)
    image = np.ascontiguousarray(image)
    if encoding in COMPRESSED_FORMATS:
        bgr = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        ok, data = cv2.imencode(".jpg" if encoding == "jpeg" else ".png", bgr)
        if not ok:
            raise InputError(f"OpenCV cannot encode a {image.shape} image as {encoding}")
        msg = ts.types["sensor_msgs/msg/CompressedImage"](header=header, format=encoding,
                                                          data=np.asarray(data, dtype=np.uint8).reshape(-1))
        return "sensor_msgs/msg/CompressedImage", msg
    if encoding == "mono8":
        pixels = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    elif encoding in ("rgb8", "bgr8"):
        pixels = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB) if image.ndim == 2 else image
        if encoding == "bgr8":
            pixels = pixels[:, :, ::-1]
    else:
        known = ", ".join(RAW_ENCODINGS + COMPRESSED_FORMATS)
        raise InputError(f"image encoding {encoding!r}: expected one of {known}")
    pixels = np.ascontiguousarray(pixels)
    h, w = pixels.shape[:2]
    msg = ts.types["sensor_msgs/msg/Image"](
        header=header, height=h, width=w, encoding=encoding, is_bigendian=0, step=pixels.strides[0],
        data=pixels.reshape(-1),
    )
    return "sensor_msgs/msg/Image", msg


def write_image_bag(
    path: str | Path,
    frames: Iterable[tuple[float, np.ndarray]],
    *,
    camera: Any = None,
    topic: str = "/camera/image_raw",
    encoding: str = "bgr8",
    ros1: bool = False,
    frame_id: str = "camera",
    distortion: tuple[float, ...] = (),
) -> Path:
    """Write images as a ROS 1 ``.bag`` file (``ros1=True``) or a ROS 2 bag folder.

    Parameters
    ----------
    path : the bag to create (it must not exist).
    frames : ``(timestamp seconds, uint8 image (H, W) grey or (H, W, 3) RGB)`` in time order.
    camera : a :class:`~dmtrack.geometry.camera.PinholeCamera`: a ``sensor_msgs/CameraInfo`` (no distortion) is
        written beside each image on :func:`camera_info_topic`; None writes none.
    topic : the image topic (``…/compressed`` is usual for ``jpeg`` and ``png``).
    encoding : ``mono8``, ``rgb8``, ``bgr8`` (``sensor_msgs/Image``) or ``jpeg``, ``png`` (``CompressedImage``).
    frame_id : ``header.frame_id`` of the messages.
    distortion : ``plumb_bob`` coefficients ``k1, k2, p1, p2, k3`` of the CameraInfo (default none).
    """
    rosbags_modules("writing a ROS bag")
    out = Path(path)
    if out.exists():
        raise OutputError("exists already; a bag is written to a new path", out)
    ts = typestore(ros1)
    if ros1:
        from rosbags.rosbag1 import Writer as Writer1

        writer: Any = Writer1(out)
    else:
        from rosbags.rosbag2 import Writer as Writer2

        writer = Writer2(out, version=9)
    info_topic = camera_info_topic(topic)
    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    try:
        with writer:
            connections: dict[str, Any] = {}
            for seq, (t, image) in enumerate(frames):
                msgtype, msg = image_message(ts, t, image, encoding, frame_id, ros1, seq)
                if topic not in connections:
                    connections[topic] = writer.add_connection(topic, msgtype, typestore=ts)
                    if camera is not None:
                        connections[info_topic] = writer.add_connection(
                            info_topic, "sensor_msgs/msg/CameraInfo", typestore=ts)
                if camera is not None:
                    info = _camera_info(ts, t, frame_id, camera, (image.shape[1], image.shape[0]), ros1, seq,
                                        distortion)
                    writer.write(connections[info_topic], stamp_ns(t),
                                 serialize(info, "sensor_msgs/msg/CameraInfo"))
                writer.write(connections[topic], stamp_ns(t), serialize(msg, msgtype))
    except OSError as e:
        raise output_error(out, e) from None
    return out


def time_of(sec: int, nanosec: int) -> float:
    """Seconds of a ``(sec, nanosec)`` stamp."""
    return float(sec) + float(nanosec) * 1e-9
