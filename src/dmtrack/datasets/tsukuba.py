"""New Tsukuba Stereo Dataset (Martull, Peris, Fukui 2012), official layout.

::

    NewTsukubaStereoDataset/
      illumination/{daylight,fluorescent,lamps,flashlight}/{left,right}/tsukuba_<mode>_{L,R}_NNNNN.png
      groundtruth/camera_track.txt                 1800 lines "X, Y, Z, A, B, C"
      groundtruth/depth_maps/{left,right}/tsukuba_depth_{L,R}_NNNNN.xml   (OpenCV XML, centimetres; optional)

640×480 colour, 30 fps, rectified stereo with a 10 cm baseline, ``f = 615``, ``c = (320, 240)`` (dataset
README).  ``camera_track.txt`` holds the pose of the *middle* of the stereo baseline per frame: position
``(X, Y, Z)`` in centimetres and orientation ``(A, B, C)`` as Euler angles in degrees.

Convention (established from data; see below): with ``R = Rz(C)·Ry(B)·Rx(A)`` (rotations about fixed x, then
y, then z axes) and ``F = diag(1, −1, −1)``, the camera-to-world pose of the baseline middle in OpenCV camera
axes is ``T = [R·F | F·(X, Y, Z)]``; the left camera is ``T·[I | (−b/2, 0, 0)]``, the right one
``T·[I | (+b/2, 0, 0)]``.  ``F`` is a 180° rotation about x, so the world has y down and z backwards relative
to the track's y-up world; the result is a proper rigid motion.

How it was established: ``shared/data/tsukuba-150/cam_traj_truth.txt`` stores the first 150 frames as
``X Y Z`` + a 3×3 matrix.  Decomposing those matrices as ``Rz(c)Ry(b)Rx(a)`` gives angles on the 10⁻⁶-degree
grid of the 6-decimal source file for every frame (mean distance to the grid 0.016·10⁻⁶° against ~0.25·10⁻⁶°
for the other 11 axis orders), so the matrices are exactly ``Rz(C)Ry(B)Rx(A)`` of the file's angles; and
``T = [R·F | F·p]`` reproduces the relative camera motion measured from the images themselves (essential
matrices of ORB matches: translation directions within 1–7°, rotations within 0.2–1°, on frame pairs over
the 150 frames), whereas the "OpenGL camera" reading ``F·T·F`` gets the translation direction wrong by up to
180°.  That the matrices are the file's angles *without* sign changes rests on the signed zeros of the first
frame (``-0.0`` exactly where ``−sin B`` sits); it is the simplest reading but was not checked against an
original ``camera_track.txt``, which cannot be downloaded here.

Units: ``units="m"`` (default) converts centimetres to metres (positions, baseline, depth); ``units="cm"``
keeps the dataset's centimetres (``shared/data/tsukuba-150/groundtruth.txt`` is in centimetres).
"""

from __future__ import annotations

import math
import re
from functools import partial
from pathlib import Path
from typing import Literal

import cv2
import numpy as np

from dmtrack.datasets.base import FileSequence
from dmtrack.datasets.imagefolder import list_images
from dmtrack.errors import DatasetError, InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.files import check_file, read_text_file

FORMAT = "tsukuba"
ILLUMINATIONS = ("daylight", "fluorescent", "lamps", "flashlight")
FPS = 30.0
WIDTH, HEIGHT = 640, 480
FOCAL, CX, CY = 615.0, 320.0, 240.0
BASELINE_CM = 10.0
F_FLIP = np.diag([1.0, -1.0, -1.0])
_NAME_RE = re.compile(r"^tsukuba_[a-z]+_([LR])_(\d+)\.png$", re.IGNORECASE)


def _dataset_root(path: Path) -> Path | None:
    """The folder holding ``illumination/`` and ``groundtruth/``: ``path`` itself or one of its parents."""
    for p in (path, *path.parents[:3]):
        if (p / "illumination").is_dir() and (p / "groundtruth").is_dir():
            return p
    return None


def detect(path: Path) -> bool:
    if not path.is_dir():
        return False
    root = _dataset_root(path)
    return root is not None and (root / "groundtruth" / "camera_track.txt").is_file()


def euler_to_matrix(a_deg: np.ndarray, b_deg: np.ndarray, c_deg: np.ndarray) -> np.ndarray:
    """``Rz(C)·Ry(B)·Rx(A)`` for angles in degrees, (N,) → (N, 3, 3)."""
    a, b, c = (np.radians(np.asarray(x, dtype=np.float64)) for x in (a_deg, b_deg, c_deg))
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    R = np.empty(a.shape + (3, 3))
    R[..., 0, 0] = cc * cb
    R[..., 0, 1] = cc * sb * sa - sc * ca
    R[..., 0, 2] = cc * sb * ca + sc * sa
    R[..., 1, 0] = sc * cb
    R[..., 1, 1] = sc * sb * sa + cc * ca
    R[..., 1, 2] = sc * sb * ca - cc * sa
    R[..., 2, 0] = -sb
    R[..., 2, 1] = cb * sa
    R[..., 2, 2] = cb * ca
    return R


def read_camera_track(path: Path) -> np.ndarray:
    """``camera_track.txt`` → (N, 6) ``X Y Z A B C`` (cm, degrees)."""
    rows = []
    for lineno, raw in enumerate(read_text_file(path, "camera track").splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        fields = [f for f in re.split(r"[,\s]+", line) if f]
        if len(fields) != 6:
            raise InputError(f"expected 6 values 'X, Y, Z, A, B, C', found {len(fields)}", path=path, line=lineno)
        try:
            vals = [float(f) for f in fields]
        except ValueError:
            raise InputError(f"cannot read {line[:80]!r} as numbers", path=path, line=lineno) from None
        if not all(math.isfinite(v) for v in vals):
            raise InputError("non-finite value", path=path, line=lineno)
        if not all(abs(v) < 1e150 for v in vals):
            raise InputError("absurdly large value", path=path, line=lineno)
        rows.append(vals)
    if not rows:
        raise InputError("no poses in the file", path=path)
    return np.asarray(rows)


def track_to_poses(track: np.ndarray, offset_x: float = 0.0, scale: float = 1.0) -> np.ndarray:
    """Camera-to-world poses (OpenCV axes) from (N, 6) track rows.

    Parameters
    ----------
    offset_x : position of the camera along the baseline, in track units (cm): −5 left, +5 right, 0 middle.
    scale : multiplies positions (0.01 for metres).
    """
    R = euler_to_matrix(track[:, 3], track[:, 4], track[:, 5])
    T = np.tile(np.eye(4), (track.shape[0], 1, 1))
    T[:, :3, :3] = R @ F_FLIP
    T[:, :3, 3] = track[:, :3] @ F_FLIP.T
    if offset_x:
        T[:, :3, 3] += T[:, :3, 0] * offset_x
    T[:, :3, 3] *= scale
    return T


def _read_depth_xml(path: Path, scale: float) -> np.ndarray:
    check_file(path, "depth map")
    if path.stat().st_size == 0:
        raise InputError("depth map file is empty", path=path)
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as e:  # OpenCV raises on a file it cannot parse (SystemError wraps cv2.error)
        raise InputError(f"cannot read the depth map (OpenCV XML expected): {_cv_message(e)}", path=path) from None
    try:
        if not fs.isOpened():
            raise InputError("cannot open the depth map (OpenCV XML expected)", path=path)
        node = fs.getFirstTopLevelNode()
        mat = None if node.empty() else node.mat()
    except (cv2.error, SystemError) as e:
        raise InputError(f"cannot read the depth map (OpenCV XML expected): {_cv_message(e)}", path=path) from None
    finally:
        fs.release()
    if mat is None or mat.ndim < 2 or mat.size == 0:
        raise InputError("no matrix in the depth map file", path=path)
    if mat.ndim == 3:
        mat = mat[:, :, 0]
    return mat.astype(np.float32) * np.float32(scale)


def _cv_message(e: Exception) -> str:
    """The one-line reason of an OpenCV exception (its text spans several lines and names OpenCV's sources)."""
    inner = e if isinstance(e, cv2.error) else (e.__cause__ or e.__context__)
    if isinstance(inner, cv2.error):
        text = str(getattr(inner, "msg", "") or inner)
        m = re.search(r"error: \((-?\d+):([^)]*)\) (.*)", text, re.DOTALL)
        text = f"{m.group(2)}: {m.group(3)}" if m else text
    else:
        text = str(e)
    text = " ".join(text.split())
    return text if len(text) <= 160 else text[:159] + "…"


def open_tsukuba(
    path: str | Path,
    illumination: str = "daylight",
    camera: Literal["left", "right"] = "left",
    units: Literal["m", "cm"] = "m",
) -> FileSequence:
    """Open the New Tsukuba dataset (its root, ``illumination/<mode>`` or ``illumination/<mode>/<side>``).

    Parameters
    ----------
    illumination : ``daylight``, ``fluorescent``, ``lamps`` or ``flashlight`` (taken from the path when the path
        points inside ``illumination/``).
    camera : ``left`` or ``right`` (taken from the path when it ends in ``left``/``right``).
    units : ``"m"`` (default) or ``"cm"`` (the dataset's unit) for positions and depth.
    """
    p = Path(path)
    root = _dataset_root(p) if p.is_dir() else None
    if root is None:
        raise DatasetError("not the New Tsukuba dataset (needs illumination/ and groundtruth/)", path=p)
    rel = p.resolve().relative_to(root.resolve()).parts if p.resolve() != root.resolve() else ()
    if len(rel) >= 2 and rel[0] == "illumination":
        illumination = rel[1]
    if len(rel) >= 3:
        camera = rel[2]  # type: ignore[assignment]
    if camera not in ("left", "right"):
        raise DatasetError(f"unknown camera {camera!r} (left or right)", path=p)
    folder = root / "illumination" / illumination / camera
    if not folder.is_dir():
        have = sorted(d.name for d in (root / "illumination").iterdir() if d.is_dir())
        raise DatasetError(f"illumination {illumination!r} not found (the dataset has {', '.join(have)})",
                           path=root / "illumination")
    images = list_images(folder)
    if not images:
        raise DatasetError("no images", path=folder)
    numbers = []
    for im in images:
        m = _NAME_RE.match(im.name)
        numbers.append(int(m.group(2)) if m else None)
    if all(n is not None for n in numbers):
        frame_no = np.asarray(numbers)  # 1-based frame numbers in the official names
    else:
        frame_no = np.arange(1, len(images) + 1)
    track = read_camera_track(root / "groundtruth" / "camera_track.txt")
    if frame_no.max() > track.shape[0] or frame_no.min() < 1:
        raise InputError(
            f"{track.shape[0]} poses but image numbers run {frame_no.min()}..{frame_no.max()}",
            path=root / "groundtruth" / "camera_track.txt",
        )
    scale = 0.01 if units == "m" else 1.0
    offset = -BASELINE_CM / 2 if camera == "left" else BASELINE_CM / 2
    poses = track_to_poses(track[frame_no - 1], offset_x=offset, scale=scale)
    side = "L" if camera == "left" else "R"
    depth_dir = root / "groundtruth" / "depth_maps" / camera
    depth_xml = None
    if depth_dir.is_dir():
        depth_xml = [depth_dir / f"tsukuba_depth_{side}_{n:05d}.xml" for n in frame_no]
        depth_xml = [d if d.exists() else None for d in depth_xml]
        if not any(d is not None for d in depth_xml):
            depth_xml = None
    return FileSequence(
        f"tsukuba-{illumination}-{camera}",
        FORMAT,
        folder,
        images,
        (frame_no - 1) / FPS,
        PinholeCamera(FOCAL, FOCAL, CX, CY, WIDTH, HEIGHT),
        poses,
        grey=False,
        size=(WIDTH, HEIGHT),
        details={
            "illumination": illumination,
            "camera": camera,
            "units": units,
            "baseline": BASELINE_CM * scale,
            "groundtruth": "camera_track.txt: T = [Rz(C)Ry(B)Rx(A)·F | F·XYZ], F = diag(1,-1,-1), "
                           f"shifted {offset:+g} cm along the camera x axis",
        },
        depth_paths=depth_xml,
        depth_reader=partial(_read_depth_xml, scale=scale),
    )
