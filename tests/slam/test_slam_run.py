"""SLAM runs end to end: a synthetic loop is closed, the run is deterministic, the files and metrics are there,
and a failing back end never loses the odometry's trajectory."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("gtsam", reason="gtsam is not installed (pip install 'dmtrack[slam]')")

from dmtrack.datasets.synthetic.sequence import SyntheticConfig, SyntheticSequence  # noqa: E402
from dmtrack.geometry.lie import SO3  # noqa: E402
from dmtrack.io.trajectory import read_tum  # noqa: E402
from dmtrack.pipeline import run_to_directory, track  # noqa: E402

LOOP = 150  # frames per turn
EXTRA = 30  # frames past the start again, so that the camera sees its first keyframes once more


def loop_sequence() -> SyntheticSequence:
    """The renderer's room seen from a camera that goes round a closed loop (radius 0.35 m) and comes back to where
    it started, turning ±15° as it goes (the renderer's own path never returns)."""
    n = LOOP + EXTRA
    seq = SyntheticSequence(SyntheticConfig(width=320, height=240, n_frames=n, seed=5, texel=0.02))
    start = seq._all_poses[0]
    a = 2 * np.pi * np.arange(n) / LOOP
    poses = np.tile(np.eye(4), (n, 1, 1))
    for k in range(n):
        offset = 0.35 * np.array([math.sin(a[k]), 0.1 * math.sin(2 * a[k]), 1 - math.cos(a[k])])
        poses[k, :3, :3] = start[:3, :3] @ SO3.exp([0.0, math.radians(15) * math.sin(a[k]), 0.0]).matrix()
        poses[k, :3, 3] = start[:3, 3] + start[:3, :3] @ offset
    seq._all_poses = poses
    return seq


def _end_to_start(poses: np.ndarray) -> tuple[float, float]:
    """Rotation (°) and distance between the first pose and the pose one turn later (the same true pose), the
    distance per unit of the estimated path length over the turn."""
    rel = np.linalg.inv(poses[0]) @ poses[LOOP]
    path = float(np.linalg.norm(np.diff(poses[: LOOP + 1, :3, 3], axis=0), axis=1).sum())
    rot = float(np.degrees(SO3.from_matrix(rel[:3, :3], orthonormalize=True).angle()))
    return rot, float(np.linalg.norm(rel[:3, 3])) / path


@pytest.fixture(scope="module")
def loop_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    # the random start gives the odometry a drift worth closing (3.3° and 6.7 % of the turn; the geometric start
    # leaves only 0.05° and 0.2 % on this clean synthetic loop)
    out = tmp_path_factory.mktemp("slam") / "run"
    slam = run_to_directory(loop_sequence(), out, "gray", slam=True, depth_images=False, init="random", seed=0)
    return out, slam


def test_the_loop_is_closed(loop_runs: tuple[Path, object]):
    out, slam = loop_runs
    m = slam.metrics
    assert m["slam"] and m["slam_error"] is None and m["loop_closures"] > 0
    vo = read_tum(out / "trajectory_vo.txt").poses
    optimised = read_tum(out / "trajectory.txt").poses
    rot_vo, dist_vo = _end_to_start(vo)
    rot_slam, dist_slam = _end_to_start(optimised)
    assert rot_vo > 1 and dist_vo > 0.03  # the odometry has drifted …
    assert dist_slam < dist_vo / 5 and rot_slam < rot_vo / 5, (rot_vo, dist_vo, rot_slam, dist_slam)  # … SLAM not
    assert m["ate_rmse"] < m["vo_ate_rmse"]


def test_the_run_folder_has_the_slam_files(loop_runs: tuple[Path, object]):
    out, slam = loop_runs
    for name in ("trajectory.txt", "trajectory_vo.txt", "keyframes.txt", "keyframes_vo.txt", "pointcloud.ply",
                 "pointcloud_vo.ply", "graph.json", "metrics.json"):
        assert (out / name).is_file(), name
    graph = json.loads((out / "graph.json").read_text())
    assert len(graph["keyframes"]) == slam.metrics["keyframes"]
    kinds = {e["kind"] for e in graph["edges"] if e["accepted"]}
    assert kinds == {"odometry", "loop"}
    metrics = json.loads((out / "metrics.json").read_text())
    for key in ("loop_closures", "graph_edges", "optimisation_ms", "vo_ate_rmse"):
        assert key in metrics


def test_same_input_same_bytes(loop_runs: tuple[Path, object], tmp_path: Path):
    out, _ = loop_runs
    again = tmp_path / "again"
    run_to_directory(loop_sequence(), again, "gray", slam=True, depth_images=False, pointcloud=False, init="random",
                     seed=0)
    for name in ("trajectory.txt", "keyframes.txt", "graph.json"):
        digest = [hashlib.sha256((d / name).read_bytes()).hexdigest() for d in (out, again)]
        assert digest[0] == digest[1], name


def test_a_failing_back_end_keeps_the_odometry(monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    from dmtrack.slam import backend

    def broken(self, *args):  # noqa: ANN001, ANN202
        raise RuntimeError("optimiser exploded")

    monkeypatch.setattr(backend.SlamBackend, "on_keyframe", broken)
    seq = SyntheticSequence(SyntheticConfig(width=160, height=128, n_frames=30, seed=1))
    res = run_to_directory(seq, tmp_path, "gray", slam=True, depth_images=False, init="random")
    assert res.metrics["slam_error"] == "RuntimeError: optimiser exploded"
    assert (tmp_path / "trajectory.txt").read_bytes() == (tmp_path / "trajectory_vo.txt").read_bytes()
    plain = track(seq, "gray", init="random")
    assert np.array_equal(res.trajectory.poses, plain.trajectory.poses)


def test_without_gtsam_the_cli_says_which_extra_in_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
):
    from dmtrack.cli import main

    monkeypatch.setitem(__import__("sys").modules, "gtsam", None)  # import gtsam raises ImportError
    rc = main(["run", "synthetic:n_frames=5,width=160,height=128", "--slam", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1
    assert err == ["dmtrack: error: SLAM needs gtsam, which is not installed: pip install 'dmtrack[slam]'"]
    assert not (tmp_path / "o" / "trajectory_vo.txt").exists()  # refused before the first frame
