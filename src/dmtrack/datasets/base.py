"""The sequence protocol every dataset reader implements.

A *sequence* is an ordered list of frames from one camera.  Frames are read lazily, one at a time, so a
5000-frame sequence never sits in memory at once.  Every reader returns :class:`Frame` objects with:

* ``image`` — ``uint8``, ``(H, W)`` grey or ``(H, W, 3)`` **RGB** (not OpenCV's BGR);
* ``pose`` — ground-truth camera-to-world ``T_wc`` (4×4 float64) or ``None`` where there is none;
* ``depth`` — ground-truth depth in metres (float32, 0 where invalid) or ``None``.

Readers deliver images at their native size; the odometry crops them to multiples of 16
(:meth:`dmtrack.geometry.camera.PinholeCamera.crop_to_multiple`).

A reader may also offer ``read_frame(index, depth=False)``: the frame without its ground-truth depth, which a run
does not need (:class:`LoaderSequence` and every reader built on it do; :func:`dmtrack.pipeline.track` uses it when
it is there).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
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
        return self.read_frame(index)

    def read_frame(self, index: int, depth: bool = True) -> Frame:
        """Frame ``index`` (``seq[index]``); ``depth=False`` does not read its ground-truth depth (``Frame.depth``
        is then ``None``): a run needs only the image, and decoding a depth map costs as much as the image."""
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
        depth_map = None if self._load_depth is None or not depth else self._load_depth(src)
        path = None if self._paths is None else self._paths[src]
        return Frame(index, float(self._all_timestamps[src]), image, pose, depth_map, path)

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


class FileSequence(LoaderSequence):
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
    depth_reader : reads one depth file into float32 metres, replacing the 16-bit PNG reading (e.g. New
        Tsukuba's OpenCV-XML depth maps); ``depth_scale``/``depth_invalid`` are then unused.
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
        depth_reader: Callable[[Path], np.ndarray] | None = None,
    ) -> None:
        paths = list(image_paths)
        if not paths:
            raise DatasetError("no images found", path=root)
        timestamps = np.asarray(timestamps, dtype=np.float64)
        if timestamps.shape != (len(paths),):
            raise DatasetError(f"{len(paths)} images but {timestamps.shape[0]} timestamps", path=root)
        depths = None if depth_paths is None else list(depth_paths)
        if depths is not None and len(depths) != len(paths):
            raise DatasetError(f"{len(paths)} images but {len(depths)} depth maps", path=root)
        if size is None and camera is not None:
            size = (camera.width, camera.height)
        if size is None:
            first = read_image(paths[0], grey=grey)
            size = (first.shape[1], first.shape[0])

        def load_image(i: int) -> np.ndarray:
            return read_image(paths[i], grey=grey)

        width, height = int(size[0]), int(size[1])

        def load_depth(i: int) -> np.ndarray | None:
            p = depths[i] if depths is not None else None
            if p is None:
                return None
            d = depth_reader(p) if depth_reader is not None else read_depth_png(p, depth_scale, depth_invalid)
            if d.shape[:2] != (height, width):
                raise DatasetError(f"depth map is {d.shape[1]}x{d.shape[0]}, the images are {width}x{height}", path=p)
            return d

        has_depth = depths is not None and any(p is not None for p in depths)
        super().__init__(
            name, format, root, load_image, timestamps, camera, size, poses,
            load_depth if has_depth else None, paths, details,
        )
