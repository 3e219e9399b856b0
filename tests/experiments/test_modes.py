"""A bench's SLAM dimension (``--modes vo,slam``) and its ``--device`` (issues 31, 32)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from dmtrack.errors import InputError
from dmtrack.evaluation.records import collect_runs
from dmtrack.experiments.bench import run_bench
from dmtrack.experiments.grid import plan_grid

SYN = "synthetic:n_frames=25,width=320,height=240,seed=1,texel=0.02"


def test_modes_and_device_enter_the_grid(tmp_path: Path) -> None:
    tasks, _ = plan_grid([SYN], ["gray", "tracknet"], tmp_path, modes=("vo", "slam"), device="cpu")
    assert [t.key for t in tasks] == ["synthetic-seed1/gray", "synthetic-seed1/gray+slam", "synthetic-seed1/tracknet",
                                      "synthetic-seed1/tracknet+slam"]  # fmt: skip
    assert [t.spec["feature"] for t in tasks] == ["gray", "gray", "tracknet", "tracknet"]
    assert [t.spec.get("slam") for t in tasks] == [None, True, None, True]
    assert {t.spec["device"] for t in tasks} == {"cpu"}
    # without them the specs are those of earlier benches (their folders resume)
    plain, _ = plan_grid([SYN], ["gray"], tmp_path)
    assert "device" not in plain[0].spec and "slam" not in plain[0].spec
    for bad in ((), ("vo", "vo"), ("slam3",)):
        with pytest.raises(InputError, match="mode"):
            plan_grid([SYN], ["gray"], tmp_path, modes=bad)


@pytest.mark.skipif(importlib.util.find_spec("gtsam") is None,
                    reason="gtsam not installed (pip install 'dmtrack[slam]')")
def test_a_bench_runs_vo_and_slam_side_by_side(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    res = run_bench([SYN], ["gray"], out, jobs=0, max_frames=20, modes=("vo", "slam"), device="cpu",
                    progress=False, figures=False)  # fmt: skip
    assert sorted(res.executed) == ["synthetic-seed1/gray", "synthetic-seed1/gray+slam"] and not res.failed
    records = {r.feature: r for r in collect_runs(out)}
    assert set(records) == {"gray", "gray+slam"}
    assert records["gray+slam"].metrics["slam"] is True and "slam" not in records["gray"].metrics
    assert (records["gray+slam"].path / "trajectory_vo.txt").is_file()
    assert records["gray"].metrics["device"] == "cpu"
    report = (out / "report.md").read_text()
    assert "| gray+slam |" in report and "| gray |" in report
    # resumed: nothing runs again
    again = run_bench([SYN], ["gray"], out, jobs=0, max_frames=20, modes=("vo", "slam"), device="cpu",
                      progress=False, report=False)  # fmt: skip
    assert again.executed == [] and len(again.skipped) == 2


def test_a_bench_runs_the_window_beside_the_odometry(tmp_path: Path) -> None:
    """``--modes vo,window``: the window is a dimension of the bench, each cell with its own spec and row."""
    tasks, _ = plan_grid([SYN], ["gray"], tmp_path, modes=("vo", "window"))
    assert [t.key for t in tasks] == ["synthetic-seed1/gray", "synthetic-seed1/gray+window"]
    assert [t.spec["config"]["window"]["size"] for t in tasks] == [0, 5]
    assert [t.spec.get("window") for t in tasks] == [None, True]
    out = tmp_path / "bench"
    syn = SYN.replace("n_frames=25", "n_frames=45")
    res = run_bench([syn], ["gray"], out, jobs=0, modes=("vo", "window"), progress=False, figures=False)
    assert not res.failed
    records = {r.feature: r for r in collect_runs(out)}
    assert set(records) == {"gray", "gray+window"}
    assert records["gray+window"].metrics["window"]["optimisations"] >= 1 and "window" not in records["gray"].metrics
    assert "| gray+window |" in (out / "report.md").read_text()
