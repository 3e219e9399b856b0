"""TUM RGB-D benchmark, official layout (``rgbd_dataset_freiburgX_NAME/``).

::

    rgb.txt          "# comments", then "timestamp rgb/timestamp.png" lines
    depth.txt        likewise for depth/ (16-bit PNG, 5000 units per metre)
    groundtruth.txt  TUM trajectory (100 Hz motion capture, camera-to-world, metres)
    rgb/  depth/

The ground truth is interpolated at each colour image's timestamp (linear in position, slerp in
rotation) when both neighbouring ground-truth poses are less than ``max_gt_gap`` apart; other frames have
no ground truth.  Depth images are associated to colour images by nearest timestamp (≤ 0.02 s, as TUM's
``associate.py``).  Intrinsics: ``camera.txt`` / ``intrinsics.txt`` in the folder when present, otherwise
the published calibration of the Freiburg camera named in the folder (fr1, fr2, fr3).  fr1 and fr2 images
are distorted; the distortion is recorded in ``details`` and not applied by this reader.
"""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import numpy as np

from dmtrack.datasets.base import FileSequence
from dmtrack.datasets.intrinsics import find_intrinsics_file, read_intrinsics_file
from dmtrack.errors import DatasetError, InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.association import associate
from dmtrack.io.files import read_text_file
from dmtrack.io.trajectory import read_tum

FORMAT = "tum-rgbd"
WIDTH, HEIGHT = 640, 480
DEPTH_SCALE = 1.0 / 5000.0
#: Published colour-camera calibrations (fx, fy, cx, cy, k1, k2, p1, p2, k3) of the TUM RGB-D benchmark.
CALIBRATIONS = {
    "freiburg1": (517.3, 516.5, 318.6, 255.3, 0.2624, -0.9531, -0.0054, 0.0026, 1.1633),
    "freiburg2": (520.9, 521.0, 325.1, 249.7, 0.2312, -0.7849, -0.0033, -0.0001, 0.9172),
    "freiburg3": (535.4, 539.2, 320.1, 247.6, 0.0, 0.0, 0.0, 0.0, 0.0),
}
#: ROS default intrinsics, used by the benchmark's own tools when the camera is unknown.
DEFAULT_INTRINSICS = (525.0, 525.0, 319.5, 239.5)


def detect(path: Path) -> bool:
    return path.is_dir() and (path / "rgb.txt").is_file()


def read_file_list(path: Path) -> tuple[np.ndarray, list[str]]:
    """``timestamp filename`` lines of ``rgb.txt`` / ``depth.txt`` (comments skipped)."""
    stamps: list[float] = []
    names: list[str] = []
    for lineno, raw in enumerate(read_text_file(path, "file list").splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.replace(",", " ").split()
        if len(fields) < 2:
            raise InputError("expected 'timestamp filename'", path=path, line=lineno)
        try:
            stamps.append(float(fields[0]))
        except ValueError:
            raise InputError(f"cannot read timestamp {fields[0][:40]!r}", path=path, line=lineno) from None
        if not math.isfinite(stamps[-1]):
            raise InputError(f"timestamp {fields[0][:40]!r} is not a finite number", path=path, line=lineno)
        names.append(fields[1])
    if not names:
        raise InputError("no entries", path=path)
    return np.asarray(stamps), names


def _camera_for(root: Path) -> tuple[PinholeCamera, dict]:
    intr = find_intrinsics_file(root, ("camera.txt", "intrinsics.txt"))
    if intr is not None:
        return read_intrinsics_file(intr, WIDTH, HEIGHT), {"intrinsics_source": intr.name}
    m = re.search(r"freiburg([123])", root.resolve().name)
    if m:
        key = f"freiburg{m.group(1)}"
        c = CALIBRATIONS[key]
        details = {"intrinsics_source": f"published TUM RGB-D calibration of {key}"}
        if any(c[4:]):
            details["distortion_k1k2p1p2k3"] = list(c[4:])
            details["distortion_applied"] = False
        return PinholeCamera(*c[:4], WIDTH, HEIGHT), details
    warnings.warn(
        f"{root}: camera unknown (folder name has no freiburg1/2/3 and no camera.txt); "
        "using the ROS default intrinsics 525, 525, 319.5, 239.5",
        stacklevel=3,
    )
    return PinholeCamera(*DEFAULT_INTRINSICS, WIDTH, HEIGHT), {"intrinsics_source": "ROS default"}


def open_tum_rgbd(path: str | Path, max_gt_gap: float = 0.1, max_depth_diff: float = 0.02) -> FileSequence:
    root = Path(path)
    if not root.is_dir():
        raise DatasetError("not a folder", path=root)
    stamps, names = read_file_list(root / "rgb.txt")
    images = [root / n for n in names]
    for p in (images[0], images[-1]):
        if not p.is_file():
            raise DatasetError("image listed in rgb.txt " + ("is a folder" if p.is_dir() else "not found"), path=p)
    camera, details = _camera_for(root)

    poses = None
    gt_path = root / "groundtruth.txt"
    if gt_path.exists():
        gt = read_tum(gt_path)
        poses = gt.interpolate(stamps, max_gap=max_gt_gap)
        if not np.isfinite(poses[:, 0, 0]).any():
            warnings.warn(f"{gt_path}: no ground-truth pose near any image timestamp", stacklevel=2)
            poses = None

    depth_paths = None
    if (root / "depth.txt").exists():
        d_stamps, d_names = read_file_list(root / "depth.txt")
        ia, ib = associate(stamps, d_stamps, max_depth_diff)
        depth_paths = [None] * len(images)
        for a, b in zip(ia, ib, strict=True):
            depth_paths[a] = root / d_names[b]
    return FileSequence(
        name=root.name,
        format=FORMAT,
        root=root,
        image_paths=images,
        timestamps=stamps,
        camera=camera,
        poses=poses,
        depth_paths=depth_paths,
        depth_scale=DEPTH_SCALE,
        size=(WIDTH, HEIGHT),
        details=details,
    )
