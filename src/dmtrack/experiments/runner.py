"""The benchmark grid runner: every (sequence, feature) pair, in parallel processes, resumable.

>>> from dmtrack.experiments import SequenceSpec, run_bench
>>> res = run_bench([SequenceSpec("data/7scenes-redkitchen-0000-0299")], ["gray", "gray-affine"],
...                 "bench-out", jobs=2, max_frames=100)                         # doctest: +SKIP

Layout of the output folder ``DIR``::

    DIR/bench.json                      the grid of the last invocation (features, sequences, options, machine)
    DIR/runs/<sequence>/<feature>/      one run: the files of ``dmtrack run`` (trajectory.txt, keyframes.txt,
                                        pointcloud.ply, depth/, config.yaml, metrics.json) and
        spec.json                       what defines the run (compared on resume)
        evaluation.json                 dmtrack.evaluation.evaluate() of the run (per-length RPE, alignment)
        groundtruth.txt                 ground truth of the processed frames (TUM, T_wc) for the figures
        run_info.json                   where/when it ran: host, platform, CPUs, elapsed, status
        error.json                      only for a crashed run: exception, traceback, frames reached
    DIR/report.md, DIR/results.csv, DIR/tables/*.csv, DIR/figures/*.png   (dmtrack.evaluation.report)

Several seeds
-------------
With ``seeds`` (``dmtrack bench --seeds 0,1,2``) every (sequence, feature) *cell* is run once per seed of the
random depth initialisation, each run in ``DIR/runs/<sequence>/<feature>/seed-<S>/`` (the same files as
above); the seeds are just more tasks of the grid, run in parallel like any other.  With exactly one seed
(``seeds=[S]`` or ``seed=S``) the run stays in ``DIR/runs/<sequence>/<feature>/``, the layout of
single-seed benches, so their folders resume as before.  A feature folder may hold a single-seed run and
``seed-<S>/`` runs at the same time (a folder benched both ways); replacing the single-seed run keeps the
``seed-<S>/`` folders inside it, and the report uses, for such a cell, the runs of the last bench's grid.
The report gives per cell the median and the min–max over the seeds (:mod:`dmtrack.evaluation.report`).

Resuming
--------
A run is *done* when its folder holds a ``metrics.json`` and a ``spec.json`` equal to the spec the grid
would run now — sequence (absolute path or ``synthetic:…`` string), format, intrinsics, feature, start,
max_frames, seed, r_l, the whole odometry configuration after ``--set`` overrides, whether depth images and
the point cloud are written, and the dmtrack version.  The seed compares as the seed the run uses: no seed
(the configuration's ``seed``, 0 by default) equals that seed given explicitly.  Each seed's run is its own
task, so a killed multi-seed bench resumes per seed.  Done runs are skipped; anything else (no folder, a
folder without ``metrics.json``, a different spec) is (re)run.  A crashed run (``error.json``, no
``metrics.json``) is run again unless ``skip_failed``.  A tracking loss is not a crash: the run finishes
with ``lost_at`` in ``metrics.json``.

Atomic results: a run writes into a hidden temporary folder next to its final one
(``runs/<sequence>/.<feature>.tmp-<host>-<pid>-<random>``; ``.seed-<S>.tmp-…`` in the feature folder) and
is moved into place with ``os.replace`` only when complete (the old folder, if any, is first renamed away
and then deleted).  A killed bench therefore
never leaves a half-written ``metrics.json``; its leftover temporary folders are deleted by the next bench
on the same ``DIR`` — so two benches must not write into the same ``DIR`` at the same time.

Parallelism and threads
-----------------------
``jobs ≥ 1`` runs the grid in a :class:`~concurrent.futures.ProcessPoolExecutor` with the ``spawn`` start
method (no fork of a process holding numba / OpenCV thread pools).  Each worker process gets
``NUMBA_NUM_THREADS``, ``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS``,
``VECLIB_MAXIMUM_THREADS`` and ``NUMEXPR_NUM_THREADS`` = ``threads_per_job`` (default 1) before it imports
anything heavy, and each run also calls ``numba.set_num_threads`` and ``cv2.setNumThreads``, so ``jobs``
workers use about ``jobs × threads_per_job`` cores instead of oversubscribing them.  ``jobs = 0`` runs the
grid serially in the calling process with its thread settings untouched (for debugging).  The first run in a
fresh worker loads (or, with a cold cache, compiles) the numba kernels, which adds seconds to that run's
wall time; so that this never reaches the measured per-frame times, every worker first runs the odometry
on a tiny in-memory sequence with the run's feature (:func:`warm_up`, once per feature and process;
``warmup_s`` in ``run_info.json``).  Timings measured with ``jobs > 1`` share the machine with the other
workers.

A worker process that dies (segfault, out of memory) breaks the pool: the runs that were in flight are
retried once, each alone in a fresh pool; a run that kills its worker again is recorded as failed.

``scheduler="tcp://HOST:PORT"`` runs the same grid on a Dask distributed cluster instead
(:mod:`dmtrack.experiments.dask_backend`).
"""

from __future__ import annotations

import json
import os
import platform
import re
import shutil
import socket
import sys
import time
import traceback
import uuid
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from dmtrack import __version__
from dmtrack.errors import DmtrackError, InputError

SPEC_VERSION = 1
#: Environment variables set in every worker process to ``threads_per_job``.
THREAD_ENV_VARS = (
    "NUMBA_NUM_THREADS",
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)
_SAFE_NAME = re.compile(r"[^A-Za-z0-9._+-]+")

Outcome = dict[str, Any]


# ============================================================================================ sequences
def parse_r_l(value: Any) -> float:
    """An RPE length ratio from a number or a fraction string (``"1/20"``); must be in (0, 1]."""
    try:
        if isinstance(value, str) and "/" in value:
            num, den = value.split("/", 1)
            r = float(num) / float(den)
        else:
            r = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        raise InputError(f"r_l: not a number: {value!r}") from None
    if not 0.0 < r <= 1.0:
        raise InputError(f"r_l must be in (0, 1], got {value!r}")
    return r


_SEED_ITEM = re.compile(r"^\s*(\d+)\s*(?:-\s*(\d+)\s*)?$")


def parse_seeds(text: str | int | Iterable[int]) -> list[int]:
    """Seeds from ``"0,1,2"``, ``"0-2"``, ``"0-2,5"`` (a comma list of seeds and inclusive ranges), an int or
    a list of ints, in the given order; seeds are integers ≥ 0 and each may appear once.

    >>> parse_seeds("0-2,5")
    [0, 1, 2, 5]
    """
    if isinstance(text, bool):
        raise InputError(f"seeds: not an integer: {text!r}")
    if isinstance(text, int):
        items: list[int] = [text]
    elif isinstance(text, str):
        items = []
        if not text.strip():
            raise InputError("seeds: empty list (expected e.g. 0,1,2 or 0-2 or 0-2,5)")
        for part in text.split(","):
            m = _SEED_ITEM.match(part)
            if not m:
                raise InputError(f"seeds: cannot read {part.strip()!r} in {text!r} (expected e.g. 0,1,2 or 0-2 or "
                                 "0-2,5; seeds are integers ≥ 0)")  # fmt: skip
            lo = int(m.group(1))
            hi = lo if m.group(2) is None else int(m.group(2))
            if hi < lo:
                raise InputError(f"seeds: empty range {part.strip()!r} in {text!r} (write LOW-HIGH, LOW ≤ HIGH)")
            items += range(lo, hi + 1)
    else:
        items = []
        for v in text:
            if isinstance(v, bool) or not isinstance(v, int):
                raise InputError(f"seeds: not an integer: {v!r}")
            items.append(int(v))
        if not items:
            raise InputError("seeds: empty list")
    for v in items:
        if v < 0:
            raise InputError(f"seeds must be ≥ 0, got {v}")
    dup = sorted({v for v in items if items.count(v) > 1})
    if dup:
        raise InputError(f"seeds: {', '.join(map(str, dup))} listed twice in {text!r}")
    return items


def format_seeds(seeds: Iterable[int]) -> str:
    """The inverse of :func:`parse_seeds` for sorted output: ``[0, 1, 2, 5]`` → ``"0-2,5"``."""
    xs = sorted(set(int(s) for s in seeds))
    parts: list[str] = []
    i = 0
    while i < len(xs):
        j = i
        while j + 1 < len(xs) and xs[j + 1] == xs[j] + 1:
            j += 1
        parts.append(str(xs[i]) if j == i else f"{xs[i]}-{xs[j]}" if j > i + 1 else f"{xs[i]},{xs[j]}")
        i = j + 1
    return ",".join(parts)


def seed_dir_name(seed: int) -> str:
    """Folder of one seed's run inside a feature folder with several seeds: ``seed-<S>``."""
    return f"seed-{int(seed)}"


#: A seed's run folder inside a feature folder (see :func:`seed_dir_name`).
SEED_DIR = re.compile(r"^seed-(\d+)$")


def _intrinsics_str(value: Any) -> str | None:
    if value is None:
        return None
    if isinstance(value, (list, tuple)):
        if len(value) != 4:
            raise InputError(f"intrinsics must be 4 numbers fx, fy, cx, cy, got {value!r}")
        return ",".join(f"{float(v):g}" for v in value)
    return str(value)


@dataclass(frozen=True)
class SequenceSpec:
    """One sequence of the grid, with its own options.

    Attributes
    ----------
    path : a sequence folder or a ``synthetic[:key=value,…]`` string.
    name : folder name of its runs (``DIR/runs/<name>/``); default: the dataset reader's sequence name.
    format : force a dataset format (default: detected).
    intrinsics : ``"fx,fy,cx,cy"`` replacing or supplying the dataset's intrinsics.
    r_l : RPE length ratio (default: 1/20 for KITTI, 1/3 otherwise — give 1/20 for Tsukuba).
    start, max_frames : frame range (default: the bench's).
    dataset : group name for the ranking tables (default: from the format and the name, see
        :func:`dataset_label`).
    unit : length unit of the ground truth, for the report's labels (default: see :func:`length_unit`).
    """

    path: str
    name: str | None = None
    format: str | None = None
    intrinsics: str | None = None
    r_l: float | None = None
    start: int | None = None
    max_frames: int | None = None
    dataset: str | None = None
    unit: str | None = None


_SPEC_KEYS = {"path", "name", "format", "intrinsics", "r_l", "start", "max_frames", "dataset", "unit"}


def _spec_from_mapping(entry: Any, base: Path, where: str, defaults: dict[str, Any]) -> SequenceSpec:
    if isinstance(entry, str):
        entry = {"path": entry}
    if not isinstance(entry, dict):
        raise InputError(f"{where}: a sequence is a path or a mapping with 'path', got {entry!r}")
    data = {**defaults, **entry}
    unknown = sorted(set(data) - _SPEC_KEYS)
    if unknown:
        raise InputError(f"{where}: unknown key(s) {', '.join(unknown)}; known: {', '.join(sorted(_SPEC_KEYS))}")
    if "path" not in data or not data["path"]:
        raise InputError(f"{where}: missing 'path'")
    path = str(data["path"])
    if not path.startswith("synthetic") and not Path(path).expanduser().is_absolute():
        path = str((base / Path(path).expanduser()).resolve())
    for key in ("start", "max_frames"):
        if data.get(key) is not None and (isinstance(data[key], bool) or not isinstance(data[key], int)):
            raise InputError(f"{where}: {key} must be an integer, got {data[key]!r}")
    return SequenceSpec(
        path=path,
        name=None if data.get("name") is None else str(data["name"]),
        format=data.get("format"),
        intrinsics=_intrinsics_str(data.get("intrinsics")),
        r_l=None if data.get("r_l") is None else parse_r_l(data["r_l"]),
        start=data.get("start"),
        max_frames=data.get("max_frames"),
        dataset=None if data.get("dataset") is None else str(data["dataset"]),
        unit=None if data.get("unit") is None else str(data["unit"]),
    )


def load_sequences_file(path: str | Path) -> list[SequenceSpec]:
    """Read a sequences YAML file.

    The file is either a list of entries or a mapping with ``sequences:`` (the list) and optional
    ``defaults:`` (keys applied to every entry unless it sets them).  An entry is a path string or a mapping
    with ``path`` and optional ``name``, ``format``, ``intrinsics`` (``"fx,fy,cx,cy"`` or a list of 4
    numbers), ``r_l`` (a number or ``"1/20"``), ``start``, ``max_frames``, ``dataset`` (ranking group) and
    ``unit`` (ground-truth length unit for the report's labels).  Relative paths are relative to the folder
    of the YAML file.

    Example::

        defaults: {max_frames: 300}
        sequences:
          - path: ../../shared/data/7scenes-0000-0699
          - {path: ../../shared/data/tsukuba-150, intrinsics: 615,615,320,240, r_l: 1/20, dataset: Tsukuba}
          - path: synthetic:n_frames=100,width=320,height=240
    """
    import yaml

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise InputError(f"cannot read the sequences file: {e.strerror}", path=p) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        raise InputError(f"invalid YAML: {e}", path=p, line=None if mark is None else mark.line + 1) from None
    defaults: dict[str, Any] = {}
    if isinstance(data, dict):
        unknown = sorted(set(data) - {"sequences", "defaults"})
        if unknown:
            raise InputError(f"unknown top-level key(s) {', '.join(unknown)} (expected sequences, defaults)", path=p)
        defaults = data.get("defaults") or {}
        if not isinstance(defaults, dict):
            raise InputError("'defaults' must be a mapping", path=p)
        data = data.get("sequences")
    if not isinstance(data, list) or not data:
        raise InputError("expected a non-empty list of sequences (or a mapping with 'sequences:')", path=p)
    base = p.resolve().parent
    return [_spec_from_mapping(e, base, f"{p}: sequence {i + 1}", defaults) for i, e in enumerate(data)]


def safe_name(text: str) -> str:
    """``text`` made safe as one folder name (letters, digits, ``. _ + -``; anything else → ``_``)."""
    s = _SAFE_NAME.sub("_", text).strip("._") or "sequence"
    return s[:120]


def dataset_label(format: str | None, name: str | None) -> str:
    """The dataset a sequence belongs to, for the ranking tables (used when none is given).

    By format (``kitti`` → KITTI, ``7scenes`` → 7-Scenes, ``tsukuba`` → Tsukuba, ``icl-nuim`` → ICL-NUIM,
    ``tum-monovo`` → TUM monoVO, ``tum-rgbd`` → TUM RGB-D, ``euroc`` → EuRoC, ``lsd-slam`` → LSD-SLAM,
    ``synthetic``); for image folders and videos by name (``tsukuba``, ``icl``, ``monovo``/``mono``/``tum``,
    ``lsd``, ``kitti``, ``7scenes``, ``euroc`` in it), else the format itself.
    """
    fmt = (format or "").lower()
    low = (name or "").lower()
    fixed = {"kitti": "KITTI", "7scenes": "7-Scenes", "synthetic": "synthetic", "tum-rgbd": "TUM RGB-D",
             "tsukuba": "Tsukuba", "icl-nuim": "ICL-NUIM", "tum-monovo": "TUM monoVO", "euroc": "EuRoC",
             "lsd-slam": "LSD-SLAM"}  # fmt: skip
    if fmt in fixed:
        return fixed[fmt]
    for needle, label in (("tsukuba", "Tsukuba"), ("icl", "ICL-NUIM"), ("monovo", "TUM monoVO"),
                          ("mono", "TUM monoVO"), ("tum", "TUM monoVO"), ("lsd", "LSD-SLAM"),
                          ("kitti", "KITTI"), ("7scenes", "7-Scenes"), ("euroc", "EuRoC")):  # fmt: skip
        if needle in low:
            return label
    return fmt or "unknown"


def length_unit(format: str | None, name: str | None) -> str:
    """The ground truth's length unit when the sequences file gives none: ``"cm"`` for New Tsukuba read as
    an image folder (its ``groundtruth.txt`` keeps the dataset's centimetres; the ``tsukuba`` reader converts
    to metres), else ``"m"``."""
    fmt = (format or "").lower()
    if fmt in ("image-folder", "") and "tsukuba" in (name or "").lower():
        return "cm"
    return "m"


@dataclass(frozen=True)
class ResolvedSequence:
    """A :class:`SequenceSpec` after opening it once: the run-folder name, format and dataset group."""

    spec: SequenceSpec
    path: str
    name: str
    format: str | None
    dataset: str
    unit: str = "m"
    open_error: str | None = None


def resolve_sequence(
    spec: SequenceSpec, default_format: str | None, default_intrinsics: str | None
) -> ResolvedSequence:
    """Find the name and format of a sequence without reading frames (a synthetic one is not rendered).

    A sequence that cannot be opened still resolves (named after its path, ``open_error`` set): its runs
    will fail and be recorded like any other crash.
    """
    fmt = spec.format or default_format
    raw = spec.path
    if raw.startswith("synthetic"):
        from dmtrack.datasets.registry import _parse_synthetic

        path = raw
        try:
            opts = _parse_synthetic(raw)
            name = str(opts.get("name") or f"synthetic-seed{int(opts.get('seed', 0))}")
            err = None
        except (DmtrackError, ValueError) as e:
            name, err = "synthetic", str(e)
        fmt = "synthetic"
    else:
        path = str(Path(raw).expanduser().resolve())
        try:
            from dmtrack.datasets import open_sequence

            seq = open_sequence(path, format=fmt, intrinsics=spec.intrinsics or default_intrinsics)
            name, fmt, err = seq.name, seq.format, None
        except (DmtrackError, OSError, ValueError) as e:
            name, err = Path(path).name or "sequence", str(e)
    final_name = safe_name(spec.name or name)
    dataset = spec.dataset or dataset_label(fmt, name)
    return ResolvedSequence(spec, path, final_name, fmt, dataset, spec.unit or length_unit(fmt, name), err)


# ================================================================================================ tasks
@dataclass(frozen=True)
class RunTask:
    """One run of the grid (picklable; sent to worker processes or Dask workers).

    ``spec`` defines the run and is compared on resume; ``threads`` limits numba/OpenCV threads in the
    worker (``None``: leave them alone).
    """

    bench_dir: str
    sequence_name: str
    feature: str
    spec: dict[str, Any]
    dataset: str
    threads: int | None = 1
    unit: str = "m"
    seed_dir: str | None = None

    @property
    def key(self) -> str:
        """``"<sequence>/<feature>"``, or ``"<sequence>/<feature>/seed-<S>"`` in a bench with several seeds."""
        base = f"{self.sequence_name}/{self.feature_dir}"
        return base if self.seed_dir is None else f"{base}/{self.seed_dir}"

    @property
    def feature_dir(self) -> str:
        return safe_name(self.feature)

    @property
    def run_dir(self) -> Path:
        """``DIR/runs/<sequence>/<feature>`` (one seed) or ``DIR/runs/<sequence>/<feature>/seed-<S>``."""
        d = Path(self.bench_dir) / "runs" / self.sequence_name / self.feature_dir
        return d if self.seed_dir is None else d / self.seed_dir


def _normalise(obj: Any) -> Any:
    """JSON round trip: tuples → lists, keys → str (so that a spec compares equal to its file)."""
    return json.loads(json.dumps(obj, sort_keys=True))


def make_spec(
    seq: ResolvedSequence,
    feature: str,
    *,
    start: int,
    max_frames: int | None,
    seed: int | None,
    r_l: float | None,
    format: str | None,
    intrinsics: str | None,
    config: dict[str, Any],
    overrides: Sequence[str],
    depth_images: bool,
    pointcloud: bool,
) -> dict[str, Any]:
    """The run spec stored in ``spec.json`` and compared on resume (see the module docstring)."""
    s = seq.spec
    return _normalise(
        {
            "spec_version": SPEC_VERSION,
            "sequence": seq.path,
            "sequence_name": seq.name,
            "format": s.format or format,
            "intrinsics": s.intrinsics or intrinsics,
            "feature": feature,
            "start": int(s.start if s.start is not None else start),
            "max_frames": s.max_frames if s.max_frames is not None else max_frames,
            "seed": seed,
            "r_l": s.r_l if s.r_l is not None else r_l,
            "config": config,
            "overrides": list(overrides),
            "depth_images": bool(depth_images),
            "pointcloud": bool(pointcloud),
            "dmtrack_version": __version__,
        }
    )


def plan_grid(
    sequences: Sequence[SequenceSpec | str],
    features: Sequence[str],
    out_dir: str | Path,
    *,
    start: int = 0,
    max_frames: int | None = None,
    seed: int | None = None,
    r_l: float | None = None,
    format: str | None = None,
    intrinsics: str | None = None,
    config: Any = None,
    overrides: Sequence[str] = (),
    depth_images: bool = True,
    pointcloud: bool = True,
    threads_per_job: int = 1,
    seeds: Sequence[int] | str | None = None,
) -> tuple[list[RunTask], list[ResolvedSequence]]:
    """The tasks of the grid ``sequences × features`` (× ``seeds``; sequence-major order) and the resolved
    sequences.

    ``config`` is a :class:`~dmtrack.odometry.config.VOConfig` (default: LSD-SLAM's) to which
    ``overrides`` (``"section.key=value"``) are applied; both are validated here.  Sequence names that
    collide get ``-2``, ``-3``… appended.  ``seeds`` (a list or ``"0-2,5"``) runs every cell once per seed,
    each into ``<feature>/seed-<S>/`` when there are several (``seed`` and ``seeds`` exclude each other; one
    seed is the same as ``seed``).
    """
    from dmtrack.odometry.config import VOConfig

    seed_list = _seed_list(seed, seeds)
    if not features:
        raise InputError("no features given")
    if not sequences:
        raise InputError("no sequences given")
    if len(set(features)) != len(features):
        raise InputError(f"a feature is listed twice: {list(features)}")
    cfg = config if config is not None else VOConfig()
    if overrides:
        cfg = cfg.with_overrides(*overrides)
    cfg_dict = _normalise(cfg.to_dict())
    bench_dir = str(Path(out_dir).expanduser().resolve())
    resolved: list[ResolvedSequence] = []
    used: set[str] = set()
    for s in sequences:
        spec = s if isinstance(s, SequenceSpec) else SequenceSpec(str(s))
        rs = resolve_sequence(spec, format, intrinsics)
        name, k = rs.name, 2
        while name in used:
            name, k = f"{rs.name}-{k}", k + 1
        used.add(name)
        resolved.append(replace(rs, name=name))
    tasks = []
    for rs in resolved:
        for f in features:
            for s in seed_list:
                spec = make_spec(
                    rs, f, start=start, max_frames=max_frames, seed=s, r_l=r_l, format=format,
                    intrinsics=intrinsics, config=cfg_dict, overrides=overrides, depth_images=depth_images,
                    pointcloud=pointcloud,
                )  # fmt: skip
                sub = seed_dir_name(s) if len(seed_list) > 1 and s is not None else None
                tasks.append(RunTask(bench_dir, rs.name, f, spec, rs.dataset, threads_per_job, rs.unit, sub))
    return tasks, resolved


def _seed_list(seed: int | None, seeds: Sequence[int] | str | None) -> list[int | None]:
    """The seeds of every cell: ``[seed]`` (``None``: the configuration's) or the parsed ``seeds``."""
    if seeds is None:
        return [seed]
    if seed is not None:
        raise InputError("give either seed (one seed) or seeds (several), not both")
    return list(parse_seeds(seeds))


# ============================================================================================ file helpers
def read_json(path: Path) -> Any:
    """The JSON in ``path``, or ``None`` if it is missing or unreadable."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _write_json(path: Path, data: Any) -> None:
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:8]}.tmp")
    tmp.write_text(json.dumps(data, indent=2, default=str) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def run_state(task: RunTask) -> str:
    """``"done"`` (metrics.json and an equal spec.json), ``"failed"`` (error.json and an equal spec) or
    ``"todo"``."""
    d = task.run_dir
    if not same_spec(read_json(d / "spec.json"), task.spec):
        return "todo"
    if isinstance(read_json(d / "metrics.json"), dict):
        return "done"
    if (d / "error.json").is_file():
        return "failed"
    return "todo"


def effective_seed(spec: Any) -> Any:
    """The seed a run with this spec uses: its ``seed``, else its configuration's (``None`` if unknown)."""
    if not isinstance(spec, dict):
        return None
    if spec.get("seed") is not None:
        return spec["seed"]
    cfg = spec.get("config")
    return cfg.get("seed", 0) if isinstance(cfg, dict) else None


def same_spec(stored: Any, wanted: dict[str, Any]) -> bool:
    """Whether a stored ``spec.json`` defines the same run as ``wanted``: equal, except that the seed compares
    as :func:`effective_seed` (no seed with a configuration seed 0 is the same run as seed 0)."""
    if not isinstance(stored, dict):
        return False
    if stored == wanted:
        return True
    a, b = dict(stored), dict(wanted)
    a["seed"], b["seed"] = effective_seed(stored), effective_seed(wanted)
    return a == b


def _temp_dir(task: RunTask) -> Path:
    host = safe_name(socket.gethostname())[:40]
    final = task.run_dir
    tmp = final.with_name(f".{final.name}.tmp-{host}-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    tmp.mkdir(parents=True)
    return tmp


def _commit(tmp: Path, final: Path) -> None:
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
        for child in sorted(trash.iterdir()):
            if child.is_dir() and SEED_DIR.match(child.name) and not (final / child.name).exists():
                os.replace(child, final / child.name)
        shutil.rmtree(trash, ignore_errors=True)


_STALE_SEED_DIR = re.compile(r"^\.seed-\d+\.(?:tmp|trash)-")


def _is_stale(p: Path) -> bool:
    return p.name.startswith(".") and (".tmp-" in p.name or ".trash-" in p.name)


def clean_stale(bench_dir: str | Path) -> list[Path]:
    """Delete the temporary / trash folders a killed bench left in ``DIR/runs/*/`` and, for the runs of
    several seeds, in ``DIR/runs/*/*/``; returns them."""
    removed = []
    runs = Path(bench_dir) / "runs"
    if not runs.is_dir():
        return removed
    for seq_dir in runs.iterdir():
        if not seq_dir.is_dir():
            continue
        for d in seq_dir.iterdir():
            if _is_stale(d):
                shutil.rmtree(d, ignore_errors=True) if d.is_dir() else d.unlink(missing_ok=True)
                removed.append(d)
            elif d.is_dir() and not d.name.startswith("."):
                for sub in d.iterdir():
                    if sub.is_dir() and _STALE_SEED_DIR.match(sub.name):
                        shutil.rmtree(sub, ignore_errors=True)
                        removed.append(sub)
    return removed


def machine_info() -> dict[str, Any]:
    """Platform, CPU (model and count), Python and dmtrack versions of this machine."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
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


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


# ================================================================================================ worker
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


def _init_worker(threads: int, parent_pid: int | None = None) -> None:
    """Process-pool initializer: runs in each fresh worker before any task (and before numba is imported).

    With ``parent_pid``, a daemon thread ends the worker as soon as its parent is gone (a bench killed with
    SIGKILL, or whose pool was torn down): an orphaned worker must not go on computing and writing into DIR.
    """
    for var in THREAD_ENV_VARS:
        os.environ[var] = str(max(1, int(threads)))
    os.environ.setdefault("MPLBACKEND", "Agg")
    if parent_pid is not None:
        import threading

        def watch() -> None:
            while os.getppid() == parent_pid:
                time.sleep(0.5)
            os._exit(1)

        threading.Thread(target=watch, name="dmtrack-parent-watch", daemon=True).start()


def _terminate_pool(pool: Any) -> None:
    """Stop a ProcessPoolExecutor now: cancel what is queued and kill the workers mid-run."""
    procs = list((getattr(pool, "_processes", None) or {}).values())  # private, but the only handle on them
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    for proc in procs:
        proc.join(timeout=5)


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


class _WarmupSequence:
    """A tiny in-memory sequence (blurred noise seen by a camera moving sideways) for :func:`warm_up`."""

    name = "warm-up"
    format = "warm-up"

    def __init__(self, n_frames: int = 6, width: int = 128, height: int = 96) -> None:
        import cv2
        import numpy as np

        from dmtrack.geometry.camera import PinholeCamera

        rng = np.random.default_rng(0)
        big = rng.uniform(0.0, 255.0, size=(height, width + 2 * n_frames)).astype(np.float32)
        big = cv2.GaussianBlur(big, (0, 0), 1.5)
        big = cv2.normalize(big, None, 0, 255, cv2.NORM_MINMAX)
        self._images = [np.ascontiguousarray(big[:, 2 * k : 2 * k + width]).astype(np.uint8) for k in range(n_frames)]
        self.camera = PinholeCamera(0.8 * width, 0.8 * width, (width - 1) / 2, (height - 1) / 2, width, height)
        self.width, self.height = width, height
        self.timestamps = np.arange(n_frames, dtype=np.float64) / 30.0
        self.groundtruth = None
        self.has_groundtruth = False

    def __len__(self) -> int:
        return len(self._images)

    def __getitem__(self, index: int) -> Any:
        from dmtrack.datasets.base import Frame

        return Frame(index, float(self.timestamps[index]), self._images[index])

    def __iter__(self) -> Any:
        return (self[i] for i in range(len(self)))


_WARMED: set[str] = set()


def warm_up(feature: str, config: Any = None) -> float:
    """Run the odometry once on a tiny in-memory sequence with ``feature`` so that numba's kernels are
    compiled or loaded from its cache *before* a timed run; returns the seconds spent (0 if this process
    has warmed up ``feature`` already).  Failures are ignored: the real run reports them."""
    if feature in _WARMED:
        return 0.0
    t0 = time.perf_counter()
    try:
        from dmtrack.api import track

        track(_WarmupSequence(), feature, config, progress=False)
    except Exception:  # noqa: BLE001 - the real run will raise and record the same problem
        pass
    _WARMED.add(feature)
    return time.perf_counter() - t0


def _groundtruth_in_range(seq: Any, start: int, stop: int) -> Any:
    gt = seq.groundtruth
    if gt is None or len(gt) == 0:
        return None
    ts = seq.timestamps[start:stop]
    if len(ts) == 0:
        return None
    lo, hi = float(ts.min()), float(ts.max())
    keep = (gt.timestamps >= lo - 1e-6) & (gt.timestamps <= hi + 1e-6)
    return gt[keep]


def _run_info(task: RunTask, status: str, t0: float, started: str) -> dict[str, Any]:
    numba = sys.modules.get("numba")
    return {
        "numba_threads": None if numba is None else int(numba.get_num_threads()),
        "numba_max_threads": None if numba is None else int(numba.config.NUMBA_NUM_THREADS),
        **machine_info(),
        "pid": os.getpid(),
        "dataset": task.dataset,
        "unit": task.unit,
        "status": status,
        "started": started,
        "finished": _now(),
        "elapsed_s": time.perf_counter() - t0,
        "threads": task.threads,
    }


def execute_task(task: RunTask) -> Outcome:
    """Run one task and commit its folder; never raises for a failing run (only for an interrupt).

    Returns
    -------
    dict
        ``key``, ``status`` (``"ok"``, ``"lost"`` or ``"failed"``), ``tracked_frames``, ``total_frames``,
        ``lost_at``, ``message`` (the error for a failed run), ``elapsed_s``, ``run_dir``.
    """
    limit_threads(task.threads)  # first: sizes numba's pool if this process has not imported numba yet

    from dmtrack.api import run_to_directory
    from dmtrack.datasets import open_sequence
    from dmtrack.io.trajectory import write_tum
    from dmtrack.odometry.config import VOConfig

    t0 = time.perf_counter()
    started = _now()
    spec = task.spec
    tmp = _temp_dir(task)
    counter = _ProgressSink()
    try:
        _write_json(tmp / "spec.json", spec)
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
            )
        except Exception as e:  # a crash of this run must not stop the grid
            (tmp / "metrics.json").unlink(missing_ok=True)
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
                "elapsed_s": time.perf_counter() - t0,
            }
            _write_json(tmp / "error.json", error)
            _write_json(tmp / "run_info.json", _run_info(task, "failed", t0, started))
            _commit(tmp, task.run_dir)
            return {
                "key": task.key, "status": "failed", "tracked_frames": counter.tracked, "total_frames": None,
                "lost_at": None, "message": f"{type(e).__name__}: {e}", "elapsed_s": error["elapsed_s"],
                "run_dir": str(task.run_dir),
            }  # fmt: skip

        # evaluation details for the report (per-length RPE, Sim(3) alignment) and the ground truth it used
        m = result.metrics
        stop = spec["start"] + result.total_frames
        gt = _groundtruth_in_range(seq, spec["start"], stop)
        if gt is not None:
            write_tum(tmp / "groundtruth.txt", gt)
            try:
                from dmtrack.evaluation import evaluate

                ev = evaluate(gt, result.trajectory, max_diff=0.01, r_l=float(m["r_l"]), align="sim3")
            except (DmtrackError, ValueError) as e:
                ev = {"error": str(e)}
            _write_json(tmp / "evaluation.json", ev)
        status = "lost" if m.get("lost_at") is not None else "ok"
        info = _run_info(task, status, t0, started)
        info["processed_frames"] = int(result.vo.total_frames) if result.vo is not None else result.total_frames
        info["warmup_s"] = warmup_s
        _write_json(tmp / "run_info.json", info)
        _commit(tmp, task.run_dir)
        return {
            "key": task.key, "status": status, "tracked_frames": m.get("tracked_frames"),
            "total_frames": m.get("total_frames"), "lost_at": m.get("lost_at"), "message": m.get("lost_reason"),
            "elapsed_s": info["elapsed_s"], "run_dir": str(task.run_dir),
        }  # fmt: skip
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def record_failure(task: RunTask, message: str, details: str = "") -> Outcome:
    """Record a run that failed outside :func:`execute_task` (its worker died, it could not be sent…) as
    ``error.json`` in its folder (written by the calling process)."""
    tmp = _temp_dir(task)
    try:
        _write_json(tmp / "spec.json", task.spec)
        _write_json(
            tmp / "error.json",
            {"key": task.key, "sequence": task.spec["sequence"], "feature": task.feature, "type": "WorkerError",
             "message": message, "traceback": details, "tracked_frames": None, "last_frame": None},
        )  # fmt: skip
        _write_json(tmp / "run_info.json", {**machine_info(), "status": "failed", "dataset": task.dataset,
                                            "unit": task.unit, "finished": _now(), "recorded_by": "bench"})  # fmt: skip
        _commit(tmp, task.run_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return {"key": task.key, "status": "failed", "tracked_frames": None, "total_frames": None, "lost_at": None,
            "message": message, "elapsed_s": None, "run_dir": str(task.run_dir)}  # fmt: skip


# =============================================================================================== backends
OnDone = Callable[[RunTask, Outcome], None]


def run_tasks_inprocess(tasks: Iterable[RunTask], on_done: OnDone) -> None:
    """Run the tasks one after the other in this process."""
    for t in tasks:
        on_done(t, execute_task(replace(t, threads=None)))


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


# ================================================================================================ the bench
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
    outcomes : per executed key, the outcome dict of :func:`execute_task`.
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


def _write_bench_json(out: Path, tasks: list[RunTask], resolved: list[ResolvedSequence], features: Sequence[str],
                      options: dict[str, Any]) -> None:  # fmt: skip
    path = out / "bench.json"
    old = read_json(path) or {}
    data = {
        "dmtrack_version": __version__,
        "created": old.get("created", _now()),
        "updated": _now(),
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
        "options": _normalise(options),
        "machine": machine_info(),
        "command": sys.argv if sys.argv and sys.argv[0] else None,
    }
    _write_json(path, data)


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
) -> BenchResult:
    """Run the grid ``sequences × features`` into ``out_dir`` and write the report.

    Parameters
    ----------
    sequences : paths / ``synthetic:…`` strings or :class:`SequenceSpec` (per-sequence options).
    features : feature names (see ``dmtrack features``).
    out_dir : the bench folder ``DIR`` (see the module docstring for its layout).
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

    Returns
    -------
    BenchResult
    """
    if jobs < 0:
        raise InputError(f"jobs must be ≥ 0, got {jobs}")
    if threads_per_job < 1:
        raise InputError(f"threads per job must be ≥ 1, got {threads_per_job}")
    out = Path(out_dir).expanduser().resolve()
    seed_list = _seed_list(seed, seeds)
    tasks, resolved = plan_grid(
        sequences, features, out, start=start, max_frames=max_frames, seed=seed, r_l=r_l, format=format,
        intrinsics=intrinsics, config=config, overrides=overrides, depth_images=depth_images,
        pointcloud=pointcloud, threads_per_job=threads_per_job, seeds=seeds,
    )  # fmt: skip
    (out / "runs").mkdir(parents=True, exist_ok=True)
    clean_stale(out)
    options = {"start": start, "max_frames": max_frames, "seed": seed,
               "seeds": None if seeds is None else list(seed_list), "r_l": r_l, "format": format,
               "intrinsics": intrinsics, "overrides": list(overrides), "depth_images": depth_images,
               "pointcloud": pointcloud, "jobs": jobs, "scheduler": scheduler,
               "threads_per_job": threads_per_job}  # fmt: skip
    _write_bench_json(out, tasks, resolved, features, options)

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
