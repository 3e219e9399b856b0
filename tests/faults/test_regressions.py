"""The rows of issue 17 ("faults as figures"), each reproduced: before the fix every one of these was a traceback, a
message showing ``np.float64(…)``, or wrong intrinsics."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from dmtrack.cli import main
from dmtrack.datasets import open_sequence
from dmtrack.datasets.euroc import read_image_list, read_sensor_yaml
from dmtrack.datasets.iclnuim import read_associations
from dmtrack.datasets.intrinsics import read_intrinsics_file
from dmtrack.datasets.kitti import read_calib
from dmtrack.datasets.tsukuba import read_camera_track
from dmtrack.datasets.tum_monovo import read_times_file
from dmtrack.datasets.tumrgbd import read_file_list
from dmtrack.datasets.undistort import Undistorter, read_calibration_file
from dmtrack.errors import InputError
from dmtrack.evaluation.metrics import rpe_pairs
from dmtrack.geometry.camera import PinholeCamera, crop_image
from dmtrack.geometry.distortion import RadTanModel
from dmtrack.io.trajectory import Trajectory, read_times, read_tum
from dmtrack.odometry.config import VOConfig

SAMPLE = Path(__file__).resolve().parents[2] / "data" / "7scenes-redkitchen-0000-0299"
GOOD_TUM = "".join(f"{t}.0 {t}.0 {0.1 * t * t:.2f} 0 0 0 0 1\n" for t in range(5))
PNG = cv2.imencode(".png", np.full((8, 8), 7, np.uint8))[1].tobytes()


# -- binary files where text is expected -------------------------------------------------------------------------
@pytest.mark.parametrize("content", [np.random.default_rng(3).bytes(300), PNG], ids=["random bytes", "PNG"])
@pytest.mark.parametrize("which", ["ground truth", "estimate"])
def test_eval_of_a_binary_file_is_one_line(content: bytes, which: str, tmp_path: Path, capsys, fault_log) -> None:
    good, bad = tmp_path / "good.txt", tmp_path / "bad.bin"
    good.write_text(GOOD_TUM)
    bad.write_bytes(content)
    assert main(["eval", *map(str, [bad, good] if which == "ground truth" else [good, bad])]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"dmtrack: error: {bad}: not a text trajectory (") and err.count("\n") == 1, err
    fault_log.tried("dmtrack eval", f"{which}: binary file")


TEXT_READERS = {
    "calibration file (camera.txt)": lambda p: read_calibration_file(p, "dso"),
    "calibration file (cameraCalibration.cfg)": lambda p: read_calibration_file(p, "lsdslam"),
    "intrinsics file": lambda p: read_intrinsics_file(p, 640, 480),
    "KITTI calib.txt": read_calib,
    "EuRoC sensor.yaml": read_sensor_yaml,
    "EuRoC data.csv": read_image_list,
    "times.txt": read_times,
    "TUM monoVO times.txt": read_times_file,
    "TUM RGB-D rgb.txt": read_file_list,
    "ICL-NUIM associations.txt": read_associations,
    "New Tsukuba camera_track.txt": read_camera_track,
    "TUM trajectory": read_tum,
    "configuration (--config)": VOConfig.from_yaml,
}


@pytest.mark.parametrize("reader", list(TEXT_READERS))
@pytest.mark.parametrize("content", [PNG, "0.5 0.5 0.5 0.5 0.9\n".encode("utf-16")], ids=["PNG", "UTF-16"])
def test_text_readers_refuse_binary_files_naming_them(reader: str, content: bytes, tmp_path: Path) -> None:
    path = tmp_path / "file.txt"
    path.write_bytes(content)
    with pytest.raises(InputError, match="not a text") as err:
        TEXT_READERS[reader](path)
    assert err.value.path == path and str(err.value).startswith(f"{path}: ")


# -- numbers in messages -----------------------------------------------------------------------------------------
def test_duplicate_timestamp_is_a_plain_number(tmp_path: Path, capsys) -> None:
    path = tmp_path / "dup.txt"
    path.write_text("1.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n")
    with pytest.raises(InputError) as err:
        read_tum(path)
    assert str(err.value) == f"{path}:2: TUM trajectory: duplicate timestamp 1.0"
    assert main(["eval", str(path), str(path)]) == 1
    assert capsys.readouterr().err == f"dmtrack: error: {path}:2: TUM trajectory: duplicate timestamp 1.0\n"


@pytest.mark.parametrize(
    ("make", "text"),
    [
        (lambda: PinholeCamera(np.float64("nan"), 1.0, 0.0, 0.0, 4, 4), "fx must be finite, got nan"),
        (lambda: PinholeCamera(1.0, 1.0, 0.0, 0.0, np.float64(2.5), 4), "width must be an integer, got 2.5"),
        (lambda: crop_image(np.zeros((4, 4)), tuple(np.array([0, 0, 2]))), "got (0, 0, 2)"),
        (lambda: rpe_pairs(Trajectory.from_positions(np.arange(3.0), np.eye(3)), r_l=np.float64(2.0)), "got 2.0"),
        (lambda: VOConfig(info_channels=np.float64(-1.0)), "not -1.0"),
    ],
    ids=["PinholeCamera fx", "PinholeCamera width", "crop box", "rpe r_l", "VOConfig info_channels"],
)
def test_numpy_scalars_print_as_plain_numbers(make, text: str) -> None:
    with pytest.raises((ValueError, InputError)) as err:
        make()
    assert text in str(err.value) and "np." not in str(err.value), str(err.value)


# -- FOV calibration with ω = 0 is a pinhole ---------------------------------------------------------------------
REL = (0.9140625, 1.21875, 0.5, 0.5)  # fx/w fy/h cx/w cy/h: fx = fy = 585 for 640×480
PIXELS = (REL[0] * 640, REL[1] * 480, REL[2] * 640 - 0.5, REL[3] * 480 - 0.5)  # the relative→pixel conversion


def _grey_frames(folder: Path, n: int = 2) -> list[np.ndarray]:
    folder.mkdir(parents=True)
    frames = []
    for i in range(n):
        grey = cv2.cvtColor(cv2.imread(str(SAMPLE / f"frame-{i:06d}.color.jpg")), cv2.COLOR_BGR2GRAY)
        cv2.imwrite(str(folder / f"{i:05d}.png"), grey)
        frames.append(grey)
    return frames


@pytest.mark.parametrize("mode", ["crop", "full"])
@pytest.mark.parametrize("fmt", ["lsd-slam", "tum-monovo"])
def test_fov_omega_zero_passes_images_through(fmt: str, mode: str, tmp_path: Path) -> None:
    root = tmp_path / "seq"
    frames = _grey_frames(root / "images")
    calibration = " ".join(map(str, REL)) + f" 0\n640 480\n{mode}\n640 480\n"
    if fmt == "lsd-slam":
        (root / "cameraCalibration.cfg").write_text(calibration)
    else:
        (root / "camera.txt").write_text(calibration)
        (root / "times.txt").write_text("00000 1.0 10\n00001 1.05 10\n")
    seq = open_sequence(root, format=fmt)
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == PIXELS
    assert (seq.width, seq.height) == (640, 480)
    for i, raw in enumerate(frames):
        np.testing.assert_array_equal(seq[i].image, raw)  # untouched: no resampling, no crop


def test_distortion_free_models_are_not_resampled() -> None:
    model = RadTanModel(585.0, 585.0, 319.5, 239.5, 640, 480)  # all coefficients zero
    und = Undistorter.create(model, "crop")
    assert und.is_identity and und.camera == model.pinhole()
    # another output size is a plain resize: pixel centres 0 and W − 1 map onto 0 and w − 1, every pixel valid
    half = Undistorter.create(model, "crop", size=(320, 240))
    assert half.valid.all() and (half.camera.width, half.camera.height) == (320, 240)
    assert half.camera.fx == pytest.approx(585.0 * 319 / 639) and half.camera.cx == pytest.approx(159.5)
