"""Property-based fuzzing of every text parser: a malformed file is parsed into sane values or refused with one line.

Each fuzzer feeds its parser random text, random bytes and — mostly — mutations of valid files (truncated, columns
dropped or duplicated, junk tokens, NaN / inf / huge numbers, lines dropped or repeated, other encodings, stray
bytes, empty).  The property: the parser either returns values that make sense (finite, rotations that are
rotations, positive focal lengths, …) or raises :class:`dmtrack.errors.DmtrackError` with a one-line message naming
the file — never another exception, and no numeric warning on the way.

``DMTRACK_FUZZ_EXAMPLES`` examples per parser (default 200); every example is recorded with ``fault_log``.
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from dmtrack.datasets.euroc import camera_from_sensor_yaml, read_groundtruth_csv, read_image_list, read_sensor_yaml
from dmtrack.datasets.iclnuim import read_associations
from dmtrack.datasets.intrinsics import parse_intrinsics, read_intrinsics_file
from dmtrack.datasets.kitti import read_calib
from dmtrack.datasets.sevenscenes import read_pose_file
from dmtrack.datasets.tsukuba import read_camera_track, track_to_poses
from dmtrack.datasets.tum_monovo import read_groundtruth_sync, read_pcalib, read_times_file
from dmtrack.datasets.tumrgbd import read_file_list
from dmtrack.datasets.undistort import MAX_SIDE, CalibrationFile, Undistorter, read_calibration_file
from dmtrack.errors import DmtrackError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.trajectory import Trajectory, read_kitti, read_trajectory, read_tum
from dmtrack.odometry.config import VOConfig

FUZZ_EXAMPLES = int(os.environ.get("DMTRACK_FUZZ_EXAMPLES", "200"))
# The test suite's fuzzing is derandomised (the same examples every run: CI must not pass or fail by chance);
# benchmarks/reliability.py explores new ones (DMTRACK_FUZZ_RANDOM=1) at its full profile.
FUZZ = settings(
    max_examples=FUZZ_EXAMPLES,
    derandomize=os.environ.get("DMTRACK_FUZZ_RANDOM") != "1",
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)

# -- valid files (the seeds of the mutations) -----------------------------------------------------------------
TUM = [
    "# timestamp tx ty tz qx qy qz qw\n1305031102.175304 1.3405 0.6266 1.6575 0.6574 0.6126 -0.2949 -0.3248\n"
    "1305031102.211214 1.3303 0.6256 1.6464 0.6579 0.6161 -0.2932 -0.3189\n"
    "1305031102.243211 1.3160 0.6254 1.6302 0.6609 0.6199 -0.2893 -0.3086\n",
    "0.0 0 0 0 0 0 0 1\n0.1,0.1,0,0,0,0,0.0998,0.995\n0.2\t0.2\t0\t0\t0\t0\t0.198\t0.980\n",
    "1433184983.043186 NaN NaN NaN NaN NaN NaN NaN\n1433184983.093186 0.1 0.2 0.3 0 0 0 1\n",
]
KITTI = [
    "1.000000e+00 9.043680e-12 2.326809e-11 5.551115e-17 9.043683e-12 1.000000e+00 2.392370e-10 3.330669e-16 "
    "2.326810e-11 2.392370e-10 9.999999e-01 -4.440892e-16\n"
    "9.999978e-01 5.272628e-04 -2.066935e-03 -4.690294e-02 -5.296506e-04 9.999992e-01 -1.154865e-03 "
    "-2.839928e-02 2.066324e-03 1.155958e-03 9.999971e-01 8.586941e-01\n",
    "1 0 0 0 0 1 0 0 0 0 1 0\n0 -1 0 1 1 0 0 2 0 0 1 3\nnan nan nan nan nan nan nan nan nan nan nan nan\n",
]
TIMES = ["0.000000e+00\n1.036000e-01\n2.072000e-01\n", "1.0 extra columns ignored\n2.0\n# comment\n3.0\n"]
DSO_CAMERA = [
    "0.349153000000000 0.436593000000000 0.493140000000000 0.499021000000000 0.933271000000000\n"
    "1280 1024\ncrop\n640 480\n",
    "RadTan 458.654 457.296 367.215 248.375 -0.28340811 0.07395907 0.00019359 1.76187114e-05\n752 480\n"
    "0.6 0.9 0.5 0.5 0\n752 480\n",
    "KannalaBrandt 0.3 0.3 0.5 0.5 0.01 0.002 0 0\n100 80\nfull\n96 80\n",
    "Pinhole 100 100 79.5 63.5 0\n160 128\nnone\n160 128\n",
    "0.9140625 1.21875 0.5 0.5 0\n640 480\ncrop\n640 480\n",
]
LSD_CAMERA = [
    "0.527334 0.827306 0.473568 0.499436 0.928161\n640 480\ncrop\n640 480\n",
    "500 500 350 240 -0.1 0.01 0 0\n752 480\ncrop\n640 480\n",
    "0.6 0.8 0.5 0.5 0 0 0 0\n100 80\nnone\n100 80\n",
]
KITTI_CALIB = [
    "P0: 7.188560e+02 0.000000e+00 6.071928e+02 0.000000e+00 0.000000e+00 7.188560e+02 1.852157e+02 "
    "0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00\n"
    "P1: 7.188560e+02 0.000000e+00 6.071928e+02 -3.861448e+02 0.000000e+00 7.188560e+02 1.852157e+02 "
    "0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00\n"
    "Tr: 4.276802e-04 -9.999672e-01 -8.084492e-03 -1.198459e-02 -7.210626e-03 8.081198e-03 -9.999413e-01 "
    "-5.403984e-02 9.999738e-01 4.859485e-04 -7.206933e-03 -2.921968e-01\n",
]
SENSOR_YAML = [
    "%YAML:1.0\nsensor_type: camera\nT_BS:\n  cols: 4\n  rows: 4\n  data: [0.0148655429818, -0.999880929698, "
    "0.00414029679422, -0.0216401454975,\n         0.999557249008, 0.0149672133247, 0.025715529948, "
    "-0.064676986768,\n        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,\n"
    "         0.0, 0.0, 0.0, 1.0]\nrate_hz: 20\nresolution: [752, 480]\ncamera_model: pinhole\n"
    "intrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv\ndistortion_model: radial-tangential\n"
    "distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]\n",
    "T_BS: {rows: 4, cols: 4, data: [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]}\nresolution: [64, 48]\n"
    "intrinsics: [50, 50, 31.5, 23.5]\ndistortion_model: equidistant\ndistortion_coefficients: [0.01, 0, 0, 0]\n",
]
INTRINSICS = ["517.3 516.5 318.6 255.3\n", "5.85e+02 0 3.2e+02\n0 5.85e+02 2.4e+02\n0 0 1\n", "525, 525, 319.5, 239.5"]
RGB_LIST = [
    "# color images\n# file: 'rgbd_dataset_freiburg1_xyz.bag'\n# timestamp filename\n"
    "1305031102.175304 rgb/1305031102.175304.png\n1305031102.211214 rgb/1305031102.211214.png\n",
]
ASSOCIATIONS = ["0 depth/0.png 0 rgb/0.png\n1 depth/1.png 1 rgb/1.png\n2 depth/2.png 2 rgb/2.png\n"]
EUROC_LIST = ["#timestamp [ns],filename\n1403636579763555584,1403636579763555584.png\n"
              "1403636579813555456,1403636579813555456.png\n"]
EUROC_GT = [
    "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_x, v_y, "
    "v_z, b_w_x, b_w_y, b_w_z, b_a_x, b_a_y, b_a_z\n"
    "1403636580838555648,4.688319,-1.786938,0.783338,0.534108,-0.153029,-0.827383,-0.082152,-0.027876,0.033207,"
    "0.800006,-0.003172,0.021267,0.078502,-0.025266,0.136696,0.075593\n"
    "1403636580843555328,4.688177,-1.786770,0.787350,0.534640,-0.152990,-0.826976,-0.082863,-0.029272,0.033992,"
    "0.804818,-0.003172,0.021267,0.078502,-0.025266,0.136696,0.075593\n",
]
MONOVO_TIMES = ["00000 1433184983.043186 10.0000\n00001 1433184983.093186 11.0000\n00002 1433184983.143186\n"]
MONOVO_GT = TUM[2:] + ["1433184983.043186 0.1 0.2 0.3 0 0 0 1\n1433184983.093186 0.2 0.2 0.3 0 0.1 0 1\n"]
PCALIB = [" ".join(f"{v:.3f}" for v in np.linspace(0.0, 255.0, 256) ** 1.1) + "\n"]
POSE_4X4 = [
    "9.9935108e-001\t-1.4576308e-002\t-3.2917984e-002\t-1.5346603e-002\n"
    "1.6035756e-002\t 9.9889886e-001\t 4.3632928e-002\t-2.9003180e-002\n"
    "3.2212023e-002\t-4.4155315e-002\t 9.9850518e-001\t 9.8474644e-003\n"
    "0.0000000e+000\t 0.0000000e+000\t 0.0000000e+000\t 1.0000000e+000\n",
    "-inf -inf -inf -inf\n-inf -inf -inf -inf\n-inf -inf -inf -inf\n-inf -inf -inf -inf\n",
]
CAMERA_TRACK = ["0.000000, 0.000000, 0.000000, 0.000000, 0.000000, 0.000000\n"
                "-0.000043, 0.000008, 0.217041, -0.336346, 0.389588, 0.000030\n"
                "-14.2, 3.1, 12.5, 12.0, -35.5, 4.25\n"]
CONFIG_YAML = [
    "tracker:\n  affine: true\n  levels: [3, 2, 1]\n  huber_d: 2.5\nkeyframe:\n  threshold: 0.2\n"
    "  loss_not_good_after: null\ndepth:\n  update_variance: smoothed\nseed: 7\nchannel_cost: sum\n",
    "%YAML 1.1\n---\npyramid_levels: 5\nmap_lag: 0\ninfo_channels: 2.5\ninit: random\ntracker:\n",
]

# -- mutations ------------------------------------------------------------------------------------------------
JUNK = ["nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e308", "-1e308", "1e400", "1.0e+400", "9" * 400, "0",
        "-0", "-1", "1e-320", "abc", "#", ",", ";", "--", "0x1F", "1_0", "١٢", "∞", "é", "\x00", "\t", "\ufeff",
        "\r", "\u2028", "\x85", "[", "]", "{", "}", ":", "!!python/object:os.system", "*a", "&a", "? [x]", "null",
        "true", "2001-02-30", "1:30", "'", '"', "\\", "%YAML", "---", "...", "crop", "full", "none", "FOV", "P0:"]
NUMBERS = ["nan", "-nan", "inf", "-inf", "1e308", "-1e308", "1.7976931348623157e308", "1e-320", "0", "-0", "-1",
           "1e16", "4294967296", "18446744073709551616", "0.5", "1", "2", "1e400"]
_TOKEN = re.compile(r"(\s+|,)")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _tokens(text: str) -> list[str]:
    return _TOKEN.split(text)


def _mutate(draw: st.DrawFn, text: str) -> str:
    op = draw(st.sampled_from([
        "truncate", "drop_token", "dup_token", "insert_junk", "replace_junk", "replace_number", "replace_number",
        "replace_number", "drop_line", "dup_line", "swap_lines", "insert_text", "empty", "strip_newlines", "crlf",
    ]))
    toks = _tokens(text)
    words = [i for i, t in enumerate(toks) if t and not _TOKEN.fullmatch(t)]
    lines = text.splitlines(keepends=True)
    if op == "truncate":
        return text[: draw(st.integers(0, len(text)))]
    if op in ("drop_token", "dup_token", "replace_junk", "replace_number") and words:
        numeric = [i for i in words if _is_number(toks[i])]
        i = draw(st.sampled_from(numeric if op == "replace_number" and numeric else words))
        if op == "drop_token":
            toks[i] = ""
        elif op == "dup_token":
            toks[i] = toks[i] + " " + toks[i]
        else:
            toks[i] = draw(st.sampled_from(NUMBERS if op == "replace_number" else JUNK))
        return "".join(toks)
    if op == "insert_junk":
        i = draw(st.integers(0, len(toks)))
        return "".join(toks[:i] + [" " + draw(st.sampled_from(JUNK)) + " "] + toks[i:])
    if op in ("drop_line", "dup_line", "swap_lines") and lines:
        i = draw(st.integers(0, len(lines) - 1))
        if op == "drop_line":
            del lines[i]
        elif op == "dup_line":
            lines.insert(i, lines[i])
        else:
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        return "".join(lines)
    if op == "insert_text":
        i = draw(st.integers(0, len(text)))
        return text[:i] + draw(st.text(max_size=12)) + text[i:]
    if op == "empty":
        return draw(st.sampled_from(["", "\n", "   \n\n", "# only a comment\n"]))
    if op == "strip_newlines":
        return text.replace("\n", " ")
    return text.replace("\n", "\r\n")


@st.composite
def fuzzed(draw: st.DrawFn, samples: list[str]) -> bytes:
    """Bytes of a malformed (or sometimes still valid) file derived from ``samples``."""
    kind = draw(st.sampled_from(["mutant"] * 8 + ["text", "bytes"]))
    if kind == "text":
        return draw(st.text(max_size=200)).encode("utf-8", "surrogatepass")
    if kind == "bytes":
        return draw(st.binary(max_size=200))
    text = draw(st.sampled_from(samples))
    for _ in range(draw(st.integers(1, 3))):
        text = _mutate(draw, text)
    encoding = draw(st.sampled_from(["utf-8"] * 12 + ["utf-8-sig", "utf-16", "utf-32", "latin-1", "cp1252"]))
    data = text.encode(encoding, "replace") if encoding in ("latin-1", "cp1252") else text.encode(encoding,
                                                                                                  "surrogatepass")
    if draw(st.integers(0, 9)) == 0:  # stray bytes: a torn write, a binary blob appended
        i = draw(st.integers(0, len(data)))
        data = data[:i] + draw(st.binary(min_size=1, max_size=8)) + data[i:]
    return data


# -- the property ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


def _parses_or_refuses(parse: Callable[[], Any], named: str | Path | None) -> Any:
    """``parse()``'s value, or ``None`` when it refused with a one-line DmtrackError naming ``named``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "skipped NaN rows", "sorted the timestamps": by design
        warnings.simplefilter("error", RuntimeWarning)  # overflow / invalid value on the way: a bug
        try:
            return parse()
        except DmtrackError as e:
            message = str(e)
            assert message and "\n" not in message and "\r" not in message, message
            assert "np.float64" not in message and "np.int64" not in message, message
            if named is not None:
                assert str(named) in message, message
            return None


def _finite(*values: Any) -> bool:
    return all(np.isfinite(np.asarray(v, dtype=np.float64)).all() for v in values)


def _sane_trajectory(traj: Trajectory, increasing: bool = True, tol: float = 1e-6) -> None:
    assert isinstance(traj, Trajectory) and len(traj) >= 1
    assert _finite(traj.timestamps, traj.poses)
    if increasing:
        assert (np.diff(traj.timestamps) > 0).all()
    R = traj.rotations
    np.testing.assert_allclose(np.swapaxes(R, 1, 2) @ R, np.broadcast_to(np.eye(3), R.shape), atol=tol)
    assert (np.linalg.det(R) > 0).all()
    np.testing.assert_array_equal(traj.poses[:, 3], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (len(traj), 4)))


def _sane_camera(cam: Any) -> None:
    assert _finite(cam.fx, cam.fy, cam.cx, cam.cy) and cam.fx > 0 and cam.fy > 0
    assert 0 < cam.width <= MAX_SIDE and 0 < cam.height <= MAX_SIDE


def _run(scratch: Path, fault_log: Any, target: str, data: bytes, parse: Callable[[Path], Any],
         sane: Callable[[Any], None], name: str = "file.txt") -> None:
    path = scratch / name
    path.write_bytes(data)
    value = _parses_or_refuses(lambda: parse(path), path)
    event("refused" if value is None else "parsed")  # pytest --hypothesis-show-statistics shows the mix
    if value is not None:
        sane(value)
    fault_log.tried(target, "fuzzed text")


# -- trajectories ---------------------------------------------------------------------------------------------
@FUZZ
@given(data=fuzzed(TUM))
def test_tum_trajectory(scratch: Path, fault_log, data: bytes) -> None:
    _run(scratch, fault_log, "TUM trajectory reader", data, read_tum, _sane_trajectory)


@FUZZ
@given(data=fuzzed(KITTI))
# found by CI: a subnormal entry in an exact rotation made np.linalg.det warn ("divide by zero")
@example(data=b"1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0\n0 -1 0 1 1e-320 0 0 2 0 0 1 3\n"
              b"nan nan nan nan nan nan nan nan nan nan nan nan\n")
def test_kitti_trajectory(scratch: Path, fault_log, data: bytes) -> None:
    # KITTI rotations are accepted within the printed-digit tolerance of the reader (1e-2)
    _run(scratch, fault_log, "KITTI trajectory reader", data, read_kitti,
         lambda t: _sane_trajectory(t, tol=2e-2))


@FUZZ
@given(data=fuzzed(TIMES))
def test_kitti_times(scratch: Path, fault_log, data: bytes) -> None:
    poses = scratch / "poses.txt"
    poses.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0\n1 0 0 2 0 1 0 0 0 0 1 0\n")

    def sane(traj: Trajectory) -> None:
        _sane_trajectory(traj, increasing=False)
        assert len(traj) == 3

    # read_kitti reads the timestamps with read_times (also the reader of image folders' and LSD-SLAM's times.txt)
    _run(scratch, fault_log, "times.txt reader (KITTI, image folder, LSD-SLAM)", data,
         lambda p: read_kitti(poses, timestamps=p), sane, name="times.txt")


@FUZZ
@given(data=fuzzed(TUM + KITTI))
def test_trajectory_format_guessed(scratch: Path, fault_log, data: bytes) -> None:
    _run(scratch, fault_log, "trajectory reader (format guessed)", data, read_trajectory,
         lambda t: _sane_trajectory(t, increasing=False, tol=2e-2))


# -- calibration ----------------------------------------------------------------------------------------------
def _sane_calibration(cal: CalibrationFile) -> None:
    assert isinstance(cal, CalibrationFile)
    _sane_camera(cal.model)
    assert cal.output in ("crop", "full", "none") or isinstance(cal.output, PinholeCamera)
    if isinstance(cal.output, PinholeCamera):
        _sane_camera(cal.output)
    w, h = cal.output_size
    assert 0 < w <= MAX_SIDE and 0 < h <= MAX_SIDE
    # small ones are also turned into undistortion maps: that may refuse (a calibration whose principal ray
    # misses the image, …) but only with a DmtrackError naming the file
    if max(cal.model.width, cal.model.height, w, h) <= 160:
        und = _parses_or_refuses(cal.undistorter, cal.path)
        if und is not None:
            assert isinstance(und, Undistorter)
            _sane_camera(und.camera)


@FUZZ
@given(data=fuzzed(DSO_CAMERA + [c.replace("640 480", "64 48").replace("1280 1024", "128 96") for c in DSO_CAMERA]))
@example(data=b"KannalaBrandt 1e-320 0.3 0.5 0.5 0.01 0.002 0 0\n100 80\nfull\n96 80\n")  # found at 1,000: overflow
@example(data=b"KannalaBrandt 0.5 0.3 0.5 0.5 0.01 0.002 0 0\n100 1\nfull\n96 80\n")  # found in CI: a 1-pixel row
def test_dso_camera_txt(scratch: Path, fault_log, data: bytes) -> None:
    _run(scratch, fault_log, "TUM monoVO camera.txt reader", data, lambda p: read_calibration_file(p, "dso"),
         _sane_calibration, name="camera.txt")


@FUZZ
@given(data=fuzzed(LSD_CAMERA + [c.replace("640 480", "64 48") for c in LSD_CAMERA]))
@example(data=b"0.527334 0.827306 0.473568 0.499436 1e-320\n64 48\ncrop\n64 48\n")  # found at 1,000: 1/tan(ω/2)
def test_lsdslam_camera_cfg(scratch: Path, fault_log, data: bytes) -> None:
    _run(scratch, fault_log, "LSD-SLAM cameraCalibration.cfg reader", data,
         lambda p: read_calibration_file(p, "lsdslam"), _sane_calibration, name="cameraCalibration.cfg")


@FUZZ
@given(data=fuzzed(KITTI_CALIB))
def test_kitti_calib(scratch: Path, fault_log, data: bytes) -> None:
    def sane(calib: dict[str, np.ndarray]) -> None:
        assert all(isinstance(k, str) and m.shape == (3, 4) and _finite(m) for k, m in calib.items())

    _run(scratch, fault_log, "KITTI calib.txt reader", data, read_calib, sane, name="calib.txt")


@FUZZ
@given(data=fuzzed(SENSOR_YAML))
def test_euroc_sensor_yaml(scratch: Path, fault_log, data: bytes) -> None:
    def parse(p: Path) -> Any:
        return camera_from_sensor_yaml(read_sensor_yaml(p), p)

    def sane(value: Any) -> None:
        model, T_BS = value
        _sane_camera(model)
        assert T_BS.shape == (4, 4) and _finite(T_BS)
        np.testing.assert_allclose(T_BS[:3, :3].T @ T_BS[:3, :3], np.eye(3), atol=1e-9)

    _run(scratch, fault_log, "EuRoC sensor.yaml reader", data, parse, sane, name="sensor.yaml")


@FUZZ
@given(data=fuzzed(INTRINSICS))
def test_intrinsics_file(scratch: Path, fault_log, data: bytes) -> None:
    # TUM RGB-D / image-folder camera.txt, 7-Scenes camera-intrinsics.txt, video sidecars
    _run(scratch, fault_log, "intrinsics file reader (TUM RGB-D, 7-Scenes, image folder)", data,
         lambda p: read_intrinsics_file(p, 640, 480), _sane_camera, name="camera-intrinsics.txt")


@FUZZ
@given(text=st.one_of(
    st.text(max_size=40),
    st.lists(st.sampled_from(JUNK + ["525", "525.0", "319.5", "239.5", "1e-3", " ", ","]), max_size=6).map(",".join),
))
def test_intrinsics_option(fault_log, text: str) -> None:
    cam = _parses_or_refuses(lambda: parse_intrinsics(text, 640, 480), None)
    if cam is not None:
        _sane_camera(cam)
    fault_log.tried("--intrinsics FX,FY,CX,CY parser", "fuzzed text")


@FUZZ
@given(data=fuzzed(POSE_4X4))
def test_7scenes_pose(scratch: Path, fault_log, data: bytes) -> None:
    def sane(pose: np.ndarray) -> None:
        assert pose.shape == (4, 4)
        if np.isfinite(pose).all():  # all-NaN marks a failed KinectFusion frame
            np.testing.assert_allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-9)
        else:
            assert np.isnan(pose).all()

    _run(scratch, fault_log, "7-Scenes pose file reader", data, read_pose_file, sane, name="frame-000000.pose.txt")


@FUZZ
@given(data=fuzzed(CAMERA_TRACK))
def test_tsukuba_camera_track(scratch: Path, fault_log, data: bytes) -> None:
    def sane(track: np.ndarray) -> None:
        assert track.ndim == 2 and track.shape[1] == 6 and _finite(track)
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            assert _finite(track_to_poses(track, offset_x=-5.0, scale=0.01))

    _run(scratch, fault_log, "New Tsukuba camera_track.txt reader", data, read_camera_track, sane,
         name="camera_track.txt")


# -- sequence lists (association, timestamps, ground truth of the dataset layouts) --------------------------------
@FUZZ
@given(data=fuzzed(RGB_LIST))
def test_tum_rgbd_file_list(scratch: Path, fault_log, data: bytes) -> None:
    def sane(value: Any) -> None:
        stamps, names = value
        assert len(names) == stamps.size > 0 and _finite(stamps)

    _run(scratch, fault_log, "TUM RGB-D rgb.txt / depth.txt reader", data, read_file_list, sane, name="rgb.txt")


@FUZZ
@given(data=fuzzed(ASSOCIATIONS))
def test_iclnuim_associations(scratch: Path, fault_log, data: bytes) -> None:
    def sane(value: Any) -> None:
        ids, depth, rgb = value
        assert ids.size == len(depth) == len(rgb) > 0 and _finite(ids)

    _run(scratch, fault_log, "ICL-NUIM associations.txt reader", data, read_associations, sane,
         name="associations.txt")


@FUZZ
@given(data=fuzzed(EUROC_LIST))
def test_euroc_image_list(scratch: Path, fault_log, data: bytes) -> None:
    def sane(value: Any) -> None:
        stamps, names = value
        assert stamps.dtype == np.int64 and stamps.size == len(names) > 0

    _run(scratch, fault_log, "EuRoC data.csv reader", data, read_image_list, sane, name="data.csv")


@FUZZ
@given(data=fuzzed(EUROC_GT))
def test_euroc_groundtruth(scratch: Path, fault_log, data: bytes) -> None:
    def sane(value: Any) -> None:
        stamps, T = value
        assert stamps.size == T.shape[0] > 0 and _finite(T)
        np.testing.assert_allclose(np.swapaxes(T[:, :3, :3], 1, 2) @ T[:, :3, :3],
                                   np.broadcast_to(np.eye(3), (stamps.size, 3, 3)), atol=1e-9)

    _run(scratch, fault_log, "EuRoC ground-truth data.csv reader", data, read_groundtruth_csv, sane,
         name="data.csv")


@FUZZ
@given(data=fuzzed(MONOVO_TIMES))
def test_monovo_times(scratch: Path, fault_log, data: bytes) -> None:
    def sane(value: Any) -> None:
        ids, stamps, exposures = value
        assert ids.size == stamps.size == exposures.size > 0 and _finite(stamps)

    _run(scratch, fault_log, "TUM monoVO times.txt reader", data, read_times_file, sane, name="times.txt")


@FUZZ
@given(data=fuzzed(MONOVO_GT))
def test_monovo_groundtruth(scratch: Path, fault_log, data: bytes) -> None:
    def sane(value: Any) -> None:
        stamps, T = value
        assert stamps.size == T.shape[0] and _finite(stamps, T)

    _run(scratch, fault_log, "TUM monoVO groundtruthSync.txt reader", data, read_groundtruth_sync, sane,
         name="groundtruthSync.txt")


@FUZZ
@given(data=fuzzed(PCALIB))
def test_monovo_pcalib(scratch: Path, fault_log, data: bytes) -> None:
    def sane(G: np.ndarray) -> None:
        assert G.size >= 256 and _finite(G) and (np.diff(G) >= 0).all()

    _run(scratch, fault_log, "TUM monoVO pcalib.txt reader", data, read_pcalib, sane, name="pcalib.txt")


# -- configuration ----------------------------------------------------------------------------------------------
def _sane_config(cfg: VOConfig) -> None:
    assert isinstance(cfg, VOConfig)
    assert VOConfig.from_dict(cfg.to_dict()) == cfg

    def numbers(d: dict[str, Any]) -> list[Any]:
        out = []
        for v in d.values():
            out.extend(numbers(v) if isinstance(v, dict) else [v])
        return out

    floats = [v for v in numbers(cfg.to_dict()) if isinstance(v, float)]
    assert _finite(floats)
    assert all(isinstance(lv, int) for lv in cfg.tracker.levels + cfg.tracker.max_its)


@FUZZ
@given(data=fuzzed(CONFIG_YAML))
def test_config_yaml(scratch: Path, fault_log, data: bytes) -> None:
    _run(scratch, fault_log, "VOConfig.from_yaml (--config)", data, VOConfig.from_yaml, _sane_config,
         name="vo.yaml")


def _keys(d: dict[str, Any], prefix: str = "") -> list[str]:
    out = []
    for k, v in d.items():
        out.extend(_keys(v, f"{prefix}{k}.") if isinstance(v, dict) else [f"{prefix}{k}"])
    return out


KEYS = _keys(VOConfig().to_dict())
VALUES = JUNK + ["1", "2.5", "0", "-3", "[3, 2, 1]", "[5, 20, 50, 100, 0]", "[]", "[a]", "[1.5]", "true", "false",
                 "null", "sum", "mean", "balanced", "groundtruth", "raw", "{a: 1}", "1e999", ".inf", ".nan", "~",
                 "10000000000000000000000", "[[1]]", "'2'"]


@FUZZ
@given(items=st.lists(st.one_of(
    st.builds(lambda k, v: f"{k}={v}", st.sampled_from(KEYS + ["tracker", "depth.", "nope", "", " seed "]),
              st.one_of(st.sampled_from(VALUES), st.text(max_size=10))),
    st.text(max_size=20),
), min_size=1, max_size=3))
def test_set_overrides(fault_log, items: list[str]) -> None:
    cfg = _parses_or_refuses(lambda: VOConfig().with_overrides(*items), None)
    if cfg is not None:
        _sane_config(cfg)
    fault_log.tried("--set KEY=VALUE (VOConfig.with_overrides)", "fuzzed text")
