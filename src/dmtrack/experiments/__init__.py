"""dmtrack.experiments: the benchmark grid runner (``dmtrack bench``) and its backends.

* :mod:`dmtrack.experiments.runner` — :func:`run_bench` runs every (sequence, feature) pair (× seeds) in
  parallel processes, resumably, and writes the report (:mod:`dmtrack.evaluation.report`);
* :mod:`dmtrack.experiments.dask_backend` — the same on a Dask distributed cluster;
* :mod:`dmtrack.experiments.cli` — the ``bench`` and ``report`` subcommands.
"""

from dmtrack.experiments.runner import (
    BenchResult,
    ResolvedSequence,
    RunTask,
    SequenceSpec,
    dataset_label,
    execute_task,
    format_seeds,
    load_sequences_file,
    parse_seeds,
    plan_grid,
    run_bench,
    run_state,
)

__all__ = [
    "BenchResult",
    "ResolvedSequence",
    "RunTask",
    "SequenceSpec",
    "dataset_label",
    "execute_task",
    "format_seeds",
    "load_sequences_file",
    "parse_seeds",
    "plan_grid",
    "run_bench",
    "run_state",
]
