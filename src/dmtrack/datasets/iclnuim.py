"""ICL-NUIM (Handa et al., ICRA 2014), the "TUM RGB-D compatible" release.

::

    living_room_traj0_frei_png/          (office: traj0_frei_png/ …)
      rgb/0.png … rgb/1508.png           640×480 colour (rendered)
      depth/0.png …                      16-bit, 5000 units per metre (TUM RGB-D convention)
      associations.txt                   "id depth/id.png id rgb/id.png" per line (ids 0, 1, 2, …)
      livingRoom0.gt.freiburg            TUM format "id tx ty tz qx qy qz qw" (ids 1 … N; office: traj0.gt.freiburg)

Frames are the lines of ``associations.txt``; a frame gets the ground-truth line with the same id (the
release has one more image than poses: image 0 has none).  The ids are frame numbers of a 30 fps rendering,
so timestamps are ``id / 30`` seconds.

Camera: ``fx = 481.20, fy = −480.00, cx = 319.5, cy = 239.5`` — the **negative** ``fy`` is official (ICL-NUIM
code page; ``ankurhanda/living_room_iclnuim``: "the focal length on the y-axis is negative. Your projections
will not work properly if you do not use the negative focal length").  The scene was rendered by POV-Ray in a
left-handed frame, and the released poses ``T`` project the images with that negative ``fy``.  dmtrack's
cameras have positive focal lengths, so the reader hands out ``fy = +480`` and poses in the mirrored world:
``T' = F·T·F`` with ``F = diag(1, −1, 1, 1)``.  Then for a world point ``X`` of the release, ``F·X`` projects
with ``T'`` and ``fy = +480`` to exactly the pixel ``X`` projects to with ``T`` and ``fy = −480`` (the camera
frame is ``x_c' = F x_c``).  ``T'`` is a proper rigid motion (det +1).  Without this, VO run with ``fy > 0``
recovers a trajectory whose y coordinates are the negatives of the released ones (reported e.g. in
``victorprad/InfiniTAM#65``).  ``mirror_y=False`` returns the released poses unchanged.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from dmtrack.datasets.base import FileSequence
from dmtrack.errors import DatasetError, InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.files import check_file, read_text_file
from dmtrack.io.trajectory import read_tum

FORMAT = "icl-nuim"
FPS = 30.0
WIDTH, HEIGHT = 640, 480
#: official intrinsics with the sign of fy made positive (see the module documentation)
CAMERA = PinholeCamera(481.20, 480.00, 319.5, 239.5, WIDTH, HEIGHT)
DEPTH_SCALE = 1.0 / 5000.0
F_MIRROR = np.diag([1.0, -1.0, 1.0, 1.0])


def detect(path: Path) -> bool:
    return path.is_dir() and (path / "associations.txt").is_file() and (path / "rgb").is_dir()


def read_associations(path: Path) -> tuple[np.ndarray, list[str], list[str]]:
    """``associations.txt`` → (ids as float (N,), depth paths, rgb paths)."""
    ids: list[float] = []
    depth: list[str] = []
    rgb: list[str] = []
    for lineno, raw in enumerate(read_text_file(path, "association file").splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        f = line.split()
        if len(f) != 4:
            raise InputError(f"expected 'id depth/N.png id rgb/N.png' (4 fields), found {len(f)}",
                             path=path, line=lineno)
        try:
            t_d, t_r = float(f[0]), float(f[2])
        except ValueError:
            raise InputError(f"cannot read the ids of {line[:80]!r}", path=path, line=lineno) from None
        if not (math.isfinite(t_d) and math.isfinite(t_r)):
            raise InputError("the ids must be finite numbers", path=path, line=lineno)
        if t_d != t_r:
            raise InputError(f"depth id {f[0]} and colour id {f[2]} differ", path=path, line=lineno)
        ids.append(t_r)
        depth.append(f[1])
        rgb.append(f[3])
    if not ids:
        raise InputError("no entries", path=path)
    return np.asarray(ids), depth, rgb


def _groundtruth_file(root: Path) -> Path | None:
    cands = sorted(root.glob("*.gt.freiburg")) + [root / "groundtruth.txt"]
    return next((p for p in cands if p.exists()), None)


def mirror_poses(poses: np.ndarray) -> np.ndarray:
    """``F·T·F`` with ``F = diag(1, −1, 1, 1)`` for (..., 4, 4) poses (an involution)."""
    return F_MIRROR @ poses @ F_MIRROR


def open_iclnuim(path: str | Path, mirror_y: bool = True) -> FileSequence:
    """Open an ICL-NUIM sequence in the TUM RGB-D compatible layout.

    Parameters
    ----------
    mirror_y : convert the released poses to the positive-``fy`` camera (``F·T·F``, default).
    """
    root = Path(path)
    if not detect(root):
        if root.is_dir() and (root / "rgb").is_dir():
            check_file(root / "associations.txt", "association file")
        raise DatasetError("not an ICL-NUIM sequence (needs associations.txt and rgb/)", path=root)
    ids, depth_names, rgb_names = read_associations(root / "associations.txt")
    images = [root / n for n in rgb_names]
    for p in (images[0], images[-1]):
        if not p.is_file():
            raise DatasetError("image listed in associations.txt " + ("is a folder" if p.is_dir() else "not found"),
                               path=p)
    depth_paths = [root / n for n in depth_names]
    details: dict = {"intrinsics_source": "ICL-NUIM (fx 481.20, fy -480.00 made positive, cx 319.5, cy 239.5)",
                     "timestamps": "id / 30"}
    poses = None
    gt_path = _groundtruth_file(root)
    if gt_path is not None:
        gt = read_tum(gt_path)
        poses = np.full((ids.size, 4, 4), np.nan)
        lookup = {float(t): k for k, t in enumerate(gt.timestamps)}
        idx = np.asarray([lookup.get(float(t), -1) for t in ids])
        have = idx >= 0
        if not have.any():
            raise InputError("no ground-truth id matches an id of associations.txt", path=gt_path)
        gt_poses = mirror_poses(gt.poses) if mirror_y else gt.poses
        poses[have] = gt_poses[idx[have]]
        details["groundtruth_file"] = gt_path.name
        details["groundtruth_matched"] = int(have.sum())
        details["groundtruth_convention"] = "F·T·F, F = diag(1,-1,1,1) (positive fy)" if mirror_y else "as released"
    return FileSequence(
        name=root.name,
        format=FORMAT,
        root=root,
        image_paths=images,
        timestamps=ids / FPS,
        camera=CAMERA,
        poses=poses,
        depth_paths=[p if p.exists() else None for p in depth_paths],
        depth_scale=DEPTH_SCALE,
        size=(WIDTH, HEIGHT),
        details=details,
    )
