"""A selection of a sequence's frames as a sequence of its own (``dmtrack run … --frames 0-349,500-699``).

:class:`FrameSelection` wraps any reader's sequence and exposes the chosen frames, in increasing order, as frames
0, 1, … of a new sequence: their images, timestamps, ground-truth poses and depth are the original's. Leaving frames
out of a recording makes a camera that jumps — the kidnapped camera of issue 37: 7-Scenes 0–349 followed directly
by 500–699 puts the camera, between two frames, where it had been 200 frames earlier.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Iterator
from typing import Any

import numpy as np

from dmtrack.datasets.base import Frame, Sequence
from dmtrack.errors import InputError
from dmtrack.io.trajectory import Trajectory

__all__ = ["FrameSelection", "parse_frames", "select_frames"]

_RANGE = re.compile(r"^\s*(\d+)\s*(?:(-|:)\s*(\d+)\s*)?$")


def parse_frames(spec: str, n: int) -> np.ndarray:
    """The frame indices of ``spec`` for a sequence of ``n`` frames: comma-separated single frames ``N``, inclusive
    ranges ``A-B`` and half-open ranges ``A:B`` (Python's), in increasing order without repeats."""
    out: list[int] = []
    for part in str(spec).split(","):
        m = _RANGE.match(part)
        if m is None:
            raise InputError(f"--frames {spec!r}: {part.strip()!r} is not N, A-B (inclusive) or A:B (half-open)")
        a = int(m.group(1))
        if m.group(2) is None:
            b = a + 1
        else:
            b = int(m.group(3)) + (1 if m.group(2) == "-" else 0)
        if b <= a:
            raise InputError(f"--frames {spec!r}: the range {part.strip()!r} is empty")
        if b > n:
            raise InputError(f"--frames {spec!r}: frame {b - 1} is outside the sequence (0..{n - 1})")
        if out and a <= out[-1]:
            raise InputError(f"--frames {spec!r}: the frames must increase ({part.strip()!r} comes after frame "
                             f"{out[-1]})")  # fmt: skip
        out.extend(range(a, b))
    if not out:
        raise InputError(f"--frames {spec!r} selects no frame")
    return np.array(out, dtype=np.int64)


class FrameSelection:
    """Frames ``indices`` (increasing) of ``seq`` as a sequence (implements :class:`~dmtrack.datasets.base.Sequence`).

    Frame ``i`` of the selection is frame ``indices[i]`` of ``seq`` with its index renumbered; timestamps, poses and
    depth are the original's. ``groundtruth`` is the original's whole ground truth (runs associate by timestamp).
    """

    def __init__(self, seq: Sequence, indices: np.ndarray, spec: str | None = None) -> None:
        indices = np.asarray(indices, dtype=np.int64)
        if indices.size == 0 or np.any(np.diff(indices) <= 0) or indices[0] < 0 or indices[-1] >= len(seq):
            raise InputError(f"frame selection of {seq.name!r}: indices must increase within 0..{len(seq) - 1}")
        self.seq = seq
        self.indices = indices
        self.spec = spec if spec is not None else f"{len(indices)} frames"
        self.name = f"{seq.name}[{self.spec}]" if spec is not None else seq.name
        self.format = seq.format
        self.camera = seq.camera
        self.details: dict[str, Any] = {**dict(getattr(seq, "details", {}) or {}), "frames": self.spec}

    @property
    def width(self) -> int:
        return int(self.seq.width)

    @property
    def height(self) -> int:
        return int(self.seq.height)

    @property
    def timestamps(self) -> np.ndarray:
        return np.asarray(self.seq.timestamps, dtype=np.float64)[self.indices]

    @property
    def groundtruth(self) -> Trajectory | None:
        return self.seq.groundtruth

    @property
    def has_groundtruth(self) -> bool:
        return bool(self.seq.has_groundtruth)

    @property
    def has_depth(self) -> bool:
        return bool(getattr(self.seq, "has_depth", False))

    def __len__(self) -> int:
        return int(self.indices.size)

    def _source(self, index: int) -> int:
        n = len(self)
        if not -n <= index < n:
            raise IndexError(f"frame {index} out of range for a selection of {n} frames")
        return int(self.indices[index % n])

    def __getitem__(self, index: int) -> Frame:
        return dataclasses.replace(self.seq[self._source(index)], index=int(index) % len(self))

    def read_frame(self, index: int, depth: bool = True) -> Frame:
        """Frame ``index`` without reading its ground-truth depth when ``depth`` is False (if the reader can)."""
        read = getattr(self.seq, "read_frame", None)
        frame = read(self._source(index), depth=depth) if read is not None else self.seq[self._source(index)]
        return dataclasses.replace(frame, index=int(index) % len(self))

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]

    def __repr__(self) -> str:
        return f"FrameSelection({self.seq!r}, frames={self.spec})"


def select_frames(seq: Sequence, spec: str | None) -> Sequence:
    """``seq`` itself for no ``spec``, else its frames ``spec`` (see :func:`parse_frames`) as a sequence."""
    if spec is None:
        return seq
    from dmtrack.datasets.stream import live_source

    if live_source(seq) is not None:
        raise InputError(f"--frames needs a recorded sequence; {seq.name!r} is a live source")
    return FrameSelection(seq, parse_frames(spec, len(seq)), spec=str(spec).replace(" ", ""))
