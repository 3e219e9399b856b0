"""ROS bags: a ROS 1 ``.bag`` file or a ROS 2 bag folder (``metadata.yaml`` with sqlite3 or MCAP storage), read
with ``rosbags`` (pure Python, ``pip install 'dmtrack[ros]'``).

The sequence is one image topic (``open_rosbag(path, topic=…)``, ``dmtrack run BAG --topic TOPIC``; a bag with one
image topic needs none): ``sensor_msgs/Image`` in ``mono8``, ``rgb8``, ``bgr8`` (``rgba8``, ``bgra8``: the alpha is
dropped) or ``sensor_msgs/CompressedImage`` (any format OpenCV decodes). Frames are delivered as grey or RGB uint8,
as every reader does. Timestamps are the images' header stamps (the bag's own times when the stamps are all zero or
do not increase).

Intrinsics come from the ``sensor_msgs/CameraInfo`` of the same camera when the bag has one: the topic
``NS/camera_info`` beside ``NS/image…`` (``image_transport``'s naming, :func:`dmtrack.io.rosbag.camera_info_topic`).
Its ``K`` gives the pinhole camera; a ``plumb_bob`` (or ``rational_polynomial`` with only k1, k2, p1, p2, k3)
distortion is removed from every frame as the other readers do (:mod:`dmtrack.datasets.undistort`, ``crop``);
``equidistant`` likewise. Without one, ``--intrinsics`` is needed.

Frames are read lazily: the bag is scanned once when opened (each image's time and stamp), frame ``i`` is then
read by seeking to its time; reading in order continues one iterator. Each thread has its own open reader (a
sqlite3 connection belongs to the thread that made it).
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack.datasets.base import LoaderSequence
from dmtrack.datasets.undistort import CalibrationFile, UndistortedSequence, undistort_sequence
from dmtrack.errors import DatasetError, InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.rosbag import camera_info_topic, rosbags_modules, time_of

FORMAT = "rosbag"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
IMAGE_TYPES = (IMAGE, COMPRESSED)


def detect(path: Path) -> bool:
    """A ROS 1 ``.bag`` file, or a ROS 2 bag folder (``metadata.yaml``)."""
    if path.is_file():
        return path.suffix.lower() == ".bag"
    return path.is_dir() and (path / "metadata.yaml").is_file()


@dataclass(frozen=True)
class ImageTopic:
    """One image topic of a bag (``dmtrack info BAG``).

    Attributes
    ----------
    topic : its name.
    msgtype : ``sensor_msgs/msg/Image`` or ``sensor_msgs/msg/CompressedImage``.
    count : messages in the bag.
    camera_info : the ``camera_info`` topic of the same camera when the bag has it, else None.
    """

    topic: str
    msgtype: str
    count: int
    camera_info: str | None


def _open_reader(path: Path) -> Any:
    rosbags_modules("reading a ROS bag")
    from rosbags.highlevel import AnyReader

    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as e:  # rosbags raises its own errors, OSError, sqlite3 and decoding errors for a broken bag
        raise DatasetError(f"cannot read this ROS bag ({type(e).__name__}: {e})", path=path) from None
    return reader


def _topics(reader: Any) -> dict[str, tuple[str, list[Any]]]:
    """topic → (msgtype, its connections)."""
    out: dict[str, tuple[str, list[Any]]] = {}
    for c in reader.connections:
        out.setdefault(c.topic, (c.msgtype, []))[1].append(c)
    return out


def image_topics(path: str | Path) -> list[ImageTopic]:
    """The image topics of the bag at ``path`` (Image and CompressedImage), sorted by name."""
    p = Path(path)
    reader = _open_reader(p)
    try:
        return _image_topics(reader)
    finally:
        reader.close()


def _image_topics(reader: Any) -> list[ImageTopic]:
    topics = _topics(reader)
    out = []
    for name, (msgtype, conns) in sorted(topics.items()):
        if msgtype not in IMAGE_TYPES:
            continue
        info = camera_info_topic(name)
        has_info = info in topics and topics[info][0] == CAMERA_INFO
        out.append(ImageTopic(name, msgtype, sum(int(c.msgcount) for c in conns), info if has_info else None))
    return out


def _choose_topic(path: Path, reader: Any, topic: str | None) -> ImageTopic:
    found = _image_topics(reader)
    names = ", ".join(t.topic for t in found) or "none"
    if topic is None:
        if len(found) == 1:
            return found[0]
        if not found:
            raise DatasetError("the bag has no sensor_msgs/Image or CompressedImage topic", path=path)
        raise DatasetError(f"the bag has {len(found)} image topics; choose one with --topic: {names}", path=path)
    for t in found:
        if t.topic == topic:
            return t
    topics = _topics(reader)
    if topic in topics:
        raise DatasetError(f"topic {topic} is {topics[topic][0]}, not an image; image topics: {names}", path=path)
    raise DatasetError(f"no topic {topic} in the bag; image topics: {names}", path=path)


def decode_image(msg: Any, msgtype: str, where: str) -> np.ndarray:
    """The uint8 grey ``(H, W)`` or RGB ``(H, W, 3)`` pixels of a deserialised Image or CompressedImage."""
    import cv2

    if msgtype == COMPRESSED:
        data = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
        if image is None:
            raise InputError(f"{where}: OpenCV cannot decode this {msg.format or 'compressed'} image")
        if image.dtype != np.uint8:
            raise InputError(f"{where}: expected an 8-bit image, got {image.dtype}")
        if image.ndim == 3:
            code = cv2.COLOR_BGRA2RGB if image.shape[2] == 4 else cv2.COLOR_BGR2RGB
            image = cv2.cvtColor(image, code)
        return np.ascontiguousarray(image)
    enc = str(msg.encoding).lower()
    channels = {"mono8": 1, "8uc1": 1, "rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "8uc3": 3}.get(enc)
    if channels is None:
        raise InputError(f"{where}: image encoding {msg.encoding!r} is not supported (mono8, rgb8, bgr8, rgba8, "
                         "bgra8, or a CompressedImage)")
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
    if step < w * channels or data.size < step * h:
        raise InputError(f"{where}: {data.size} bytes do not hold a {w}x{h} {enc} image with step {step}")
    rows = data[: step * h].reshape(h, step)[:, : w * channels]
    if channels == 1:
        return np.ascontiguousarray(rows)
    pixels = rows.reshape(h, w, channels)[:, :, :3]
    if enc.startswith("bgr") or enc == "8uc3":
        pixels = pixels[:, :, ::-1]
    return np.ascontiguousarray(pixels)


def _field(msg: Any, name: str) -> Any:
    """A CameraInfo field by its ROS 2 name (``k``) or its ROS 1 name (``K``)."""
    value = getattr(msg, name, None)
    return getattr(msg, name.upper()) if value is None else value


def camera_from_info(msg: Any, size: tuple[int, int], path: Path, topic: str) -> tuple[PinholeCamera | None, Any]:
    """The pinhole camera of a CameraInfo and its distortion model (None when there is none to remove).

    An all-zero ``K`` (an uncalibrated camera) gives ``(None, None)``.
    """
    from dmtrack.geometry.distortion import EquidistantModel, RadTanModel

    K = np.asarray(_field(msg, "k"), dtype=np.float64).reshape(-1)
    D = np.asarray(_field(msg, "d"), dtype=np.float64).reshape(-1)
    w, h = size
    if K.size != 9 or not np.any(K):
        return None, None
    if int(msg.width) and int(msg.height) and (int(msg.width), int(msg.height)) != (w, h):
        raise DatasetError(f"{topic} is for {msg.width}x{msg.height} images, {w}x{h} in the image topic", path=path)
    fx, fy, cx, cy = float(K[0]), float(K[4]), float(K[2]), float(K[5])
    try:
        camera = PinholeCamera(fx, fy, cx, cy, w, h)
        model = str(msg.distortion_model).lower()
        if not np.any(D):
            return camera, None
        if model in ("plumb_bob", "rational_polynomial") and (D.size <= 5 or not np.any(D[5:])):
            k = np.zeros(5)
            k[: min(5, D.size)] = D[:5]
            return camera, RadTanModel(fx, fy, cx, cy, w, h, k1=k[0], k2=k[1], p1=k[2], p2=k[3], k3=k[4])
        if model == "equidistant" and D.size >= 4:
            return camera, EquidistantModel(fx, fy, cx, cy, w, h, *(float(v) for v in D[:4]))
    except ValueError as e:
        raise DatasetError(f"{topic}: {e}", path=path) from None
    raise DatasetError(f"{topic}: distortion model {msg.distortion_model!r} with {D.size} coefficients is not "
                       "supported; pass --intrinsics (a calibration file) instead", path=path)


class _BagImages:
    """Reads image ``i`` of one topic; one open reader and one iterator per thread."""

    def __init__(self, path: Path, topic: str, msgtype: str, times_ns: np.ndarray, ordinals: np.ndarray) -> None:
        self.path, self.topic, self.msgtype = path, topic, msgtype
        self.times_ns, self.ordinals = times_ns, ordinals
        self._local = threading.local()

    def _state(self) -> Any:
        s = self._local
        if getattr(s, "reader", None) is None:
            s.reader = _open_reader(self.path)
            s.connections = [c for c in s.reader.connections if c.topic == self.topic]
            s.messages, s.next = None, -1
        return s

    def read(self, i: int) -> np.ndarray:
        s = self._state()
        where = f"{self.path}: {self.topic} message {i}"
        try:
            if s.messages is None or s.next != i:
                s.messages = s.reader.messages(connections=s.connections, start=int(self.times_ns[i]))
                for _ in range(int(self.ordinals[i])):
                    next(s.messages)
            connection, _, raw = next(s.messages)
            s.next = i + 1
            msg = s.reader.deserialize(raw, connection.msgtype)
        except StopIteration:
            s.messages = None
            raise DatasetError(f"{self.topic}: message {i} is missing (the bag changed since it was opened?)",
                               path=self.path) from None
        except Exception as e:  # a truncated or corrupt bag
            s.messages = None
            raise DatasetError(f"{self.topic}: cannot read message {i} ({type(e).__name__}: {e})",
                               path=self.path) from None
        return decode_image(msg, self.msgtype, where)

    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if k != "_local"}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._local = threading.local()


def _scan(path: Path, reader: Any, connections: list[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any]:
    """Bag times (ns), header stamps (s), ordinals among equal bag times, and the first message."""
    times: list[int] = []
    stamps: list[float] = []
    first = None
    try:
        for connection, t, raw in reader.messages(connections=connections):
            msg = reader.deserialize(raw, connection.msgtype)
            if first is None:
                first = msg
            st = msg.header.stamp
            stamps.append(time_of(st.sec, st.nanosec))
            times.append(int(t))
    except Exception as e:
        raise DatasetError(f"cannot read this ROS bag ({type(e).__name__}: {e})", path=path) from None
    t_ns = np.asarray(times, dtype=np.int64)
    ordinals = np.zeros(len(times), dtype=np.int64)
    for k in range(1, len(times)):
        if t_ns[k] == t_ns[k - 1]:
            ordinals[k] = ordinals[k - 1] + 1
    return t_ns, np.asarray(stamps, dtype=np.float64), ordinals, first


def _first_camera_info(path: Path, reader: Any, topic: str | None) -> Any:
    if topic is None:
        return None
    connections = [c for c in reader.connections if c.topic == topic]
    try:
        for connection, _, raw in reader.messages(connections=connections):
            return reader.deserialize(raw, connection.msgtype)
    except Exception as e:
        raise DatasetError(f"{topic}: cannot read its first message ({type(e).__name__}: {e})", path=path) from None
    return None


def open_rosbag(path: str | Path, topic: str | None = None) -> LoaderSequence | UndistortedSequence:
    """Open one image topic of a ROS 1 ``.bag`` or a ROS 2 bag folder as a sequence (see the module docstring).

    Parameters
    ----------
    topic : the image topic; None when the bag has exactly one.

    Raises
    ------
    InputError
        ``rosbags`` is not installed (naming ``pip install 'dmtrack[ros]'``), the bag cannot be read, has no such
        image topic (the message lists the ones it has), or an image cannot be decoded.
    """
    p = Path(path)
    if not p.exists():
        raise DatasetError("no such file or folder", path=p)
    reader = _open_reader(p)
    try:
        chosen = _choose_topic(p, reader, topic)
        connections = [c for c in reader.connections if c.topic == chosen.topic]
        times_ns, stamps, ordinals, first = _scan(p, reader, connections)
        if first is None:
            raise DatasetError(f"{chosen.topic} has no messages", path=p)
        info = _first_camera_info(p, reader, chosen.camera_info)
    finally:
        reader.close()
    image = decode_image(first, chosen.msgtype, f"{p}: {chosen.topic} message 0")
    size = (int(image.shape[1]), int(image.shape[0]))
    camera, distortion = (None, None) if info is None else camera_from_info(info, size, p, chosen.camera_info or "")
    use_stamps = bool((np.diff(stamps) > 0).all() and (stamps[-1] > 0 or len(stamps) == 1))
    timestamps = stamps if use_stamps else times_ns.astype(np.float64) * 1e-9
    details: dict[str, Any] = {
        "bag": "ROS 1" if p.is_file() else "ROS 2",
        "topic": chosen.topic,
        "message_type": chosen.msgtype,
        "timestamps": "image header stamps" if use_stamps else "bag times (the header stamps are zero or do not "
        "increase)",
        "intrinsics_source": chosen.camera_info if camera is not None else None,
    }
    images = _BagImages(p, chosen.topic, chosen.msgtype, times_ns, ordinals)
    name = re.sub(r"[^A-Za-z0-9._-]+", "-", f"{p.stem}{chosen.topic}").strip("-")
    seq = LoaderSequence(name, FORMAT, p, images.read, timestamps, camera, size, details=details)
    if distortion is not None:
        calibration = CalibrationFile(model=distortion, output="crop", output_size=size, path=p, relative=False)
        return undistort_sequence(seq, calibration)
    return seq
