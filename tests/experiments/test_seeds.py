"""Multi-seed benches (``dmtrack bench --seeds``): seed lists, layout, resuming per seed, the report's medians.

One real bench (synthetic sequence × gray, gray-affine × seeds 0-2, few frames) runs once per module in 2
spawned worker processes; the other tests work on copies of its folder (``bench_copy``) or on hand-written
spec files.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
from pathlib import Path

import pytest

from dmtrack.errors import InputError
from dmtrack.experiments.bench import run_bench
from dmtrack.experiments.cli import add_bench_parser
from dmtrack.experiments.grid import plan_grid
from dmtrack.experiments.store import clean_stale, commit, run_state
from dmtrack.io.bench_layout import format_seeds, parse_seeds

SYN = "synthetic:n_frames=25,width=320,height=240,seed=1,texel=0.02"
FEATURES = ["gray", "gray-affine"]
SEEDS = [0, 1, 2]
N = 10
SEQ = "synthetic-seed1"
KEYS = [f"{SEQ}/{f}/seed-{s}" for f in FEATURES for s in SEEDS]
METRICS = ["tracked_frames", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "ate_rmse", "fps", "tracking_ms"]


@pytest.fixture(scope="module")
def grid(tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("seeds") / "out"
    result = run_bench([SYN], FEATURES, out, seeds="0-2", jobs=2, max_frames=N, progress=False,
                       pointcloud=False)  # fmt: skip
    return out, result


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def metrics_of(out: Path, feature: str) -> dict[int, dict]:
    return {s: json.loads((out / "runs" / SEQ / feature / f"seed-{s}" / "metrics.json").read_text()) for s in SEEDS}


# ---------------------------------------------------------------------------------------------- seed lists
@pytest.mark.parametrize(
    ("text", "seeds"),
    [("0,1,2", [0, 1, 2]), ("0-2", [0, 1, 2]), ("0-2,5", [0, 1, 2, 5]), (" 7 ", [7]), ("3-3", [3]),
     ("10-12,1", [10, 11, 12, 1]), ([4, 2], [4, 2]), (3, [3])],
)  # fmt: skip
def test_parse_seeds(text, seeds):
    assert parse_seeds(text) == seeds


@pytest.mark.parametrize(
    ("text", "match"),
    [("", "empty"), ("2-0", "empty range"), ("0,x", "cannot read 'x'"), ("1,1", "1 listed twice"),
     ("0-2,1", "1 listed twice"), ("-1", "cannot read"), ("1.5", "cannot read"), (",", "cannot read"),
     ([], "empty"), ([-3], "≥ 0"), ([True], "not an integer")],
)  # fmt: skip
def test_parse_seeds_errors(text, match):
    with pytest.raises(InputError, match=match):
        parse_seeds(text)


def test_format_seeds():
    assert format_seeds([0, 1, 2]) == "0-2"
    assert format_seeds([5, 0, 1, 2]) == "0-2,5"
    assert format_seeds([0, 1]) == "0,1"
    assert format_seeds([3]) == "3" and format_seeds([]) == ""
    assert parse_seeds(format_seeds([9, 1, 2, 3, 7])) == [1, 2, 3, 7, 9]


# ------------------------------------------------------------------------------------------------- planning
def test_plan_grid_with_seeds(tmp_path: Path):
    tasks, _ = plan_grid([SYN], FEATURES, tmp_path, seeds=[0, 1, 2], max_frames=N)
    assert [t.key for t in tasks] == KEYS
    assert [t.spec["seed"] for t in tasks] == SEEDS * 2
    assert tasks[4].run_dir == tmp_path.resolve() / "runs" / SEQ / "gray-affine" / "seed-1"
    # exactly one seed: today's layout, the same run as --seed S
    one, _ = plan_grid([SYN], ["gray"], tmp_path, seeds="5", max_frames=N)
    same, _ = plan_grid([SYN], ["gray"], tmp_path, seed=5, max_frames=N)
    assert one[0].key == f"{SEQ}/gray" and one[0].run_dir == same[0].run_dir and one[0].spec == same[0].spec
    with pytest.raises(InputError, match="not both"):
        plan_grid([SYN], ["gray"], tmp_path, seed=1, seeds=[0, 1])


def test_no_seed_resumes_as_the_configurations_seed(tmp_path: Path):
    """A folder benched without --seed (config seed 0) is done for --seeds 0 / --seed 0, not for seed 1."""
    (old,), _ = plan_grid([SYN], ["gray"], tmp_path, max_frames=N)
    assert old.spec["seed"] is None and old.spec["config"]["seed"] == 0
    old.run_dir.mkdir(parents=True)
    (old.run_dir / "spec.json").write_text(json.dumps(old.spec))
    (old.run_dir / "metrics.json").write_text(json.dumps({"tracked_frames": N}))
    (zero,), _ = plan_grid([SYN], ["gray"], tmp_path, seeds=[0], max_frames=N)
    (one,), _ = plan_grid([SYN], ["gray"], tmp_path, seed=1, max_frames=N)
    (cfg_one,), _ = plan_grid([SYN], ["gray"], tmp_path, max_frames=N, overrides=["seed=1"])
    assert zero.run_dir == old.run_dir and run_state(zero) == "done"
    assert run_state(one) == "todo" and run_state(cfg_one) == "todo"


def test_replacing_a_single_seed_run_keeps_the_seed_folders(tmp_path: Path):
    final = tmp_path / "runs" / "s" / "gray"
    (final / "seed-0").mkdir(parents=True)
    (final / "seed-0" / "metrics.json").write_text("{}")
    (final / "old.txt").write_text("old single-seed run")
    tmp = tmp_path / "runs" / "s" / ".gray.tmp-x"
    tmp.mkdir()
    (tmp / "metrics.json").write_text('{"new": true}')
    commit(tmp, final)
    assert not tmp.exists() and not (final / "old.txt").exists()
    assert json.loads((final / "metrics.json").read_text()) == {"new": True}
    assert (final / "seed-0" / "metrics.json").read_text() == "{}"
    assert [p.name for p in (tmp_path / "runs" / "s").iterdir()] == ["gray"]  # no trash left


# --------------------------------------------------------------------------------------------- the bench
def test_layout_one_folder_per_seed(grid):
    out, res = grid
    assert sorted(res.executed) == sorted(KEYS) and res.skipped == [] and res.failed == []
    for f in FEATURES:
        assert not (out / "runs" / SEQ / f / "metrics.json").exists()  # only the seeds' folders hold runs
        assert sorted(p.name for p in (out / "runs" / SEQ / f).iterdir()) == ["seed-0", "seed-1", "seed-2"]
        for s, m in metrics_of(out, f).items():
            d = out / "runs" / SEQ / f / f"seed-{s}"
            for name in ("spec.json", "trajectory.txt", "keyframes.txt", "config.yaml", "evaluation.json",
                         "groundtruth.txt", "run_info.json"):  # fmt: skip
                assert (d / name).is_file(), (d, name)
            assert json.loads((d / "spec.json").read_text())["seed"] == s
            assert m["seed"] == s and m["feature"] == f and m["total_frames"] == N
    # the seed reaches the odometry: the runs of one feature differ
    rot = [m["rpe_rot_deg_per_m"] for m in metrics_of(out, "gray").values()]
    assert len(set(rot)) == 3, rot
    bench = json.loads((out / "bench.json").read_text())
    assert bench["runs"] == KEYS and bench["options"]["seeds"] == SEEDS
    assert not list((out / "runs").rglob(".*"))  # no temporary folder left behind


def test_results_csv_has_one_row_per_seed(grid):
    out, _ = grid
    rows = read_csv(out / "results.csv")
    assert [(r["feature"], r["seed"]) for r in rows] == [(f, str(s)) for f in FEATURES for s in SEEDS]
    for r in rows:
        assert r["run_dir"] == str(out / "runs" / SEQ / r["feature"] / f"seed-{r['seed']}")
        m = metrics_of(out, r["feature"])[int(r["seed"])]
        assert float(r["rpe_rot_deg_per_m"]) == m["rpe_rot_deg_per_m"]


def test_tables_give_median_and_range_of_the_seeds(grid):
    out, _ = grid
    cells = {r["feature"]: r for r in read_csv(out / "tables" / "cells.csv")}
    assert set(cells) == set(FEATURES)
    md = (out / "report.md").read_text()
    assert "3 seeds of the random depth initialisation (0-2)" in md
    medians = {}
    for f in FEATURES:
        c = cells[f]
        assert (c["sequence"], c["seeds"], c["runs"], c["n_failed"]) == (SEQ, "0-2", "3", "0")
        assert int(c["n_ok"]) + int(c["n_lost"]) == 3
        ms = metrics_of(out, f)
        for k in METRICS:
            vals = [ms[s][k] for s in SEEDS]
            assert float(c[f"{k}_median"]) == pytest.approx(statistics.median(vals), rel=1e-12), k
            assert float(c[f"{k}_min"]) == pytest.approx(min(vals), rel=1e-12), k
            assert float(c[f"{k}_max"]) == pytest.approx(max(vals), rel=1e-12), k
            assert c[f"{k}_n"] == "3"
        rot = [ms[s]["rpe_rot_deg_per_m"] for s in SEEDS]
        medians[f] = statistics.median(rot)
        # report.md: median (min–max) of the seeds' metrics.json values
        assert f"{statistics.median(rot):.3f} ({min(rot):.3f}–{max(rot):.3f})" in md
        ate = [ms[s]["ate_rmse"] for s in SEEDS]
        assert f"{statistics.median(ate):.4f} ({min(ate):.4f}–{max(ate):.4f})" in md
    # rankings are computed on the medians
    ranks = {r["feature"]: r for r in read_csv(out / "tables" / "ranks_per_sequence.csv")}
    best = min(medians.values())
    for f in FEATURES:
        assert ranks[f]["rpe_rot_deg_per_m_rank"] == ("1" if medians[f] == best else "2")
        assert ranks[f]["seeds"] == "0-2"
    for name in ("rankings.csv", "averages.csv", "timings.csv"):
        assert {r["seeds"] for r in read_csv(out / "tables" / name)} == {"0-2"}, name
    averages = {r["feature"]: r for r in read_csv(out / "tables" / "averages.csv")}
    for f in FEATURES:
        assert float(averages[f]["rpe_rot"]) == pytest.approx(medians[f], rel=1e-12)
    for fig in ("rpe_synthetic-seed1.png", "accuracy_vs_time_synthetic.png", "trajectory_synthetic-seed1.png"):
        assert (out / "figures" / fig).is_file() and f"(figures/{fig})" in md
    assert "Problems while writing" not in md


# ---------------------------------------------------------------------------------------------- resuming
def test_second_invocation_recomputes_nothing(bench_copy: Path, mtimes):
    out = bench_copy
    before = mtimes(out)
    res = run_bench([SYN], FEATURES, out, seeds=[0, 1, 2], jobs=2, max_frames=N, progress=False,
                    pointcloud=False, report=False)  # fmt: skip
    assert res.executed == [] and res.skipped == KEYS
    assert mtimes(out) == before


def test_killed_multi_seed_bench_resumes_per_seed(grid, bench_copy: Path, mtimes):
    out = bench_copy
    gray = out / "runs" / SEQ / "gray"
    (gray / "seed-1" / "metrics.json").unlink()  # killed before seed 1 finished
    stale = gray / ".seed-2.tmp-host-123-deadbeef"  # and while seed 2 was being rewritten
    stale.mkdir()
    (stale / "metrics.json").write_text("{half")
    before = mtimes(out)
    # one more seed: only the unfinished seed 1 and the new seed 3 run
    res = run_bench([SYN], ["gray"], out, seeds="0-3", jobs=0, max_frames=N, progress=False, pointcloud=False,
                    figures=False)  # fmt: skip
    assert res.executed == [f"{SEQ}/gray/seed-1", f"{SEQ}/gray/seed-3"]
    assert res.skipped == [f"{SEQ}/gray/seed-0", f"{SEQ}/gray/seed-2"]
    assert not stale.exists()
    after = mtimes(out)
    for s in (0, 2):
        key = f"runs/{SEQ}/gray/seed-{s}/metrics.json"
        assert after[key] == before[key]
    again = json.loads((gray / "seed-1" / "metrics.json").read_text())
    assert again["seed"] == 1 and again["rpe_rot_deg_per_m"] == pytest.approx(
        metrics_of(grid[0], "gray")[1]["rpe_rot_deg_per_m"], rel=1e-9)  # fmt: skip
    assert json.loads((gray / "seed-3" / "metrics.json").read_text())["seed"] == 3
    cells = {r["feature"]: r for r in read_csv(out / "tables" / "cells.csv")}
    assert cells["gray"]["seeds"] == "0-3" and cells["gray"]["runs"] == "4"


# ------------------------------------------------------------------------------------------------- the CLI
def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dmtrack")
    add_bench_parser(p.add_subparsers(dest="command"))
    return p


def test_cli_bench_seeds_resumes(bench_copy: Path, capsys: pytest.CaptureFixture[str]):
    out = bench_copy
    args = parser().parse_args(["bench", "--sequences", SYN, "--features", "gray,gray-affine", "--out", str(out),
                                "--max-frames", str(N), "--seeds", "0,1-2", "--no-pointcloud",
                                "--no-figures"])  # fmt: skip
    assert args.func(args) == 0
    assert "6 runs (2 cells × seeds 0-2) — 6 finished before, 0 run now" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("extra", "match"),
    [(["--seed", "1", "--seeds", "0-2"], "--seed and --seeds exclude each other"),
     (["--seeds", "2-0"], "--seeds: empty range"), (["--seeds", "a"], "--seeds: cannot read 'a'"),
     (["--seeds", "0,0"], "--seeds: 0 listed twice")],
)  # fmt: skip
def test_cli_seed_errors(tmp_path: Path, extra: list[str], match: str):
    args = parser().parse_args(["bench", "--sequences", SYN, "--features", "gray", "--out", str(tmp_path / "b"),
                                *extra])  # fmt: skip
    with pytest.raises(InputError, match=match) as e:
        args.func(args)
    assert "\n" not in str(e.value)  # one line
    assert not (tmp_path / "b").exists()  # nothing was started


def test_cli_help_documents_seeds():
    text = " ".join(parser()._subparsers._group_actions[0].choices["bench"].format_help().split())  # type: ignore[union-attr]
    assert "--seeds LIST" in text and "0-2,5" in text and "seed-<S>" in text and "median" in text


def _killed_inside_commit(tmp_path: Path, moved_seeds: int) -> tuple[Path, Path]:
    """The folders a bench killed inside :func:`commit` leaves: the old ``gray`` (a single-seed run holding
    seed-0 and seed-1) renamed to trash, and the new run still in its temporary folder; ``moved_seeds`` ≥ 0
    means the rename of the new run happened and that many seed folders were moved before the kill."""
    seq = tmp_path / "runs" / "s"
    trash = seq / ".gray.trash-0123abcd"
    for s in (0, 1):
        (trash / f"seed-{s}").mkdir(parents=True)
        (trash / f"seed-{s}" / "metrics.json").write_text(f'{{"seed": {s}}}')
    (trash / "metrics.json").write_text('{"old": true}')
    tmp = seq / ".gray.tmp-host-1-deadbeef"
    tmp.mkdir()
    (tmp / "metrics.json").write_text('{"new": true}')
    final = seq / "gray"
    if moved_seeds >= 0:
        os.replace(tmp, final)
        for s in range(moved_seeds):
            os.replace(trash / f"seed-{s}", final / f"seed-{s}")
    return seq, final


@pytest.mark.parametrize("moved_seeds", [-1, 0, 1])
def test_a_bench_killed_inside_commit_loses_no_seed_run(tmp_path: Path, moved_seeds: int):
    seq, final = _killed_inside_commit(tmp_path, moved_seeds)
    clean_stale(tmp_path)
    assert [p.name for p in seq.iterdir()] == ["gray"]  # no temporary or trash folder left
    for s in (0, 1):
        assert json.loads((final / f"seed-{s}" / "metrics.json").read_text()) == {"seed": s}
    # killed between the two renames, the old run is put back (and re-run if its spec differs); after them, the new
    assert json.loads((final / "metrics.json").read_text()) == ({"old": True} if moved_seeds < 0 else {"new": True})


def test_a_seed_run_killed_between_the_renames_is_put_back(tmp_path: Path):
    feat = tmp_path / "runs" / "s" / "gray"
    (feat / ".seed-1.trash-0a").mkdir(parents=True)
    (feat / ".seed-1.trash-0a" / "metrics.json").write_text("{}")
    (feat / ".seed-1.tmp-host-2-0b").mkdir()
    assert clean_stale(tmp_path) == [feat / ".seed-1.tmp-host-2-0b"]
    assert [p.name for p in feat.iterdir()] == ["seed-1"] and (feat / "seed-1" / "metrics.json").is_file()
