"""The bench's result store: which runs are done, and the atomic commit of a run folder.

The bench folder's layout is :mod:`dmtrack.io.bench_layout` (the report reads the same folder).

Resuming
--------
A run is *done* when its folder holds a ``metrics.json`` and a ``spec.json`` equal to the spec the grid
would run now (:func:`dmtrack.experiments.grid.make_spec`) — sequence (absolute path or ``synthetic:…``
string), format, intrinsics, feature, start, max_frames, seed, r_l, the whole odometry configuration after
``--set`` overrides, whether depth images and the point cloud are written, and the dmtrack version.  The seed
compares as the seed the run uses: no seed (the configuration's ``seed``, 0 by default) equals that seed given
explicitly (:func:`same_spec`).  Each seed's run is its own task, so a killed multi-seed bench resumes per
seed.  Done runs are skipped; anything else (no folder, a folder without ``metrics.json``, a different spec)
is (re)run.  A crashed run (``error.json``, no ``metrics.json``) is run again unless ``skip_failed``.  A
tracking loss is not a crash: the run finishes with ``lost_at`` in ``metrics.json``.

Atomic results
--------------
A run writes into a hidden temporary folder next to its final one (:func:`run_folder`:
``runs/<sequence>/.<feature>.tmp-<host>-<pid>-<random>``; ``.seed-<S>.tmp-…`` in the feature folder) and is
moved into place with ``os.replace`` only when complete (:func:`commit`: the old folder, if any, is first
renamed away and then deleted).  A killed bench therefore never leaves a half-written ``metrics.json``; its
leftover temporary folders are deleted by the next bench on the same ``DIR`` (:func:`clean_stale`; a bench
killed inside :func:`commit` is completed or undone there first, so no finished run is lost) — so two benches
must not write into the same ``DIR`` at the same time.  A bench's worker processes die with it (on Linux at
once, :func:`dmtrack.experiments.backends._init_worker`): none writes into ``DIR`` after its bench was killed.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import socket
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from dmtrack.experiments.grid import RunTask
from dmtrack.io.bench_layout import (
    ERROR_JSON,
    METRICS_JSON,
    RUNS_DIR,
    SEED_DIR,
    SPEC_JSON,
    effective_seed,
    read_json,
    safe_name,
    write_json,
)


# ============================================================================================ resuming
def run_state(task: RunTask) -> str:
    """``"done"`` (metrics.json and an equal spec.json), ``"failed"`` (error.json and an equal spec) or
    ``"todo"``."""
    d = task.run_dir
    if not same_spec(read_json(d / SPEC_JSON), task.spec):
        return "todo"
    if isinstance(read_json(d / METRICS_JSON), dict):
        return "done"
    if (d / ERROR_JSON).is_file():
        return "failed"
    return "todo"


def same_spec(stored: Any, wanted: dict[str, Any]) -> bool:
    """Whether a stored ``spec.json`` defines the same run as ``wanted``: equal, except that the seed compares
    as :func:`~dmtrack.io.bench_layout.effective_seed` (no seed with a configuration seed 0 is the same run
    as seed 0)."""
    if not isinstance(stored, dict):
        return False
    if stored == wanted:
        return True
    a, b = dict(stored), dict(wanted)
    a["seed"], b["seed"] = effective_seed(stored), effective_seed(wanted)
    return a == b


# ============================================================================================ run folders
def _temp_dir(task: RunTask) -> Path:
    host = safe_name(socket.gethostname())[:40]
    final = task.run_dir
    tmp = final.with_name(f".{final.name}.tmp-{host}-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    tmp.mkdir(parents=True)
    return tmp


@contextlib.contextmanager
def run_folder(task: RunTask) -> Iterator[Path]:
    """A fresh temporary folder for ``task``'s run, holding its ``spec.json``; :func:`commit` it when complete.

    The folder is deleted if the block raises (an interrupt included); after a commit nothing is left to delete.
    """
    tmp = _temp_dir(task)
    try:
        write_json(tmp / SPEC_JSON, task.spec)
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def commit(tmp: Path, final: Path) -> None:
    """Move the finished temporary folder ``tmp`` to ``final`` (replacing it) with ``os.replace``.

    The ``seed-<S>/`` runs inside a replaced feature folder (a folder benched with one seed and with several)
    are moved into the new one, each with ``os.replace``: they are kept, not deleted with the old run.
    """
    trash = None
    if final.exists():
        trash = final.with_name(f".{final.name}.trash-{uuid.uuid4().hex[:8]}")
        os.replace(final, trash)
    os.replace(tmp, final)
    if trash is not None:
        _move_seed_runs(trash, final)
        shutil.rmtree(trash, ignore_errors=True)


def _move_seed_runs(old: Path, new: Path) -> None:
    """Move the ``seed-<S>/`` runs of the replaced feature folder ``old`` that ``new`` lacks into ``new``."""
    for child in sorted(old.iterdir()):
        if child.is_dir() and SEED_DIR.match(child.name) and not (new / child.name).exists():
            os.replace(child, new / child.name)


_STALE_SEED_DIR = re.compile(r"^\.seed-\d+\.(?:tmp|trash)-")


def _is_stale(p: Path) -> bool:
    return p.name.startswith(".") and (".tmp-" in p.name or ".trash-" in p.name)


_TRASH = re.compile(r"^\.(?P<name>.+)\.trash-[0-9a-f]+$")


def _recover_trash(trash: Path) -> None:
    """Undo what a bench killed inside :func:`commit` left half done, before ``trash`` is deleted.

    Killed between its two renames, the final folder is missing: the old one is put back (it is re-run if its
    spec is not today's).  Killed while moving the ``seed-<S>/`` runs of a replaced feature folder into the new
    one, those not yet moved are moved now: finished runs of other seeds are never deleted with the trash.
    """
    m = _TRASH.match(trash.name)
    if m is None or not trash.is_dir():
        return
    final = trash.with_name(m["name"])
    if not final.exists():
        os.replace(trash, final)
        return
    _move_seed_runs(trash, final)


def clean_stale(bench_dir: str | Path) -> list[Path]:
    """Delete the temporary / trash folders a killed bench left in ``DIR/runs/*/`` and, for the runs of
    several seeds, in ``DIR/runs/*/*/``; returns them.  A trash folder is first recovered
    (:func:`_recover_trash`): a bench killed inside :func:`commit` loses no finished run."""
    removed = []
    runs = Path(bench_dir) / RUNS_DIR
    if not runs.is_dir():
        return removed
    for seq_dir in runs.iterdir():
        if not seq_dir.is_dir():
            continue
        for d in list(seq_dir.iterdir()):
            if _is_stale(d):
                _recover_trash(d)
                if not d.exists():  # restored as its final folder
                    continue
                shutil.rmtree(d, ignore_errors=True) if d.is_dir() else d.unlink(missing_ok=True)
                removed.append(d)
        for d in seq_dir.iterdir():
            if d.is_dir() and not d.name.startswith("."):
                for sub in list(d.iterdir()):
                    if sub.is_dir() and _STALE_SEED_DIR.match(sub.name):
                        _recover_trash(sub)
                        if sub.exists():
                            shutil.rmtree(sub, ignore_errors=True)
                            removed.append(sub)
    return removed


__all__ = ["clean_stale", "commit", "run_folder", "run_state", "same_spec"]
