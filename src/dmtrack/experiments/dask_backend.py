"""Running the benchmark grid on a Dask distributed cluster (``dmtrack bench --scheduler tcp://HOST:PORT``).

Needs the optional extra ``cluster`` (``pip install "dmtrack[cluster]"``, i.e. ``dask[distributed]``) on the
machine running ``dmtrack bench`` *and* on every worker, with the same dmtrack version installed (tasks
call :func:`dmtrack.experiments.task.execute_task` by reference).

How it works: the bench process connects a :class:`distributed.Client` to the scheduler, decides which runs
are already done (reading ``DIR``), submits one task per remaining run (``Client.submit``, not pure, no
automatic retries) and gathers the results as they finish (``distributed.as_completed``).  Each *worker*
runs the odometry and writes the run's files itself, into a temporary folder that it moves into place when
complete — exactly as the local process pool does, so resuming and the atomic writes work the same.

Requirements and advice:

* ``DIR`` must be on a filesystem that every worker sees **at the same absolute path** (NFS, Lustre…),
  and so must the sequences (their absolute paths are sent to the workers).  ``os.replace`` of a folder
  is atomic on POSIX filesystems, NFS included, as long as the temporary and final folders are on the same
  filesystem (they are: siblings in ``DIR/runs/<sequence>/``).
* Start workers with one thread each and the thread limits in their environment, e.g.
  ``NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 dask worker tcp://HOST:8786 --nworkers 8 --nthreads 1``
  (each run also calls ``numba.set_num_threads`` / ``cv2.setNumThreads`` with ``--threads-per-job``).
* A worker that dies while running a task makes the scheduler reschedule it (up to its
  ``allowed-failures``), then the task fails with ``KilledWorker``; the bench records that as the run's
  ``error.json`` and goes on.
"""

from __future__ import annotations

import traceback
import uuid
from collections.abc import Sequence
from typing import Any

from dmtrack.errors import InputError
from dmtrack.experiments.backends import OnDone
from dmtrack.experiments.grid import RunTask
from dmtrack.experiments.task import execute_task, record_failure

INSTALL_HINT = 'running on a Dask cluster needs dask.distributed: pip install "dmtrack[cluster]"'


def have_dask() -> bool:
    """Whether ``dask.distributed`` can be imported."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def run_tasks_dask(tasks: Sequence[RunTask], scheduler: Any, on_done: OnDone, timeout: str = "30s") -> None:
    """Run ``tasks`` on the Dask cluster at ``scheduler`` and call ``on_done`` as each finishes.

    Parameters
    ----------
    tasks : the runs to do.
    scheduler : ``"tcp://HOST:PORT"`` (or anything :class:`distributed.Client` accepts, e.g. a cluster).
    on_done : called in this process with ``(task, outcome)``, in completion order.
    timeout : how long to wait for the scheduler to answer.

    Raises
    ------
    InputError
        dask.distributed is not installed, or the scheduler cannot be reached.
    """
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise InputError(INSTALL_HINT) from None
    try:
        client = Client(scheduler, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as e:
        raise InputError(f"cannot connect to the Dask scheduler {scheduler!r}: {e}") from None
    with client:
        futures = {}
        for t in tasks:
            key = f"dmtrack-run-{t.key}-{uuid.uuid4().hex[:8]}"
            fut = client.submit(execute_task, t, key=key, pure=False, retries=0)
            futures[fut] = t
        for fut in as_completed(list(futures), loop=client.loop):
            t = futures[fut]
            try:
                outcome = fut.result()
            except Exception as e:  # KilledWorker, a worker without dmtrack, …: record it, go on
                outcome = record_failure(t, f"{type(e).__name__} on the Dask cluster: {e}", traceback.format_exc())
            on_done(t, outcome)
