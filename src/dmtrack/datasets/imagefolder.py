"""A folder of images, with optional ground truth, timestamps and intrinsics beside them.

::

    FOLDER/
      images/ (or rgb/, image/, img/; or the images directly in FOLDER)   *.png *.jpg …, in natural name order
      groundtruth.txt           optional, TUM format (camera-to-world)
      times.txt                 optional, one timestamp per image (first column)
      camera.txt | intrinsics.txt | camera-intrinsics.txt | K.txt | calib.txt
                                optional, "fx fy cx cy" or a 3×3 K

Timestamps come from ``times.txt``; otherwise they are the frame index (or index / ``fps`` if given).
Ground-truth poses are matched to frames by timestamp (``max_gt_diff``, 0.01 s by default; exact for
frame-index timestamps).  Without an intrinsics file the sequence has no camera: ``dmtrack info`` still
describes it, and ``--intrinsics fx,fy,cx,cy`` supplies one.  This is the layout of
``shared/data/tsukuba-150`` (New Tsukuba: f = 615, cx = 320, cy = 240).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from dmtrack.datasets.base import FileSequence
from dmtrack.datasets.intrinsics import find_intrinsics_file, read_intrinsics_file
from dmtrack.errors import DatasetError, InputError
from dmtrack.io.association import associate
from dmtrack.io.images import read_image
from dmtrack.io.trajectory import read_times, read_tum

FORMAT = "image-folder"
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm")
IMAGE_SUBDIRS = ("images", "rgb", "image", "img", "frames")
GROUNDTRUTH_FILES = ("groundtruth.txt", "groundtruth_tum.txt", "gt.txt")


def _natural_key(path: Path) -> list:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path.name)]


def list_images(folder: Path) -> list[Path]:
    """The images of ``folder`` in natural name order (an entry with an image name that is not a readable image —
    a folder, say — stays in the list, so that reading its frame names it)."""
    return sorted((p for p in folder.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS), key=_natural_key)


def image_dir(root: Path) -> Path | None:
    for name in IMAGE_SUBDIRS:
        if (root / name).is_dir() and list_images(root / name):
            return root / name
    if root.is_dir() and list_images(root):
        return root
    return None


def detect(path: Path) -> bool:
    return path.is_dir() and image_dir(path) is not None


def open_image_folder(path: str | Path, fps: float | None = None, max_gt_diff: float = 0.01) -> FileSequence:
    """Open an image folder.

    Parameters
    ----------
    fps : timestamps = index / fps when there is no ``times.txt`` (default: the frame index).
    max_gt_diff : largest timestamp difference for matching a ground-truth pose to an image.
    """
    root = Path(path)
    if not root.is_dir():
        raise DatasetError("not a folder", path=root)
    folder = image_dir(root)
    if folder is None:
        raise DatasetError(f"no images ({', '.join(IMAGE_EXTENSIONS)}) in the folder or in images/", path=root)
    images = list_images(folder)
    first = read_image(images[0])
    height, width = first.shape[:2]

    details: dict = {"intrinsics_source": None}
    camera = None
    intr = find_intrinsics_file(root)
    if intr is not None:
        camera = read_intrinsics_file(intr, width, height)
        details["intrinsics_source"] = intr.name

    times_path = root / "times.txt"
    if times_path.exists():
        timestamps = read_times(times_path)
        if timestamps.shape[0] != len(images):
            raise InputError(f"{timestamps.shape[0]} timestamps for {len(images)} images in {folder}",
                             path=times_path)
        details["timestamps"] = "times.txt"
    elif fps is not None:
        timestamps = np.arange(len(images)) / float(fps)
        details["timestamps"] = f"index / {fps:g} fps"
    else:
        timestamps = np.arange(len(images), dtype=np.float64)
        details["timestamps"] = "frame index"

    poses = None
    gt_path = next((root / n for n in GROUNDTRUTH_FILES if (root / n).exists()), None)
    if gt_path is not None:
        gt = read_tum(gt_path)
        ia, ib = associate(timestamps, gt.timestamps, max_gt_diff)
        if ia.size == 0:
            raise InputError(
                f"no ground-truth timestamp matches an image timestamp (within {max_gt_diff} s; images: "
                f"{details['timestamps']})",
                path=gt_path,
            )
        poses = np.full((len(images), 4, 4), np.nan)
        poses[ia] = gt.poses[ib]
        details["groundtruth_file"] = gt_path.name
        details["groundtruth_matched"] = int(ia.size)
    return FileSequence(
        name=root.name,
        format=FORMAT,
        root=root,
        image_paths=images,
        timestamps=timestamps,
        camera=camera,
        poses=poses,
        size=(width, height),
        details=details,
    )
