"""EuRoC MAV dataset (Burri et al., IJRR 2016), ASL folder layout.

::

    MH_01_easy/mav0/
      cam0/data.csv                          "#timestamp [ns],filename", then lines like
                                             "1403636579763555584,1403636579763555584.png"
      cam0/data/<timestamp>.png              752×480 grey, 20 Hz
      cam0/sensor.yaml                       T_BS (4×4, row-major ``data``), intrinsics [fu, fv, cu, cv],
                                             distortion_model radial-tangential,
                                             distortion_coefficients [k1, k2, p1, p2]
      state_groundtruth_estimate0/data.csv   "#timestamp, p_RS_R_x [m], p_RS_R_y, p_RS_R_z, q_RS_w [], q_RS_x,
                                             q_RS_y, q_RS_z, v…, b_w…, b_a…" (200 Hz; quaternion **w x y z**)

``T_BS`` is the pose of the sensor S (camera) in the body frame B (the IMU): ``p_B = T_BS · p_S``.  The ground
truth is the body pose in the world R, ``T_RB``; so the camera-to-world pose is ``T_wc = T_RB · T_BS``
(interpolated at each image timestamp, linear position / slerp rotation, gaps ≤ ``max_gt_gap``).  Frames
outside the ground-truth time span have none.  Images are undistorted to a pinhole camera (``crop``, size a
multiple of 16) unless ``undistort=False``.  Timestamps: nanoseconds → seconds.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from dmtrack.datasets.base import FileSequence
from dmtrack.datasets.intrinsics import check_range
from dmtrack.datasets.undistort import MAX_SIDE, UndistortedSequence, Undistorter
from dmtrack.errors import DatasetError, InputError
from dmtrack.geometry.distortion import CameraModel, EquidistantModel, PinholeModel, RadTanModel
from dmtrack.geometry.lie import quaternion_to_matrix
from dmtrack.io.files import read_text_file
from dmtrack.io.images import read_image
from dmtrack.io.trajectory import Trajectory

FORMAT = "euroc"
CAMERAS = ("cam0", "cam1")


def _mav_dir(path: Path) -> Path | None:
    for p in (path / "mav0", path):
        if (p / "cam0" / "data.csv").exists() or (p / "cam1" / "data.csv").exists():
            return p
    return None


def detect(path: Path) -> bool:
    return path.is_dir() and _mav_dir(path) is not None


def read_sensor_yaml(path: Path) -> dict[str, Any]:
    """``sensor.yaml`` (plain YAML; a leading ``%YAML:1.0`` line, as OpenCV writes, is tolerated)."""
    text = read_text_file(path, "camera description")
    if text.startswith("%YAML"):
        text = text.split("\n", 1)[1] if "\n" in text else ""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        line = getattr(getattr(e, "problem_mark", None), "line", None)
        reason = " ".join(str(getattr(e, "problem", None) or e).split())  # one line
        raise InputError(f"cannot parse YAML ({reason})", path=path, line=None if line is None else line + 1) from None
    except (ValueError, TypeError, OverflowError, RecursionError) as e:  # e.g. a date like 2001-02-30
        raise InputError(f"cannot parse YAML ({type(e).__name__}: {str(e)[:80]})", path=path) from None
    if not isinstance(data, dict):
        raise InputError("expected a YAML mapping", path=path)
    return data


def _matrix(value: Any, path: Path, key: str) -> np.ndarray:
    if not isinstance(value, dict) or "data" not in value:
        raise InputError(f"{key}: expected a mapping with rows, cols, data", path=path)
    try:
        data = np.asarray(value["data"], dtype=np.float64)
        rows, cols = int(value.get("rows", 4)), int(value.get("cols", 4))
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{key}: cannot read the matrix", path=path) from None
    if data.size != rows * cols or (rows, cols) != (4, 4):
        raise InputError(f"{key}: expected a 4×4 matrix (16 numbers), found {data.size} numbers", path=path)
    if not np.isfinite(data).all() or np.abs(data).max() > 1e150:
        raise InputError(f"{key}: the matrix has a value that is not a finite number (or is absurdly large)",
                         path=path)
    T = data.reshape(4, 4)
    if not np.allclose(T[3], (0, 0, 0, 1), atol=1e-9):
        raise InputError(f"{key}: the last row must be 0 0 0 1", path=path)
    u, s, vt = np.linalg.svd(T[:3, :3])
    if np.abs(s - 1).max() > 1e-3 or np.linalg.det(u @ vt) < 0:
        raise InputError(f"{key}: the rotation part is not a rotation (singular values {np.round(s, 5).tolist()})",
                         path=path)
    T[:3, :3] = u @ vt
    return T


def camera_from_sensor_yaml(data: dict[str, Any], path: Path) -> tuple[CameraModel, np.ndarray]:
    """(camera model, ``T_BS``) from a parsed ``sensor.yaml``."""
    for key in ("T_BS", "resolution", "intrinsics"):
        if key not in data:
            raise InputError(f"missing key {key!r}", path=path)
    T_BS = _matrix(data["T_BS"], path, "T_BS")
    try:
        w, h = (int(v) for v in data["resolution"])
        fu, fv, cu, cv = (float(v) for v in data["intrinsics"])
    except (TypeError, ValueError, OverflowError):
        raise InputError("resolution must be [width, height] and intrinsics [fu, fv, cu, cv]", path=path) from None
    if not (0 < w <= MAX_SIDE and 0 < h <= MAX_SIDE):
        raise InputError(f"resolution {w}x{h}: each side must be 1..{MAX_SIDE} pixels", path=path)
    model_name = str(data.get("camera_model", "pinhole"))
    if model_name != "pinhole":
        raise InputError(f"camera_model {model_name[:40]!r} is not supported (pinhole)", path=path)
    dist = str(data.get("distortion_model", "none")).lower()
    raw_coeffs = data.get("distortion_coefficients", []) or []
    try:
        coeffs = [float(v) for v in raw_coeffs]
    except (TypeError, ValueError, OverflowError):
        raise InputError("distortion_coefficients must be a list of numbers", path=path) from None
    check_range((fu, fv, cu, cv), "intrinsics", path)
    check_range(coeffs, "distortion_coefficients", path)
    try:
        if dist in ("radial-tangential", "radtan", "plumb_bob"):
            if len(coeffs) not in (4, 5):
                raise InputError(f"radial-tangential needs 4 coefficients k1 k2 p1 p2, found {len(coeffs)}",
                                 path=path)
            model: CameraModel = RadTanModel(fu, fv, cu, cv, w, h, *coeffs)
        elif dist in ("equidistant", "fisheye", "kannala-brandt"):
            if len(coeffs) != 4:
                raise InputError(f"equidistant needs 4 coefficients, found {len(coeffs)}", path=path)
            model = EquidistantModel(fu, fv, cu, cv, w, h, *coeffs)
        elif dist in ("none", ""):
            model = PinholeModel(fu, fv, cu, cv, w, h)
        else:
            raise InputError(f"distortion_model {dist[:40]!r} is not supported", path=path)
    except ValueError as e:
        raise InputError(f"camera parameters: {e}", path=path) from None
    return model, T_BS


def read_image_list(path: Path) -> tuple[np.ndarray, list[str]]:
    """``data.csv`` of a camera: (timestamps ns as int64, file names)."""
    stamps: list[int] = []
    names: list[str] = []
    for lineno, raw in enumerate(read_text_file(path, "image list").splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        f = [x.strip() for x in line.split(",")]
        if len(f) != 2:
            raise InputError(f"expected 'timestamp,filename', found {len(f)} fields", path=path, line=lineno)
        try:
            stamps.append(int(f[0]))
        except ValueError:
            raise InputError(f"cannot read timestamp {f[0][:40]!r} (integer nanoseconds)", path=path,
                             line=lineno) from None
        if not -(2**63) < stamps[-1] < 2**63:
            raise InputError(f"timestamp {f[0][:40]} is out of range (64-bit nanoseconds)", path=path, line=lineno)
        names.append(f[1])
    if not names:
        raise InputError("no images listed", path=path)
    return np.asarray(stamps, dtype=np.int64), names


def read_groundtruth_csv(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``state_groundtruth_estimate0/data.csv`` → (timestamps ns int64 (M,), body poses T_RB (M, 4, 4))."""
    stamps: list[int] = []
    rows: list[list[float]] = []
    for lineno, raw in enumerate(read_text_file(path, "ground-truth file").splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        f = [x.strip() for x in line.split(",")]
        if len(f) < 8:
            raise InputError(f"expected at least 8 fields 'timestamp, p_x, p_y, p_z, q_w, q_x, q_y, q_z', "
                             f"found {len(f)}", path=path, line=lineno)
        try:
            stamp = int(f[0])
            rows.append([float(x) for x in f[1:8]])
        except ValueError:
            raise InputError(f"cannot read {line[:60]!r} as numbers", path=path, line=lineno) from None
        if not -(2**63) < stamp < 2**63:
            raise InputError(f"timestamp {f[0][:40]} is out of range (64-bit nanoseconds)", path=path, line=lineno)
        if not all(math.isfinite(v) and abs(v) < 1e150 for v in rows[-1]):
            raise InputError("a value is not a finite number (or is absurdly large)", path=path, line=lineno)
        stamps.append(stamp)
    if not rows:
        raise InputError("no ground-truth rows", path=path)
    data = np.asarray(rows)
    q_wxyz = data[:, 3:7]
    norms = np.abs(q_wxyz).max(axis=1)
    if (norms < 1e-8).any():
        raise InputError("zero quaternion", path=path)
    T = np.tile(np.eye(4), (data.shape[0], 1, 1))
    T[:, :3, :3] = quaternion_to_matrix(q_wxyz[:, [1, 2, 3, 0]] / norms[:, None])  # w x y z → x y z w
    T[:, :3, 3] = data[:, :3]
    t = np.asarray(stamps, dtype=np.int64)
    order = np.argsort(t, kind="stable")
    return t[order], T[order]


def open_euroc(
    path: str | Path,
    camera: str = "cam0",
    undistort: bool = True,
    output: str = "crop",
    max_gt_gap: float = 0.05,
    multiple: int = 16,
) -> FileSequence | UndistortedSequence:
    """Open a EuRoC sequence (the folder holding ``mav0/``, or ``mav0`` itself).

    Parameters
    ----------
    camera : ``cam0`` (left, default) or ``cam1``.
    undistort : rectify to a pinhole camera (default); ``False`` delivers the raw images with the pinhole part
        of the model as ``camera``.
    output : undistortion output mode (``crop`` or ``full``).
    max_gt_gap : largest gap (s) between ground-truth samples to interpolate across.
    """
    root = Path(path)
    mav = _mav_dir(root) if root.is_dir() else None
    if mav is None:
        for cam_dir in (root / "mav0" / camera, root / camera):
            if cam_dir.is_dir():  # the layout is there, its image list is not
                raise DatasetError("image list not found", path=cam_dir / "data.csv")
        raise DatasetError("not a EuRoC sequence (needs mav0/cam0/data.csv)", path=root)
    if camera not in CAMERAS:
        raise DatasetError(f"unknown EuRoC camera {camera!r} (cam0 or cam1)", path=root)
    cam_dir = mav / camera
    stamps_ns, names = read_image_list(cam_dir / "data.csv")
    images = [cam_dir / "data" / n for n in names]
    for p in (images[0], images[-1]):
        if not p.is_file():
            raise DatasetError("image listed in data.csv " + ("is a folder" if p.is_dir() else "not found"), path=p)
    yaml_path = cam_dir / "sensor.yaml"
    model, T_BS = camera_from_sensor_yaml(read_sensor_yaml(yaml_path), yaml_path)
    first = read_image(images[0], grey=True)  # before building undistortion maps for the size sensor.yaml claims
    if (first.shape[1], first.shape[0]) != (model.width, model.height):
        raise InputError(f"resolution is {model.width}x{model.height}, {images[0].name} is "
                         f"{first.shape[1]}x{first.shape[0]}", path=yaml_path)
    t0 = stamps_ns[0]
    timestamps = stamps_ns.astype(np.float64) * 1e-9
    details: dict[str, Any] = {"camera": camera, "T_BS": T_BS.round(12).tolist()}

    poses = None
    gt_path = mav / "state_groundtruth_estimate0" / "data.csv"
    if gt_path.exists():
        gt_ns, T_RB = read_groundtruth_csv(gt_path)
        # interpolate in seconds relative to the first image (keeps float64 precision)
        gt = Trajectory((gt_ns - t0).astype(np.float64) * 1e-9, T_RB)
        T_RB_at = gt.interpolate((stamps_ns - t0).astype(np.float64) * 1e-9, max_gap=max_gt_gap)
        poses = T_RB_at @ T_BS
        details["groundtruth"] = "state_groundtruth_estimate0: T_wc = T_RB · T_BS"
        details["groundtruth_frames"] = int(np.isfinite(poses[:, 0, 0]).sum())
    base = FileSequence(
        name=f"{root.name if root != mav else mav.parent.name}-{camera}",
        format=FORMAT,
        root=root,
        image_paths=images,
        timestamps=timestamps,
        camera=model.pinhole(),
        poses=poses,
        grey=True,
        size=(model.width, model.height),
        details=details,
    )
    if not undistort:
        base.details["undistortion"] = "off (raw images; camera is only the pinhole part of the model)"
        base.details["distortion_model"] = model.to_dict()
        return base
    und = Undistorter.create(model, output, multiple=multiple, source=yaml_path)  # type: ignore[arg-type]
    return UndistortedSequence(base, und)
