"""The bench (:func:`~dmtrack.experiments.bench.run_bench`): parallel runs, files, resuming, crashes, CLI.

One real bench (synthetic sequence × gray, gray-affine, plus a sequence that does not exist) runs once per
module in 2 spawned worker processes; the other tests work on copies of its folder (``bench_copy``).  The
first odometry run in a fresh process loads (or compiles) the numba kernels, so these tests keep process
starts few.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.experiments.bench import run_bench
from dmtrack.experiments.cli import add_bench_parser, add_report_parser
from dmtrack.experiments.grid import plan_grid
from dmtrack.experiments.store import run_state
from dmtrack.features.base import register, unregister
from dmtrack.features.gray import GrayFeature
from dmtrack.io.trajectory import read_tum

SYN = "synthetic:n_frames=25,width=320,height=240,seed=1,texel=0.02"
MISSING = "/nonexistent/dmtrack-test-sequence"
FEATURES = ["gray", "gray-affine"]
N = 12
OK_KEYS = ["synthetic-seed1/gray", "synthetic-seed1/gray-affine"]
FAILED_KEYS = ["dmtrack-test-sequence/gray", "dmtrack-test-sequence/gray-affine"]


@pytest.fixture(scope="module")
def grid(tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("bench") / "out"
    result = run_bench([SYN, MISSING], FEATURES, out, jobs=2, max_frames=N, progress=False)
    return out, result


# ------------------------------------------------------------------------------------------------ a grid
def test_grid_runs_every_pair_and_records_the_crashes(grid):
    out, res = grid
    assert sorted(res.executed) == sorted(OK_KEYS + FAILED_KEYS) and res.skipped == []
    assert sorted(res.failed) == sorted(FAILED_KEYS)
    for key in OK_KEYS:
        o = res.outcomes[key]
        assert o["status"] in ("ok", "lost") and o["total_frames"] == N
        d = out / "runs" / key
        for name in ("spec.json", "metrics.json", "trajectory.txt", "keyframes.txt", "pointcloud.ply", "config.yaml",
                     "evaluation.json", "groundtruth.txt", "run_info.json"):  # fmt: skip
            assert (d / name).is_file(), name
        assert not (d / "error.json").exists()
        assert list((d / "depth").glob("kf_*.png"))
        m = json.loads((d / "metrics.json").read_text())
        assert m["feature"] == key.split("/")[1] and m["total_frames"] == N and m["tracked_frames"] >= 2
        info = json.loads((d / "run_info.json").read_text())
        assert info["threads"] == 1 and info["status"] == o["status"] and info["dataset"] == "synthetic"
        assert info["numba_threads"] == 1 and info["numba_max_threads"] == 1  # NUMBA_NUM_THREADS set in the worker
        assert info["processed_frames"] >= m["tracked_frames"] and info["warmup_s"] >= 0
        gt = read_tum(d / "groundtruth.txt")
        assert len(gt) == N  # the ground truth of the processed frames only
        ev = json.loads((d / "evaluation.json").read_text())
        assert len(ev["rpe_rot_per_length"]) == 8
        assert ev["rpe_rot_deg_per_m"] == pytest.approx(m["rpe_rot_deg_per_m"], rel=1e-9)
        spec = json.loads((d / "spec.json").read_text())
        assert spec["sequence"] == SYN and spec["max_frames"] == N and spec["feature"] == m["feature"]
    for key in FAILED_KEYS:
        d = out / "runs" / key
        err = json.loads((d / "error.json").read_text())
        assert err["type"] == "DatasetError" and MISSING in err["message"]
        assert "Traceback" in err["traceback"] and err["tracked_frames"] == 0
        assert not (d / "metrics.json").exists()
    assert not list((out / "runs").glob("*/.*"))  # no temporary folder left behind


def test_grid_writes_the_report(grid):
    out, res = grid
    assert res.report == out / "report.md"
    md = res.report.read_text()
    assert "## synthetic" in md and "Experimental rankings for the synthetic dataset" in md
    assert "dmtrack-test-sequence / gray: **failed** — DatasetError" in md
    assert "2 run(s) at a time in separate processes" in md
    lines = (out / "results.csv").read_text().splitlines()
    assert len(lines) == 1 + 4
    for name in ("rankings.csv", "averages.csv", "timings.csv", "ranks_per_sequence.csv"):
        assert (out / "tables" / name).is_file()
    for fig in ("rpe_synthetic-seed1.png", "trajectory_synthetic-seed1.png", "depth_synthetic-seed1.png",
                "accuracy_vs_time_synthetic.png"):  # fmt: skip
        assert (out / "figures" / fig).is_file() and f"(figures/{fig})" in md
    bench = json.loads((out / "bench.json").read_text())
    assert bench["features"] == FEATURES and [s["name"] for s in bench["sequences"]] == [
        "synthetic-seed1", "dmtrack-test-sequence"]  # fmt: skip


# ---------------------------------------------------------------------------------------------- resuming
def test_second_invocation_skips_finished_runs(bench_copy: Path, mtimes):
    out = bench_copy
    before = mtimes(out)
    res = run_bench([SYN, MISSING], FEATURES, out, jobs=2, max_frames=N, skip_failed=True, progress=False,
                    figures=False)  # fmt: skip
    assert res.executed == [] and sorted(res.skipped) == sorted(OK_KEYS + FAILED_KEYS)
    assert mtimes(out) == before


def test_failed_runs_are_retried_by_default(bench_copy: Path, mtimes):
    out = bench_copy
    before = mtimes(out)
    res = run_bench([SYN, MISSING], FEATURES, out, jobs=0, max_frames=N, progress=False, report=False)
    assert sorted(res.executed) == sorted(FAILED_KEYS) and sorted(res.skipped) == sorted(OK_KEYS)
    after = mtimes(out)
    for key in OK_KEYS:
        assert after[f"runs/{key}/metrics.json"] == before[f"runs/{key}/metrics.json"]
    for key in FAILED_KEYS:
        assert after[f"runs/{key}/error.json"] != before[f"runs/{key}/error.json"]


def test_killed_bench_is_resumed_without_redoing_finished_runs(grid, bench_copy: Path, mtimes):
    out = bench_copy
    gray = out / "runs" / "synthetic-seed1" / "gray"
    (gray / "metrics.json").unlink()  # killed before it finished: a partial folder without metrics.json
    (gray / "leftover.txt").write_text("from the killed run")
    stale = out / "runs" / "synthetic-seed1" / ".gray-affine.tmp-host-123-deadbeef"
    stale.mkdir()
    (stale / "metrics.json").write_text("{half")
    before = mtimes(out)
    res = run_bench([SYN, MISSING], FEATURES, out, jobs=0, max_frames=N, skip_failed=True, progress=False,
                    report=False)  # fmt: skip
    assert res.executed == ["synthetic-seed1/gray"]
    assert res.outcomes["synthetic-seed1/gray"]["status"] in ("ok", "lost")
    assert json.loads((gray / "metrics.json").read_text())["total_frames"] == N
    assert not (gray / "leftover.txt").exists()  # the folder was replaced as a whole
    assert not stale.exists()
    after = mtimes(out)
    key = "runs/synthetic-seed1/gray-affine/metrics.json"
    assert after[key] == before[key]
    # the same settings give the same trajectory (deterministic runs)
    a = read_tum(gray / "trajectory.txt")
    b = read_tum(grid[0] / "runs" / "synthetic-seed1" / "gray" / "trajectory.txt")
    assert np.allclose(a.poses, b.poses, atol=1e-6)


def test_run_state_compares_the_spec(bench_copy: Path):
    out = bench_copy
    tasks, _ = plan_grid([SYN, MISSING], FEATURES, out, max_frames=N)
    states = {t.key: run_state(t) for t in tasks}
    assert states == {**dict.fromkeys(OK_KEYS, "done"), **dict.fromkeys(FAILED_KEYS, "failed")}
    other, _ = plan_grid([SYN], ["gray"], out, max_frames=N, overrides=["tracker.huber_d=2"])
    assert run_state(other[0]) == "todo"  # different configuration
    other, _ = plan_grid([SYN], ["gray"], out, max_frames=N + 1)
    assert run_state(other[0]) == "todo"  # different frame range
    spec_file = out / "runs" / "synthetic-seed1" / "gray" / "spec.json"
    spec = json.loads(spec_file.read_text())
    spec["dmtrack_version"] = "0.0.0"
    spec_file.write_text(json.dumps(spec))
    assert run_state(tasks[0]) == "todo"  # another dmtrack version


# ------------------------------------------------------------------------------------------------ crashes
class _ExplodingFeature(GrayFeature):
    name = "test-explodes"

    def __init__(self, scale: float = 1.0) -> None:
        super().__init__(scale)
        self.calls = 0

    def _compute(self, image, gain):  # noqa: ANN001, ANN202
        self.calls += 1
        if self.calls == 4:
            raise RuntimeError("feature exploded on its 4th frame")
        return super()._compute(image, gain)


def test_a_feature_that_raises_is_recorded_and_the_others_finish(bench_copy: Path):
    out = bench_copy
    register("test-explodes", _ExplodingFeature, channels=1, replace=True)
    try:
        res = run_bench([SYN], ["test-explodes", "gray"], out, jobs=0, max_frames=N, progress=False, figures=False)
    finally:
        unregister("test-explodes")
    assert res.executed == ["synthetic-seed1/test-explodes"] and res.skipped == ["synthetic-seed1/gray"]
    d = out / "runs" / "synthetic-seed1" / "test-explodes"
    err = json.loads((d / "error.json").read_text())
    assert err["type"] == "RuntimeError" and "4th frame" in err["message"] and "_compute" in err["traceback"]
    assert err["tracked_frames"] == 3 and err["last_frame"] == 2  # frames 0, 1, 2 were tracked
    assert len(read_tum(d / "trajectory.txt")) == 3  # the partial outputs are kept for inspection
    assert not (d / "metrics.json").exists()
    md = (out / "report.md").read_text()
    assert "test-explodes: **failed** — RuntimeError: feature exploded on its 4th frame (after 3 tracked frames)" in md


# ------------------------------------------------------------------------------------------------- the CLI
def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dmtrack")
    sub = p.add_subparsers(dest="command")
    add_bench_parser(sub)
    add_report_parser(sub)
    return p


def test_cli_bench_resumes_the_same_grid(bench_copy: Path, capsys: pytest.CaptureFixture[str]):
    out = bench_copy
    args = parser().parse_args(
        [
            "bench",
            "--sequences",
            SYN,
            MISSING,
            "--features",
            "gray,gray-affine",
            "--out",
            str(out),
            "--max-frames",
            str(N),
            "--jobs",
            "2",
            "--skip-failed",
            "--no-figures",
        ]
    )
    assert args.func(args) == 0
    text = capsys.readouterr().out
    assert "4 runs — 4 finished before, 0 run now" in text and "report:" in text


def test_cli_bench_errors(tmp_path: Path):
    p = parser()
    args = p.parse_args(["bench", "--sequences", SYN, "--features", "no-such-feature", "--out", str(tmp_path)])
    with pytest.raises(InputError, match="unknown feature"):
        args.func(args)
    args = p.parse_args(["bench", "--features", "gray", "--out", str(tmp_path)])
    with pytest.raises(InputError, match="no sequences"):
        args.func(args)
    with pytest.raises(SystemExit):
        p.parse_args(["bench", "--sequences", SYN, "--features", "gray", "--out", "x", "--r-l", "2"])
