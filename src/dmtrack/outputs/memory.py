"""In-memory sinks: :class:`MemorySink` records every call (tests, notebooks); :class:`MultiSink` fans out."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dmtrack.odometry.sink import FrameInfo, KeyframeSnapshot, OutputSink


@dataclass
class MemorySink:
    """Records every call (poses are copied)."""

    frames: list[tuple[int, float, np.ndarray]] = field(default_factory=list)
    keyframes: list[KeyframeSnapshot] = field(default_factory=list)
    lost: list[tuple[int, str]] = field(default_factory=list)
    closed: bool = False

    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        self.frames.append((int(frame_index), float(timestamp), np.array(T_wc, dtype=np.float64)))

    def on_keyframe(
        self,
        keyframe_id: int,
        frame_index: int,
        timestamp: float,
        T_wc: np.ndarray,
        depthmap_snapshot: KeyframeSnapshot,
    ) -> None:
        self.keyframes.append(depthmap_snapshot)

    def on_lost(self, frame_index: int, reason: str) -> None:
        self.lost.append((int(frame_index), str(reason)))

    def close(self) -> None:
        self.closed = True


class MultiSink:
    """Forwards every call to each of ``sinks`` in order.

    The optional ``on_frame_info`` (:class:`~dmtrack.odometry.sink.FrameInfo`, for viewers), ``on_initial_map``,
    ``on_relocalised`` and ``on_window`` exist only when at least one of ``sinks`` has them, and go to those; so a
    fan-out to sinks without them costs the odometry nothing.
    The children are fixed when the MultiSink is made. :meth:`close` closes each of them even when one fails.
    """

    def __init__(self, *sinks: OutputSink):
        self.sinks = list(sinks)
        self._info_sinks = [s for s in self.sinks if callable(getattr(s, "on_frame_info", None))]
        if self._info_sinks:
            self.on_frame_info = self._forward_frame_info
        self._map_sinks = [s for s in self.sinks if callable(getattr(s, "on_initial_map", None))]
        if self._map_sinks:
            self.on_initial_map = self._forward_initial_map
        self._reloc_sinks = [s for s in self.sinks if callable(getattr(s, "on_relocalised", None))]
        if self._reloc_sinks:
            self.on_relocalised = self._forward_relocalised
        self._window_sinks = [s for s in self.sinks if callable(getattr(s, "on_window", None))]
        if self._window_sinks:
            self.on_window = self._forward_window

    def _forward_window(self, *args: Any) -> None:
        for s in self._window_sinks:
            s.on_window(*args)  # type: ignore[attr-defined]

    def _forward_relocalised(self, *args: Any) -> None:
        for s in self._reloc_sinks:
            s.on_relocalised(*args)  # type: ignore[attr-defined]

    def _forward_initial_map(self, snapshot: KeyframeSnapshot) -> None:
        for s in self._map_sinks:
            s.on_initial_map(snapshot)  # type: ignore[attr-defined]

    def _forward_frame_info(self, info: FrameInfo) -> None:
        for s in self._info_sinks:
            s.on_frame_info(info)  # type: ignore[attr-defined]

    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        for s in self.sinks:
            s.on_frame(frame_index, timestamp, T_wc)

    def on_keyframe(
        self,
        keyframe_id: int,
        frame_index: int,
        timestamp: float,
        T_wc: np.ndarray,
        depthmap_snapshot: KeyframeSnapshot,
    ) -> None:
        for s in self.sinks:
            s.on_keyframe(keyframe_id, frame_index, timestamp, T_wc, depthmap_snapshot)

    def on_lost(self, frame_index: int, reason: str) -> None:
        for s in self.sinks:
            s.on_lost(frame_index, reason)

    def close(self) -> None:
        """Close every child, in order, even when one raises; the first exception is raised afterwards."""
        error: BaseException | None = None
        for s in self.sinks:
            try:
                s.close()
            except BaseException as e:  # noqa: BLE001 - raised below, after the others are closed
                error = error or e
        if error is not None:
            raise error
