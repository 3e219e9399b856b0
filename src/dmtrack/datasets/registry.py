"""Opening a sequence by path: format detection from the folder's contents, or a forced format.

Detection order (first match wins, most specific layouts first): ``7scenes`` (``frame-*.color.*``), ``kitti``
(``image_0/`` or ``image_2/`` with ``calib.txt``/``times.txt``), ``euroc`` (``mav0/cam0/data.csv``),
``tum-monovo`` (``camera.txt`` + ``times.txt`` + ``images.zip``/``images/``), ``tum-rgbd`` (``rgb.txt``),
``icl-nuim`` (``associations.txt`` + ``rgb/``), ``tsukuba`` (``illumination/`` + ``groundtruth/camera_track.txt``),
``lsd-slam`` (``cameraCalibration.cfg`` + images), ``image-folder`` (images in the folder or in ``images/``); a
ROS 2 bag folder (``metadata.yaml``) is a ``rosbag``, checked first. A file with a video extension is a ``video``,
a ``.bag`` file a ``rosbag`` (ROS 1; ``topic=`` chooses the image topic).  ``synthetic`` is not a folder:
``synthetic`` or ``synthetic:key=value,…`` (keys of :class:`~dmtrack.datasets.synthetic.SyntheticConfig`).
``camera:N``, ``rtsp://…`` and ``http(s)://…`` are live sources (format ``stream``, :mod:`dmtrack.datasets.stream`);
they need intrinsics.

Intrinsics given to :func:`open_sequence` replace the dataset's: a :class:`PinholeCamera`, the string
``"fx,fy,cx,cy"``, or a file — ``fx fy cx cy`` / a 3×3 K (pixels), or a 4-line DSO calibration such as
``dmtrack calibrate-camera`` writes, whose distortion is then removed from every frame (``undistort_sequence``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dmtrack.datasets import (
    euroc,
    iclnuim,
    imagefolder,
    kitti,
    lsdslam,
    rosbag,
    sevenscenes,
    stream,
    tsukuba,
    tum_monovo,
    tumrgbd,
    video,
)
from dmtrack.datasets.base import Sequence
from dmtrack.datasets.intrinsics import parse_intrinsics, read_intrinsics_file
from dmtrack.datasets.undistort import UndistortedSequence, read_calibration_file, undistort_sequence
from dmtrack.errors import DatasetError, InputError
from dmtrack.geometry.camera import PinholeCamera


@dataclass(frozen=True)
class Reader:
    name: str
    detect: Callable[[Path], bool]
    open: Callable[..., Sequence]
    description: str


READERS: dict[str, Reader] = {
    r.name: r
    for r in (
        Reader("rosbag", rosbag.detect, rosbag.open_rosbag,
               "ROS 1 .bag or ROS 2 bag folder, one image topic (--topic; rosbags, pip install 'dmtrack[ros]')"),
        Reader("7scenes", sevenscenes.detect, sevenscenes.open_7scenes, "Microsoft 7-Scenes sequence folder"),
        Reader("kitti", kitti.detect, kitti.open_kitti, "KITTI odometry (sequences/NN/image_0|image_2)"),
        Reader("euroc", euroc.detect, euroc.open_euroc, "EuRoC MAV (mav0/cam0, undistorted)"),
        Reader("tum-monovo", tum_monovo.detect, tum_monovo.open_tum_monovo,
               "TUM monoVO (images.zip, times.txt, camera.txt; undistorted)"),
        Reader("tum-rgbd", tumrgbd.detect, tumrgbd.open_tum_rgbd, "TUM RGB-D benchmark (rgb.txt)"),
        Reader("icl-nuim", iclnuim.detect, iclnuim.open_iclnuim, "ICL-NUIM, TUM-compatible (associations.txt)"),
        Reader("tsukuba", tsukuba.detect, tsukuba.open_tsukuba,
               "New Tsukuba stereo (illumination/, groundtruth/camera_track.txt)"),
        Reader("lsd-slam", lsdslam.detect, lsdslam.open_lsdslam,
               "LSD-SLAM image sequence (cameraCalibration.cfg; undistorted)"),
        Reader("image-folder", imagefolder.detect, imagefolder.open_image_folder,
               "image folder (+ groundtruth.txt, times.txt, camera.txt)"),
        Reader("video", video.detect, video.open_video, "video file (.mp4, .avi, …; OpenCV)"),
    )
}
FORMATS = (*READERS, "synthetic", stream.FORMAT)


def detect_format(path: str | Path) -> str:
    """The format name of the sequence at ``path``; raises :class:`DatasetError` naming what was looked for."""
    p = Path(path)
    if str(path).split(":", 1)[0] == "synthetic":
        return "synthetic"
    if stream.is_stream(str(path)):
        return stream.FORMAT
    if not p.exists():
        raise DatasetError("no such file or folder", path=p)
    if not p.is_dir():
        if video.detect(p):
            return "video"
        if rosbag.detect(p):
            return "rosbag"
        raise DatasetError(
            f"a sequence is a folder or a video file ({', '.join(video.VIDEO_EXTENSIONS)}), or a ROS 1 .bag; this "
            "is none of them", path=p
        )
    for reader in READERS.values():
        if reader.detect(p):
            return reader.name
    raise DatasetError(
        "cannot recognise the sequence format (looked for 7-Scenes frame-*.color.*, KITTI image_0/ + calib.txt, "
        "EuRoC mav0/, TUM monoVO camera.txt + times.txt + images.zip, TUM RGB-D rgb.txt, ICL-NUIM associations.txt, "
        "New Tsukuba illumination/ + groundtruth/, LSD-SLAM cameraCalibration.cfg, or images in the folder or "
        "images/); use --format to force one",
        path=p,
    )


def _parse_synthetic(spec: str) -> dict[str, Any]:
    _, _, rest = spec.partition(":")
    options: dict[str, Any] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, sep, value = item.partition("=")
        if not sep:
            raise InputError(f"synthetic sequence option {item!r}: expected key=value")
        for conv in (int, float):
            try:
                options[key.strip()] = conv(value)
                break
            except ValueError:
                continue
        else:
            low = value.strip().lower()
            options[key.strip()] = {"true": True, "false": False}.get(low, value.strip())
    return options


def open_sequence(
    path: str | Path,
    format: str | None = None,
    intrinsics: str | Path | PinholeCamera | None = None,
    **options: Any,
) -> Sequence:
    """Open the sequence at ``path`` (a folder, a video file, ``synthetic[:key=value,…]``, or a live source
    ``camera:N`` / ``rtsp://…`` / ``http(s)://…``).

    Parameters
    ----------
    format
        Force a format (one of :data:`FORMATS`) instead of detecting it.
    intrinsics
        Intrinsics replacing the dataset's — a camera, the string ``"fx,fy,cx,cy"`` (pixels of the
        stored images), or the path of a file: ``fx fy cx cy`` or a 3×3 K, or a 4-line DSO calibration (e.g.
        written by ``dmtrack calibrate-camera``) whose distortion is then removed from every frame.  Required
        for a live source.
    **options
        Passed to the reader (e.g. ``camera_folder="image_2"`` for KITTI, ``fps=`` for an image folder,
        ``capture=`` (the ``VideoCapture`` factory) for a live source).

    Raises
    ------
    InputError
        An unreadable sequence, a bad intrinsics string or file, a live source without intrinsics or that
        cannot be opened.
    """
    fmt = format or detect_format(path)
    if fmt == stream.FORMAT and intrinsics is None:
        raise InputError(f"{path}: a live source has no intrinsics: {stream.CALIBRATE_HINT}")
    seq = _open(path, fmt, **options)
    if intrinsics is None:
        return seq
    try:
        return apply_intrinsics(seq, intrinsics)
    except BaseException:
        live = stream.live_source(seq)
        if live is not None:
            live.close()
        raise


def _is_numbers(text: str) -> bool:
    """Whether ``text`` is meant as numbers (``fx,fy,cx,cy``) rather than a file name."""
    fields = text.replace(",", " ").split()
    try:
        [float(f) for f in fields]
    except ValueError:
        return False
    return bool(fields)


def apply_intrinsics(seq: Any, intrinsics: str | Path | PinholeCamera) -> Any:
    """``seq`` with the given intrinsics (see :func:`open_sequence`); may return a new, undistorted sequence."""
    if isinstance(intrinsics, PinholeCamera):
        if (intrinsics.width, intrinsics.height) != (seq.width, seq.height):
            raise InputError(
                f"intrinsics are for {intrinsics.width}x{intrinsics.height}, the images are {seq.width}x{seq.height}"
            )
        seq.camera = intrinsics
        source = "given"
    elif isinstance(intrinsics, str) and _is_numbers(intrinsics):
        seq.camera = parse_intrinsics(intrinsics, seq.width, seq.height)
        source = "given"
    else:
        path = Path(intrinsics).expanduser()
        if not path.exists():
            raise InputError(f"--intrinsics {str(intrinsics)!r}: neither four numbers 'fx,fy,cx,cy' nor an existing "
                             "calibration file")
        if path.is_dir():
            raise InputError("--intrinsics: expected a calibration file (fx fy cx cy, a 3x3 K or a 4-line DSO "
                             "calibration), this is a folder", path=path)
        from dmtrack.io.files import read_text_file

        lines = [ln for ln in read_text_file(path, "intrinsics file").splitlines() if ln.strip()]
        if len(lines) >= 4:
            # a distorted camera: undistort the frames as delivered (an already undistorted sequence is
            # unwrapped: this calibration replaces the dataset's)
            base = seq.base if isinstance(seq, UndistortedSequence) else seq
            seq = undistort_sequence(base, read_calibration_file(path, flavour="dso"))
        else:
            seq.camera = read_intrinsics_file(path, seq.width, seq.height)
        source = str(path)
    if hasattr(seq, "details"):
        seq.details["intrinsics_source"] = source
    return seq


def _open(path: str | Path, fmt: str, **options: Any) -> Sequence:
    if fmt == stream.FORMAT:
        if not stream.is_stream(str(path)):
            raise InputError(f"{path}: a live source is camera:N, rtsp://…, http://… or https://…")
        return stream.open_stream(str(path), **options)
    if fmt == "synthetic":
        from dmtrack.datasets.synthetic import SyntheticConfig, SyntheticSequence

        spec = _parse_synthetic(str(path)) if str(path).startswith("synthetic") else {}
        try:
            config = SyntheticConfig(**{**spec, **options})
        except TypeError as e:
            raise InputError(f"synthetic sequence: {e}") from None
        return SyntheticSequence(config)
    if fmt not in READERS:
        raise InputError(f"unknown format {fmt!r}; known formats: {', '.join(FORMATS)}")
    p = Path(path)
    if not p.exists():
        raise DatasetError("no such file or folder", path=p)
    return READERS[fmt].open(p, **options)
