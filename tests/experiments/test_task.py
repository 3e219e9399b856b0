"""One run → one record (:mod:`dmtrack.experiments.task`): the record of every outcome, thread limits."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from dmtrack.experiments.grid import plan_grid
from dmtrack.experiments.task import THREAD_ENV_VARS, execute_task, limit_threads, record_failure

MISSING = "/nonexistent/dmtrack-test-sequence"


def test_a_crash_and_a_lost_worker_give_the_same_record(tmp_path: Path):
    """A run that raises (recorded by its worker) and a run whose worker could not report (recorded by the
    bench): the same outcome keys, the same files, ``run_info.json`` saying who recorded it."""
    (task,), _ = plan_grid([MISSING], ["gray"], tmp_path, max_frames=5)
    task = replace(task, threads=None)  # leave this process's thread pools alone
    crashed = execute_task(task)
    d = task.run_dir
    assert sorted(p.name for p in d.iterdir()) == ["error.json", "run_info.json", "spec.json"]
    info = json.loads((d / "run_info.json").read_text())
    assert info["status"] == "failed" and info["pid"] > 0 and "recorded_by" not in info
    assert json.loads((d / "spec.json").read_text()) == task.spec
    assert json.loads((d / "error.json").read_text())["type"] == "DatasetError"

    lost = record_failure(task, "its worker died", "details")
    assert sorted(p.name for p in d.iterdir()) == ["error.json", "run_info.json", "spec.json"]
    info = json.loads((d / "run_info.json").read_text())
    assert info["status"] == "failed" and info["recorded_by"] == "bench" and "pid" not in info
    err = json.loads((d / "error.json").read_text())
    assert (err["type"], err["message"], err["traceback"]) == ("WorkerError", "its worker died", "details")

    assert list(crashed) == list(lost) == ["key", "status", "tracked_frames", "total_frames", "lost_at", "message",
                                           "elapsed_s", "run_dir"]  # fmt: skip
    assert crashed["status"] == lost["status"] == "failed" and crashed["run_dir"] == lost["run_dir"] == str(d)
    assert crashed["message"].startswith("DatasetError: ") and crashed["tracked_frames"] == 0
    assert lost["message"] == "its worker died" and lost["tracked_frames"] is None and lost["elapsed_s"] is None
    assert not [p for p in d.parent.iterdir() if p.name.startswith(".")]  # no temporary folder left behind


def test_limit_threads_leaves_numbas_pool_size_alone_once_imported(monkeypatch: pytest.MonkeyPatch):
    # numba re-reads NUMBA_NUM_THREADS at every compilation and raises if it changed after its threads started
    import os

    import cv2
    import numba

    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    for var in THREAD_ENV_VARS[1:]:
        monkeypatch.setenv(var, "7")  # restored by monkeypatch
    cv_threads, nb_threads = cv2.getNumThreads(), numba.get_num_threads()
    try:
        limit_threads(1)
        assert "NUMBA_NUM_THREADS" not in os.environ
        assert os.environ["OMP_NUM_THREADS"] == "1" and numba.get_num_threads() == 1
    finally:
        numba.set_num_threads(nb_threads)
        cv2.setNumThreads(cv_threads)
