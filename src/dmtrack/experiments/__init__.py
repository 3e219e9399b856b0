"""dmtrack.experiments: the benchmark grid runner (``dmtrack bench``) and its backends.

* :mod:`dmtrack.experiments.bench` — :func:`run_bench` runs every (sequence, feature) pair (× seeds) in
  parallel processes, resumably, and writes the report (:mod:`dmtrack.evaluation.report`);
* :mod:`dmtrack.experiments.grid` — the grid: sequences (:class:`SequenceSpec`, the sequences file) and runs
  (:class:`RunTask`, :func:`plan_grid`);
* :mod:`dmtrack.experiments.task` — one run → one record (:func:`execute_task`);
* :mod:`dmtrack.experiments.store` — which runs are done (:func:`run_state`), atomic run folders;
* :mod:`dmtrack.experiments.backends` — in this process or a pool of local processes;
  :mod:`dmtrack.experiments.dask_backend` — the same on a Dask distributed cluster;
* :mod:`dmtrack.experiments.cli` — the ``bench`` and ``report`` subcommands.

The bench folder's layout, seed lists (``parse_seeds``) and dataset labels are :mod:`dmtrack.io.bench_layout`.
"""

from __future__ import annotations

from dmtrack.io.machine import lazy_exports

# imported on first use (PEP 562): `dmtrack run` builds the whole command line, the bench's parser included, and
# needs none of these modules (7 ms)
_WHERE = {
    "BenchResult": "bench", "run_bench": "bench",
    "ResolvedSequence": "grid", "RunTask": "grid", "SequenceSpec": "grid", "load_sequences_file": "grid",
    "plan_grid": "grid",
    "run_state": "store",
    "execute_task": "task",
}  # fmt: skip

__getattr__, __dir__ = lazy_exports(__name__, _WHERE)

__all__ = [
    "BenchResult",
    "ResolvedSequence",
    "RunTask",
    "SequenceSpec",
    "execute_task",
    "load_sequences_file",
    "plan_grid",
    "run_bench",
    "run_state",
]
