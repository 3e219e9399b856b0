"""The frames a ROS node receives, as a live sequence the run loop reads (:class:`TopicFrames`).

The node's subscription hands each decoded image to :meth:`TopicFrames.push` with its header stamp; the run reads
them in order with ``frames[i]``, which waits for the next one. At most ``queue_size`` frames wait: when one more
comes, the oldest waiting frame is dropped and counted (:attr:`TopicFrames.dropped`), as a ROS subscription with
``KEEP_LAST`` history does, so an odometry slower than the camera tracks recent frames instead of falling further
behind. ``queue_size=1`` is ``--realtime``'s rule (always the newest frame); the default keeps a few seconds, so that
the burst of frames the geometric start read before the odometry began is tracked, not dropped.

Nothing here imports ROS: the node (:mod:`dmtrack.ros.node`) feeds it, tests can feed it directly.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from dmtrack.datasets.base import Frame
from dmtrack.datasets.stream import EndOfStream, LiveSequence
from dmtrack.geometry.camera import PinholeCamera

FORMAT = "ros2"
#: Frames that may wait for the odometry by default (3 s of a 10 Hz camera).
QUEUE_SIZE = 30
#: Stamps remembered for the messages the node sends (a keyframe's stamp is asked for some frames after its image).
STAMPS_KEPT = 100_000


class TopicFrames(LiveSequence):
    """A live sequence fed by a subscription (see the module docstring).

    Parameters
    ----------
    name : the sequence's name (``metrics.json``, the run folder).
    queue_size : frames that may wait; the oldest is dropped when one more comes.

    Attributes
    ----------
    live : always True (read in order, no length in advance).
    camera : the pinhole camera, set by the node before the run (from ``camera_info`` or the command line).
    received, dropped : images pushed, and images dropped from the queue unread.
    """

    live = True

    def __init__(self, name: str = "ros2", queue_size: int = QUEUE_SIZE) -> None:
        if queue_size < 1:
            raise ValueError(f"queue_size must be ≥ 1, got {queue_size}")
        self.name = name
        self.format = FORMAT
        self.root = name
        self.camera: PinholeCamera | None = None
        self.details: dict[str, Any] = {
            "source": "ROS 2 image topic",
            "timestamps": "image header stamps",
            "frames": "live: until the node is stopped",
            "queue_size": queue_size,
        }
        self._queue: deque[tuple[float, np.ndarray]] = deque()
        self.queue_size = queue_size
        self._cond = threading.Condition()
        self._times: list[float] = []
        self._last: tuple[int, Frame] | None = None
        self._closed = False
        self._should_stop: Callable[[], bool] = lambda: False
        self._stamps: OrderedDict[float, tuple[int, int]] = OrderedDict()
        self._size: tuple[int, int] | None = None
        self.received = 0
        self.dropped = 0

    # -- the subscription's side -------------------------------------------------------------------------------

    def push(self, image: np.ndarray, sec: int, nanosec: int) -> bool:
        """A new image (uint8 grey or RGB) stamped ``(sec, nanosec)``; False (and not queued) when its size differs
        from the first image's or the source is closed."""
        t = float(sec) + float(nanosec) * 1e-9
        with self._cond:
            if self._closed:
                return False
            size = (int(image.shape[1]), int(image.shape[0]))
            if self._size is None:
                self._size = size
            elif size != self._size:
                return False
            self.received += 1
            if len(self._queue) >= self.queue_size:
                self._queue.popleft()
                self.dropped += 1
            self._queue.append((t, image))
            self._stamps[t] = (int(sec), int(nanosec))
            while len(self._stamps) > STAMPS_KEPT:
                self._stamps.popitem(last=False)
            self._cond.notify_all()
        return True

    def wait_first(self, timeout: float) -> bool:
        """Wait at most ``timeout`` seconds for the first image; True once there is one."""
        with self._cond:
            return self._cond.wait_for(lambda: self._size is not None or self._closed, timeout) and not self._closed

    def stamp(self, t: float) -> tuple[int, int]:
        """The ``(sec, nanosec)`` header stamp of the image whose timestamp is ``t`` (rounded from ``t`` for one
        that is not remembered)."""
        with self._cond:
            found = self._stamps.get(t)
        if found is not None:
            return found
        ns = round(t * 1e9)
        return ns // 1_000_000_000, ns % 1_000_000_000

    def close(self) -> None:
        """No more frames: a read waiting for one ends the stream."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    @property
    def closed(self) -> bool:
        return self._closed

    def watch_stop(self, should_stop: Callable[[], bool]) -> None:
        """Called by the run loop: a read waiting for a frame ends the stream once ``should_stop()`` (Ctrl-C)."""
        self._should_stop = should_stop

    # -- the sequence protocol --------------------------------------------------------------------------------

    @property
    def width(self) -> int:
        return 0 if self._size is None else self._size[0]

    @property
    def height(self) -> int:
        return 0 if self._size is None else self._size[1]

    def __getitem__(self, index: int) -> Frame:
        """Frame ``index`` of the frames read so far, or the next one to come (waits); earlier ones are gone."""
        with self._cond:
            if self._last is not None and index == self._last[0]:
                return self._last[1]
            if index != len(self._times):
                raise IndexError(f"{self.name}: frame {index} is not the next one (a live source is read in order; "
                                 f"{len(self._times)} read)")
            while not self._queue:
                if self._closed or self._should_stop():
                    raise EndOfStream(f"{self.name}: stopped after {len(self._times)} frames")
                self._cond.wait(0.05)
            t, image = self._queue.popleft()
            self._times.append(t)
            frame = Frame(index, t, image)
            self._last = (index, frame)
            return frame

    def __iter__(self) -> Iterator[Frame]:
        i = len(self._times)
        while True:
            try:
                yield self[i]
            except EndOfStream:
                return
            i += 1

    def __repr__(self) -> str:
        return (f"TopicFrames({self.name!r}, {self.width}x{self.height}, {self.received} received, "
                f"{self.dropped} dropped)")


def wait_until(predicate: Callable[[], bool], timeout: float | None, step: float = 0.1) -> bool:
    """Poll ``predicate`` every ``step`` seconds (Ctrl-C interrupts) until it holds or ``timeout`` passes."""
    end = None if timeout is None else time.monotonic() + timeout
    while not predicate():
        if end is not None and time.monotonic() >= end:
            return False
        time.sleep(step)
    return True
