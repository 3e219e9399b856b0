"""KITTI odometry, official layout.

::

    <root>/sequences/NN/image_0/NNNNNN.png   left grey camera (image_1: right grey)
    <root>/sequences/NN/image_2/NNNNNN.png   left colour camera (image_3: right colour)
    <root>/sequences/NN/calib.txt            "P0: 12 numbers" … "P3:", "Tr:" rows (3×4 projection matrices)
    <root>/sequences/NN/times.txt            one timestamp (s) per frame
    <root>/poses/NN.txt                      3×4 row-major camera-0-to-world poses (sequences 00–10 only)

The ground truth is the pose of camera 0 (left grey).  For another camera it is moved by that camera's
offset read from its projection matrix ``P_i = K [I | t_i]`` (the rectified cameras share rotation):
``T_w_ci = T_w_c0 · [I | −t_i]``.  Images are rectified, so the pinhole intrinsics are exact.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dmtrack.datasets.base import FileSequence
from dmtrack.datasets.intrinsics import check_range
from dmtrack.errors import DatasetError, InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.files import read_text_file
from dmtrack.io.images import read_image
from dmtrack.io.trajectory import read_kitti, read_times

FORMAT = "kitti"
CAMERAS = ("image_0", "image_1", "image_2", "image_3")
_IMAGE_EXT = (".png", ".jpg", ".jpeg")


def _sequence_dir(path: Path) -> Path:
    """Accept the sequence folder itself, or a dataset root / ``sequences`` folder holding exactly one."""
    if any((path / c).is_dir() for c in CAMERAS):
        return path
    seqs_dir = path / "sequences" if (path / "sequences").is_dir() else path
    seqs = sorted(p for p in seqs_dir.iterdir() if p.is_dir() and any((p / c).is_dir() for c in CAMERAS))
    if len(seqs) == 1:
        return seqs[0]
    if not seqs:
        raise DatasetError("no KITTI sequence (a folder with image_0/ or image_2/) found", path=path)
    names = ", ".join(p.name for p in seqs)
    raise DatasetError(f"several KITTI sequences ({names}): pass one, e.g. {seqs[0]}", path=path)


def detect(path: Path) -> bool:
    if not path.is_dir():
        return False
    try:
        seq = _sequence_dir(path)
    except DatasetError:
        return False
    return (seq / "calib.txt").is_file() or (seq / "times.txt").is_file()


def read_calib(path: Path) -> dict[str, np.ndarray]:
    """The ``KEY: 12 numbers`` rows of a KITTI ``calib.txt`` as 3×4 matrices."""
    out: dict[str, np.ndarray] = {}
    for lineno, raw in enumerate(read_text_file(path, "KITTI calibration file").splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        key, sep, rest = line.partition(":")
        if not sep:
            raise InputError("expected 'KEY: numbers'", path=path, line=lineno)
        try:
            values = np.asarray([float(v) for v in rest.split()])
        except ValueError:
            raise InputError(f"cannot read the numbers of {key.strip()[:40]!r}", path=path, line=lineno) from None
        if values.size != 12:
            raise InputError(f"{key.strip()[:40]}: expected 12 numbers (3×4), found {values.size}", path=path,
                             line=lineno)
        if not np.isfinite(values).all():
            raise InputError(f"{key.strip()[:40]}: a value is not a finite number", path=path, line=lineno)
        out[key.strip()] = values.reshape(3, 4)
    return out


def open_kitti(path: str | Path, camera_folder: str | None = None) -> FileSequence:
    """Open a KITTI odometry sequence.

    Parameters
    ----------
    camera_folder : ``image_0`` (left grey, the default when present), ``image_1``, ``image_2`` (left
        colour) or ``image_3``.
    """
    root = Path(path)
    if not root.is_dir():
        raise DatasetError("not a folder", path=root)
    seq_dir = _sequence_dir(root)
    camera = camera_folder or next((c for c in CAMERAS if (seq_dir / c).is_dir()), None)
    if camera not in CAMERAS:
        raise DatasetError(f"unknown KITTI camera {camera!r} (use one of {', '.join(CAMERAS)})", path=seq_dir)
    image_dir = seq_dir / camera
    if not image_dir.is_dir():
        raise DatasetError(f"camera folder {camera}/ not found", path=seq_dir)
    images = sorted(p for p in image_dir.iterdir() if p.suffix.lower() in _IMAGE_EXT)
    if not images:
        raise DatasetError("no images", path=image_dir)
    calib = read_calib(seq_dir / "calib.txt")
    cam_idx = int(camera[-1])
    key = f"P{cam_idx}"
    if key not in calib:
        raise InputError(f"no {key} row for {camera}", path=seq_dir / "calib.txt")
    P = calib[key]
    fx, fy, cx, cy = (float(v) for v in (P[0, 0], P[1, 1], P[0, 2], P[1, 2]))
    check_range((fx, fy, cx, cy), f"{key} intrinsics", seq_dir / "calib.txt")
    first = read_image(images[0], grey=cam_idx < 2)
    try:
        cam = PinholeCamera(fx, fy, cx, cy, first.shape[1], first.shape[0])
    except ValueError as e:
        raise InputError(f"{key}: {e}", path=seq_dir / "calib.txt") from None

    times_path = seq_dir / "times.txt"
    if times_path.exists():
        timestamps = read_times(times_path)
        if timestamps.shape[0] != len(images):
            raise InputError(f"{timestamps.shape[0]} timestamps for {len(images)} images", path=times_path)
    else:
        timestamps = np.arange(len(images)) / 10.0  # KITTI records at 10 Hz

    poses = None
    pose_path = seq_dir.parent.parent / "poses" / f"{seq_dir.name}.txt"
    if pose_path.exists():
        gt = read_kitti(pose_path)  # timestamps = line index of each (non-NaN) pose
        rows = gt.timestamps.astype(int)
        if rows[-1] + 1 != len(images):
            raise InputError(f"{rows[-1] + 1} poses for {len(images)} images in {image_dir}", path=pose_path)
        poses = np.full((len(images), 4, 4), np.nan)
        poses[rows] = gt.poses
        # camera i sits at t_i = K⁻¹ P_i[:, 3] in camera 0's frame, with the same rotation.
        if "P0" not in calib:
            raise InputError(f"no P0 row: the ground truth is camera 0's and cannot be moved to {camera}",
                             path=seq_dir / "calib.txt")
        try:
            t_i = np.linalg.solve(P[:, :3], P[:, 3]) - np.linalg.solve(calib["P0"][:, :3], calib["P0"][:, 3])
        except np.linalg.LinAlgError:
            raise InputError(f"{key} or P0: the left 3×3 block is singular", path=seq_dir / "calib.txt") from None
        if np.any(t_i != 0):
            offset = np.eye(4)
            offset[:3, 3] = -t_i
            poses = poses @ offset
    return FileSequence(
        name=f"kitti-{seq_dir.name}",
        format=FORMAT,
        root=seq_dir,
        image_paths=images,
        timestamps=timestamps,
        camera=cam,
        poses=poses,
        grey=cam_idx < 2,
        size=(cam.width, cam.height),
        details={"camera": camera, "groundtruth_file": str(pose_path) if poses is not None else None},
    )
