"""New Tsukuba reader: official layout, camera_track.txt (cm, Euler degrees), stereo baseline, and the pose
convention checked against the real images in ../shared."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmtrack.cli import main
from dmtrack.datasets import detect_format, open_sequence
from dmtrack.datasets.tsukuba import euler_to_matrix, track_to_poses
from dmtrack.errors import InputError
from dmtrack.io.trajectory import read_tum

W, H = 640, 480
TRACK = np.array([
    [0.000000, 0.000000, 0.000000, 0.000000, 0.000000, 0.000000],
    [-0.000043, 0.000008, 0.217041, -0.336346, 0.389588, 0.000030],
    [-0.000390, 0.000008, 0.531036, -0.761119, 0.869630, 0.000068],
    [-14.2, 3.1, 12.5, 12.0, -35.5, 4.25],
])


def write_tsukuba(root: Path, frames: int = 3, modes: tuple[str, ...] = ("daylight", "lamps"),
                  depth: bool = True) -> None:
    for mode in modes:
        for side, s in (("left", "L"), ("right", "R")):
            d = root / "illumination" / mode / side
            d.mkdir(parents=True)
            for n in range(1, frames + 1):
                img = np.full((H, W, 3), (10 * n, 20, 30), np.uint8)
                cv2.imwrite(str(d / f"tsukuba_{mode}_{s}_{n:05d}.png"), img)
    gt = root / "groundtruth"
    gt.mkdir()
    (gt / "camera_track.txt").write_text("".join(", ".join(f"{v:.6f}" for v in row) + "\n" for row in TRACK))
    if depth:
        (gt / "depth_maps" / "left").mkdir(parents=True)
        for n in range(1, frames + 1):
            fs = cv2.FileStorage(str(gt / "depth_maps" / "left" / f"tsukuba_depth_L_{n:05d}.xml"),
                                 cv2.FILE_STORAGE_WRITE)
            fs.write("depth", np.full((H, W), 250.0 + n, np.float32))  # centimetres
            fs.release()


def test_euler_convention_is_rz_ry_rx() -> None:
    rng = np.random.default_rng(0)
    ang = rng.uniform(-180, 180, size=(50, 3))
    R = euler_to_matrix(ang[:, 0], ang[:, 1], ang[:, 2])
    # rotations about the fixed x, y, z axes in that order (scipy's lower-case 'xyz' = extrinsic)
    np.testing.assert_allclose(R, Rotation.from_euler("xyz", ang, degrees=True).as_matrix(), atol=1e-12)
    Rx = Rotation.from_euler("x", ang[:, [0]], degrees=True).as_matrix()
    Rz = Rotation.from_euler("z", ang[:, [2]], degrees=True).as_matrix()
    Ry = Rotation.from_euler("y", ang[:, [1]], degrees=True).as_matrix()
    np.testing.assert_allclose(R, Rz @ Ry @ Rx, atol=1e-12)


def test_layout_units_depth(tmp_path: Path) -> None:
    root = tmp_path / "NewTsukubaStereoDataset"
    write_tsukuba(root)
    for p in (root, root / "illumination" / "daylight", root / "illumination" / "lamps" / "right"):
        assert detect_format(p) == "tsukuba"
    seq = open_sequence(root)
    assert seq.name == "tsukuba-daylight-left" and len(seq) == 3
    assert (seq.camera.fx, seq.camera.cx, seq.camera.cy) == (615.0, 320.0, 240.0)
    np.testing.assert_allclose(seq.timestamps, np.arange(3) / 30.0)
    assert tuple(seq[1].image[0, 0]) == (30, 20, 20)  # RGB order; frame 2 (1-based name 00002) has blue 20
    assert seq.has_depth and seq[2].depth[0, 0] == pytest.approx(2.53)  # 253 cm → m
    right = open_sequence(root / "illumination" / "lamps" / "right", units="cm")
    assert right.name == "tsukuba-lamps-right" and right.details["baseline"] == 10.0
    # metres vs centimetres: same rotations, positions ×100
    np.testing.assert_allclose(right.groundtruth.poses[:, :3, :3],
                               open_sequence(root, camera="right").groundtruth.poses[:, :3, :3])
    cm = right.groundtruth.poses[:, :3, 3]
    m = open_sequence(root, camera="right").groundtruth.poses[:, :3, 3]
    np.testing.assert_allclose(cm, 100 * m, atol=1e-9)
    assert right.slice(1).groundtruth.timestamps[0] == pytest.approx(1 / 30)


def test_stereo_pair_is_rectified_with_right_camera_to_the_right(tmp_path: Path) -> None:
    root = tmp_path / "ds"
    write_tsukuba(root, frames=4, modes=("fluorescent",), depth=False)
    left = open_sequence(root, illumination="fluorescent")
    right = open_sequence(root, illumination="fluorescent", camera="right")
    for i in range(4):
        rel = np.linalg.inv(left[i].pose) @ right[i].pose
        np.testing.assert_allclose(rel[:3, :3], np.eye(3), atol=1e-12)
        np.testing.assert_allclose(rel[:3, 3], [0.10, 0.0, 0.0], atol=1e-12)  # 10 cm along +x (OpenCV: right)
    # the middle of the baseline is the track position, with y and z negated (F = diag(1, -1, -1))
    mid = track_to_poses(TRACK, scale=0.01)
    np.testing.assert_allclose((left[3].pose[:3, 3] + right[3].pose[:3, 3]) / 2, mid[3, :3, 3], atol=1e-12)
    np.testing.assert_allclose(mid[3, :3, 3], [-0.142, -0.031, -0.125], atol=1e-12)


def test_errors_and_info(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "NewTsukubaStereoDataset"
    write_tsukuba(root, frames=2, modes=("flashlight",), depth=False)
    assert main(["info", str(root / "illumination" / "flashlight"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "tsukuba" and info["frames"] == 2 and info["fx"] == 615.0
    assert info["details"]["units"] == "m" and info["has_groundtruth"]
    with pytest.raises(InputError, match=r"illumination 'daylight' not found \(the dataset has flashlight\)"):
        open_sequence(root)
    track = root / "groundtruth" / "camera_track.txt"
    track.write_text("0, 0, 0, 0, 0, 0\n1, 2, 3, 4, 5\n")
    with pytest.raises(InputError, match=r"camera_track.txt:2: expected 6 values"):
        open_sequence(root, illumination="flashlight")
    track.write_text("0, 0, 0, 0, 0, 0\n")
    with pytest.raises(InputError, match=r"camera_track.txt: 1 poses but image numbers run 1..2"):
        open_sequence(root, illumination="flashlight")


# -- the convention, against the real images --------------------------------------------------------------
def _official_layout_from_shared(shared: Path, tmp: Path) -> Path:
    """Rebuild camera_track.txt (X Y Z in cm, A B C in degrees, 6 decimals) from the shared 150-frame copy, whose
    rotation matrices are Rz(C)Ry(B)Rx(A) of the original angles, and link its images under official names."""
    src = np.loadtxt(shared / "data" / "tsukuba-150" / "cam_traj_truth.txt")
    u, _, vt = np.linalg.svd(src[:, 3:].reshape(-1, 3, 3))
    ang = Rotation.from_matrix(u @ vt).as_euler("xyz", degrees=True)
    root = tmp / "NewTsukubaStereoDataset"
    left = root / "illumination" / "daylight" / "left"
    left.mkdir(parents=True)
    (root / "groundtruth").mkdir()
    rows = np.column_stack([src[:, :3], ang])
    (root / "groundtruth" / "camera_track.txt").write_text(
        "".join(", ".join(f"{v:.6f}" for v in r) + "\n" for r in rows))
    for i in range(len(src)):  # JPEG content under .png names: OpenCV decodes by content
        (left / f"tsukuba_daylight_L_{i + 1:05d}.png").symlink_to(shared / "data" / "tsukuba-150" / "images" /
                                                                  f"{i:06d}.jpg")
    return root


def test_convention_against_real_images(shared_dir: Path, tmp_path: Path) -> None:
    root = _official_layout_from_shared(shared_dir, tmp_path)
    seq = open_sequence(root, units="cm")
    # 1. where the formats overlap, the poses agree with shared/…/groundtruth.txt (the baseline middle, in cm)
    ref = read_tum(shared_dir / "data" / "tsukuba-150" / "groundtruth.txt")
    poses = seq.groundtruth.poses.copy()
    poses[:, :3, 3] += poses[:, :3, 0] * 5.0  # left camera → middle of the 10 cm baseline
    np.testing.assert_allclose(poses[:, :3, :3], ref.poses[:, :3, :3], atol=2e-6)
    np.testing.assert_allclose(poses[:, :3, 3], ref.poses[:, :3, 3], atol=2e-5)
    # 2. the relative motion agrees with the images (essential matrix of ORB matches, K = 615, 320, 240)
    K = seq.camera.K
    orb = cv2.ORB_create(2000)
    for i, j in ((0, 10), (40, 46), (100, 104)):
        a, b = seq[i].image, seq[j].image
        ka, da = orb.detectAndCompute(cv2.cvtColor(a, cv2.COLOR_RGB2GRAY), None)
        kb, db = orb.detectAndCompute(cv2.cvtColor(b, cv2.COLOR_RGB2GRAY), None)
        m = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(da, db)
        pa = np.float64([ka[x.queryIdx].pt for x in m])
        pb = np.float64([kb[x.trainIdx].pt for x in m])
        E, mask = cv2.findEssentialMat(pa, pb, K, cv2.RANSAC, 0.999, 1.0)
        _, R_ba, t_ba, _ = cv2.recoverPose(E, pa, pb, K, mask=mask)
        # camera-b pose in camera-a coordinates from the images: [R_baᵀ | −R_baᵀ t_ba]
        t_img = -R_ba.T @ t_ba.ravel()
        rel = np.linalg.inv(seq[i].pose) @ seq[j].pose
        t_gt = rel[:3, 3] / np.linalg.norm(rel[:3, 3])
        angle_t = np.degrees(np.arccos(np.clip(t_gt @ t_img / np.linalg.norm(t_img), -1, 1)))
        angle_r = np.degrees(Rotation.from_matrix(rel[:3, :3] @ R_ba).magnitude())
        assert angle_t < 12.0, (i, j, angle_t)
        assert angle_r < 1.5, (i, j, angle_r)

