"""Live sources — a camera (``camera:N``), an RTSP or HTTP(S) stream — and the grabber of ``--realtime`` runs.

A live source has no length known in advance: frames come until the source ends (a stream closes, a camera is
unplugged) or the run is stopped (Ctrl-C, ``max_frames``).  :class:`StreamSequence` reads them in order with an
OpenCV ``VideoCapture`` and stamps each with the wall clock (``time.time()``, seconds since the epoch) when it
was read.  It has no intrinsics of its own: ``open_sequence("camera:0", intrinsics=…)`` needs ``fx,fy,cx,cy`` or a
calibration file (``dmtrack calibrate-camera camera:0 --board 9x6 --square 0.025 --out camera.txt`` makes one).

The capture is made by a factory, ``capture=cv2.VideoCapture`` by default, called with the camera index (an
``int``) or the URL: a test (or a program with its own device layer) passes another factory, e.g. one that opens a
video file as a stand-in camera.

:class:`FrameGrabber` reads frames on a background thread as a source delivers them and keeps only the newest
one, counting the frames nobody took (``dropped``).  A live source is read as fast as it delivers; a recorded
sequence (a video file, an image folder) is *played*: frame ``i`` is released at its timestamp against the wall
clock, so the video runs at its normal speed whatever the consumer does.
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import cv2
import numpy as np

from dmtrack.datasets.base import Frame
from dmtrack.errors import DatasetError, InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.trajectory import Trajectory

FORMAT = "stream"
#: What a live source's name starts with.
PREFIXES = ("camera:", "rtsp://", "rtsps://", "http://", "https://")
#: The hint every "no intrinsics" message gives.
CALIBRATE_HINT = (
    "pass --intrinsics FX,FY,CX,CY or a calibration file; make one with "
    "`dmtrack calibrate-camera SOURCE --board 9x6 --square 0.025 --out camera.txt` (a printed checkerboard "
    "filmed by this camera)"
)

CaptureFactory = Callable[[Any], Any]


class EndOfStream(IndexError):
    """A live source has no more frames (the stream ended, the device went away)."""


def is_stream(spec: object) -> bool:
    """Whether ``spec`` names a live source (``camera:N``, ``rtsp://…``, ``http(s)://…``)."""
    return isinstance(spec, str) and spec.lower().startswith(PREFIXES)


def capture_target(spec: str) -> int | str:
    """What ``cv2.VideoCapture`` opens for ``spec``: the device index of ``camera:N``, a device path
    (``camera:/dev/video2``), or the URL itself."""
    if spec.lower().startswith("camera:"):
        rest = spec.split(":", 1)[1].strip()
        if re.fullmatch(r"[0-9]+", rest):
            return int(rest)
        if rest.startswith("/"):
            return rest
        raise InputError(f"{spec!r}: expected camera:N (a device index, e.g. camera:0) or camera:/dev/videoN")
    return spec


def stream_name(spec: str) -> str:
    """A short name for run folders and metrics: ``camera0``, ``rtsp-192.168.1.10-live``."""
    target = capture_target(spec)
    if isinstance(target, int):
        return f"camera{target}"
    text = re.sub(r"^[a-z]+:/*", "", str(target), flags=re.IGNORECASE).split("?", 1)[0]
    scheme = spec.split(":", 1)[0].lower()
    cleaned = re.sub(r"[^A-Za-z0-9._-]+", "-", text).strip("-.")
    return f"{scheme}-{cleaned}"[:80] if scheme != "camera" else f"camera-{cleaned}"[:80]


def _to_rgb(frame: np.ndarray) -> np.ndarray:
    if frame.ndim == 2:
        return np.ascontiguousarray(frame)
    if frame.shape[2] == 4:
        return cv2.cvtColor(frame, cv2.COLOR_BGRA2RGB)
    return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)


class LiveSequence:
    """The part of the sequence protocol every live source shares: the timestamps of the frames delivered so far
    (``_times``), their count, and no ground truth or depth."""

    _times: list[float]

    @property
    def timestamps(self) -> np.ndarray:
        return np.asarray(self._times, dtype=np.float64)

    @property
    def groundtruth(self) -> Trajectory | None:
        return None

    @property
    def has_groundtruth(self) -> bool:
        return False

    @property
    def has_depth(self) -> bool:
        return False

    def __len__(self) -> int:
        return len(self._times)


class StreamSequence(LiveSequence):
    """Frames of a live source, read in order as they come (see the module documentation).

    Parameters
    ----------
    spec : ``camera:N``, ``camera:/dev/videoN``, ``rtsp://…``, ``http(s)://…``.
    capture : ``target -> VideoCapture-like`` (``isOpened``, ``read``, ``release``); ``cv2.VideoCapture`` by default.

    Attributes
    ----------
    live : always True: the pipeline reads the frames in order and never asks for the length first.
    camera : ``None`` until intrinsics are given (:func:`dmtrack.datasets.open_sequence` requires them).

    ``len(seq)`` is the number of frames read so far and :attr:`timestamps` their wall-clock times; ``seq[i]``
    reads frames up to ``i`` (skipping the ones before) and returns frame ``i``; the last frame read can be asked
    for again, earlier ones are gone.  At the end of the source ``seq[i]`` raises :class:`EndOfStream`.
    """

    live = True

    def __init__(self, spec: str, capture: CaptureFactory = cv2.VideoCapture) -> None:
        self.spec = spec
        self.name = stream_name(spec)
        self.format = FORMAT
        self.root = spec
        self.camera: PinholeCamera | None = None
        target = capture_target(spec)
        what = f"camera {target}" if isinstance(target, int) else spec
        try:
            cap = capture(target)
        except (cv2.error, OSError) as e:
            raise InputError(f"cannot open {spec} ({what}): {e}") from None
        if cap is None or not cap.isOpened():
            if cap is not None:
                cap.release()
            reason = ("no such device, or another program is using it" if isinstance(target, int)
                      else "unreachable, or not a stream OpenCV can decode")
            raise InputError(f"cannot open {spec} ({what}): {reason}")
        ok, frame = cap.read()
        if not ok or frame is None:
            cap.release()
            raise InputError(f"{spec} ({what}) opened, but it delivered no frame")
        self._cap: Any = cap
        self._lock = threading.Lock()
        image = _to_rgb(frame)
        self._size = (int(image.shape[1]), int(image.shape[0]))
        self._times: list[float] = [time.time()]
        self._last: tuple[int, np.ndarray] = (0, image)
        self._next = 1  # index of the frame the next capture read returns
        backend = getattr(cap, "getBackendName", None)
        self.details: dict[str, Any] = {
            "source": spec,
            "timestamps": "wall clock (time.time()) when each frame was read",
            "frames": "live: until the source ends or the run is stopped",
            "intrinsics_source": None,
        }
        try:
            if callable(backend):
                self.details["capture_backend"] = str(backend())
        except cv2.error:
            pass

    # -- the sequence protocol --------------------------------------------------------------------
    @property
    def width(self) -> int:
        return self._size[0]

    @property
    def height(self) -> int:
        return self._size[1]

    def __getitem__(self, index: int) -> Frame:
        with self._lock:
            last, image = self._last
            if index == last:
                return Frame(index, self._times[index], image)
            if index < last:
                raise IndexError(f"{self.spec}: frame {index} is gone (a live source is read in order; at frame "
                                 f"{last} now)")
            while self._next <= index:
                image = self._read()
                self._times.append(time.time())
                self._last = (self._next, image)
                self._next += 1
            return Frame(index, self._times[index], image)

    def _read(self) -> np.ndarray:
        if self._cap is None:
            raise EndOfStream(f"{self.spec}: the source is closed")
        ok, frame = self._cap.read()
        if not ok or frame is None:
            raise EndOfStream(f"{self.spec}: the source ended after {self._next} frames")
        image = _to_rgb(frame)
        if (image.shape[1], image.shape[0]) != self._size:
            raise DatasetError(f"{self.spec}: frame {self._next} is {image.shape[1]}x{image.shape[0]}, the first "
                               f"was {self._size[0]}x{self._size[1]}")
        return image

    def __iter__(self) -> Iterator[Frame]:
        i = self._last[0]
        while True:
            try:
                yield self[i]
            except EndOfStream:
                return
            i += 1

    def close(self) -> None:
        """Release the capture (the device is free for other programs); later reads end the stream."""
        with self._lock:
            if self._cap is not None:
                self._cap.release()
            self._cap = None

    @property
    def closed(self) -> bool:
        return self._cap is None

    def __repr__(self) -> str:
        return f"StreamSequence({self.spec!r}, {self.width}x{self.height}, {len(self)} frames read)"


def open_stream(spec: str, capture: CaptureFactory = cv2.VideoCapture) -> StreamSequence:
    """Open a live source (see :class:`StreamSequence`)."""
    return StreamSequence(str(spec), capture=capture)


def live_source(seq: Any) -> StreamSequence | None:
    """The live source under ``seq`` (itself, or the base of an undistorted sequence), or ``None``."""
    for _ in range(8):
        if seq is None:
            return None
        if getattr(seq, "live", False) is True and hasattr(seq, "close"):
            return seq
        seq = getattr(seq, "base", None)
    return None


class FrameGrabber:
    """Frames ``start … stop − 1`` read on a background thread; the consumer always gets the newest one.

    Parameters
    ----------
    read : ``i -> Frame`` (blocks until frame ``i`` is there; :class:`EndOfStream` when the source ends).
    start, stop : the frames to read (``stop=None``: until the source ends).
    timestamps : per-frame times (seconds) of a recorded sequence: frame ``i`` is released
        ``timestamps[i] − timestamps[start]`` seconds after the first one (played at normal speed); ``None`` for
        a live source (released as soon as it is read).
    clock : the monotonic clock the pacing uses.

    Attributes
    ----------
    delivered : frames released to the consumer's slot.
    dropped : released frames that were replaced by a newer one before the consumer took them.
    finished : the thread has ended (source ended, ``stop`` reached, stopped, or an error).
    error : the exception that ended the thread, re-raised by :meth:`take`.
    """

    def __init__(
        self,
        read: Callable[[int], Frame],
        start: int,
        stop: int | None,
        timestamps: np.ndarray | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._read = read
        self._start = start
        self._stop = stop
        self._times = None if timestamps is None else np.asarray(timestamps, dtype=np.float64)
        self._clock = clock
        self._cond = threading.Condition()
        self._halt = threading.Event()
        self._slot: tuple[int, Frame, float] | None = None
        self._thread = threading.Thread(target=self._run, name="dmtrack-grabber", daemon=True)
        self.delivered = 0
        self.dropped = 0
        self.finished = False
        self.error: BaseException | None = None

    def start(self) -> FrameGrabber:
        self._thread.start()
        return self

    def _due(self, i: int, t0: float) -> float | None:
        if self._times is None:
            return None
        dt = float(self._times[i] - self._times[self._start])
        return t0 + dt if np.isfinite(dt) else None

    def _run(self) -> None:
        t0: float | None = None
        i = self._start
        try:
            while (self._stop is None or i < self._stop) and not self._halt.is_set():
                t_read = time.perf_counter()
                try:
                    frame = self._read(i)
                except EndOfStream:
                    break
                read_s = time.perf_counter() - t_read
                if t0 is None:
                    t0 = self._clock()
                due = self._due(i, t0)
                if due is not None:
                    wait = due - self._clock()
                    if wait > 0 and self._halt.wait(wait):
                        break
                with self._cond:
                    if self._slot is not None:
                        self.dropped += 1
                    self._slot = (i, frame, read_s)
                    self.delivered += 1
                    self._cond.notify_all()
                i += 1
        except BaseException as e:  # noqa: BLE001 - handed to the consumer by take()
            self.error = e
        finally:
            with self._cond:
                self.finished = True
                self._cond.notify_all()

    def take(self, timeout: float | None = None) -> tuple[int, Frame, float] | None:
        """The newest frame not taken yet as ``(index, frame, read_seconds)``; ``None`` after ``timeout`` seconds
        without one, or when :attr:`finished` and nothing is left.  Re-raises the thread's error."""
        with self._cond:
            self._cond.wait_for(lambda: self._slot is not None or self.finished, timeout)
            item, self._slot = self._slot, None
            if item is None and self.error is not None:
                error, self.error = self.error, None
                raise error
            return item

    def close(self, timeout: float = 5.0) -> bool:
        """Stop the thread and wait for it (at most ``timeout`` seconds: a read blocked on a stalled stream
        cannot be cut short); True when it has ended."""
        self._halt.set()
        if self._thread.is_alive():
            self._thread.join(timeout)
        return not self._thread.is_alive()


class RealtimeFrames:
    """The newest frame of a :class:`~dmtrack.datasets.stream.FrameGrabber` (reading frames with ``read(i)``) each
    time the odometry is ready; ``prepare`` (crop + feature) runs on the calling thread. Stops when the grabber ends
    or ``should_stop()``.

    ``first`` (optional) gives frame ``start`` when the iteration begins — a frame read already (the geometric start
    read the first frames, and the odometry must begin with the frame its map belongs to) — or None; that frame is
    delivered first, never dropped, and the grabber begins after it."""

    def __init__(
        self, seq: Any, read: Any, start: int, stop: int | None, live: bool, prepare: Any, should_stop: Any,
        first: Callable[[], Frame | None] | None = None,
    ) -> None:  # fmt: skip
        self._read, self._start, self._stop = read, start, stop
        self._times = None if live else seq.timestamps
        self._grabber: FrameGrabber | None = None
        self._prepare = prepare
        self._should_stop = should_stop
        self._first = first
        self._given = 0  # frames delivered besides the grabber's

    @property
    def delivered(self) -> int:
        return self._given + (0 if self._grabber is None else self._grabber.delivered)

    @property
    def dropped(self) -> int:
        return 0 if self._grabber is None else self._grabber.dropped

    def __iter__(self) -> Any:
        start = self._start
        frame = None if self._first is None else self._first()
        if frame is not None:
            self._given = 1
            yield start, self._prepare(frame, 0.0)
            start += 1
        self._grabber = FrameGrabber(self._read, start, self._stop, self._times).start()
        while True:
            item = self._grabber.take(timeout=0.05)
            if item is None:
                if self._grabber.finished or self._should_stop():
                    return
                continue
            i, frame, read_s = item
            yield i, self._prepare(frame, read_s)

    def close(self) -> None:
        if self._grabber is not None:
            self._grabber.close()
