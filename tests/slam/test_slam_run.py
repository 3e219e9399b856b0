"""SLAM runs end to end: a synthetic loop is closed, the run is deterministic, the files and metrics are there,
and a failing back end never loses the odometry's trajectory."""

from __future__ import annotations

import hashlib
import json
import math
import threading
import warnings
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


# ------------------------------------------------------------------------------------ seeing the graph (viewer, report)
class GraphRecorder:
    """A sink that is also a graph listener: keeps every optimised graph it is told of, and the thread that told it."""

    def __init__(self) -> None:
        self.graphs: list[tuple[str, object]] = []

    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        pass

    def on_keyframe(self, *args: object) -> None:
        pass

    def on_lost(self, frame_index: int, reason: str) -> None:
        pass

    def close(self) -> None:
        pass

    def on_graph_optimised(self, graph: object) -> None:
        self.graphs.append((threading.current_thread().name, graph))


class BrokenViewer(GraphRecorder):
    def on_graph_optimised(self, graph: object) -> None:
        super().on_graph_optimised(graph)
        raise RuntimeError("viewer window closed")


@pytest.fixture(scope="module")
def viewed_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """The loop run of ``loop_runs`` again, told to a Rerun recording, a recorder and a listener that raises; then
    its report.html and its ``dmtrack view`` recording."""
    pytest.importorskip("rerun")
    from dmtrack.evaluation.alignment import umeyama
    from dmtrack.evaluation.html import write_html_report
    from dmtrack.outputs.rerun_sink import RerunSink
    from dmtrack.outputs.rerun_view import log_run_folder

    tmp = tmp_path_factory.mktemp("slam-view")
    out = tmp / "run"
    recorder, broken = GraphRecorder(), BrokenViewer()
    viewer = RerunSink(rrd=tmp / "live.rrd", image_downscale=4)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = run_to_directory(loop_sequence(), out, "gray", slam=True, depth_images=False, init="random",
                                  seed=0, extra_sinks=(broken, viewer, recorder))  # fmt: skip
    report = write_html_report(out)
    view = log_run_folder(out, rrd=tmp / "view.rrd", align=umeyama)
    return {"out": out, "result": result, "recorder": recorder, "broken": broken, "viewer": viewer,
            "warnings": [str(w.message) for w in caught], "report": report, "view": view,
            "live": tmp / "live.rrd", "view_rrd": tmp / "view.rrd"}  # fmt: skip


def _entities(rrd: Path) -> dict[str, list]:
    from rerun.chunk import RrdReader

    batches: dict[str, list] = {}
    for chunk in RrdReader(rrd).stream().to_chunks():
        batches.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return batches


def _last(batches: list, component: str) -> list:
    """The last logged value of ``component`` (by frame; static rows first)."""
    out = []
    for b in batches:
        if component in b.schema.names:
            frames = b.column("frame").to_pylist() if "frame" in b.schema.names else [None] * b.num_rows
            out += [(-1 if f is None else f, v) for f, v in zip(frames, b.column(component).to_pylist(), strict=True)
                    if v is not None]  # fmt: skip
    return sorted(out, key=lambda fv: fv[0])[-1][1]


def test_the_listener_gets_the_optimised_graph(viewed_run: dict, loop_runs: tuple[Path, object]):
    out, result, recorder = viewed_run["out"], viewed_run["result"], viewed_run["recorder"]
    graphs = recorder.graphs
    assert len(graphs) >= 2 and [g.optimisation for _, g in graphs] == list(range(1, len(graphs) + 1))
    assert {name for name, g in graphs if not g.final} == {"dmtrack-slam"}  # from the back end's thread
    name, final = graphs[-1]
    assert final.final and not any(g.final for _, g in graphs[:-1])
    keyframes = read_tum(out / "keyframes.txt")  # the optimised keyframes, as the final graph has them
    np.testing.assert_allclose(final.poses, keyframes.poses, atol=1e-6)
    np.testing.assert_allclose(final.timestamps, keyframes.timestamps, atol=1e-6)  # written with 6 decimals
    loops = [e for e in final.edges if e[2] == "loop"]
    assert len(loops) == result.metrics["loop_closures"] > 0 and final.segments("loop").shape == (len(loops), 2, 3)
    # neither the viewer nor the listeners change the run: the same bytes as the run without them
    for name in ("trajectory.txt", "keyframes.txt", "graph.json"):
        assert (out / name).read_bytes() == (loop_runs[0] / name).read_bytes(), name


def test_a_listener_that_raises_is_dropped_and_the_run_goes_on(viewed_run: dict):
    result, broken = viewed_run["result"], viewed_run["broken"]
    assert len(broken.graphs) == 1  # told once, dropped after its error
    backend = result.slam.backend
    assert backend.listener_errors == ["BrokenViewer.on_graph_optimised: RuntimeError: viewer window closed"]
    assert any("SLAM graph listener dropped" in w for w in viewed_run["warnings"])
    assert result.metrics["slam_error"] is None and result.metrics["loop_closures"] > 0
    assert len(viewed_run["recorder"].graphs) > 1  # the listeners after it are still told


def test_the_live_viewer_draws_the_optimised_graph(viewed_run: dict):
    ent = _entities(viewed_run["live"])
    _, final = viewed_run["recorder"].graphs[-1]
    assert viewed_run["viewer"].n_graph_updates == len(viewed_run["recorder"].graphs)
    kf = np.asarray(_last(ent["/world/slam/keyframes"], "Points3D:positions"), dtype=np.float64)
    np.testing.assert_allclose(kf, final.positions, atol=1e-5)
    strip = np.asarray(_last(ent["/world/slam/trajectory"], "LineStrips3D:strips")[0], dtype=np.float64)
    np.testing.assert_allclose(strip, final.positions, atol=1e-5)
    loops = _last(ent["/world/slam/edges/loop"], "LineStrips3D:strips")
    odometry = _last(ent["/world/slam/edges/odometry"], "LineStrips3D:strips")
    assert len(loops) == len(final.segments("loop")) > 0 and len(odometry) == len(final.positions) - 1
    np.testing.assert_allclose(np.asarray(loops, dtype=np.float64), final.segments("loop"), atol=1e-5)
    assert "/world/keyframes/0000" in ent and "/world/trajectory/estimate/0000" in ent  # the odometry's, as before


def test_view_of_a_slam_run_folder_draws_the_graph_and_both_trajectories(viewed_run: dict):
    out, view = viewed_run["out"], viewed_run["view"]
    graph = json.loads((out / "graph.json").read_text())
    accepted = [e for e in graph["edges"] if e["accepted"]]
    n_loops = sum(e["kind"] == "loop" for e in accepted)
    assert view["slam"] == {"keyframes": len(graph["keyframes"]), "odometry": len(accepted) - n_loops,
                            "loop": n_loops}  # fmt: skip
    assert view["groundtruth"] == "aligned"
    ent = _entities(viewed_run["view_rrd"])
    assert "/world/trajectory/estimate" not in ent
    for name, path in (("trajectory.txt", "/world/trajectory/slam"),
                       ("trajectory_vo.txt", "/world/trajectory/odometry")):  # fmt: skip
        strip = np.asarray(_last(ent[path], "LineStrips3D:strips")[0], dtype=np.float64)
        np.testing.assert_allclose(strip, read_tum(out / name).positions, atol=1e-5)
    centres = np.array([np.asarray(k["sim3"])[:3, 3] for k in graph["keyframes"]])
    np.testing.assert_allclose(np.asarray(_last(ent["/world/slam/keyframes"], "Points3D:positions")), centres,
                               atol=1e-5)  # fmt: skip
    assert len(_last(ent["/world/slam/edges/loop"], "LineStrips3D:strips")) == n_loops > 0
    kf_vo = read_tum(out / "keyframes_vo.txt")  # world/keyframes: the odometry's keyframes, as live
    np.testing.assert_allclose(np.asarray(_last(ent["/world/keyframes"], "Points3D:positions")), kf_vo.positions,
                               atol=1e-5)  # fmt: skip


def test_report_shows_odometry_against_slam(viewed_run: dict):
    from html.parser import HTMLParser

    from dmtrack.evaluation.tables import fmt_value

    out, report = viewed_run["out"], viewed_run["report"]
    m = json.loads((out / "metrics.json").read_text())
    text = report.read_text(encoding="utf-8")

    class Cells(HTMLParser):
        def __init__(self) -> None:
            super().__init__()
            self.rows: list[list[str]] = []
            self.cell: list[str] | None = None

        def handle_starttag(self, tag: str, attrs: list) -> None:
            if tag == "tr":
                self.rows.append([])
            elif tag in ("td", "th"):
                self.cell = []

        def handle_endtag(self, tag: str) -> None:
            if tag in ("td", "th") and self.cell is not None:
                self.rows[-1].append("".join(self.cell))
                self.cell = None

        def handle_data(self, data: str) -> None:
            if self.cell is not None:
                self.cell.append(data)

    doc = Cells()
    doc.feed(text)
    rows = {r[0]: r[1:] for r in doc.rows if r}
    assert rows[""] == ["odometry", "SLAM"]
    assert rows["ATE RMSE (m, Sim(3)-aligned)"] == [fmt_value(m["vo_ate_rmse"], 4), fmt_value(m["ate_rmse"], 4)]
    assert rows["RPE rotation (deg/m)"] == [fmt_value(m["vo_rpe_rot_deg_per_m"], 3),
                                            fmt_value(m["rpe_rot_deg_per_m"], 3)]  # fmt: skip
    assert rows["RPE translation angle (deg/m)"] == [fmt_value(m["vo_rpe_trans_angle_deg_per_m"], 3),
                                                     fmt_value(m["rpe_trans_angle_deg_per_m"], 3)]  # fmt: skip
    assert rows["Loop closures (accepted pairs)"] == [str(m["loop_closures"])]
    # the top view: both trajectories over the ground truth, and the loop edges
    n = m["tracked_frames"]
    for name in (f"SLAM: gray [{n}]", f"odometry [{n}]", "ground truth", f"loop edges ({m['loop_closures']})"):
        assert f'"name":"{name}"' in text, name
    assert "Odometry against SLAM" in text and "Top view (Sim(3)-aligned to the ground truth)" in text
