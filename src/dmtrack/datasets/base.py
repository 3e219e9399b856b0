"""The sequence protocol every dataset reader implements.

A *sequence* is an ordered list of frames from one camera.  Frames are read lazily, one at a time, so a
5000-frame sequence never sits in memory at once.  Every reader returns :class:`Frame` objects with:

* ``image`` — ``uint8``, ``(H, W)`` grey or ``(H, W, 3)`` **RGB** (not OpenCV's BGR);
* ``pose`` — ground-truth camera-to-world ``T_wc`` (4×4 float64) or ``None`` where there is none;
* ``depth`` — ground-truth depth in metres (float32, 0 where invalid) or ``None``.

Readers deliver images at their native size; the odometry crops them to multiples of 16
(:meth:`dmtrack.geometry.camera.PinholeCamera.crop_to_multiple`).
"""

from __future__ import annotations

from collections.abc import Iterator
from collections.abc import Sequence as _Seq
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from dmtrack.errors import DatasetError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.images import read_depth_png, read_image
from dmtrack.io.trajectory import Trajectory


@dataclass(frozen=True)
class Frame:
    """One frame of a sequence.

    Attributes
    ----------
    index : position in the sequence (0-based, after any slicing of the sequence).
    timestamp : seconds (or the dataset's own time unit / frame index where it has no clock).
    image : uint8 ``(H, W)`` grey or ``(H, W, 3)`` RGB.
    pose : ground-truth ``T_wc`` (4×4 float64) or ``None``.
    depth : ground-truth depth in metres (float32, 0 = invalid) or ``None``.
    path : the image file, when there is one.
    """

    index: int
    timestamp: float
    image: np.ndarray
    pose: np.ndarray | None = None
    depth: np.ndarray | None = None
    path: Path | None = None


@runtime_checkable
class Sequence(Protocol):
    """What the odometry, the CLI and the benchmarks need from a dataset."""

    name: str
    format: str
    camera: PinholeCamera | None

    @property
    def width(self) -> int: ...

    @property
    def height(self) -> int: ...

    @property
    def timestamps(self) -> np.ndarray: ...

    @property
    def groundtruth(self) -> Trajectory | None: ...

    @property
    def has_groundtruth(self) -> bool: ...

    def __len__(self) -> int: ...

    def __getitem__(self, index: int) -> Frame: ...

    def __iter__(self) -> Iterator[Frame]: ...


class FileSequence:
    """A sequence backed by one image file per frame (the common case for every file-based reader).

    Parameters
    ----------
    name, format : shown by ``dmtrack info`` and written to ``metrics.json``.
    root : the folder the sequence was opened from.
    image_paths : one image per frame, in order.
    timestamps : (N,) float64.
    camera : intrinsics of the images as stored, or ``None`` if the dataset gives none.
    poses : (N, 4, 4) ground-truth ``T_wc`` per frame, NaN-filled where a frame has none; or ``None``.
    depth_paths : per-frame depth PNGs (``None`` entries allowed), or ``None``.
    depth_scale : metres per depth-PNG unit (e.g. 1/1000 for millimetres, 1/5000 for TUM RGB-D).
    depth_invalid : PNG values meaning "no depth" besides 0 (7-Scenes uses 65535).
    grey : read images as grey (True), colour (False) or as stored (None).
    size : (width, height) if known without reading an image; else the first image is read once.
    details : further facts about the sequence shown by ``dmtrack info`` (e.g. where the intrinsics
        came from, distortion that is not applied).
    """

    def __init__(
        self,
        name: str,
        format: str,
        root: Path,
        image_paths: _Seq[Path],
        timestamps: np.ndarray,
        camera: PinholeCamera | None,
        poses: np.ndarray | None = None,
        depth_paths: _Seq[Path | None] | None = None,
        depth_scale: float = 1.0 / 1000.0,
        depth_invalid: int | None = None,
        grey: bool | None = None,
        size: tuple[int, int] | None = None,
        details: dict[str, Any] | None = None,
    ) -> None:
        if len(image_paths) == 0:
            raise DatasetError("no images found", path=root)
        timestamps = np.asarray(timestamps, dtype=np.float64)
        if timestamps.shape != (len(image_paths),):
            raise DatasetError(
                f"{len(image_paths)} images but {timestamps.shape[0]} timestamps", path=root
            )
        if poses is not None and poses.shape != (len(image_paths), 4, 4):
            raise DatasetError(f"{len(image_paths)} images but {poses.shape[0]} poses", path=root)
        if depth_paths is not None and len(depth_paths) != len(image_paths):
            raise DatasetError(f"{len(image_paths)} images but {len(depth_paths)} depth maps", path=root)
        self.name = name
        self.format = format
        self.root = Path(root)
        self.camera = camera
        self._paths = list(image_paths)
        self._timestamps = timestamps
        self._poses = poses
        self._depth_paths = None if depth_paths is None else list(depth_paths)
        self._depth_scale = depth_scale
        self._depth_invalid = depth_invalid
        self._grey = grey
        self.details: dict[str, Any] = dict(details or {})
        if size is None and camera is not None:
            size = (camera.width, camera.height)
        if size is None:
            first = read_image(self._paths[0], grey=self._grey)
            size = (first.shape[1], first.shape[0])
        self._size = (int(size[0]), int(size[1]))

    # -- protocol -------------------------------------------------------------------------------
    @property
    def width(self) -> int:
        return self._size[0]

    @property
    def height(self) -> int:
        return self._size[1]

    @property
    def timestamps(self) -> np.ndarray:
        return self._timestamps

    @property
    def image_paths(self) -> list[Path]:
        return list(self._paths)

    @property
    def has_depth(self) -> bool:
        return self._depth_paths is not None and any(p is not None for p in self._depth_paths)

    @property
    def has_groundtruth(self) -> bool:
        return self._poses is not None and bool(np.isfinite(self._poses[:, 0, 0]).any())

    @property
    def groundtruth(self) -> Trajectory | None:
        """Ground truth of the frames that have it, stamped with the frames' timestamps."""
        if not self.has_groundtruth:
            return None
        assert self._poses is not None
        ok = np.isfinite(self._poses).all(axis=(1, 2))
        return Trajectory(self._timestamps[ok], self._poses[ok])

    def __len__(self) -> int:
        return len(self._paths)

    def __getitem__(self, index: int) -> Frame:
        n = len(self._paths)
        if not -n <= index < n:
            raise IndexError(f"frame {index} out of range for a sequence of {n} frames")
        index %= n
        image = read_image(self._paths[index], grey=self._grey)
        if image.shape[1] != self.width or image.shape[0] != self.height:
            raise DatasetError(
                f"image is {image.shape[1]}x{image.shape[0]}, the sequence is {self.width}x{self.height}",
                path=self._paths[index],
            )
        pose = None
        if self._poses is not None and np.isfinite(self._poses[index]).all():
            pose = self._poses[index].copy()
        depth = None
        if self._depth_paths is not None and self._depth_paths[index] is not None:
            depth = read_depth_png(self._depth_paths[index], self._depth_scale, self._depth_invalid)
        return Frame(index, float(self._timestamps[index]), image, pose, depth, self._paths[index])

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]

    def slice(self, start: int = 0, stop: int | None = None) -> FileSequence:
        """Frames ``start:stop`` as a new sequence (indices restart at 0)."""
        n = len(self)
        stop = n if stop is None else min(stop, n)
        if not 0 <= start < n:
            raise DatasetError(f"start frame {start} is outside the sequence (0..{n - 1})", path=self.root)
        if stop <= start:
            raise DatasetError(f"empty frame range {start}:{stop}", path=self.root)
        return FileSequence(
            self.name,
            self.format,
            self.root,
            self._paths[start:stop],
            self._timestamps[start:stop],
            self.camera,
            None if self._poses is None else self._poses[start:stop],
            None if self._depth_paths is None else self._depth_paths[start:stop],
            self._depth_scale,
            self._depth_invalid,
            self._grey,
            self._size,
            {**self.details, "slice": [start, stop]},
        )

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(name={self.name!r}, format={self.format!r}, frames={len(self)}, "
            f"size={self.width}x{self.height}, groundtruth={self.has_groundtruth})"
        )
