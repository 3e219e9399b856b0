"""The bench on a Dask distributed cluster: a local one-worker cluster on loopback started by the test."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from dmtrack.errors import InputError
from dmtrack.experiments.bench import run_bench
from dmtrack.experiments.grid import plan_grid

distributed = pytest.importorskip(
    "distributed", reason='dask.distributed is not installed (optional extra: pip install "dmtrack[cluster]")'
)

from dmtrack.experiments.dask_backend import run_tasks_dask  # noqa: E402

SYN = "synthetic:n_frames=25,width=320,height=240,seed=1,texel=0.02"
MISSING = "/nonexistent/dmtrack-test-sequence"
N = 10


@pytest.fixture(scope="module")
def cluster(restored_state):  # noqa: ANN001
    # the nanny sets OMP/MKL/OPENBLAS_NUM_THREADS=1 and PYTHONHASHSEED in this process's environment for its workers
    with restored_state(), distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as c:
        yield c


def test_bench_on_a_dask_cluster_runs_resumes_and_records_crashes(cluster, tmp_path: Path):
    out = tmp_path / "bench"
    res = run_bench([SYN, MISSING], ["gray"], out, scheduler=cluster.scheduler_address, max_frames=N,
                    progress=False, figures=False)  # fmt: skip
    assert sorted(res.executed) == ["dmtrack-test-sequence/gray", "synthetic-seed1/gray"]
    assert res.failed == ["dmtrack-test-sequence/gray"]
    d = out / "runs" / "synthetic-seed1" / "gray"
    m = json.loads((d / "metrics.json").read_text())
    assert m["total_frames"] == N and m["tracked_frames"] >= 2
    info = json.loads((d / "run_info.json").read_text())
    assert info["threads"] == 1 and info["numba_threads"] == 1
    assert info["pid"] != os.getpid()  # ran in the worker process
    err = json.loads((out / "runs" / "dmtrack-test-sequence" / "gray" / "error.json").read_text())
    assert err["type"] == "DatasetError"
    assert not list((out / "runs").glob("*/.*"))  # the worker committed its folders
    assert "synthetic-seed1" in (out / "report.md").read_text()

    before = (d / "metrics.json").stat().st_mtime_ns
    again = run_bench([SYN, MISSING], ["gray"], out, scheduler=cluster.scheduler_address, max_frames=N,
                      skip_failed=True, progress=False, report=False)  # fmt: skip
    assert again.executed == [] and len(again.skipped) == 2
    assert (d / "metrics.json").stat().st_mtime_ns == before


def test_unreachable_scheduler_is_a_clear_error(tmp_path: Path):
    tasks, _ = plan_grid([MISSING], ["gray"], tmp_path / "b")
    with pytest.raises(InputError, match="cannot connect to the Dask scheduler"):
        run_tasks_dask(tasks, "tcp://127.0.0.1:9", lambda t, o: None, timeout="2s")
