"""Dataset readers on small files written here in each official layout, and on the shared real data."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmtrack.datasets import detect_format, open_sequence
from dmtrack.datasets.base import Frame, Sequence
from dmtrack.errors import DatasetError, InputError
from dmtrack.io.trajectory import Trajectory, write_kitti, write_tum

W, H = 64, 48


def _image(seed: int, colour: bool = True) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 256, size=(H, W, 3) if colour else (H, W), dtype=np.uint8)
    return img


def _poses(n: int, seed: int = 0) -> np.ndarray:
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = Rotation.from_rotvec(np.linspace(0, 0.3, n)[:, None] * [0, 1, 0]).as_matrix()
    poses[:, :3, 3] = np.linspace(0, 1, n)[:, None] * [1.0, 0.2, 0.1] + seed
    return poses


# -- 7-Scenes ----------------------------------------------------------------------------------------
def write_7scenes(root: Path, n: int = 4, ext: str = "png", intrinsics: bool = False) -> np.ndarray:
    root.mkdir(parents=True)
    poses = _poses(n)
    for i in range(n):
        cv2.imwrite(str(root / f"frame-{i:06d}.color.{ext}"), _image(i))
        depth = np.full((H, W), 1500, np.uint16)
        depth[0, 0] = 65535
        cv2.imwrite(str(root / f"frame-{i:06d}.depth.png"), depth)
        np.savetxt(root / f"frame-{i:06d}.pose.txt", poses[i])
    if intrinsics:
        np.savetxt(root / "camera-intrinsics.txt", [[50.0, 0, 31.5], [0, 51.0, 23.5], [0, 0, 1]])
    return poses


def test_7scenes_layout(tmp_path: Path) -> None:
    poses = write_7scenes(tmp_path / "seq-01", intrinsics=True)
    # the official release has 640x480 images; these are small, so the reader must refuse them clearly
    assert detect_format(tmp_path / "seq-01") == "7scenes"
    seq = open_sequence(tmp_path / "seq-01")
    assert isinstance(seq, Sequence)
    assert len(seq) == 4 and seq.has_groundtruth and seq.has_depth
    assert seq.camera is not None and seq.camera.fx == 50.0 and seq.camera.cy == 23.5
    np.testing.assert_allclose(seq.timestamps, np.arange(4) / 30.0)
    np.testing.assert_allclose(seq.groundtruth.poses, poses)
    with pytest.raises(DatasetError, match="64x48, the sequence is 640x480"):
        seq[0]


def test_7scenes_frames(tmp_path: Path) -> None:
    root = tmp_path / "seq-02"
    root.mkdir()
    img = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    cv2.imwrite(str(root / "frame-000000.color.png"), img)
    depth = np.full((480, 640), 2000, np.uint16)
    depth[10, 20] = 65535
    cv2.imwrite(str(root / "frame-000000.depth.png"), depth)
    pose = _poses(1)[0]
    np.savetxt(root / "frame-000000.pose.txt", pose)
    seq = open_sequence(root)
    assert seq.camera.fx == 585.0 and seq.details["intrinsics_source"] == "documented 7-Scenes calibration"
    frame = seq[0]
    assert isinstance(frame, Frame)
    np.testing.assert_array_equal(frame.image, img[:, :, ::-1])  # RGB, not BGR
    assert frame.depth.dtype == np.float32 and frame.depth[0, 0] == pytest.approx(2.0)
    assert frame.depth[10, 20] == 0.0  # 65535 = invalid
    np.testing.assert_allclose(frame.pose, pose)


def test_7scenes_parent_folder_and_bad_pose(tmp_path: Path) -> None:
    write_7scenes(tmp_path / "redkitchen" / "seq-01")
    with pytest.raises(DatasetError, match="seq-01: pass one of them"):
        open_sequence(tmp_path / "redkitchen", format="7scenes")
    (tmp_path / "redkitchen" / "seq-01" / "frame-000002.pose.txt").write_text("1 0 0\n0 1 0\n")
    with pytest.raises(InputError, match=r"frame-000002.pose.txt: expected a 4×4 pose matrix"):
        open_sequence(tmp_path / "redkitchen" / "seq-01")


# -- KITTI ---------------------------------------------------------------------------------------------
def write_kitti_layout(root: Path, seq: str = "00", n: int = 5, colour: bool = False) -> np.ndarray:
    sdir = root / "sequences" / seq
    (sdir / "image_0").mkdir(parents=True)
    (sdir / "image_2").mkdir(parents=True)
    for i in range(n):
        cv2.imwrite(str(sdir / "image_0" / f"{i:06d}.png"), _image(i, colour=False))
        cv2.imwrite(str(sdir / "image_2" / f"{i:06d}.png"), _image(i + 100))
    K = np.array([[70.0, 0, 31.0], [0, 70.0, 22.0], [0, 0, 1]])
    P0 = np.hstack([K, np.zeros((3, 1))])
    P1 = np.hstack([K, K @ np.array([[-0.54], [0], [0]])])
    P2 = np.hstack([K, K @ np.array([[0.06], [-0.001], [0.002]])])
    with open(sdir / "calib.txt", "w") as f:
        for name, P in (("P0", P0), ("P1", P1), ("P2", P2), ("P3", P2), ("Tr", P0)):
            f.write(f"{name}: " + " ".join(f"{v:.12e}" for v in P.reshape(-1)) + "\n")
    np.savetxt(sdir / "times.txt", np.arange(n) * 0.1036, fmt="%e")
    (root / "poses").mkdir()
    poses = _poses(n)
    write_kitti(root / "poses" / f"{seq}.txt", Trajectory(np.arange(n), poses))
    return poses


def test_kitti_layout(tmp_path: Path) -> None:
    poses = write_kitti_layout(tmp_path / "dataset")
    for path in (tmp_path / "dataset", tmp_path / "dataset" / "sequences", tmp_path / "dataset/sequences/00"):
        assert detect_format(path) == "kitti"
    seq = open_sequence(tmp_path / "dataset" / "sequences" / "00")
    assert seq.format == "kitti" and len(seq) == 5
    assert (seq.width, seq.height) == (W, H)
    assert (seq.camera.fx, seq.camera.cx, seq.camera.cy) == (70.0, 31.0, 22.0)
    np.testing.assert_allclose(seq.timestamps, np.arange(5) * 0.1036)
    np.testing.assert_allclose(seq.groundtruth.poses, poses, atol=1e-8)
    assert seq[0].image.ndim == 2


def test_kitti_colour_camera_pose_offset(tmp_path: Path) -> None:
    poses = write_kitti_layout(tmp_path / "dataset")
    seq = open_sequence(tmp_path / "dataset", camera_folder="image_2")
    assert seq[0].image.shape == (H, W, 3)
    # camera 2 sits at t2 = K⁻¹P2[:,3] = (0.06, −0.001, 0.002) in camera-0 coordinates … a point X0 in camera-0
    # coordinates is at X2 = X0 + t2 in camera-2 coordinates; the ground truth must agree with that.
    t2 = np.array([0.06, -0.001, 0.002])
    X0 = np.array([0.3, -0.2, 4.0])
    for i in range(5):
        world = poses[i] @ np.append(X0, 1.0)
        X2 = np.linalg.inv(seq.groundtruth.poses[i]) @ world
        np.testing.assert_allclose(X2[:3], X0 + t2, atol=1e-9)


def test_kitti_errors(tmp_path: Path) -> None:
    write_kitti_layout(tmp_path / "a", "00")
    write_kitti_layout(tmp_path / "b", "01")
    (tmp_path / "a" / "sequences" / "01").symlink_to(tmp_path / "b" / "sequences" / "01")
    with pytest.raises(DatasetError, match=r"several KITTI sequences \(00, 01\)"):
        open_sequence(tmp_path / "a", format="kitti")
    calib = tmp_path / "b" / "sequences" / "01" / "calib.txt"
    calib.write_text("P0: 1 2 3\n")
    with pytest.raises(InputError, match=r"calib.txt:1: P0: expected 12 numbers"):
        open_sequence(tmp_path / "b" / "sequences" / "01")
    with pytest.raises(DatasetError, match="unknown KITTI camera"):
        open_sequence(tmp_path / "a" / "sequences" / "00", camera_folder="image_9")


# -- TUM RGB-D -----------------------------------------------------------------------------------------
def write_tum_rgbd(root: Path, n: int = 6) -> tuple[np.ndarray, Trajectory]:
    (root / "rgb").mkdir(parents=True)
    (root / "depth").mkdir()
    t0 = 1305031102.175304
    stamps = t0 + np.arange(n) / 30.0
    lines = ["# color images", "# file: 'rgbd_dataset_freiburg1_xyz.bag'", "# timestamp filename"]
    dlines = list(lines)
    for i, t in enumerate(stamps):
        name = f"{t:.6f}.png"
        img = np.zeros((480, 640, 3), np.uint8)
        img[:, :, 2] = i  # red in BGR order
        cv2.imwrite(str(root / "rgb" / name), img)
        lines.append(f"{t:.6f} rgb/{name}")
        td = t + 0.004
        cv2.imwrite(str(root / "depth" / f"{td:.6f}.png"), np.full((480, 640), 5000 * (i + 1), np.uint16))
        dlines.append(f"{td:.6f} depth/{td:.6f}.png")
    (root / "rgb.txt").write_text("\n".join(lines) + "\n")
    (root / "depth.txt").write_text("\n".join(dlines) + "\n")
    gt_t = np.arange(t0 - 0.05, stamps[-1] + 0.05, 0.01)  # 100 Hz motion capture
    poses = np.tile(np.eye(4), (gt_t.size, 1, 1))
    poses[:, 0, 3] = gt_t - t0  # x = time: interpolation is exact
    gt = Trajectory(gt_t, poses)
    write_tum(root / "groundtruth.txt", gt, header="ground truth trajectory\ntimestamp tx ty tz qx qy qz qw")
    return stamps, gt


def test_tum_rgbd_layout(tmp_path: Path) -> None:
    root = tmp_path / "rgbd_dataset_freiburg1_xyz"
    stamps, _ = write_tum_rgbd(root)
    assert detect_format(root) == "tum-rgbd"
    seq = open_sequence(root)
    assert len(seq) == 6 and seq.has_depth
    assert (seq.camera.fx, seq.camera.cy) == (517.3, 255.3)
    assert seq.details["distortion_applied"] is False
    np.testing.assert_allclose(seq.timestamps, stamps)
    np.testing.assert_allclose(seq.groundtruth.positions[:, 0], stamps - stamps[0], atol=1e-6)
    frame = seq[3]
    assert frame.image[0, 0, 0] == 3  # RGB order
    assert frame.depth[0, 0] == pytest.approx(4.0)


def test_tum_rgbd_gap_in_groundtruth(tmp_path: Path) -> None:
    root = tmp_path / "rgbd_dataset_freiburg3_long_office_household"
    stamps, gt = write_tum_rgbd(root)
    keep = (gt.timestamps < stamps[2] - 0.02) | (gt.timestamps > stamps[3] + 0.02)  # mocap lost the camera
    write_tum(root / "groundtruth.txt", gt[keep])
    seq = open_sequence(root, max_gt_gap=0.05)  # the 0.08 s hole is too long to interpolate across
    assert seq.camera.fx == 535.4
    assert seq.groundtruth.timestamps.size == 4  # frames 2 and 3 have no ground truth
    assert seq[2].pose is None and seq[1].pose is not None


# -- image folder ----------------------------------------------------------------------------------------
def test_image_folder(tmp_path: Path) -> None:
    root = tmp_path / "seq"
    (root / "images").mkdir(parents=True)
    for i in (0, 1, 2, 10):  # natural order: 10 after 2
        cv2.imwrite(str(root / "images" / f"{i}.jpg"), _image(i))
    poses = _poses(4)
    write_tum(root / "groundtruth.txt", Trajectory(np.arange(4.0), poses))
    assert detect_format(root) == "image-folder"
    seq = open_sequence(root)
    assert seq.camera is None and seq.has_groundtruth
    assert [p.name for p in seq.image_paths] == ["0.jpg", "1.jpg", "2.jpg", "10.jpg"]
    np.testing.assert_allclose(seq.groundtruth.poses, poses)
    seq = open_sequence(root, intrinsics="60,60,31.5,23.5")
    assert seq.camera.fx == 60.0 and seq.camera.width == W
    (root / "camera.txt").write_text("55 56 31.5 23.5\n")
    assert open_sequence(root).camera.fy == 56.0
    (root / "camera.txt").write_text("55 56 31.5\n")
    with pytest.raises(InputError, match="camera.txt: intrinsics: expected 'fx fy cx cy'"):
        open_sequence(root)


def test_image_folder_times_and_gt_mismatch(tmp_path: Path) -> None:
    root = tmp_path / "seq"
    root.mkdir()
    for i in range(3):
        cv2.imwrite(str(root / f"{i:04d}.png"), _image(i, colour=False))
    (root / "times.txt").write_text("0.0\n0.5\n")
    with pytest.raises(InputError, match="2 timestamps for 3 images"):
        open_sequence(root)
    (root / "times.txt").write_text("100.0\n100.5\n101.0\n")
    write_tum(root / "groundtruth.txt", Trajectory(np.arange(3.0), _poses(3)))
    with pytest.raises(InputError, match="no ground-truth timestamp matches"):
        open_sequence(root)


def test_corrupt_image_named(tmp_path: Path) -> None:
    root = tmp_path / "seq"
    root.mkdir()
    cv2.imwrite(str(root / "0000.png"), _image(0))
    (root / "0001.png").write_bytes(b"\x89PNG\r\n\x1a\ngarbage")
    seq = open_sequence(root)
    assert seq[0].image.shape == (H, W, 3)
    with pytest.raises(InputError, match=r"0001.png: cannot decode image"):
        seq[1]


def test_detection_errors(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="no such file or folder"):
        open_sequence(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetError, match="cannot recognise the sequence format"):
        open_sequence(tmp_path / "empty")
    with pytest.raises(InputError, match="unknown format"):
        open_sequence(tmp_path / "empty", format="bogus")


def test_slice(tmp_path: Path) -> None:
    write_kitti_layout(tmp_path / "d", n=5)
    seq = open_sequence(tmp_path / "d").slice(1, 4)
    assert len(seq) == 3 and seq[0].index == 0
    np.testing.assert_allclose(seq.timestamps, np.arange(1, 4) * 0.1036)
    with pytest.raises(DatasetError, match="start frame 7"):
        open_sequence(tmp_path / "d").slice(7)


# -- shared real data -------------------------------------------------------------------------------------
def test_shared_7scenes(shared_dir: Path) -> None:
    seq = open_sequence(shared_dir / "data" / "7scenes-0000-0699")
    assert (seq.format, len(seq), seq.width, seq.height) == ("7scenes", 700, 640, 480)
    assert seq.has_groundtruth and seq.has_depth
    frame = seq[699]
    assert frame.image.shape == (480, 640, 3) and frame.depth.shape == (480, 640)
    valid = frame.depth[frame.depth > 0]
    assert 0.3 < np.median(valid) < 5.0  # metres, indoor kitchen
    # the files' rotations are scaled by ~0.9998 (KinectFusion); the reader hands out true rotations
    np.testing.assert_allclose(frame.pose[:3, :3] @ frame.pose[:3, :3].T, np.eye(3), atol=1e-12)
    raw = np.loadtxt(shared_dir / "data" / "7scenes-0000-0699" / "frame-000699.pose.txt")
    np.testing.assert_allclose(frame.pose, raw, atol=1e-3)


def test_shared_kitti(shared_dir: Path) -> None:
    seq = open_sequence(shared_dir / "data" / "kitti-odometry")
    assert (seq.format, len(seq), seq.width, seq.height) == ("kitti", 51, 1226, 370)
    cam, box = seq.camera.crop_to_multiple(16)
    assert (cam.width, cam.height) == (1216, 368)
    gt = seq.groundtruth
    # the car drives forward along the camera's z axis: about 1.2 m per frame at the start
    assert gt.positions[1, 2] == pytest.approx(1.198998, abs=1e-6)


def test_shared_tsukuba(shared_dir: Path) -> None:
    seq = open_sequence(shared_dir / "data" / "tsukuba-150", intrinsics="615,615,320,240")
    assert (seq.format, len(seq), seq.width, seq.height) == ("image-folder", 150, 640, 480)
    assert seq.has_groundtruth and len(seq.groundtruth) == 150
    assert seq[149].image.shape == (480, 640, 3)


def test_sample_sequence_shipped(sample_dir: Path) -> None:
    seq = open_sequence(sample_dir)
    assert (seq.format, len(seq), seq.width, seq.height) == ("7scenes", 300, 640, 480)
    assert seq.has_groundtruth and not seq.has_depth
    assert seq[299].image.shape == (480, 640, 3)


def test_7scenes_pose_files_read_together_equal_each_read_alone(tmp_path: Path) -> None:
    """``read_pose_files`` (a folder's poses, checked and projected all at once) gives the bytes of
    ``read_pose_file`` on each; with a file it refuses, the first such file's error, naming it."""
    from dmtrack.datasets.sevenscenes import read_pose_file, read_pose_files

    rng = np.random.default_rng(3)
    texts = []
    for k in range(12):
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_rotvec(rng.normal(size=3)).as_matrix() * (0.9997 if k % 3 else 1.0)
        pose[:3, 3] = rng.normal(size=3)
        texts.append("\n".join(" ".join(f"{v:.7e}" for v in row) for row in pose) + "\n")
    texts[4] = texts[4].replace(texts[4].split()[0], "-inf", 1)  # KinectFusion's failed frame
    paths = []
    for k, text in enumerate(texts):
        paths.append(tmp_path / f"frame-{k:06d}.pose.txt")
        paths[-1].write_text(text)
    together = read_pose_files(paths)
    assert together.tobytes() == np.stack([read_pose_file(p) for p in paths]).tobytes()
    assert np.isnan(together[4]).all() and np.isfinite(np.delete(together, 4, axis=0)).all()
    paths[7].write_text("\n".join(texts[7].splitlines()[:3] + ["0 0 0.5 1"]) + "\n")  # not a rigid motion
    paths[9].write_text("1 2 three\n")
    with pytest.raises(InputError) as alone:
        read_pose_file(paths[7])
    with pytest.raises(InputError) as first:  # the earlier of the two bad files
        read_pose_files(paths)
    assert str(first.value) == str(alone.value) and paths[7].name in str(first.value)
    paths[7].write_text(texts[7])
    with pytest.raises(InputError, match="three") as e:
        read_pose_files(paths)
    assert paths[9].name in str(e.value)
