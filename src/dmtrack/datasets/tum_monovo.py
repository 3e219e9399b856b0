"""TUM monocular visual odometry dataset ("TUM monoVO", Engel, Usenko, Cremers 2016), official layout.

::

    sequence_NN/
      images.zip            00000.jpg … (grey, 1280×1024); read member by member, never extracted
      (or images/)          the same files unpacked
      times.txt             "id timestamp exposure" per line (seconds since the epoch; exposure in ms)
      camera.txt            DSO geometric calibration, 4 lines (FOV model, relative intrinsics; see
                            :mod:`dmtrack.datasets.undistort`), e.g. "0.349 0.436 0.493 0.499 0.933 /
                            1280 1024 / crop / 640 480"
      pcalib.txt            inverse camera response G: 256 increasing values (pixel value → irradiance)
      vignette.png          16-bit vignette V (attenuation factor, max = 1 after normalisation)
      groundtruthSync.txt   "timestamp tx ty tz qx qy qz qw" per line, NaN rows where the motion capture
                            did not see the camera

Images are undistorted to the pinhole camera asked for by ``camera.txt`` (as DSO does), so ``camera`` is the
*output* camera.  With ``photometric=True`` the photometric calibration is applied first, as DSO's
``PhotometricUndistorter``: ``I' = G(I) / V`` with G rescaled to 0..255 and V divided by its maximum; the
result is rounded and clipped to uint8 (over-bright vignette corners saturate).

Ground truth: the motion-capture poses exist only for the start and end segments of each sequence (the
sequences start and end in the same room; the benchmark measures the drift between the two).  Rows are
synchronised to the image timestamps; they are matched to frames by timestamp (within 1 ms, as the official
``efficientEvalDrift.m``).  The translation is the camera centre in the motion-capture world frame, i.e. the
translation of a camera-to-world pose — the official evaluation aligns exactly these positions with DSO's
camera-to-world output by Sim(3).  That evaluation uses positions only, so the orientation axes of the file
were not verified against the images; they are handed out as stored (``details['groundtruth_rotation']``).
"""

from __future__ import annotations

import math
import re
import zipfile
import zlib
from pathlib import Path

import cv2
import numpy as np

from dmtrack.datasets.base import LoaderSequence
from dmtrack.datasets.undistort import Undistorter, read_calibration_file
from dmtrack.errors import DatasetError, InputError
from dmtrack.geometry.lie import quaternion_to_matrix
from dmtrack.io.files import check_file, read_text_file
from dmtrack.io.images import read_image

FORMAT = "tum-monovo"
_IMAGE_EXT = (".jpg", ".jpeg", ".png", ".pgm", ".bmp")
GT_MATCH_TOLERANCE = 1e-3  # seconds, as the official evaluation code


def detect(path: Path) -> bool:
    return (
        path.is_dir()
        and (path / "camera.txt").is_file()
        and (path / "times.txt").is_file()
        and ((path / "images.zip").is_file() or (path / "images").is_dir())
    )


def _natural_key(name: str) -> list:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def read_times_file(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``times.txt``: ``id timestamp [exposure]`` lines → (ids, timestamps s, exposures ms or NaN)."""
    ids, stamps, expo = [], [], []
    for lineno, raw in enumerate(read_text_file(path, "timestamps file").splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        f = line.split()
        if len(f) < 2:
            raise InputError("expected 'id timestamp exposure'", path=path, line=lineno)
        try:
            ids.append(int(f[0]))
            stamps.append(float(f[1]))
            expo.append(float(f[2]) if len(f) > 2 else math.nan)
        except ValueError:
            raise InputError(f"cannot read {line[:80]!r} as 'id timestamp exposure'", path=path, line=lineno) from None
        if not math.isfinite(stamps[-1]):
            raise InputError(f"timestamp {f[1]!r} is not a finite number", path=path, line=lineno)
    if not ids:
        raise InputError("no timestamps in the file", path=path)
    return np.asarray(ids), np.asarray(stamps), np.asarray(expo)


def read_groundtruth_sync(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``groundtruthSync.txt`` → (timestamps (M,), poses (M, 4, 4)) of the rows without NaN.

    Rows with NaN (no motion capture) are skipped silently — they are the normal case in this file.
    """
    stamps, poses = [], []
    lines = 0
    for lineno, raw in enumerate(read_text_file(path, "ground-truth file").splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        lines += 1
        f = line.replace(",", " ").split()
        if len(f) != 8:
            raise InputError(f"expected 8 numbers 'timestamp tx ty tz qx qy qz qw', found {len(f)}",
                             path=path, line=lineno)
        try:
            v = [float(x) for x in f]
        except ValueError:
            raise InputError(f"cannot read {line[:80]!r} as numbers", path=path, line=lineno) from None
        if any(math.isnan(x) for x in v[1:]):
            continue
        if not all(math.isfinite(x) for x in v):
            raise InputError("infinite or NaN value", path=path, line=lineno)
        q = np.asarray(v[4:8])
        size = np.abs(q).max()
        if not size > 1e-8:
            raise InputError("zero quaternion", path=path, line=lineno)
        T = np.eye(4)
        T[:3, :3] = quaternion_to_matrix(q / size)
        T[:3, 3] = v[1:4]
        stamps.append(v[0])
        poses.append(T)
    if not lines:
        raise InputError("no lines in the ground-truth file", path=path)
    if not stamps:
        return np.zeros(0), np.zeros((0, 4, 4))
    return np.asarray(stamps), np.asarray(poses)


def read_pcalib(path: Path) -> np.ndarray:
    """Inverse response ``G`` (≥ 256 strictly increasing values) rescaled to 0..255, as DSO."""
    text = read_text_file(path, "photometric calibration").splitlines()
    first = text[0] if text else ""
    try:
        G = np.asarray([float(x) for x in first.split()])
    except ValueError:
        raise InputError("photometric calibration: cannot read the numbers", path=path, line=1) from None
    if not np.isfinite(G).all() or (G.size and np.abs(G).max() > 1e300):
        raise InputError("photometric calibration: values must be finite numbers", path=path, line=1)
    if G.size < 256:
        raise InputError(f"photometric calibration needs at least 256 values on line 1, found {G.size}",
                         path=path, line=1)
    if not (np.diff(G) > 0).all():
        raise InputError("photometric calibration: the inverse response must be strictly increasing",
                         path=path, line=1)
    return (255.0 * (G - G[0]) / (G[-1] - G[0])).astype(np.float32)


def read_vignette(path: Path, width: int, height: int) -> np.ndarray:
    """Vignette image (16- or 8-bit) divided by its maximum, float32 (H, W)."""
    check_file(path, "vignette image")
    try:
        with open(path, "rb") as f:
            data = np.frombuffer(f.read(), dtype=np.uint8)
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    except (OSError, cv2.error) as e:
        raise InputError(f"cannot read the vignette image ({getattr(e, 'strerror', None) or e})", path=path) from None
    if img is None:
        raise InputError("cannot decode the vignette image", path=path)
    if img.ndim == 3:
        img = img[:, :, 0]
    if img.shape != (height, width):
        raise InputError(f"vignette is {img.shape[1]}x{img.shape[0]}, the images are {width}x{height}", path=path)
    v = img.astype(np.float32)
    if v.max() <= 0:
        raise InputError("vignette image is all zero", path=path)
    v /= v.max()
    return np.maximum(v, 1e-3)  # avoid division by zero at never-observed border pixels


class _ImageSource:
    """Frame i as stored: a member of images.zip (opened once, read lazily) or a file in images/."""

    def __init__(self, root: Path) -> None:
        self.zip_path = root / "images.zip"
        self._zip: zipfile.ZipFile | None = None
        if (root / "images").is_dir() and not self.zip_path.is_file():
            files = [p for p in (root / "images").iterdir() if p.suffix.lower() in _IMAGE_EXT]
            self.names = [p.name for p in sorted(files, key=lambda p: _natural_key(p.name))]
            self.folder: Path | None = root / "images"
        else:
            self.folder = None
            check_file(self.zip_path, "image archive")
            try:
                with zipfile.ZipFile(self.zip_path) as z:
                    members = [m for m in z.namelist()
                               if not m.endswith("/") and Path(m).suffix.lower() in _IMAGE_EXT]
            except zipfile.BadZipFile as e:
                raise InputError(f"not a readable zip file ({e})", path=self.zip_path) from None
            except OSError as e:
                raise InputError(f"cannot read the image archive ({e.strerror or e})", path=self.zip_path) from None
            self.names = sorted(members, key=lambda m: _natural_key(Path(m).name))
        if not self.names:
            raise DatasetError("no images", path=self.folder or self.zip_path)

    def path(self, i: int) -> Path:
        return self.folder / self.names[i] if self.folder is not None else self.zip_path / self.names[i]

    def read(self, i: int) -> np.ndarray:
        if self.folder is not None:
            return read_image(self.folder / self.names[i], grey=True)
        try:
            if self._zip is None:
                self._zip = zipfile.ZipFile(self.zip_path)
            data = np.frombuffer(self._zip.read(self.names[i]), dtype=np.uint8)
        except (zipfile.BadZipFile, zlib.error, EOFError, OSError, KeyError, NotImplementedError, RuntimeError) as e:
            # a damaged or truncated archive, a member that vanished, an unsupported compression or encryption
            self._zip = None
            raise InputError(f"cannot read zip member {self.names[i]!r} ({getattr(e, 'strerror', None) or e})",
                             path=self.zip_path) from None
        try:
            img = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE) if data.size else None
        except cv2.error:
            img = None
        if img is None:
            raise InputError(f"cannot decode zip member {self.names[i]!r}", path=self.zip_path)
        return img

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_zip"] = None
        return state


def open_tum_monovo(
    path: str | Path,
    photometric: bool = False,
    undistort: bool = True,
    multiple: int = 16,
) -> LoaderSequence:
    """Open a TUM monoVO sequence folder (``sequence_NN``).

    Parameters
    ----------
    photometric : apply the photometric calibration (``pcalib.txt`` + ``vignette.png``) before undistortion.
    undistort : rectify with ``camera.txt`` (default); ``False`` delivers the raw fisheye images with the
        pinhole part of the FOV model as ``camera`` (for inspection only — it is not a pinhole camera).
    multiple : the undistorted size is reduced to a multiple of this.
    """
    root = Path(path)
    if not detect(root):
        if root.is_dir():  # name the file that is missing (or is a folder)
            check_file(root / "camera.txt", "calibration file")
            check_file(root / "times.txt", "timestamps file")
            if not (root / "images").is_dir():
                check_file(root / "images.zip", "image archive (or an images/ folder)")
        raise DatasetError("not a TUM monoVO sequence (needs camera.txt, times.txt and images.zip or images/)",
                           path=root)
    source = _ImageSource(root)
    ids, stamps, exposures = read_times_file(root / "times.txt")
    if ids.size != len(source.names):
        raise InputError(f"{ids.size} lines for {len(source.names)} images in {source.zip_path.name}",
                         path=root / "times.txt")
    calib = read_calibration_file(root / "camera.txt", flavour="dso")
    model = calib.model
    first = source.read(0)  # before building the undistortion maps for the size camera.txt claims
    if first.shape != (model.height, model.width):
        raise InputError(f"the calibration is for {model.width}x{model.height} images, {Path(source.names[0]).name} "
                         f"is {first.shape[1]}x{first.shape[0]}", path=calib.path)
    und = calib.undistorter(multiple) if undistort else Undistorter.create(model, "none", multiple=1)
    details: dict = {
        "images": "images.zip" if source.folder is None else "images/",
        "exposure_ms": [float(np.nanmin(exposures)), float(np.nanmax(exposures))] if np.isfinite(exposures).any()
        else None,
        **und.describe(),
    }
    if not undistort:
        details["undistortion"] = "off (raw distorted images; camera is only the pinhole part of the model)"

    G = V = None
    if photometric:
        pc, vg = root / "pcalib.txt", root / "vignette.png"
        for p in (pc, vg):
            if not p.exists():
                raise InputError("photometric calibration requested but the file is missing", path=p)
            check_file(p, "photometric calibration file")
        G = read_pcalib(pc)
        V = read_vignette(vg, model.width, model.height)
        details["photometric"] = "G(I)/V (pcalib.txt, vignette.png)"
    else:
        details["photometric"] = "off"

    def load(i: int) -> np.ndarray:
        raw = source.read(i)
        if raw.shape != (model.height, model.width):
            raise DatasetError(f"image is {raw.shape[1]}x{raw.shape[0]}, camera.txt says "
                               f"{model.width}x{model.height}", path=source.path(i))
        if G is None:
            return und(raw)
        energy = G[raw] / V
        return np.clip(np.rint(und(energy.astype(np.float32))), 0, 255).astype(np.uint8)

    poses = None
    gt_path = root / "groundtruthSync.txt"
    if gt_path.exists():
        gt_t, gt_T = read_groundtruth_sync(gt_path)
        poses = np.full((ids.size, 4, 4), np.nan)
        if gt_t.size:
            j = np.clip(np.searchsorted(gt_t, stamps), 1, max(gt_t.size - 1, 1))
            cand = np.stack([j - 1, np.minimum(j, gt_t.size - 1)])
            diff = np.abs(gt_t[cand] - stamps[None, :])
            best = cand[np.argmin(diff, axis=0), np.arange(stamps.size)]
            ok = np.abs(gt_t[best] - stamps) <= GT_MATCH_TOLERANCE
            poses[ok] = gt_T[best[ok]]
            details["groundtruth_frames"] = int(ok.sum())
        details["groundtruth_rotation"] = "as stored (official evaluation uses positions only)"
    seq = LoaderSequence(
        name=root.name,
        format=FORMAT,
        root=root,
        load_image=load,
        timestamps=stamps,
        camera=und.camera,
        size=(und.camera.width, und.camera.height),
        poses=poses,
        paths=[source.path(i) for i in range(ids.size)],
        details=details,
    )
    seq.exposures = exposures  # type: ignore[attr-defined]
    return seq
