"""The bench: :func:`run_bench` runs every (sequence, feature) pair (× seeds) of a grid, resumably, and reports.

>>> from dmtrack.experiments import SequenceSpec, run_bench
>>> res = run_bench([SequenceSpec("data/7scenes-redkitchen-0000-0299")], ["gray", "gray-affine"],
...                 "bench-out", jobs=2, max_frames=100)                         # doctest: +SKIP

The bench plans the grid (:mod:`dmtrack.experiments.grid`), skips the runs already done
(:mod:`dmtrack.experiments.store`), runs the others on a backend (:mod:`dmtrack.experiments.backends`, or
:mod:`dmtrack.experiments.dask_backend` with ``scheduler="tcp://HOST:PORT"``), each run making its record
(:mod:`dmtrack.experiments.task`), and writes the report (:func:`dmtrack.evaluation.report.write_report`).
The bench folder's layout is :mod:`dmtrack.io.bench_layout`.

Several seeds
-------------
With ``seeds`` (``dmtrack bench --seeds 0,1,2``) every (sequence, feature) *cell* is run once per seed of the
random depth initialisation, each run in ``DIR/runs/<sequence>/<feature>/seed-<S>/`` (the same files as a
single run); the seeds are just more tasks of the grid, run in parallel like any other.  With exactly one seed
(``seeds=[S]`` or ``seed=S``) the run stays in ``DIR/runs/<sequence>/<feature>/``, the layout of
single-seed benches, so their folders resume as before.  A feature folder may hold a single-seed run and
``seed-<S>/`` runs at the same time (a folder benched both ways); replacing the single-seed run keeps the
``seed-<S>/`` folders inside it, and the report uses, for such a cell, the runs of the last bench's grid.
The report gives per cell the median and the min–max over the seeds (:mod:`dmtrack.evaluation.report`).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dmtrack import __version__
from dmtrack.errors import InputError
from dmtrack.experiments.backends import run_tasks_inprocess, run_tasks_processes
from dmtrack.experiments.grid import ResolvedSequence, RunTask, SequenceSpec, normalise, plan_grid, seed_list
from dmtrack.experiments.store import clean_stale, run_state
from dmtrack.experiments.task import Outcome, machine_info, utc_now
from dmtrack.io.atomic import prepare_folder
from dmtrack.io.bench_layout import BENCH_JSON, RUNS_DIR, read_json, write_json


@dataclass
class BenchResult:
    """What :func:`run_bench` did.

    Attributes
    ----------
    out_dir : the bench folder.
    tasks : every run of the grid.
    sequences : the resolved sequences.
    executed : keys (``"<sequence>/<feature>"``, ``"<sequence>/<feature>/seed-<S>"`` with several seeds) of
        the runs run now.
    skipped : keys of the runs found done (or failed, with ``skip_failed``) and not run again.
    outcomes : per executed key, the outcome dict of :func:`~dmtrack.experiments.task.execute_task`.
    report : path of ``report.md`` (``None`` if not written).
    """

    out_dir: Path
    tasks: list[RunTask]
    sequences: list[ResolvedSequence]
    executed: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    outcomes: dict[str, Outcome] = field(default_factory=dict)
    report: Path | None = None

    @property
    def failed(self) -> list[str]:
        """Keys of the runs that crashed now."""
        return [k for k, o in self.outcomes.items() if o["status"] == "failed"]


def _progress_bar(total: int, initial_note: str, enabled: bool | None) -> Any:
    if enabled is False or total == 0:
        return None
    from tqdm import tqdm

    disable = None if enabled is None else False  # None: off when stderr is not a terminal
    if enabled is None and os.environ.get("CI"):
        disable = True
    return tqdm(total=total, desc=f"bench{initial_note}", unit="run", disable=disable, dynamic_ncols=True)


def _check_runtime(device: str | None, modes: Sequence[str]) -> None:
    """Before any run: ``device`` can be used (one line naming what is missing) and gtsam is there for SLAM."""
    if device is not None:
        from dmtrack.features.device import resolve_device

        resolve_device(device)
    if "slam" in modes:
        from dmtrack.slam.pose_graph import gtsam_module

        gtsam_module()


def _write_bench_json(out: Path, tasks: list[RunTask], resolved: list[ResolvedSequence], features: Sequence[str],
                      options: dict[str, Any]) -> None:  # fmt: skip
    path = out / BENCH_JSON
    old = read_json(path) or {}
    data = {
        "dmtrack_version": __version__,
        "created": old.get("created", utc_now()),
        "updated": utc_now(),
        "features": list(features),
        "sequences": [
            {
                "name": r.name,
                "path": r.path,
                "format": r.format,
                "dataset": r.dataset,
                "unit": r.unit,
                "r_l": r.spec.r_l,
                "open_error": r.open_error,
            }
            for r in resolved
        ],  # fmt: skip
        "runs": [t.key for t in tasks],
        "options": normalise(options),
        "machine": machine_info(),
        "command": sys.argv if sys.argv and sys.argv[0] else None,
    }
    write_json(path, data)


def run_bench(
    sequences: Sequence[SequenceSpec | str],
    features: Sequence[str],
    out_dir: str | Path,
    *,
    jobs: int = 1,
    scheduler: str | None = None,
    start: int = 0,
    max_frames: int | None = None,
    seed: int | None = None,
    seeds: Sequence[int] | str | None = None,
    r_l: float | None = None,
    format: str | None = None,
    intrinsics: str | None = None,
    config: Any = None,
    overrides: Sequence[str] = (),
    depth_images: bool = True,
    pointcloud: bool = True,
    threads_per_job: int = 1,
    skip_failed: bool = False,
    report: bool = True,
    figures: bool = True,
    progress: bool | None = None,
    log: Callable[[str], None] | None = None,
    device: str | None = None,
    modes: Sequence[str] = ("vo",),
) -> BenchResult:
    """Run the grid ``sequences × features`` into ``out_dir`` and write the report.

    Parameters
    ----------
    sequences : paths / ``synthetic:…`` strings or :class:`SequenceSpec` (per-sequence options).
    features : feature names (see ``dmtrack features``).
    out_dir : the bench folder ``DIR`` (its layout: :mod:`dmtrack.io.bench_layout`).
    jobs : worker processes (0: run in this process, serially).
    scheduler : ``"tcp://HOST:PORT"`` of a Dask scheduler: run on that cluster instead of local processes
        (``out_dir`` must then be on a filesystem every worker sees at the same path).
    start, max_frames, seed, r_l, format, intrinsics : run options (a :class:`SequenceSpec` overrides
        ``start``, ``max_frames``, ``r_l``, ``format`` and ``intrinsics`` for its sequence).
    seeds : run every cell once per seed (a list, or ``"0,1,2"`` / ``"0-2,5"``), into
        ``<feature>/seed-<S>/`` when there are several; not together with ``seed``.
    config, overrides : odometry configuration (a VOConfig; default LSD-SLAM's) and ``key=value`` overrides.
    depth_images, pointcloud : write ``depth/*.png`` and ``pointcloud.ply`` per run.
    threads_per_job : numba / OpenCV / BLAS threads per worker.
    skip_failed : do not run again runs that crashed before (default: run them again).
    report, figures : write ``report.md`` + CSVs (+ figures) at the end.
    progress : progress bar (None: only on a terminal and not under CI).
    log : called with one line per finished run (e.g. ``print``).
    device : where the network features run, ``"auto"``, ``"cpu"``, ``"cuda"``, ``"cuda:N"`` (None: their
        default); checked here, before any run.
    modes : ``("vo",)`` (default), ``("slam",)`` or both: every feature once per mode, the SLAM cells labelled
        ``<feature>+slam`` (needs gtsam, checked here).

    Returns
    -------
    BenchResult
    """
    if jobs < 0:
        raise InputError(f"jobs must be ≥ 0, got {jobs}")
    if threads_per_job < 1:
        raise InputError(f"threads per job must be ≥ 1, got {threads_per_job}")
    out = Path(out_dir).expanduser().resolve()
    cell_seeds = seed_list(seed, seeds)
    tasks, resolved = plan_grid(
        sequences, features, out, start=start, max_frames=max_frames, seed=seed, r_l=r_l, format=format,
        intrinsics=intrinsics, config=config, overrides=overrides, depth_images=depth_images,
        pointcloud=pointcloud, threads_per_job=threads_per_job, seeds=seeds, device=device, modes=modes,
    )  # fmt: skip
    _check_runtime(device, modes)
    prepare_folder(out / RUNS_DIR)
    clean_stale(out)
    options = {"start": start, "max_frames": max_frames, "seed": seed,
               "seeds": None if seeds is None else list(cell_seeds), "r_l": r_l, "format": format,
               "intrinsics": intrinsics, "overrides": list(overrides), "depth_images": depth_images,
               "pointcloud": pointcloud, "jobs": jobs, "scheduler": scheduler,
               "threads_per_job": threads_per_job, "device": device, "modes": list(modes)}  # fmt: skip
    labels = list(dict.fromkeys(t.feature for t in tasks))
    _write_bench_json(out, tasks, resolved, labels, options)

    result = BenchResult(out, tasks, resolved)
    todo = []
    for t in tasks:
        state = run_state(t)
        if state == "done" or (state == "failed" and skip_failed):
            result.skipped.append(t.key)
        else:
            todo.append(t)

    note = f" ({len(result.skipped)} done before)" if result.skipped else ""
    bar = _progress_bar(len(todo), note, progress)

    def on_done(task: RunTask, outcome: Outcome) -> None:
        result.executed.append(task.key)
        result.outcomes[task.key] = outcome
        line = _outcome_line(outcome)
        if bar is not None:
            bar.update(1)
            bar.set_postfix_str(task.key, refresh=False)
            if log is not None and not bar.disable:
                bar.write(line)
        if log is not None and (bar is None or bar.disable):
            log(line)

    try:
        if todo:
            if scheduler:
                from dmtrack.experiments.dask_backend import run_tasks_dask

                run_tasks_dask(todo, scheduler, on_done)
            elif jobs == 0:
                run_tasks_inprocess(todo, on_done)
            else:
                run_tasks_processes(todo, jobs, on_done, threads_per_job)
    finally:
        if bar is not None:
            bar.close()
    if report:
        from dmtrack.evaluation.report import write_report

        result.report = write_report(out, figures=figures)
    return result


def _outcome_line(o: Outcome) -> str:
    if o["status"] == "failed":
        return f"{o['key']}: FAILED — {o['message']}"
    lost = "" if o.get("lost_at") is None else f", lost at frame {o['lost_at']}"
    el = "" if o.get("elapsed_s") is None else f" in {o['elapsed_s']:.1f} s"
    return f"{o['key']}: tracked {o['tracked_frames']}/{o['total_frames']}{lost}{el}"


__all__ = ["BenchResult", "run_bench"]
