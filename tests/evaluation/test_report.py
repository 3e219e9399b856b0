"""The benchmark report from a hand-made bench folder (no odometry runs): tables, CSVs, figures, CLI."""

from __future__ import annotations

import argparse
import csv
import json
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.evaluation import evaluate
from dmtrack.evaluation.records import RESULT_COLUMNS, collect_runs, results_rows
from dmtrack.evaluation.report import write_report
from dmtrack.experiments.cli import add_report_parser
from dmtrack.io.trajectory import Trajectory, write_tum
from dmtrack.viz.plots import topview_basis


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def circle_gt(n: int = 40, radius: float = 2.0) -> Trajectory:
    t = np.arange(n) / 10.0
    poses = np.tile(np.eye(4), (n, 1, 1))
    for i, a in enumerate(np.linspace(0, 1.5 * np.pi, n)):
        poses[i, :3, 3] = [radius * np.cos(a), radius * np.sin(a), 0.1 * np.sin(3 * a)]
        poses[i, :3, :3] = _rot_z(a)
    return Trajectory(t, poses)


def estimate_of(gt: Trajectory, n: int, drift_deg: float, seed: int) -> Trajectory:
    """First n poses of gt with a slowly growing yaw drift, then a global Sim(3) (scale 0.5)."""
    rng = np.random.default_rng(seed)
    poses = gt.poses[:n].copy()
    for i in range(n):
        poses[i, :3, :3] = _rot_z(np.radians(drift_deg) * i) @ poses[i, :3, :3]
        poses[i, :3, 3] += rng.normal(0, 0.01, 3)
    S = np.eye(4)
    S[:3, :3] = 0.5 * _rot_z(0.3)
    S[:3, 3] = [1.0, -2.0, 0.5]
    poses = S @ poses
    poses[:, :3, :3] /= 0.5  # keep rotations orthonormal: only positions are scaled
    return Trajectory(gt.timestamps[:n], poses)


def make_run(root: Path, seq: str, feature: str, *, metrics: dict | None = None, error: dict | None = None,
             gt: Trajectory | None = None, est: Trajectory | None = None, depth_frames: tuple[int, ...] = (),
             info: dict | None = None, seed: int | None = None) -> Path:  # fmt: skip
    """A finished run in ``runs/<seq>/<feature>/`` (``seed``: in ``.../seed-<S>/``, as a multi-seed bench)."""
    d = root / "runs" / seq / feature
    if seed is not None:
        d = d / f"seed-{seed}"
    d.mkdir(parents=True)
    (d / "spec.json").write_text(json.dumps({"feature": feature, "start": 0, "max_frames": 40, "seed": seed or 0}))
    (d / "run_info.json").write_text(
        json.dumps(
            info
            or {
                "platform": "TestOS-1.0",
                "cpu": "TestCPU",
                "cpu_count": 8,
                "python": "3.11",
                "host": "h1",
                "processed_frames": 40,
            }
        )
    )
    if error is not None:
        (d / "error.json").write_text(json.dumps(error))
    if metrics is not None:
        m = {"feature": feature, "sequence": seq, "total_frames": 40, "lost_at": None, "channels": 1,
             "width": 64, "height": 48, "start": 0, "r_l": 1 / 3, "feature_ms": 1.0, "io_ms": 0.5,
             "tracking_ms": 2.0, "mapping_ms": 3.0, "wall_s": 1.0, "fps": 40.0, "seed": seed or 0,
             **metrics}  # fmt: skip
        (d / "metrics.json").write_text(json.dumps(m))
    if gt is not None:
        write_tum(d / "groundtruth.txt", gt)
    if est is not None:
        write_tum(d / "trajectory.txt", est)
        (d / "evaluation.json").write_text(json.dumps(evaluate(gt, est, r_l=1 / 3)))
    if depth_frames:
        (d / "depth").mkdir()
        img = np.zeros((48, 64, 3), np.uint8)
        for k, f in enumerate(depth_frames):
            img[:] = (40 * k, 100, 200)
            cv2.imwrite(str(d / "depth" / f"kf_{k:04d}_frame_{f:06d}.png"), img)
    return d


@pytest.fixture()
def bench(tmp_path: Path) -> Path:
    """Two 7-Scenes-like sequences × (gray, gray-affine), one KITTI sequence, one Tsukuba image folder.

    s1: gray rot 1.0 / trans 4.0 / 40 tracked; gray-affine rot 2.0 / trans 3.0 / 40 tracked;
    s2: gray crashed; gray-affine lost at frame 30 (30 tracked), rot 3.0 / trans 5.0.
    """
    root = tmp_path / "bench"
    gt = circle_gt()
    make_run(root, "s1", "gray", metrics={"tracked_frames": 40, "rpe_rot_deg_per_m": 1.0,
             "rpe_trans_angle_deg_per_m": 4.0, "ate_rmse": 0.01, "format": "7scenes",
             "rotation_gain": [0.82, None, 1.01]},
             gt=gt, est=estimate_of(gt, 40, 0.1, 0), depth_frames=(0, 12, 25))  # fmt: skip
    make_run(root, "s1", "gray-affine", metrics={"tracked_frames": 40, "rpe_rot_deg_per_m": 2.0,
             "rpe_trans_angle_deg_per_m": 3.0, "ate_rmse": 0.02, "format": "7scenes", "feature_ms": 3.0},
             gt=gt, est=estimate_of(gt, 40, 0.3, 1), depth_frames=(0, 20))  # fmt: skip
    make_run(root, "s2", "gray", error={"type": "RuntimeError", "message": "boom\nsecond line",
                                        "traceback": "Traceback ...", "tracked_frames": 7})  # fmt: skip
    make_run(root, "s2", "gray-affine", metrics={"tracked_frames": 30, "lost_at": 30, "lost_reason": "diverged",
             "rpe_rot_deg_per_m": 3.0, "rpe_trans_angle_deg_per_m": 5.0, "format": "7scenes"},
             gt=gt, est=estimate_of(gt, 30, 0.2, 2), depth_frames=(0,))  # fmt: skip
    make_run(root, "kitti-06", "gray", metrics={"tracked_frames": 40, "rpe_rot_deg_per_m": 0.5,
             "rpe_trans_angle_deg_per_m": 0.7, "format": "kitti"})  # fmt: skip
    make_run(root, "tsukuba-150", "gray", metrics={"tracked_frames": 40, "rpe_rot_deg_per_m": 0.05,
             "rpe_trans_angle_deg_per_m": 0.07, "format": "image-folder"})  # fmt: skip
    # an unfinished run (killed bench): no metrics.json, no error.json — must be ignored
    partial = root / "runs" / "s2" / "bitplanes"
    partial.mkdir(parents=True)
    (partial / "trajectory.txt").write_text("# nothing\n")
    (root / "runs" / "s2" / ".gray.tmp-host-1-abcd").mkdir()
    bench_json = {"features": ["gray", "gray-affine", "bitplanes"],
                  "sequences": [{"name": "s1", "dataset": "7-Scenes"}, {"name": "s2", "dataset": "7-Scenes"}],
                  "runs": ["s1/gray", "s1/gray-affine", "s2/gray", "s2/gray-affine", "s2/bitplanes"],
                  "options": {"jobs": 2, "threads_per_job": 1}}  # fmt: skip
    (root / "bench.json").write_text(json.dumps(bench_json))
    return root


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_collect_runs_finished_only_in_bench_order(bench: Path):
    recs = collect_runs(bench)
    assert [(r.sequence, r.feature, r.status) for r in recs] == [
        ("s1", "gray", "ok"), ("s1", "gray-affine", "ok"), ("s2", "gray", "failed"), ("s2", "gray-affine", "lost"),
        ("kitti-06", "gray", "ok"), ("tsukuba-150", "gray", "ok"),
    ]  # fmt: skip
    by = {(r.sequence, r.feature): r for r in recs}
    assert by[("s1", "gray")].dataset == "7-Scenes"  # from bench.json
    assert by[("kitti-06", "gray")].dataset == "KITTI"  # from the format
    assert by[("tsukuba-150", "gray")].dataset == "Tsukuba" and by[("tsukuba-150", "gray")].unit == "cm"
    rows = results_rows(recs)
    assert set(rows[0]) == set(RESULT_COLUMNS)
    failed = rows[2]
    assert failed["tracked_frames"] is None and failed["error"] == "RuntimeError: boom\nsecond line"
    assert rows[0]["total_ms"] == pytest.approx(6.5) and rows[0]["tracked_fraction"] == 1.0
    assert (rows[0]["rotation_gain_x"], rows[0]["rotation_gain_y"], rows[0]["rotation_gain_z"]) == (0.82, None, 1.01)
    assert rows[1]["rotation_gain_x"] is None and failed["rotation_gain_z"] is None  # not in its metrics / failed


def test_report_tables_and_csvs(bench: Path):
    out = write_report(bench, figures=False)
    assert out == bench / "report.md"
    md = out.read_text()
    # 7-Scenes rankings (hand computed):
    # tracked: s1 tie 40/40 → both win; s2 gray crashed → gray-affine wins, gray rank 2 → gray 1 win, avg 1.5
    # rotation: s1 gray 1.0 < 2.0; s2 only gray-affine → 1 win each, avg 1.5 each
    # trans. angle: s1 gray-affine 3.0 < 4.0; s2 gray-affine → gray-affine 2 wins avg 1.0, gray 0 wins avg 2.0
    assert "| gray | 1 | 1.50 | 1 | 1.50 | 0 | 2.00 |" in md
    assert "| gray-affine | 2 | 1.00 | 1 | 1.50 | 2 | 1.00 |" in md
    assert "## 7-Scenes" in md and "## KITTI" in md and "## Tsukuba" in md
    # pooled over the 4 sequences (gray-affine has no run on kitti-06 and tsukuba-150: it ranks last there)
    pooled = md.split("## All datasets")[1].split("## 7-Scenes")[0]
    assert "| gray | 3 | 1.25 | 3 | 1.25 | 2 | 1.50 |" in pooled
    assert "| gray-affine | 2 | 1.50 | 1 | 1.75 | 2 | 1.50 |" in pooled
    assert "errors in deg/cm" in md  # Tsukuba as an image folder: centimetres
    assert "TestOS-1.0" in md and "8 logical CPUs" in md and "dmtrack 0.1" in md
    assert "s2 / gray: **failed** — RuntimeError: boom (after 7 tracked frames)" in md
    assert "tracking lost at frame 30 (diverged)" in md
    assert "1 run(s) of the grid have not finished" in md and "s2/bitplanes" in md
    assert "![" not in md

    rows = read_csv(bench / "results.csv")
    assert len(rows) == 6 and rows[2]["status"] == "failed" and rows[2]["tracked_frames"] == ""
    ranks = read_csv(bench / "tables" / "rankings.csv")
    g = next(r for r in ranks if r["dataset"] == "7-Scenes" and r["feature"] == "gray")
    assert g["tracked_frames_wins"] == "1" and float(g["tracked_frames_average_rank"]) == 1.5
    averages = read_csv(bench / "tables" / "averages.csv")
    ga = next(r for r in averages if r["dataset"] == "7-Scenes" and r["feature"] == "gray-affine")
    assert float(ga["tracked_fraction"]) == pytest.approx((1.0 + 0.75) / 2)
    assert float(ga["rpe_rot"]) == pytest.approx(2.5) and ga["n_common"] == "1"  # only s1 is common
    assert float(ga["common_rpe_rot"]) == pytest.approx(2.0)
    timings = read_csv(bench / "tables" / "timings.csv")
    gat = next(r for r in timings if r["dataset"] == "7-Scenes" and r["feature"] == "gray-affine")
    # s1: feature 3.0 ms × 40 frames, s2: 1.0 ms × 40 (processed_frames) → 2.0; total 2 + .5 + 2 + 3
    assert float(gat["feature_ms"]) == pytest.approx(2.0) and float(gat["total_ms"]) == pytest.approx(7.5)
    per_seq = read_csv(bench / "tables" / "ranks_per_sequence.csv")
    s2g = next(r for r in per_seq if r["sequence"] == "s2" and r["feature"] == "gray")
    assert s2g["tracked_frames_rank"] == "2" and s2g["rpe_rot_deg_per_m_rank"] == "2"


def test_report_figures_exist_and_are_linked(bench: Path):
    md = write_report(bench).read_text()
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert links, md
    for link in links:
        assert not Path(link).is_absolute()
        p = bench / link
        assert p.is_file() and p.stat().st_size > 1000 and p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    names = {Path(x).name for x in links}
    assert {"rpe_s1.png", "rpe_s2.png", "trajectory_s1.png", "depth_s1.png", "accuracy_vs_time_7-Scenes.png"} <= names
    assert "Problems while writing" not in md


def test_report_rebuilds_from_what_is_there(bench: Path):
    write_report(bench, figures=False)
    assert len(read_csv(bench / "results.csv")) == 6
    shutil.rmtree(bench / "runs" / "s2")
    (bench / "figures").mkdir()
    (bench / "figures" / "rpe_gone.png").write_bytes(b"stale")  # a figure of a sequence no longer there
    (bench / "figures" / "my-notes.png").write_bytes(b"mine")  # not the report's: kept
    md = write_report(bench).read_text()
    assert len(read_csv(bench / "results.csv")) == 4
    assert not (bench / "figures" / "rpe_gone.png").exists() and (bench / "figures" / "my-notes.png").exists()
    assert (bench / "figures" / "rpe_s1.png").is_file() and "rpe_s2" not in md
    assert "| gray | 1 | 1.00 | 1 | 1.00 | 0 | 2.00 |" in md  # s1 alone


def test_report_cli(bench: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    parser = argparse.ArgumentParser(prog="dmtrack")
    add_report_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["report", str(bench), "--no-figures"])
    assert args.func(args) == 0
    assert "report:" in capsys.readouterr().out and (bench / "report.md").is_file()
    args = parser.parse_args(["report", str(tmp_path / "nothing")])
    with pytest.raises(InputError, match="not a bench folder"):
        args.func(args)


def test_topview_basis_spans_the_plane_of_motion():
    rng = np.random.default_rng(3)
    u, v = np.array([1.0, 1.0, 0.0]) / np.sqrt(2), np.array([0.0, 0.0, 1.0])
    pts = rng.normal(size=(50, 1)) * 3 * u + rng.normal(size=(50, 1)) * v + 0.001 * rng.normal(size=(50, 3))
    B = topview_basis(pts)
    assert np.allclose(B @ B.T, np.eye(2), atol=1e-9)
    normal = np.cross(u, v)
    assert np.all(np.abs(B @ normal) < 1e-2)  # both axes lie in the plane


# ------------------------------------------------------------------------------------------- several seeds
SEEDED_KEYS = [f"s1/{f}/seed-{s}" for f in ("gray", "gray-affine", "rgb") for s in (0, 1, 2)]


@pytest.fixture()
def seeded(tmp_path: Path) -> Path:
    """One 7-Scenes-like sequence × (gray, gray-affine, rgb) × seeds 0, 1, 2.

    gray: rot 10.0 / 1.0 / 1.2 (median 1.2, mean 4.07: ranking on the mean or on seed 0 would lose),
          trans 4 / 5 / 6, all 40 tracked;
    gray-affine: rot 2.0 / 2.0 / –, trans 3.0 / 3.1 / –; seed 1 lost at 25, seed 2 crashed;
    rgb: rot 3.0, trans 7.0 each; seed 1 lost at 12 (12 tracked).
    """
    root = tmp_path / "seeded"
    gt = circle_gt()
    for s, (rot, trans, ate) in enumerate([(10.0, 4.0, 0.03), (1.0, 5.0, 0.01), (1.2, 6.0, 0.02)]):
        make_run(root, "s1", "gray", seed=s, metrics={"tracked_frames": 40, "rpe_rot_deg_per_m": rot,
                 "rpe_trans_angle_deg_per_m": trans, "ate_rmse": ate, "format": "7scenes", "fps": 30.0 + s},
                 gt=gt, est=estimate_of(gt, 40, 0.1 * (s + 1), s), depth_frames=(0, 12 + s))  # fmt: skip
    make_run(root, "s1", "gray-affine", seed=0, metrics={"tracked_frames": 40, "rpe_rot_deg_per_m": 2.0,
             "rpe_trans_angle_deg_per_m": 3.0, "format": "7scenes"},
             gt=gt, est=estimate_of(gt, 40, 0.2, 0))  # fmt: skip
    make_run(root, "s1", "gray-affine", seed=1, metrics={"tracked_frames": 25, "lost_at": 25, "lost_reason": "diverged",
             "rpe_rot_deg_per_m": 2.0, "rpe_trans_angle_deg_per_m": 3.1, "format": "7scenes"},
             gt=gt, est=estimate_of(gt, 25, 0.2, 1))  # fmt: skip
    make_run(root, "s1", "gray-affine", seed=2, error={"type": "RuntimeError", "message": "boom", "tracked_frames": 3})
    for s in range(3):
        lost = {"tracked_frames": 12, "lost_at": 12} if s == 1 else {"tracked_frames": 40}
        make_run(root, "s1", "rgb", seed=s, metrics={**lost, "rpe_rot_deg_per_m": 3.0, "rpe_trans_angle_deg_per_m": 7.0,
                 "format": "7scenes"})  # fmt: skip
    bench_json = {"features": ["gray", "gray-affine", "rgb"], "sequences": [{"name": "s1", "dataset": "7-Scenes"}],
                  "runs": SEEDED_KEYS, "options": {"jobs": 2, "seeds": [0, 1, 2]}}  # fmt: skip
    (root / "bench.json").write_text(json.dumps(bench_json))
    return root


def test_seeded_runs_are_collected_with_their_seed(seeded: Path):
    recs = collect_runs(seeded)
    assert [r.key for r in recs] == SEEDED_KEYS
    assert [(r.feature, r.seed) for r in recs][:4] == [("gray", 0), ("gray", 1), ("gray", 2), ("gray-affine", 0)]
    rows = read_csv_rows(seeded)
    assert [r["seed"] for r in rows] == ["0", "1", "2"] * 3
    assert rows[5]["status"] == "failed" and rows[5]["seed"] == "2"  # the seed of a crashed run, from its spec


def read_csv_rows(root: Path) -> list[dict[str, str]]:
    write_report(root, figures=False)
    return read_csv(root / "results.csv")


def test_seeded_tables_show_median_range_and_worst_seed(seeded: Path):
    md = write_report(seeded, figures=False).read_text()
    assert "3 seeds of the random depth initialisation (0-2)" in md and "median over seeds 0-2" in md
    # rankings on the per-cell medians (hand computed): tracked 40 / 32.5 / 40, rot 1.2 / 2.0 / 3.0,
    # trans 5.0 / 3.05 / 7.0
    assert "| gray | 1 | 1.00 | 1 | 1.00 | 0 | 2.00 |" in md
    assert "| gray-affine | 0 | 3.00 | 0 | 2.00 | 1 | 1.00 |" in md
    assert "| rgb | 1 | 1.00 | 0 | 3.00 | 0 | 3.00 |" in md
    assert ("| s1 | gray | 0-2 | ok (3 of 3) | 40/40 (40–40) | 1 | 1.200 (1.000–10.000) | 1 | 5.000 (4.000–6.000) | 2 "
            "| 0.0200 (0.0100–0.0300) |") in md  # fmt: skip
    assert ("| s1 | gray-affine | 0-2 | 1 ok, 1 lost, 1 failed; worst: seed 2 failed | 32.5/40 (25–40) [2 of 3] | 3 "
            "| 2.000 (2.000–2.000) [2 of 3] | 2 | 3.050 (3.000–3.100) [2 of 3] | 1 |") in md  # fmt: skip
    assert "| s1 | rgb | 0-2 | 2 ok, 1 lost; worst: seed 1 lost @12, 12/40 tracked | 40/40 (12–40) | 1 |" in md
    assert "s1 / gray-affine / seed 2: **failed** — RuntimeError: boom" in md
    assert "traceback in `runs/s1/gray-affine/seed-2/error.json`" in md
    assert "have not finished" not in md and "Warning" not in md

    cells = {r["feature"]: r for r in read_csv(seeded / "tables" / "cells.csv")}
    ga = cells["gray-affine"]
    assert (ga["seeds"], ga["runs"], ga["n_ok"], ga["n_lost"], ga["n_failed"]) == ("0-2", "3", "1", "1", "1")
    assert (ga["worst_seed"], ga["worst_status"]) == ("2", "failed")
    assert (float(ga["tracked_frames_median"]), ga["tracked_frames_min"], ga["tracked_frames_max"],
            ga["tracked_frames_n"]) == (32.5, "25", "40", "2")  # fmt: skip
    g = cells["gray"]
    assert (float(g["rpe_rot_deg_per_m_median"]), float(g["rpe_rot_deg_per_m_min"]),
            float(g["rpe_rot_deg_per_m_max"])) == (1.2, 1.0, 10.0)  # fmt: skip
    assert (float(g["fps_median"]), float(g["fps_min"]), float(g["fps_max"])) == (31.0, 30.0, 32.0)
    rgb = cells["rgb"]
    assert (rgb["worst_seed"], rgb["worst_status"], rgb["worst_tracked_frames"], rgb["worst_lost_at"]) == (
        "1", "lost", "12", "12")  # fmt: skip
    averages = {r["feature"]: r for r in read_csv(seeded / "tables" / "averages.csv")}
    assert float(averages["gray"]["rpe_rot"]) == pytest.approx(1.2) and averages["gray"]["seeds"] == "0-2"
    assert float(averages["gray-affine"]["tracked_fraction"]) == pytest.approx((1.0 + 25 / 40) / 2)
    ranks = {r["feature"]: r for r in read_csv(seeded / "tables" / "rankings.csv")}
    assert ranks["gray"]["rpe_rot_deg_per_m_wins"] == "1" and ranks["gray"]["seeds"] == "0-2"


def test_seeded_figures_plot_medians_with_ranges(seeded: Path, monkeypatch: pytest.MonkeyPatch):
    from dmtrack.evaluation.report import representatives, rpe_curves
    from dmtrack.viz import plots

    recs = collect_runs(seeded)
    assert [(r.feature, r.seed) for r in representatives(recs)] == [("gray", 2), ("gray-affine", 0), ("rgb", 1)]
    curves = {c.label.split()[0]: c for c in rpe_curves(recs)}
    assert curves["gray"].label == "gray [40; 40–40] · 3 seeds"
    per_seed = np.array([json.loads((seeded / "runs" / "s1" / "gray" / f"seed-{s}" / "evaluation.json").read_text())
                         ["rpe_rot_per_length"] for s in range(3)], dtype=float)  # fmt: skip
    assert np.allclose(curves["gray"].rot, np.median(per_seed, axis=0))
    assert np.allclose(curves["gray"].rot_lo, per_seed.min(axis=0))
    assert np.allclose(curves["gray"].rot_hi, per_seed.max(axis=0))

    points = []
    real = plots.save_accuracy_vs_time
    monkeypatch.setattr(plots, "save_accuracy_vs_time", lambda path, pts, *a: points.extend(pts) or real(path, pts, *a))
    md = write_report(seeded).read_text()
    gray = next(p for p in points if p.label == "gray")
    assert gray.rot == pytest.approx(1.2) and gray.rot_range == pytest.approx((1.0, 10.0))
    assert gray.trans_range == pytest.approx((4.0, 6.0)) and gray.ms_range is not None
    for name in ("rpe_s1.png", "trajectory_s1.png", "depth_s1.png", "accuracy_vs_time_7-Scenes.png"):
        p = seeded / "figures" / name
        assert p.is_file() and p.stat().st_size > 1000 and f"(figures/{name})" in md
    assert "Problems while writing" not in md
    assert "per feature the run of the seed with the median RPE rotation error" in md


def test_a_folder_benched_with_one_seed_and_with_several(seeded: Path):
    """A feature folder holding a single-seed run and seed-<S>/ runs: the report uses the last grid's runs."""
    gt = circle_gt()
    d = seeded / "runs" / "s1" / "gray"
    single = make_run(seeded / "single", "s1", "gray", metrics={"tracked_frames": 40, "rpe_rot_deg_per_m": 99.0,
                      "rpe_trans_angle_deg_per_m": 9.0, "format": "7scenes"},
                      gt=gt, est=estimate_of(gt, 40, 0.1, 0))  # fmt: skip
    for f in single.iterdir():
        shutil.move(str(f), d / f.name)
    assert [r.key for r in collect_runs(seeded)] == SEEDED_KEYS  # the grid of bench.json: the seeds
    bench = json.loads((seeded / "bench.json").read_text())
    bench["runs"] = ["s1/gray"]
    (seeded / "bench.json").write_text(json.dumps(bench))
    recs = collect_runs(seeded)
    assert [r.key for r in recs if r.feature == "gray"] == ["s1/gray"]
    assert recs[0].metrics["rpe_rot_deg_per_m"] == 99.0


def test_one_seed_per_cell_keeps_the_single_seed_tables(bench: Path):
    md = write_report(bench, figures=False).read_text()
    assert "Several seeds" not in md and "| Seeds |" not in md and "(n = number of runs with a value)" in md
    assert "| s1 | gray | ok | 40/40 | 1 | 1.000 | 1 | 4.000 | 2 | 0.0100 |" in md  # no ranges for one run
    cells = read_csv(bench / "tables" / "cells.csv")
    assert len(cells) == 6 and all(c["runs"] == "1" for c in cells)
