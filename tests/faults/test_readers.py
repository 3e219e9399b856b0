"""Damaged sequences, every format: each injected fault ends in one DmtrackError line naming the damaged file.

A tiny valid sequence of each format is built once (with the builders of ``tests/datasets``, loaded through the
``builders`` fixture, and frames of the shipped 7-Scenes sample for 7-Scenes, the image folder and the video), then
copied and damaged, one fault per case:

* text files the reader reads (lists, timestamps, calibration, ground truth): empty, binary junk, another encoding
  (UTF-16), a folder in its place, unreadable (EACCES; ``chmod 000`` where the tests do not run as root, a simulated
  ``open`` failure everywhere), missing (where the file is required);
* image / depth / archive / video files of one frame: truncated, empty, binary junk, a folder, unreadable, deleted
  after the sequence was opened, a different size than the rest of the sequence (or than the calibration);
* calibration numbers: NaN, 1e300, an absurd image size.

Opening the sequence (format given, as with ``--format``) and reading the damaged frame must raise
:class:`~dmtrack.errors.DmtrackError` whose message is one line containing the damaged file's path.  Trajectory files
go through ``dmtrack eval`` the same way: exit status 1 and one line on stderr.
"""

from __future__ import annotations

import builtins
import errno
import importlib.util
import io
import os
import re
import shutil
import sys
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType, SimpleNamespace
from typing import Any

import cv2
import numpy as np
import pytest

from dmtrack.cli import main
from dmtrack.datasets import open_sequence
from dmtrack.datasets.sevenscenes import read_pose_file
from dmtrack.errors import DmtrackError
from dmtrack.geometry.distortion import FOVModel
from dmtrack.io.trajectory import Trajectory, write_tum

TESTS = Path(__file__).resolve().parents[1]
SAMPLE = TESTS.parent / "data" / "7scenes-redkitchen-0000-0299"
JUNK = np.random.default_rng(17).integers(0, 256, 512, dtype=np.uint8).tobytes()
AS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


def _load(name: str) -> ModuleType:
    """A module of tests/datasets (test folders are not packages): its builders write the official layouts."""
    spec = importlib.util.spec_from_file_location(f"_dmtrack_faults_{name}", TESTS / "datasets" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses and pickling look their module up there
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def builders() -> SimpleNamespace:
    return SimpleNamespace(**{n: _load(f"test_{n}") for n in ("readers", "euroc", "iclnuim", "lsdslam", "tsukuba",
                                                               "tum_monovo", "video")})


# -- the layouts --------------------------------------------------------------------------------------------------
def _sample_frames(n: int) -> list[Path]:
    return [SAMPLE / f"frame-{i:06d}.color.jpg" for i in range(n)]


def _build_7scenes(root: Path, b: SimpleNamespace) -> Path:
    root.mkdir(parents=True)
    for i, img in enumerate(_sample_frames(3)):
        shutil.copy(img, root / img.name)
        shutil.copy(SAMPLE / f"frame-{i:06d}.pose.txt", root)
    shutil.copy(SAMPLE / "camera-intrinsics.txt", root)
    return root


def _build_image_folder(root: Path, b: SimpleNamespace) -> Path:
    (root / "images").mkdir(parents=True)
    for i, img in enumerate(_sample_frames(3)):
        shutil.copy(img, root / "images" / f"{i:06d}.jpg")
    (root / "camera.txt").write_text("585 585 320 240\n")
    (root / "times.txt").write_text("0.0\n0.033\n0.067\n")
    poses = np.stack([read_pose_file(SAMPLE / f"frame-{i:06d}.pose.txt") for i in range(3)])
    write_tum(root / "groundtruth.txt", Trajectory(np.array([0.0, 0.033, 0.067]), poses))
    return root


def _build_kitti(root: Path, b: SimpleNamespace) -> Path:
    b.readers.write_kitti_layout(root, n=4)
    return root / "sequences" / "00"


def _build_tum_rgbd(root: Path, b: SimpleNamespace) -> Path:
    b.readers.write_tum_rgbd(root, n=3)
    (root / "camera.txt").write_text("517.3 516.5 318.6 255.3\n")
    return root


def _build_icl(root: Path, b: SimpleNamespace) -> Path:
    b.iclnuim.write_icl(root, n=3)
    return root


def _build_euroc(root: Path, b: SimpleNamespace) -> Path:
    b.euroc.write_euroc(root, n=3)
    return root


def _build_monovo(root: Path, b: SimpleNamespace, unzipped: bool = False) -> Path:
    b.tum_monovo.write_monovo(root, unzipped=unzipped)
    return root


def _build_lsdslam(root: Path, b: SimpleNamespace) -> Path:
    rel = (0.527334, 0.827306, 0.473568, 0.499436, 0.928161)  # LSD-SLAM's FOV example calibration
    w, h = b.lsdslam.W, b.lsdslam.H
    model = FOVModel(rel[0] * w, rel[1] * h, rel[2] * w - 0.5, rel[3] * h - 0.5, w, h, omega=rel[4])
    b.lsdslam.write_lsd(root, " ".join(map(str, rel)) + f"\n{w} {h}\ncrop\n{w} {h}\n", model, n=3)
    (root / "times.txt").write_text("0.00\n0.02\n0.04\n")
    return root


def _build_tsukuba(root: Path, b: SimpleNamespace) -> Path:
    b.tsukuba.write_tsukuba(root, frames=3, modes=("daylight",), depth=False)
    return root


def _build_video(root: Path, b: SimpleNamespace) -> Path:
    root.mkdir(parents=True)
    b.video.write_video(root / "walk.avi")
    w, h = b.video.W, b.video.H
    (root / "walk.avi.camera.txt").write_text(f"Pinhole 60 60 {(w - 1) / 2} {(h - 1) / 2} 0\n{w} {h}\nnone\n{w} {h}\n")
    return root / "walk.avi"


@dataclass(frozen=True)
class Layout:
    """A format's tiny sequence and where its faults go (paths relative to the folder ``build`` writes)."""

    build: Callable[[Path, SimpleNamespace], Path]
    texts: tuple[str, ...]  # text files the reader reads
    images: tuple[str, ...]  # image / depth / archive / video files of frame ``frame``
    frame: int = 1
    required: tuple[str, ...] = ()  # files without which the sequence cannot be opened
    calibration: str | None = None  # the file with the camera parameters …
    number: str = r"^\s*([-+0-9.eE]+)"  # … and (group 1) the number that is poisoned in it
    size_line: str | None = None  # (group 1) the image width in it, where it has one
    simulated_open: bool = True  # the images are read through Python's open (not by OpenCV's own file I/O)
    held_open: bool = False  # the image file stays open once the sequence is (deleting it then changes nothing)
    options: dict[str, Any] = field(default_factory=dict)


def _monovo_zip(root: Path, b: SimpleNamespace) -> Path:
    return _build_monovo(root, b)


def _monovo_dir(root: Path, b: SimpleNamespace) -> Path:
    return _build_monovo(root, b, unzipped=True)


LAYOUTS: dict[str, Layout] = {
    "7scenes": Layout(_build_7scenes, ("frame-000001.pose.txt", "camera-intrinsics.txt"),
                      ("frame-000001.color.jpg",), calibration="camera-intrinsics.txt"),
    "image-folder": Layout(_build_image_folder, ("camera.txt", "times.txt", "groundtruth.txt"), ("images/000001.jpg",),
                           calibration="camera.txt"),
    "kitti": Layout(_build_kitti, ("sequences/00/calib.txt", "sequences/00/times.txt", "poses/00.txt"),
                    ("sequences/00/image_0/000001.png",), required=("sequences/00/calib.txt",),
                    calibration="sequences/00/calib.txt", number=r"P0:\s*(\S+)"),
    "tum-rgbd": Layout(_build_tum_rgbd, ("rgb.txt", "depth.txt", "groundtruth.txt", "camera.txt"),
                       ("rgb/{1}", "depth/{1}"), required=("rgb.txt",), calibration="camera.txt"),
    "icl-nuim": Layout(_build_icl, ("associations.txt", "livingRoom0.gt.freiburg"), ("rgb/1.png", "depth/1.png"),
                       required=("associations.txt",)),
    "euroc": Layout(_build_euroc, ("mav0/cam0/data.csv", "mav0/cam0/sensor.yaml",
                                   "mav0/state_groundtruth_estimate0/data.csv"),
                    ("mav0/cam0/data/{1}",), required=("mav0/cam0/data.csv", "mav0/cam0/sensor.yaml"),
                    calibration="mav0/cam0/sensor.yaml", number=r"intrinsics: \[([^,\]]+)"),
    "tum-monovo": Layout(_monovo_zip, ("times.txt", "camera.txt", "groundtruthSync.txt"), ("images.zip",),
                         required=("times.txt", "camera.txt", "images.zip"), calibration="camera.txt",
                         size_line=r"\n(\d+) \d+\ncrop", held_open=True),
    "tum-monovo (images/)": Layout(_monovo_dir, ("times.txt", "camera.txt"), ("images/00001.png",),
                                   required=("camera.txt",), calibration="camera.txt"),
    "lsd-slam": Layout(_build_lsdslam, ("cameraCalibration.cfg", "times.txt"), ("images/00001.png",),
                       required=("cameraCalibration.cfg",), calibration="cameraCalibration.cfg",
                       size_line=r"\n(\d+) \d+\ncrop"),
    "tsukuba": Layout(_build_tsukuba, ("groundtruth/camera_track.txt",),
                      ("illumination/daylight/left/tsukuba_daylight_L_00002.png",),
                      required=("groundtruth/camera_track.txt",)),
    "video": Layout(_build_video, ("walk.avi.camera.txt",), ("walk.avi",), required=("walk.avi",),
                    calibration="walk.avi.camera.txt", number=r"Pinhole (\S+)", size_line=r"\n(\d+) \d+\nnone",
                    simulated_open=False),
}
# "tum-monovo (images/)" is the same reader as "tum-monovo", on unpacked images
FORMAT = {name: name.split(" ")[0] for name in LAYOUTS}


@pytest.fixture(scope="module")
def pristine(builders: SimpleNamespace, tmp_path_factory: pytest.TempPathFactory) -> Callable[[str], Path]:
    """``pristine(name)``: the folder holding the valid sequence of layout ``name`` (built once, on first use)."""
    made: dict[str, Path] = {}

    def get(name: str) -> Path:
        if name not in made:
            folder = tmp_path_factory.mktemp(re.sub(r"\W", "_", name))
            LAYOUTS[name].build(folder / "seq", builders)
            made[name] = folder / "seq"
        return made[name]

    return get


def _resolve(root: Path, rel: str) -> Path:
    """``rel`` under ``root``; ``{k}`` stands for the k-th file (natural order) of that folder."""
    m = re.fullmatch(r"(.*)/\{(\d+)\}", rel)
    if m:
        files = sorted(p for p in (root / m.group(1)).iterdir())
        return files[int(m.group(2))]
    return root / rel


# -- faults ------------------------------------------------------------------------------------------------------
def _folder(p: Path) -> None:
    p.unlink()
    p.mkdir()
    (p / "inside.txt").write_text("a folder where a file belongs\n")


def _smaller_image(p: Path) -> None:
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    assert img is not None
    cv2.imwrite(str(p), cv2.resize(img, (img.shape[1] // 2, img.shape[0] // 2), interpolation=cv2.INTER_NEAREST))


def _truncated_zip_member(p: Path) -> None:
    """The archive stays readable; the frame's member is cut in half (a torn copy)."""
    with zipfile.ZipFile(p) as z:
        members = [(info, z.read(info)) for info in z.infolist()]
    with zipfile.ZipFile(p, "w") as z:
        for info, data in members:
            z.writestr(info, data[: len(data) // 2] if info.filename == "00001.jpg" else data)


def _poison(pattern: str, value: str) -> Callable[[Path], None]:
    def apply(p: Path) -> None:
        text = p.read_text()
        m = re.search(pattern, text, re.MULTILINE)
        assert m, (pattern, text)
        p.write_text(text[: m.start(1)] + value + text[m.end(1):])

    return apply


FILE_FAULTS: dict[str, Callable[[Path], None]] = {
    "empty file": lambda p: p.write_bytes(b""),
    "binary junk": lambda p: p.write_bytes(JUNK),
    "folder instead of a file": _folder,
}
TEXT_FAULTS: dict[str, Callable[[Path], None]] = {
    **FILE_FAULTS,
    "wrong encoding (UTF-16)": lambda p: p.write_bytes(p.read_text().encode("utf-16")),
}
IMAGE_FAULTS: dict[str, Callable[[Path], None]] = {
    **FILE_FAULTS,
    "truncated file": lambda p: p.write_bytes(p.read_bytes()[: p.stat().st_size // 2]),
}


@dataclass(frozen=True)
class Case:
    layout: str
    fault: str
    file: str  # the damaged file, relative to the layout's folder ("{k}": k-th file of a folder)
    damage: Callable[[Path], None] | None  # None: the fault is applied by the test itself
    named: str | None = None  # the file the message must name, when not ``file``

    @property
    def id(self) -> str:
        return f"{self.layout}-{self.fault}-{self.file}"


def _cases() -> list[Case]:
    out: list[Case] = []
    for name, lay in LAYOUTS.items():
        for rel in lay.texts:
            out += [Case(name, fault, rel, damage) for fault, damage in TEXT_FAULTS.items()]
            out += [Case(name, "unreadable (simulated EACCES)", rel, None),
                    Case(name, "unreadable (chmod 000)", rel, None)]
        for rel in lay.images:
            out += [Case(name, fault, rel, damage) for fault, damage in IMAGE_FAULTS.items()]
            out.append(Case(name, "unreadable (chmod 000)", rel, None))
            if not lay.held_open:
                out.append(Case(name, "deleted after opening", rel, None))
            if lay.simulated_open:
                out.append(Case(name, "unreadable (simulated EACCES)", rel, None))
        for rel in lay.required:
            out.append(Case(name, "missing file", rel, lambda p: p.unlink()))
        if lay.calibration:
            out += [Case(name, "NaN in the calibration", lay.calibration, _poison(lay.number, "nan")),
                    Case(name, "huge value in the calibration", lay.calibration, _poison(lay.number, "1e300"))]
        if lay.size_line:
            out.append(Case(name, "huge image size in the calibration", lay.calibration or "",
                            _poison(lay.size_line, "99999999")))
    # one frame of another size than the rest of the sequence / than the calibration
    for name in ("7scenes", "image-folder", "kitti", "tum-rgbd", "icl-nuim", "euroc", "tum-monovo (images/)",
                 "lsd-slam", "tsukuba"):
        out.append(Case(name, "image of the wrong size", LAYOUTS[name].images[0], _smaller_image))
    out += [
        Case("tum-monovo", "truncated archive member", "images.zip", _truncated_zip_member),
        Case("tum-rgbd", "depth map of the wrong size", "depth/{1}", _smaller_image),
        Case("video", "calibration for another size", "walk.avi.camera.txt",
             lambda p: p.write_text(p.read_text().replace("96 64", "128 64"))),
        # New Tsukuba depth maps are OpenCV XML files: a damaged one, for the frame
        Case("tsukuba", "binary junk", "groundtruth/depth_maps/left/tsukuba_depth_L_00002.xml",
             lambda p: p.write_bytes(JUNK)),
        Case("tsukuba", "empty file", "groundtruth/depth_maps/left/tsukuba_depth_L_00002.xml",
             lambda p: p.write_bytes(b"")),
        Case("tsukuba", "folder instead of a file", "groundtruth/depth_maps/left/tsukuba_depth_L_00002.xml",
             lambda p: p.mkdir()),
    ]
    return out


CASES = _cases()


def _refused(run: Callable[[], Any], named: Path) -> DmtrackError:
    with pytest.raises(DmtrackError) as err:
        run()
    message = str(err.value)
    assert "\n" not in message and "\r" not in message, message
    assert str(named) in message, f"{message!r} does not name {named}"
    return err.value


def _open_and_read(layout: str, path: Path, frame: int) -> Any:
    seq = open_sequence(path, format=FORMAT[layout], **LAYOUTS[layout].options)
    return seq[frame]


def _deny_open(monkeypatch: pytest.MonkeyPatch, target: Path) -> None:
    """Every ``open`` of ``target`` fails with EACCES, as for a file without read permission (root included)."""
    target = target.resolve()
    real_open = builtins.open

    def fake_open(file: Any, *args: Any, **kwargs: Any) -> Any:
        if isinstance(file, (str, os.PathLike)) and Path(file).resolve() == target:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(file))
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", fake_open)
    monkeypatch.setattr(io, "open", fake_open)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_damaged_sequence_is_refused_naming_the_file(case: Case, pristine, tmp_path: Path, fault_log,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    if case.fault == "unreadable (chmod 000)" and AS_ROOT:
        pytest.skip("running as root: chmod 000 does not deny root; the simulated-EACCES and folder cases cover it")
    lay = LAYOUTS[case.layout]
    root = tmp_path / "seq"
    shutil.copytree(pristine(case.layout), root)
    path = _open_path(case.layout, root)
    target = _resolve(root, case.file)
    target.parent.mkdir(parents=True, exist_ok=True)  # for a file the fault creates (Tsukuba's depth maps)
    named = target
    if case.fault == "deleted after opening":
        seq = open_sequence(path, format=FORMAT[case.layout], **lay.options)
        target.unlink()
        _refused(lambda: seq[lay.frame], named)
    elif case.fault == "unreadable (chmod 000)":
        target.chmod(0)
        try:
            _refused(lambda: _open_and_read(case.layout, path, lay.frame), named)
        finally:
            target.chmod(0o644)
    elif case.fault == "unreadable (simulated EACCES)":
        _deny_open(monkeypatch, target)
        error = _refused(lambda: _open_and_read(case.layout, path, lay.frame), named)
        assert "ermission denied" in str(error), error
    else:
        assert case.damage is not None
        case.damage(target)
        _refused(lambda: _open_and_read(case.layout, path, lay.frame), named)
    fault_log.tried(f"{FORMAT[case.layout]} reader", case.fault)


def _open_path(layout: str, root: Path) -> Path:
    """The path a user passes for the sequence built in ``root`` (KITTI: the sequence folder; video: the file)."""
    return {"kitti": root / "sequences" / "00", "video": root / "walk.avi"}.get(layout, root)


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_the_pristine_sequences_read(layout: str, pristine) -> None:
    """The undamaged copies open and read: every refusal above is caused by its fault."""
    seq = open_sequence(_open_path(layout, pristine(layout)), format=FORMAT[layout], **LAYOUTS[layout].options)
    frame = seq[LAYOUTS[layout].frame]
    assert frame.image.shape[:2] == (seq.height, seq.width)


# -- trajectories through `dmtrack eval` ----------------------------------------------------------------------------
GOOD_TUM = "".join(f"{t:.1f} {t:.1f} {0.1 * t * t:.3f} 0 0 0 0 1\n" for t in range(6))
GOOD_KITTI = "".join(f"1 0 0 {t} 0 1 0 {0.1 * t * t:.3f} 0 0 1 0\n" for t in range(6))
PNG = cv2.imencode(".png", np.zeros((4, 4), np.uint8))[1].tobytes()

EVAL_FAULTS: dict[str, Callable[[Path], None]] = {
    "binary junk": lambda p: p.write_bytes(JUNK),
    "a PNG image": lambda p: p.write_bytes(PNG),
    "empty file": lambda p: p.write_bytes(b""),
    "only comments": lambda p: p.write_text("# timestamp tx ty tz qx qy qz qw\n"),
    "wrong encoding (UTF-16)": lambda p: p.write_bytes(GOOD_TUM.encode("utf-16")),
    "NUL bytes": lambda p: p.write_bytes(GOOD_TUM.encode()[:40] + b"\x00\x00" + GOOD_TUM.encode()[40:]),
    "folder instead of a file": lambda p: p.mkdir(),
    "missing file": lambda p: None,
    "every pose NaN": lambda p: p.write_text("1.0 nan nan nan nan nan nan nan\n2.0 nan nan nan nan nan nan nan\n"),
    "duplicate timestamps": lambda p: p.write_text(GOOD_TUM + GOOD_TUM.splitlines()[2] + "\n"),
    "7 columns": lambda p: p.write_text(GOOD_TUM.replace(" 0 1\n", " 1\n")),
    "a word among the numbers": lambda p: p.write_text(GOOD_TUM.replace("0 0 0 1", "0 zero 0 1", 1)),
    "infinite value": lambda p: p.write_text(GOOD_TUM.replace("2.0 2.0", "2.0 inf", 1)),
    "zero quaternion": lambda p: p.write_text(GOOD_TUM.replace("0 0 0 1", "0 0 0 0", 1)),
    "coordinates of 1e300": lambda p: p.write_text(GOOD_TUM.replace("3.0 3.0", "3.0 1e300", 1)),
    "KITTI matrix that is not a rotation": lambda p: p.write_text(GOOD_KITTI.replace("1 0 0 3", "2 0 0 3", 1)),
    "a camera that does not move": lambda p: p.write_text("".join(f"{t}.0 1 2 3 0 0 0 1\n" for t in range(6))),
}


@pytest.mark.parametrize("role", ["ground truth", "estimate"])
@pytest.mark.parametrize("fault", list(EVAL_FAULTS))
def test_eval_refuses_bad_trajectory_in_one_line(fault: str, role: str, tmp_path: Path, capsys, fault_log) -> None:
    good, bad = tmp_path / "good.txt", tmp_path / "bad.txt"
    good.write_text(GOOD_TUM)
    EVAL_FAULTS[fault](bad)
    args = [str(bad), str(good)] if role == "ground truth" else [str(good), str(bad)]
    assert main(["eval", *args]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("dmtrack: error: "), err
    assert str(bad) in err and "Traceback" not in err, err
    fault_log.tried("dmtrack eval", f"{role}: {fault}")


@pytest.mark.parametrize("fault", ["binary junk", "empty file", "folder instead of a file", "missing file",
                                   "a word", "NaN timestamp", "one timestamp too few"])
def test_eval_refuses_bad_times_file(fault: str, tmp_path: Path, capsys, fault_log) -> None:
    gt, est, times = tmp_path / "gt.txt", tmp_path / "est.txt", tmp_path / "times.txt"
    gt.write_text(GOOD_KITTI)
    est.write_text(GOOD_KITTI)
    good_times = "".join(f"{0.1 * t:.1f}\n" for t in range(6))
    damage = {
        "binary junk": lambda: times.write_bytes(JUNK),
        "empty file": lambda: times.write_bytes(b""),
        "folder instead of a file": times.mkdir,
        "missing file": lambda: None,
        "a word": lambda: times.write_text(good_times.replace("0.2", "two")),
        "NaN timestamp": lambda: times.write_text(good_times.replace("0.2", "nan")),
        "one timestamp too few": lambda: times.write_text(good_times[:-4]),
    }
    damage[fault]()
    assert main(["eval", str(gt), str(est), "--times", str(times)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("dmtrack: error: ") and str(times) in err, err
    fault_log.tried("dmtrack eval --times", fault)


@pytest.mark.parametrize("max_diff", ["nan", "-1", "inf"])
def test_eval_refuses_bad_max_diff(max_diff: str, tmp_path: Path, capsys, fault_log) -> None:
    (tmp_path / "t.txt").write_text(GOOD_TUM)
    t = str(tmp_path / "t.txt")
    assert main(["eval", t, t, "--max-diff", max_diff]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "max_diff" in err, err
    fault_log.tried("dmtrack eval", "bad --max-diff")
