"""EuRoC MAV reader: ASL layout, sensor.yaml (T_BS, radial-tangential), ground truth with w-x-y-z quaternions."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmtrack.cli import main
from dmtrack.datasets import detect_format, open_sequence
from dmtrack.errors import InputError
from dmtrack.geometry.distortion import RadTanModel

W, H = 188, 120  # the real 752×480 divided by 4
FU, FV, CU, CV = 458.654 / 4, 457.296 / 4, 367.215 / 4, 248.375 / 4
DIST = (-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05)
MODEL = RadTanModel(FU, FV, CU, CV, W, H, *DIST)
# cam0's T_BS of the real dataset (camera pose in the body/IMU frame)
T_BS = np.array([
    [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975],
    [0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768],
    [-0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949],
    [0.0, 0.0, 0.0, 1.0],
])
SENSOR_YAML = f"""# General sensor definitions.
sensor_type: camera
comment: VI-Sensor cam0 (MT9M034)

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [{", ".join(repr(float(v)) for v in T_BS.ravel())}]

# Camera specific definitions.
rate_hz: 20
resolution: [{W}, {H}]
camera_model: pinhole
intrinsics: [{FU}, {FV}, {CU}, {CV}] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [{", ".join(map(str, DIST))}]
"""
T0_NS = 1403636579763555584


def body_pose(t: np.ndarray) -> np.ndarray:
    """T_RB(t): constant angular velocity about a fixed axis and constant velocity (interpolation is exact)."""
    t = np.atleast_1d(t)
    T = np.tile(np.eye(4), (t.size, 1, 1))
    T[:, :3, :3] = Rotation.from_rotvec(t[:, None] * np.array([0.05, 0.3, -0.1])).as_matrix()
    T[:, :3, 3] = np.array([4.6, -1.8, 0.8]) + t[:, None] * np.array([0.3, 0.1, -0.05])
    return T


def _scene() -> np.ndarray:
    """Points in front of the camera at t = 0 (camera z ≈ body z; see T_BS), in world coordinates."""
    g = np.stack(np.meshgrid(np.linspace(-0.5, 0.5, 6), np.linspace(-0.35, 0.35, 4)), -1).reshape(-1, 2)
    pc = np.column_stack([g * 3.0, np.full(len(g), 3.0)])
    T_wc0 = body_pose(np.array([0.1]))[0] @ T_BS
    return (T_wc0 @ np.column_stack([pc, np.ones(len(pc))]).T).T[:, :3]


def _render(uv: np.ndarray) -> np.ndarray:
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    img = np.full((H, W), 12.0)
    for x, y in uv:
        if np.isfinite(x):
            img += 220.0 * np.exp(-((u - x) ** 2 + (v - y) ** 2) / (2 * 1.2**2))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _centroid(img: np.ndarray, x: float, y: float, r: int = 4) -> np.ndarray:
    xi, yi = int(round(x)), int(round(y))
    p = np.clip(img[yi - r:yi + r + 1, xi - r:xi + r + 1].astype(float) - 12.0, 0, None)
    vv, uu = np.mgrid[yi - r:yi + r + 1, xi - r:xi + r + 1]
    return np.array([(p * uu).sum() / p.sum(), (p * vv).sum() / p.sum()])


def write_euroc(root: Path, n: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """MH_xx/mav0 in the ASL layout; returns image times (s after T0) and the true camera-to-world poses."""
    cam = root / "mav0" / "cam0"
    (cam / "data").mkdir(parents=True)
    (cam / "sensor.yaml").write_text(SENSOR_YAML)
    t_img = 0.05 * np.arange(n)  # 20 Hz; the first image comes before the ground truth starts
    X = _scene()
    lines = ["#timestamp [ns],filename"]
    true = []
    for t in t_img:
        ns = T0_NS + int(round(t * 1e9))
        T_wc = body_pose(np.array([t]))[0] @ T_BS
        true.append(T_wc)
        Xc = (np.linalg.inv(T_wc) @ np.column_stack([X, np.ones(len(X))]).T).T[:, :3]
        cv2.imwrite(str(cam / "data" / f"{ns}.png"), _render(MODEL.project(Xc)))
        lines.append(f"{ns},{ns}.png")
    (cam / "data.csv").write_text("\n".join(lines) + "\n")
    gt = root / "mav0" / "state_groundtruth_estimate0"
    gt.mkdir(parents=True)
    t_gt = 0.0213 + np.arange(0, 0.25, 0.005)  # 200 Hz, not aligned with the images
    rows = ["#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
            "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], "
            "b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], "
            "b_a_RS_S_z [m s^-2]"]
    for t, T in zip(t_gt, body_pose(t_gt), strict=True):
        x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
        vals = [*T[:3, 3], w, x, y, z, 0.3, 0.1, -0.05, 0, 0, 0, 0, 0, 0]
        rows.append(f"{T0_NS + int(round(t * 1e9))}," + ",".join(f"{v:.12f}" for v in vals))
    (gt / "data.csv").write_text("\n".join(rows) + "\n")
    return t_img, np.asarray(true)


def test_layout_and_groundtruth(tmp_path: Path) -> None:
    root = tmp_path / "MH_01_easy"
    t_img, true = write_euroc(root)
    assert detect_format(root) == "euroc" and detect_format(root / "mav0") == "euroc"
    seq = open_sequence(root)
    assert len(seq) == 5 and (seq.width, seq.height) == (176, 112)  # undistorted, multiples of 16
    np.testing.assert_allclose(seq.timestamps, T0_NS * 1e-9 + t_img, rtol=0, atol=1e-6)
    assert seq[0].pose is None  # before the first ground-truth sample
    for i in range(1, 5):
        np.testing.assert_allclose(seq[i].pose, true[i], atol=1e-9)  # T_wc = T_RB · T_BS, interpolated
    assert seq.details["undistortion"] == "crop" and seq.details["distortion_model"]["k1"] == DIST[0]
    raw = open_sequence(root, undistort=False)
    assert (raw.width, raw.height) == (W, H) and raw[2].image.shape == (H, W)


def test_dots_after_undistortion(tmp_path: Path) -> None:
    root = tmp_path / "V1_01_easy"
    write_euroc(root)
    seq = open_sequence(root)
    X = np.column_stack([_scene(), np.ones(24)])
    errors = []
    for i in (1, 3, 4):
        f = seq[i]
        uv = seq.camera.project((np.linalg.inv(f.pose) @ X.T).T[:, :3])
        inside = seq.camera.in_image(uv, border=6)
        assert inside.sum() >= 12
        errors += [np.hypot(*(_centroid(f.image, x, y) - (x, y))) for x, y in uv[inside]]
    assert max(errors) < 0.3
    # reading the quaternion as x y z w (the TUM order) instead of w x y z puts the dots elsewhere
    f = seq[3]
    T_RB = f.pose @ np.linalg.inv(T_BS)
    q_wxyz = np.roll(Rotation.from_matrix(T_RB[:3, :3]).as_quat(), 1)
    wrong = T_RB.copy()
    wrong[:3, :3] = Rotation.from_quat(q_wxyz).as_matrix()
    uv_bad = seq.camera.project((np.linalg.inv(wrong @ T_BS) @ X.T).T[:, :3])
    uv = seq.camera.project((np.linalg.inv(f.pose) @ X.T).T[:, :3])
    assert not np.isfinite(uv_bad).all() or np.nanmedian(np.hypot(*(uv_bad - uv).T)) > 10


def test_errors_and_info(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "MH_02_easy"
    write_euroc(root, n=3)
    assert main(["info", str(root), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "euroc" and info["frames"] == 3 and info["width"] == 176
    assert info["groundtruth_frames"] == 2 and info["details"]["camera"] == "cam0"
    yaml_path = root / "mav0" / "cam0" / "sensor.yaml"
    yaml_path.write_text(SENSOR_YAML.replace("T_BS:", "T_XX:"))
    with pytest.raises(InputError, match=r"sensor.yaml: missing key 'T_BS'"):
        open_sequence(root)
    yaml_path.write_text(SENSOR_YAML.replace("0.999557249008", "1.999557249008"))
    with pytest.raises(InputError, match=r"sensor.yaml: T_BS: the rotation part is not a rotation"):
        open_sequence(root)
    yaml_path.write_text(SENSOR_YAML.replace("radial-tangential", "fov"))
    with pytest.raises(InputError, match=r"distortion_model 'fov' is not supported"):
        open_sequence(root)
    yaml_path.write_text(SENSOR_YAML)
    csv = root / "mav0" / "cam0" / "data.csv"
    csv.write_text(csv.read_text().replace(str(T0_NS), "14036365797.6", 1).replace("#timestamp", "#ts", 1))
    with pytest.raises(InputError, match=r"data.csv:2: cannot read timestamp '14036365797.6'"):
        open_sequence(root)
    with pytest.raises(InputError, match="unknown EuRoC camera"):
        open_sequence(root, camera="cam7")
