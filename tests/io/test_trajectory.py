"""Trajectory IO: TUM and KITTI round trips, leniency (whitespace, comments, NaN rows) and strictness (junk)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmtrack.errors import InputError
from dmtrack.io.trajectory import (
    Trajectory,
    format_tum,
    read_kitti,
    read_times,
    read_trajectory,
    read_tum,
    write_kitti,
    write_tum,
)


def random_trajectory(n: int = 20, seed: int = 0) -> Trajectory:
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    poses[:, :3, 3] = rng.normal(size=(n, 3))
    return Trajectory(np.arange(n) * 0.1 + 1305031102.0, poses)


def test_tum_round_trip(tmp_path: Path) -> None:
    traj = random_trajectory()
    write_tum(tmp_path / "t.txt", traj, header="timestamp tx ty tz qx qy qz qw")
    back = read_tum(tmp_path / "t.txt")
    assert len(back) == len(traj)
    np.testing.assert_allclose(back.timestamps, traj.timestamps, atol=1e-6)
    np.testing.assert_allclose(back.poses, traj.poses, atol=1e-8)


def test_kitti_round_trip(tmp_path: Path) -> None:
    traj = random_trajectory()
    write_kitti(tmp_path / "k.txt", traj)
    back = read_kitti(tmp_path / "k.txt")
    np.testing.assert_allclose(back.poses, traj.poses, atol=1e-8)
    np.testing.assert_array_equal(back.timestamps, np.arange(len(traj)))
    with_times = read_kitti(tmp_path / "k.txt", timestamps=traj.timestamps)
    np.testing.assert_array_equal(with_times.timestamps, traj.timestamps)


def test_tum_quaternion_order_is_xyzw(tmp_path: Path) -> None:
    q = Rotation.from_euler("z", 90, degrees=True).as_quat()  # scipy: x y z w
    (tmp_path / "t.txt").write_text(f"0 1 2 3 {q[0]} {q[1]} {q[2]} {q[3]}\n")
    traj = read_tum(tmp_path / "t.txt")
    np.testing.assert_allclose(traj.rotations[0], Rotation.from_quat(q).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(traj.positions[0], [1, 2, 3])


def test_lenient_whitespace_comments_and_unnormalised_quaternions(tmp_path: Path) -> None:
    text = (
        "# ground truth trajectory\n"
        "\n"
        "1.0\t0 0 0   0 0 0 2   # trailing comment\n"
        "  2.0,1,0,0,0,0,0,1\n"
        "3.0 2 0 0 0 0 0 1\r\n"
    )
    (tmp_path / "t.txt").write_text(text)
    traj = read_tum(tmp_path / "t.txt")
    assert len(traj) == 3
    np.testing.assert_allclose(traj.rotations[0], np.eye(3))
    assert traj.path_length() == pytest.approx(2.0)


def test_nan_rows_skipped_with_warning(tmp_path: Path) -> None:
    (tmp_path / "t.txt").write_text("0 0 0 0 0 0 0 1\n1 NaN NaN NaN NaN NaN NaN NaN\n2 1 0 0 0 0 0 1\n")
    with pytest.warns(UserWarning, match=r"skipped 1 line\(s\) with NaN.*line 2"):
        traj = read_tum(tmp_path / "t.txt")
    np.testing.assert_array_equal(traj.timestamps, [0, 2])


def test_kitti_nan_rows_keep_their_timestamps(tmp_path: Path) -> None:
    eye = " ".join(f"{v:g}" for v in np.eye(4)[:3].reshape(-1))
    (tmp_path / "k.txt").write_text(f"{eye}\n" + " ".join(["nan"] * 12) + f"\n{eye}\n")
    with pytest.warns(UserWarning):
        traj = read_kitti(tmp_path / "k.txt", timestamps=np.array([0.0, 0.1, 0.2]))
    np.testing.assert_allclose(traj.timestamps, [0.0, 0.2])


@pytest.mark.parametrize(
    ("text", "line", "match"),
    [
        ("0 0 0 0 0 0 0 1\n1 0 0 zero 0 0 0 1\n", 2, "cannot read 'zero'"),
        ("0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n", 2, "expected 8 numbers per line, found 7"),
        ("0 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 0\n", 2, "zero quaternion"),
        ("0 0 0 0 0 0 0 1\n0 1 0 0 0 0 0 1\n", 2, "duplicate timestamp"),
        ("0 0 0 0 0 0 0 1\n1 inf 0 0 0 0 0 1\n", 2, "infinite"),
        ("<html>not a trajectory</html>\n", 1, "cannot read"),
    ],
)
def test_junk_names_file_and_line(tmp_path: Path, text: str, line: int, match: str) -> None:
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(InputError, match=match) as err:
        read_tum(path)
    assert err.value.path == path
    assert err.value.line == line
    assert f"bad.txt:{line}:" in str(err.value)


def test_kitti_junk(tmp_path: Path) -> None:
    path = tmp_path / "k.txt"
    path.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(InputError, match="expected 12 numbers") as err:
        read_kitti(path)
    assert err.value.line == 2
    path.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n")
    with pytest.raises(InputError, match="not a rotation") as err:
        read_kitti(path)
    assert err.value.line == 2
    path.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0\n")
    with pytest.raises(InputError, match="2 poses but 3 timestamps"):
        read_kitti(path, timestamps=np.zeros(3))


def test_missing_empty_and_binary_files(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not found"):
        read_tum(tmp_path / "nope.txt")
    (tmp_path / "empty.txt").write_text("# only a comment\n")
    with pytest.raises(InputError, match="no poses"):
        read_tum(tmp_path / "empty.txt")
    (tmp_path / "bin.txt").write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe")
    with pytest.raises(InputError, match="not a text file"):
        read_tum(tmp_path / "bin.txt")


def test_unsorted_timestamps_are_sorted(tmp_path: Path) -> None:
    (tmp_path / "t.txt").write_text("2 2 0 0 0 0 0 1\n0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n")
    with pytest.warns(UserWarning, match="not in increasing order"):
        traj = read_tum(tmp_path / "t.txt")
    np.testing.assert_array_equal(traj.timestamps, [0, 1, 2])
    np.testing.assert_array_equal(traj.positions[:, 0], [0, 1, 2])


def test_read_trajectory_guesses_format(tmp_path: Path) -> None:
    traj = random_trajectory(5)
    write_tum(tmp_path / "a.txt", traj)
    write_kitti(tmp_path / "b.txt", traj)
    assert len(read_trajectory(tmp_path / "a.txt")) == 5
    np.testing.assert_allclose(read_trajectory(tmp_path / "b.txt").poses, traj.poses, atol=1e-8)


def test_write_is_deterministic_and_atomic(tmp_path: Path) -> None:
    traj = random_trajectory()
    assert format_tum(traj) == format_tum(random_trajectory())
    write_tum(tmp_path / "t.txt", traj)
    assert not list(tmp_path.glob(".*tmp"))  # no temporary file left behind


def test_read_times(tmp_path: Path) -> None:
    (tmp_path / "times.txt").write_text("0.000000e+00\n1.036703e-01\n")
    np.testing.assert_allclose(read_times(tmp_path / "times.txt"), [0.0, 0.1036703])
    (tmp_path / "bad.txt").write_text("0.0\nabc\n")
    with pytest.raises(InputError, match="bad.txt:2"):
        read_times(tmp_path / "bad.txt")


def test_interpolate_and_distances() -> None:
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[:, 0, 3] = [0.0, 1.0, 3.0]
    poses[2, :3, :3] = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    traj = Trajectory(np.array([0.0, 1.0, 2.0]), poses)
    np.testing.assert_allclose(traj.distances(), [0, 1, 3])
    out = traj.interpolate(np.array([0.5, 1.5, 1.0, 2.5, -1.0]), max_gap=1.5)
    np.testing.assert_allclose(out[0, 0, 3], 0.5)
    np.testing.assert_allclose(out[1, 0, 3], 2.0)
    angle = Rotation.from_matrix(out[1, :3, :3]).magnitude()
    assert angle == pytest.approx(np.pi / 4)
    np.testing.assert_allclose(out[2], poses[1])
    assert np.isnan(out[3]).all() and np.isnan(out[4]).all()
    assert np.isnan(traj.interpolate(np.array([0.5]), max_gap=0.5)).all()  # neighbours too far apart


def test_shared_trajectories_parse(shared_dir: Path) -> None:
    tdir = shared_dir / "data" / "trajectories"
    gt = read_tum(tdir / "freiburg1_xyz-groundtruth.txt")
    est = read_tum(tdir / "freiburg1_xyz-rgbdslam.txt")
    kitti = read_kitti(tdir / "KITTI_00_gt.txt")
    assert len(kitti) == 4541
    assert len(gt) == 3000 and len(est) > 700
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # these clean files must give no warning
        read_kitti(tdir / "KITTI_00_ORB.txt")
