"""A sequence whose frames come from a loader function (zip members, video frames, processed images).

:class:`~dmtrack.datasets.base.FileSequence` covers "one image file per frame"; the readers of TUM monoVO
(images inside ``images.zip``, photometric calibration), video files and undistorted sequences need a
frame source that is not a plain file.  :class:`LoaderSequence` implements the same protocol
(:class:`~dmtrack.datasets.base.Sequence`) around ``load(i) -> image``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack.datasets.base import Frame
from dmtrack.errors import DatasetError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.trajectory import Trajectory

ImageLoader = Callable[[int], np.ndarray]
DepthLoader = Callable[[int], "np.ndarray | None"]


class LoaderSequence:
    """Frames produced on demand by ``load_image(i)`` (and optionally ``load_depth(i)``).

    Parameters
    ----------
    name, format : shown by ``dmtrack info``.
    root : the file or folder the sequence was opened from.
    load_image : ``i -> uint8 (H, W) or (H, W, 3) RGB`` for ``0 <= i < N`` (indices of the *full* sequence).
    timestamps : (N,) float64 seconds.
    camera : pinhole intrinsics of the delivered images, or ``None``.
    size : ``(width, height)`` of the delivered images.
    poses : (N, 4, 4) ground-truth ``T_wc`` (NaN-filled where unknown) or ``None``.
    load_depth : ``i -> float32 metres`` or ``None``.
    paths : per-frame source paths (for ``Frame.path``), or ``None``.
    details : facts shown by ``dmtrack info``.
    indices : the frames of the underlying source this sequence exposes (used by :meth:`slice`).
    """

    def __init__(
        self,
        name: str,
        format: str,
        root: Path,
        load_image: ImageLoader,
        timestamps: np.ndarray,
        camera: PinholeCamera | None,
        size: tuple[int, int],
        poses: np.ndarray | None = None,
        load_depth: DepthLoader | None = None,
        paths: list[Path | None] | None = None,
        details: dict[str, Any] | None = None,
        indices: np.ndarray | None = None,
    ) -> None:
        timestamps = np.asarray(timestamps, dtype=np.float64).reshape(-1)
        n_src = timestamps.shape[0]
        if indices is None:
            indices = np.arange(n_src)
        if indices.size == 0:
            raise DatasetError("no frames", path=root)
        if poses is not None and poses.shape != (n_src, 4, 4):
            raise DatasetError(f"{n_src} frames but {poses.shape[0]} poses", path=root)
        if paths is not None and len(paths) != n_src:
            raise DatasetError(f"{n_src} frames but {len(paths)} paths", path=root)
        self.name = name
        self.format = format
        self.root = Path(root)
        self.camera = camera
        self.details: dict[str, Any] = dict(details or {})
        self._load_image = load_image
        self._load_depth = load_depth
        self._all_timestamps = timestamps
        self._all_poses = poses
        self._paths = paths
        self._indices = np.asarray(indices, dtype=np.int64)
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
        return self._all_timestamps[self._indices]

    @property
    def poses(self) -> np.ndarray | None:
        """(N, 4, 4) ground truth per frame (NaN where unknown), or ``None``."""
        return None if self._all_poses is None else self._all_poses[self._indices]

    @property
    def image_paths(self) -> list[Path | None]:
        if self._paths is None:
            return [None] * len(self)
        return [self._paths[i] for i in self._indices]

    @property
    def has_depth(self) -> bool:
        return self._load_depth is not None

    @property
    def has_groundtruth(self) -> bool:
        poses = self.poses
        return poses is not None and bool(np.isfinite(poses[:, 0, 0]).any())

    @property
    def groundtruth(self) -> Trajectory | None:
        if not self.has_groundtruth:
            return None
        poses = self.poses
        assert poses is not None
        ok = np.isfinite(poses).all(axis=(1, 2))
        return Trajectory(self.timestamps[ok], poses[ok])

    def __len__(self) -> int:
        return int(self._indices.size)

    def __getitem__(self, index: int) -> Frame:
        n = len(self)
        if not -n <= index < n:
            raise IndexError(f"frame {index} out of range for a sequence of {n} frames")
        index %= n
        src = int(self._indices[index])
        image = self._load_image(src)
        if image.shape[1] != self.width or image.shape[0] != self.height:
            raise DatasetError(
                f"frame {src} is {image.shape[1]}x{image.shape[0]}, the sequence is {self.width}x{self.height}",
                path=self._paths[src] if self._paths is not None and self._paths[src] is not None else self.root,
            )
        pose = None
        if self._all_poses is not None and np.isfinite(self._all_poses[src]).all():
            pose = self._all_poses[src].copy()
        depth = None if self._load_depth is None else self._load_depth(src)
        path = None if self._paths is None else self._paths[src]
        return Frame(index, float(self._all_timestamps[src]), image, pose, depth, path)

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]

    def slice(self, start: int = 0, stop: int | None = None) -> LoaderSequence:
        """Frames ``start:stop`` as a new sequence (indices restart at 0)."""
        n = len(self)
        stop = n if stop is None else min(stop, n)
        if not 0 <= start < n:
            raise DatasetError(f"start frame {start} is outside the sequence (0..{n - 1})", path=self.root)
        if stop <= start:
            raise DatasetError(f"empty frame range {start}:{stop}", path=self.root)
        out = LoaderSequence(
            self.name, self.format, self.root, self._load_image, self._all_timestamps, self.camera, self._size,
            self._all_poses, self._load_depth, self._paths, {**self.details, "slice": [start, stop]},
            self._indices[start:stop],
        )
        return out

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(name={self.name!r}, format={self.format!r}, frames={len(self)}, "
            f"size={self.width}x{self.height}, groundtruth={self.has_groundtruth})"
        )
