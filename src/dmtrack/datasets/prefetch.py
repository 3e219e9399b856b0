"""Frames read ahead of the odometry, in order, on one background thread.

A run reads, decodes, crops and converts (the feature) frame ``i + 1`` while the odometry works on frame ``i``: the
order is kept, so the results are those of reading inline; only memory and speed differ.
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

from dmtrack.datasets.stream import EndOfStream

__all__ = ["PREFETCH", "PREFETCH_BYTES", "PrefetchedFrames", "feature_bytes"]

#: Frames read and converted ahead of the odometry by the run's background thread (besides the next one)...
PREFETCH = 2
#: ... while their feature maps take at most this many bytes: a 640×480 dense SIFT map is 157 MB, so its frames are
#: read and converted in turn, on that thread (the order and the results are the same; only memory and speed differ).
PREFETCH_BYTES = 64 << 20


class PrefetchedFrames:
    """Frames ``start … stop − 1`` (``stop=None``: until a live source ends) loaded by one background thread, in
    order, at most :data:`PREFETCH` frames ahead; the odometry consumes them in order, so results are the same as
    loading them inline."""

    def __init__(self, load: Any, start: int, stop: int | None) -> None:
        self._load = load
        self._start, self._stop = start, stop
        self._ahead = PREFETCH  # frames in flight besides the next one, set from the first frame's feature size
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="dmtrack-prefetch")
        self._pending: deque[Future] = deque()
        self.delivered = 0
        self.dropped = 0

    def __iter__(self) -> Any:
        nxt = i = self._start
        while self._stop is None or i < self._stop:
            # none ahead until the first feature map's size is known, then as many as PREFETCH_BYTES holds
            ahead = self._ahead if i > self._start else 0
            while (self._stop is None or nxt < self._stop) and len(self._pending) <= ahead:
                self._pending.append(self._pool.submit(self._load, nxt))
                nxt += 1
            try:
                item = self._pending.popleft().result()
            except EndOfStream:  # a live source ended
                return
            if i == self._start:
                size = feature_bytes(item[2])
                self._ahead = min(PREFETCH, PREFETCH_BYTES // max(size, 1))
            self.delivered += 1
            yield i, item
            item = None  # the odometry is done with frame i: its feature map goes before the next one is awaited
            i += 1

    def close(self) -> None:
        for fut in self._pending:
            fut.cancel()
        self._pool.shutdown(wait=True)


def feature_bytes(fmap: Any) -> int:
    """Bytes of a prepared frame's feature map (one array, or one per pyramid level)."""
    if isinstance(fmap, (list, tuple)):
        return sum(int(getattr(f, "nbytes", 0)) for f in fmap)
    return int(getattr(fmap, "nbytes", 0))
