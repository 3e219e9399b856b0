"""Where the runs of a bench execute: in this process, or in a pool of local worker processes.

Both take the runs to do and an ``on_done(task, outcome)`` callback, called in the bench process as each run
finishes.  The same on a Dask distributed cluster is :mod:`dmtrack.experiments.dask_backend`.

Local processes
---------------
``jobs ≥ 1`` runs the grid in a :class:`~concurrent.futures.ProcessPoolExecutor` with the ``spawn`` start
method (no fork of a process holding numba / OpenCV thread pools).  Each worker process gets
:data:`~dmtrack.experiments.task.THREAD_ENV_VARS` = ``threads_per_job`` (default 1) before it imports anything
heavy, and each run also limits numba's and OpenCV's threads
(:func:`~dmtrack.experiments.task.limit_threads`).  ``jobs = 0`` runs the grid serially in the calling process
with its thread settings untouched (for debugging).  Timings measured with ``jobs > 1`` share the machine with
the other workers.

A worker process that dies (segfault, out of memory) breaks the pool: the runs that were in flight are
retried once, each alone in a fresh pool; a run that kills its worker again is recorded as failed.
"""

from __future__ import annotations

import os
import sys
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import replace
from typing import Any

from dmtrack.experiments.grid import RunTask
from dmtrack.experiments.task import THREAD_ENV_VARS, Outcome, execute_task, record_failure

#: ``on_done(task, outcome)``: what a backend calls, in the bench process, as each run finishes.
OnDone = Callable[[RunTask, Outcome], None]


def run_tasks_inprocess(tasks: Iterable[RunTask], on_done: OnDone) -> None:
    """Run the tasks one after the other in this process."""
    for t in tasks:
        on_done(t, execute_task(replace(t, threads=None)))


def _init_worker(threads: int, parent_pid: int | None = None) -> None:
    """Process-pool initializer: runs in each fresh worker before any task (and before numba is imported).

    With ``parent_pid``, the worker ends as soon as its parent is gone (a bench killed with SIGKILL, or whose
    pool was torn down): an orphaned worker must not go on computing and writing into DIR, where the next
    bench (resuming) would find a temporary folder created after it cleaned the stale ones.  On Linux the
    kernel kills it at once (``PR_SET_PDEATHSIG``); elsewhere, and as a second guard, a daemon thread polls
    the parent pid every 0.5 s (which a long call holding the GIL can delay).
    """
    for var in THREAD_ENV_VARS:
        os.environ[var] = str(max(1, int(threads)))
    os.environ.setdefault("MPLBACKEND", "Agg")
    if parent_pid is not None:
        import threading

        _die_with_parent()
        if os.getppid() != parent_pid:  # the parent died before the line above took effect
            os._exit(1)

        def watch() -> None:
            while os.getppid() == parent_pid:
                time.sleep(0.5)
            os._exit(1)

        threading.Thread(target=watch, name="dmtrack-parent-watch", daemon=True).start()


def _die_with_parent() -> None:
    """Linux: ask the kernel to SIGKILL this process when its parent (the thread that spawned it) exits.

    Nothing on other systems, or where ``prctl`` is unavailable (the polling thread then remains the guard).
    """
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    try:
        pr_set_pdeathsig = 1
        ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0)
    except (OSError, AttributeError):
        pass


def _terminate_pool(pool: Any) -> None:
    """Stop a ProcessPoolExecutor now: cancel what is queued and kill the workers mid-run."""
    procs = list((getattr(pool, "_processes", None) or {}).values())  # private, but the only handle on them
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    for proc in procs:
        proc.join(timeout=5)


def run_tasks_processes(
    tasks: Sequence[RunTask],
    jobs: int,
    on_done: OnDone,
    threads_per_job: int = 1,
    fn: Callable[[RunTask], Outcome] = execute_task,
) -> None:
    """Run the tasks in a pool of ``jobs`` spawned worker processes (see the module docstring).

    At most ``jobs`` tasks are in flight, so a dying worker affects only those; they are retried once,
    alone, in a fresh pool.  ``fn`` is what runs each task in a worker (:func:`execute_task`; it must be
    importable by the workers).
    """
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("spawn")
    queue: deque[RunTask] = deque(tasks)
    retry: deque[RunTask] = deque()
    attempts: dict[str, int] = {}
    in_flight: dict[Future[Outcome], RunTask] = {}
    pool: ProcessPoolExecutor | None = None
    try:
        while queue or retry or in_flight:
            if pool is None:
                pool = ProcessPoolExecutor(
                    max_workers=max(1, min(jobs, len(queue) + len(retry) + len(in_flight))),
                    mp_context=ctx, initializer=_init_worker, initargs=(threads_per_job, os.getpid()),
                )  # fmt: skip
            if retry:
                if not in_flight:  # a retried run runs alone: if its worker dies again, it is the culprit
                    t = retry.popleft()
                    in_flight[pool.submit(fn, t)] = t
            else:
                while queue and len(in_flight) < jobs:
                    t = queue.popleft()
                    in_flight[pool.submit(fn, t)] = t
            done, _ = wait(list(in_flight), return_when=FIRST_COMPLETED)
            broken = False
            for fut in done:
                t = in_flight.pop(fut)
                try:
                    outcome = fut.result()
                except BrokenProcessPool:
                    broken = True
                    _retry_or_fail(t, attempts, retry, on_done)
                    continue
                except Exception as e:  # e.g. the task could not be pickled, or failed after its run
                    outcome = record_failure(t, f"{type(e).__name__}: {e}", traceback.format_exc())
                on_done(t, outcome)
            if broken:  # the other in-flight runs died with the pool: retry them too
                for fut in list(in_flight):
                    _retry_or_fail(in_flight.pop(fut), attempts, retry, on_done)
                pool.shutdown(wait=True, cancel_futures=True)
                pool = None
    except BaseException:  # Ctrl-C, SIGTERM (see run_bench): no worker may outlive the bench
        if pool is not None:
            _terminate_pool(pool)
            pool = None
        raise
    finally:
        if pool is not None:
            pool.shutdown(wait=True)


def _retry_or_fail(task: RunTask, attempts: dict[str, int], retry: deque[RunTask], on_done: OnDone) -> bool:
    """After a worker death: queue ``task`` for its one retry (True) or record it as failed (False)."""
    attempts[task.key] = attempts.get(task.key, 0) + 1
    if attempts[task.key] < 2:
        retry.append(task)
        return True
    on_done(task, record_failure(task, "its worker process died twice (crash or out of memory) while running it"))
    return False


__all__ = ["OnDone", "run_tasks_inprocess", "run_tasks_processes"]
