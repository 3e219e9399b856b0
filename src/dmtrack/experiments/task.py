"""One run of the grid → one record: :func:`execute_task` runs a :class:`~dmtrack.experiments.grid.RunTask`.

A run goes through :mod:`dmtrack.pipeline` (:func:`~dmtrack.pipeline.run_to_directory`, the files of
``dmtrack run``) into a temporary run folder (:func:`dmtrack.experiments.store.run_folder`); the bench then
adds its record — ``evaluation.json`` and ``groundtruth.txt`` for a finished run, ``error.json`` for a crashed
one, ``run_info.json`` always — and commits the folder.  The record is made by one function,
:func:`record_run`, for every outcome: a finished run, a run that raised, and a run whose worker could not
report (:func:`record_failure`, written by the bench process).

Threads
-------
Each run calls :func:`limit_threads` with the task's ``threads`` (``threads_per_job``): numba's and OpenCV's
thread pools, and the ``*_NUM_THREADS`` variables of :data:`THREAD_ENV_VARS` for libraries loaded later, so
that ``jobs`` workers use about ``jobs × threads_per_job`` cores instead of oversubscribing them.

Warm-up
-------
The first run in a fresh worker loads (or, with a cold cache, compiles) the numba kernels, which adds seconds
to that run's wall time; so that this never reaches the measured per-frame times, every worker first runs the
odometry on a tiny in-memory sequence with the run's feature (:func:`dmtrack.pipeline.warm_up`, once per feature,
configuration and process; ``warmup_s`` in ``run_info.json``; the run itself then finds nothing left to warm up:
``compile_s`` 0 in its metrics).
"""

from __future__ import annotations

import os
import platform
import socket
import sys
import time
import traceback
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from dmtrack import __version__
from dmtrack.errors import DmtrackError
from dmtrack.experiments.grid import RunTask
from dmtrack.experiments.store import commit, run_folder
from dmtrack.io.bench_layout import (
    ERROR_JSON,
    EVALUATION_JSON,
    METRICS_JSON,
    RUN_INFO_JSON,
    write_json,
)
from dmtrack.io.machine import cpu_model

#: Environment variables set in every worker process to ``threads_per_job``.
THREAD_ENV_VARS = (
    "NUMBA_NUM_THREADS",
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)

#: What :func:`execute_task` returns: ``key``, ``status`` (``"ok"``, ``"lost"`` or ``"failed"``),
#: ``tracked_frames``, ``total_frames``, ``lost_at``, ``message`` (the error for a failed run), ``elapsed_s``,
#: ``run_dir``.
Outcome = dict[str, Any]


# ============================================================================================ this machine
def machine_info() -> dict[str, Any]:
    """Platform, CPU (model and count), Python and dmtrack versions of this machine."""
    cpu = cpu_model()
    try:
        usable = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        usable = os.cpu_count()
    return {
        "host": socket.gethostname(),
        "platform": platform.platform(),
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "cpus_usable": usable,
        "python": platform.python_version(),
        "dmtrack_version": __version__,
    }


def utc_now() -> str:
    """The time now, UTC, ISO 8601 to the second (the timestamps of ``run_info.json`` and ``bench.json``)."""
    return datetime.now(UTC).isoformat(timespec="seconds")


def limit_threads(threads: int | None) -> None:
    """Limit numba's and OpenCV's thread pools (and, for libraries loaded later, OpenMP/BLAS) to ``threads``.

    Before numba is imported, ``NUMBA_NUM_THREADS`` sizes its pool; once it is imported the variable must not
    change any more (numba re-reads the environment at every compilation and refuses a different value
    after its threads started), so then only ``numba.set_num_threads`` is used — it applies to the calling
    thread; start Dask workers with ``NUMBA_NUM_THREADS`` set to cover helper threads as well.
    """
    if threads is None:
        return
    n = max(1, int(threads))
    numba_loaded = "numba" in sys.modules
    for var in THREAD_ENV_VARS:
        if var == "NUMBA_NUM_THREADS" and numba_loaded:
            continue
        os.environ[var] = str(n)
    try:
        import numba

        numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    except (ImportError, ValueError):  # pragma: no cover
        pass
    try:
        import cv2

        cv2.setNumThreads(n)
    except ImportError:  # pragma: no cover
        pass


# ============================================================================================ warm-up
def warm_up(feature: str, config: Any = None) -> float:
    """:func:`dmtrack.pipeline.warm_up` (imported when called: importing this module must not import numba before
    :func:`limit_threads` sized its pool)."""
    from dmtrack.pipeline import warm_up as warm_up_kernels

    return warm_up_kernels(feature, config)


# ============================================================================================ the record
@dataclass(frozen=True)
class Attempt:
    """When a worker started a run: ``perf_counter()`` (for ``elapsed_s``) and the UTC time (``started``)."""

    t0: float
    started: str


def record_run(
    task: RunTask,
    tmp: Path,
    status: str,
    *,
    attempt: Attempt | None = None,
    metrics: dict[str, Any] | None = None,
    error: dict[str, Any] | None = None,
    message: str | None = None,
    info: dict[str, Any] | None = None,
) -> Outcome:
    """Write the record of ``task``'s run into its temporary folder ``tmp``, commit it, and return the outcome.

    The one place a run's record is made, for every outcome: ``status`` ``"ok"`` or ``"lost"`` with the run's
    ``metrics``, or ``"failed"`` with ``error`` (written as ``error.json``) and the outcome's ``message``.
    ``run_info.json`` says where and when it ran: measured in the worker (``attempt``, with ``info`` added at
    the end), or, without ``attempt``, recorded by the bench process for a run whose worker could not report.
    """
    if attempt is not None:
        numba = sys.modules.get("numba")
        run_info = {
            "numba_threads": None if numba is None else int(numba.get_num_threads()),
            "numba_max_threads": None if numba is None else int(numba.config.NUMBA_NUM_THREADS),
            **machine_info(),
            "pid": os.getpid(),
            "dataset": task.dataset,
            "unit": task.unit,
            "status": status,
            "started": attempt.started,
            "finished": utc_now(),
            "elapsed_s": time.perf_counter() - attempt.t0,
            "threads": task.threads,
            **(info or {}),
        }
    else:
        run_info = {**machine_info(), "status": status, "dataset": task.dataset, "unit": task.unit,
                    "finished": utc_now(), "recorded_by": "bench"}  # fmt: skip
    if error is not None:
        write_json(tmp / ERROR_JSON, error)
    write_json(tmp / RUN_INFO_JSON, run_info)
    commit(tmp, task.run_dir)
    m = metrics or {}
    return {
        "key": task.key,
        "status": status,
        "tracked_frames": m.get("tracked_frames") if metrics is not None else (error or {}).get("tracked_frames"),
        "total_frames": m.get("total_frames"),
        "lost_at": m.get("lost_at"),
        "message": m.get("lost_reason") if metrics is not None else message,
        "elapsed_s": run_info.get("elapsed_s"),
        "run_dir": str(task.run_dir),
    }


# ============================================================================================ running
class _ProgressSink:
    """Counts what the odometry delivered, so that a crash can say how far the run got."""

    def __init__(self) -> None:
        self.tracked = 0
        self.keyframes = 0
        self.last_frame: int | None = None
        self.lost: list[tuple[int, str]] = []

    def on_frame(self, frame_index: int, timestamp: float, T_wc: Any) -> None:
        self.tracked += 1
        self.last_frame = int(frame_index)

    def on_keyframe(self, keyframe_id: int, frame_index: int, *args: Any) -> None:
        self.keyframes += 1

    def on_lost(self, frame_index: int, reason: str) -> None:
        self.lost.append((int(frame_index), str(reason)))
        self.last_frame = int(frame_index)

    def close(self) -> None:
        pass


def execute_task(task: RunTask) -> Outcome:
    """Run one task and commit its folder; never raises for a failing run (only for an interrupt).

    Returns
    -------
    dict
        The :data:`Outcome`: ``key``, ``status`` (``"ok"``, ``"lost"`` or ``"failed"``), ``tracked_frames``,
        ``total_frames``, ``lost_at``, ``message`` (the error for a failed run), ``elapsed_s``, ``run_dir``.
    """
    limit_threads(task.threads)  # first: sizes numba's pool if this process has not imported numba yet

    from dmtrack.datasets import open_sequence
    from dmtrack.odometry.config import VOConfig
    from dmtrack.pipeline import run_to_directory

    attempt = Attempt(time.perf_counter(), utc_now())
    spec = task.spec
    counter = _ProgressSink()
    with run_folder(task) as tmp:
        try:
            seq = open_sequence(spec["sequence"], format=spec["format"], intrinsics=spec["intrinsics"])
            config = VOConfig.from_dict(spec["config"])
            warmup_s = warm_up(spec["feature"], config)
            result = run_to_directory(
                seq,
                tmp,
                feature=spec["feature"],
                config=config,
                start=spec["start"],
                max_frames=spec["max_frames"],
                seed=spec["seed"],
                r_l=spec["r_l"],
                depth_images=spec["depth_images"],
                pointcloud=spec["pointcloud"],
                extra_sinks=(counter,),
                progress=False,
                device=spec.get("device"),
                slam=True if spec.get("slam") else None,
            )
        except Exception as e:  # a crash of this run must not stop the grid
            (tmp / METRICS_JSON).unlink(missing_ok=True)
            error = {
                "key": task.key,
                "sequence": spec["sequence"],
                "feature": spec["feature"],
                "type": type(e).__name__,
                "message": str(e),
                "traceback": traceback.format_exc(),
                "tracked_frames": counter.tracked,
                "keyframes": counter.keyframes,
                "last_frame": counter.last_frame,
                "lost": counter.lost,
                "elapsed_s": time.perf_counter() - attempt.t0,
            }
            return record_run(task, tmp, "failed", attempt=attempt, error=error, message=f"{type(e).__name__}: {e}")

        # evaluation details for the report (per-length RPE, Sim(3) alignment); run_to_directory wrote the ground
        # truth it used (groundtruth.txt)
        m = result.metrics
        gt = result.groundtruth
        if gt is not None:
            try:
                from dmtrack.evaluation import evaluate

                ev = evaluate(gt, result.trajectory, max_diff=0.01, r_l=float(m["r_l"]), align="sim3")
            except (DmtrackError, ValueError) as e:
                ev = {"error": str(e)}
            write_json(tmp / EVALUATION_JSON, ev)
        status = "lost" if m.get("lost_at") is not None else "ok"
        processed = int(result.vo.total_frames) if result.vo is not None else result.total_frames
        return record_run(task, tmp, status, attempt=attempt, metrics=m,
                          info={"processed_frames": processed, "warmup_s": warmup_s})  # fmt: skip


def record_failure(task: RunTask, message: str, details: str = "") -> Outcome:
    """Record a run that failed outside :func:`execute_task` (its worker died, it could not be sent…) as
    ``error.json`` in its folder (written by the calling process)."""
    with run_folder(task) as tmp:
        error = {"key": task.key, "sequence": task.spec["sequence"], "feature": task.feature, "type": "WorkerError",
                 "message": message, "traceback": details, "tracked_frames": None, "last_frame": None}  # fmt: skip
        return record_run(task, tmp, "failed", error=error, message=message)


__all__ = [
    "THREAD_ENV_VARS",
    "Attempt",
    "Outcome",
    "execute_task",
    "limit_threads",
    "machine_info",
    "record_failure",
    "record_run",
    "warm_up",
]
