"""Microsoft 7-Scenes, one sequence folder (``seq-01/`` or a copy of its files).

Layout: ``frame-NNNNNN.color.png`` (or ``.color.jpg``) 640×480 colour, ``frame-NNNNNN.depth.png`` uint16
millimetres (65535 = invalid; the depth camera is **not** registered to the colour camera), and
``frame-NNNNNN.pose.txt`` a 4×4 camera-to-world matrix in metres.  The official release ships no
intrinsics file; its documented calibration (fx = fy = 585, cx = 320, cy = 240) is used unless the folder
has ``camera-intrinsics.txt`` (3×3 K).  Recorded at 30 Hz: timestamp = frame number / 30.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from dmtrack.datasets.base import FileSequence
from dmtrack.datasets.intrinsics import find_intrinsics_file, read_intrinsics_file
from dmtrack.errors import DatasetError, InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.files import read_text_file

FORMAT = "7scenes"
FPS = 30.0
WIDTH, HEIGHT = 640, 480
#: The calibration documented on the 7-Scenes page (used when the folder has no intrinsics file).
DEFAULT_CAMERA = PinholeCamera(585.0, 585.0, 320.0, 240.0, WIDTH, HEIGHT)
_FRAME_RE = re.compile(r"^frame-(\d+)\.color\.(png|jpg|jpeg)$", re.IGNORECASE)


def detect(path: Path) -> bool:
    return path.is_dir() and any(_FRAME_RE.match(p.name) for p in path.glob("frame-*.color.*"))


def read_pose_file(path: Path) -> np.ndarray:
    """A 4×4 pose matrix; NaN/inf (7-Scenes marks failed KinectFusion frames with -inf) → all-NaN.

    The stored rotation blocks are not quite orthonormal (KinectFusion's matrices are scaled by
    ~0.9997); they are projected to the nearest rotation (SVD), which moves no entry by more than 1e-3.
    """
    fields = _pose_fields(path)
    try:
        values = np.asarray([float(f) for f in fields], dtype=np.float64)
    except ValueError:
        bad = next(f for f in fields if not _is_number(f))
        raise InputError(f"cannot read {bad[:40]!r} of the 4×4 pose matrix as a number", path=path) from None
    if values.size != 16:
        raise InputError(f"expected a 4×4 pose matrix (16 numbers), found {values.size}", path=path)
    pose = values.reshape(4, 4)
    if not np.isfinite(pose).all():
        return np.full((4, 4), np.nan)
    if np.abs(pose).max() > 1e150:
        raise InputError("the pose matrix has absurdly large values", path=path)
    if not np.allclose(pose[3], (0.0, 0.0, 0.0, 1.0), atol=1e-6):
        raise InputError("the last row of the pose matrix must be 0 0 0 1", path=path)
    u, sv, vt = np.linalg.svd(pose[:3, :3])
    if np.linalg.det(u @ vt) < 0 or np.abs(sv - 1.0).max() > 0.05:
        raise InputError(f"not a rotation (singular values {np.round(sv, 4).tolist()})", path=path)
    pose[:3, :3] = u @ vt
    return pose


def read_pose_files(paths: list[Path]) -> np.ndarray:
    """(n, 4, 4): :func:`read_pose_file` of each path, the same values, the checks and the projection done on all at
    once (a 700-frame folder opens 20 ms sooner). Any file that one would refuse: the first such file's error, as the
    files are read in order (by :func:`read_pose_file`, file by file)."""
    rows = np.empty((len(paths), 16))
    for i, path in enumerate(paths):
        try:
            rows[i] = [float(f) for f in _pose_fields(path)]
        except ValueError:  # not a number, or not 16 of them
            return np.stack([read_pose_file(p) for p in paths])
    poses = rows.reshape(-1, 4, 4)
    finite = np.isfinite(rows).all(axis=1)
    poses[~finite] = np.nan
    ok = poses[finite]
    if not len(ok):
        return poses
    if np.abs(ok).max() <= 1e150 and np.allclose(ok[:, 3], (0.0, 0.0, 0.0, 1.0), atol=1e-6):  # before the SVD
        u, sv, vt = np.linalg.svd(ok[:, :3, :3])
        rot = u @ vt
        if not (np.linalg.det(rot) < 0).any() and np.abs(sv - 1.0).max() <= 0.05:
            ok[:, :3, :3] = rot
            poses[finite] = ok
            return poses
    return np.stack([read_pose_file(p) for p in paths])


def _pose_fields(path: Path) -> list[str]:
    return read_text_file(path, "pose file").replace(",", " ").split()


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def open_7scenes(path: str | Path) -> FileSequence:
    root = Path(path)
    if not root.is_dir():
        raise DatasetError("not a folder", path=root)
    frames = sorted(
        ((int(m.group(1)), p) for p in root.iterdir() if (m := _FRAME_RE.match(p.name))), key=lambda x: x[0]
    )
    if not frames:
        seqs = sorted(p.name for p in root.glob("seq-*") if p.is_dir())
        hint = f" — it has sequences {', '.join(seqs)}: pass one of them" if seqs else ""
        raise DatasetError(f"no 7-Scenes frames (frame-NNNNNN.color.png){hint}", path=root)
    numbers = np.asarray([n for n, _ in frames])
    image_paths = [p for _, p in frames]
    with os.scandir(root) as entries:  # one listing instead of a stat per file (a folder in a file's place is read
        files = {e.name for e in entries}  # as one and refused, naming it)
    poses = np.full((len(frames), 4, 4), np.nan)
    posed = [i for i, (n, _) in enumerate(frames) if f"frame-{n:06d}.pose.txt" in files]
    have_pose = bool(posed)
    if posed:
        poses[posed] = read_pose_files([root / f"frame-{frames[i][0]:06d}.pose.txt" for i in posed])
    depth_paths: list[Path | None] = [root / f"frame-{n:06d}.depth.png" if f"frame-{n:06d}.depth.png" in files
                                      else None for n, _ in frames]  # fmt: skip
    intr = find_intrinsics_file(root, ("camera-intrinsics.txt", "camera.txt", "intrinsics.txt"))
    camera = DEFAULT_CAMERA if intr is None else read_intrinsics_file(intr, WIDTH, HEIGHT)
    seq = FileSequence(
        name=root.name,
        format=FORMAT,
        root=root,
        image_paths=image_paths,
        timestamps=numbers / FPS,
        camera=camera,
        poses=poses if have_pose else None,
        depth_paths=depth_paths if any(d is not None for d in depth_paths) else None,
        depth_scale=1.0 / 1000.0,
        depth_invalid=65535,
        size=(WIDTH, HEIGHT),
        details={
            "intrinsics_source": "documented 7-Scenes calibration" if intr is None else intr.name,
            "depth_registered_to_colour": False,
        },
    )
    return seq
