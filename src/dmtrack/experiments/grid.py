"""The grid of a bench: its sequences (:class:`SequenceSpec`, the sequences file), its runs (:class:`RunTask`).

:func:`plan_grid` turns ``sequences × features`` (× seeds) into one :class:`RunTask` per run, each with the spec
that defines it (:func:`make_spec`: compared with a run folder's ``spec.json`` on resume, see
:mod:`dmtrack.experiments.store`) and its run folder in the bench folder (:mod:`dmtrack.io.bench_layout`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from dmtrack import __version__
from dmtrack.errors import DmtrackError, InputError
from dmtrack.io.bench_layout import (
    RUNS_DIR,
    dataset_label,
    length_unit,
    parse_seeds,
    safe_name,
    seed_dir_name,
)

SPEC_VERSION = 1


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
        """The feature's folder name (:func:`~dmtrack.io.bench_layout.safe_name` of the feature)."""
        return safe_name(self.feature)

    @property
    def run_dir(self) -> Path:
        """``DIR/runs/<sequence>/<feature>`` (one seed) or ``DIR/runs/<sequence>/<feature>/seed-<S>``."""
        d = Path(self.bench_dir) / RUNS_DIR / self.sequence_name / self.feature_dir
        return d if self.seed_dir is None else d / self.seed_dir


def normalise(obj: Any) -> Any:
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
    device: str | None = None,
    slam: bool = False,
    window: bool = False,
) -> dict[str, Any]:
    """The run spec stored in ``spec.json`` and compared on resume (see :mod:`dmtrack.experiments.store`).

    ``device`` (where a network feature runs), ``slam`` and ``window`` (a cell of the ``window`` mode) enter the spec
    only when given, so that the folders of benches made before they existed still resume."""
    s = seq.spec
    extra: dict[str, Any] = {}
    if device is not None:
        extra["device"] = device
    if slam:
        extra["slam"] = True
    if window:
        extra["window"] = True
    return normalise(
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
            **extra,
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
    device: str | None = None,
    modes: Sequence[str] = ("vo",),
) -> tuple[list[RunTask], list[ResolvedSequence]]:
    """The tasks of the grid ``sequences × features`` (× ``seeds``; sequence-major order) and the resolved
    sequences.

    ``config`` is a :class:`~dmtrack.odometry.config.VOConfig` (default: LSD-SLAM's) to which
    ``overrides`` (``"section.key=value"``) are applied; both are validated here.  Sequence names that
    collide get ``-2``, ``-3``… appended.  ``seeds`` (a list or ``"0-2,5"``) runs every cell once per seed,
    each into ``<feature>/seed-<S>/`` when there are several (``seed`` and ``seeds`` exclude each other; one
    seed is the same as ``seed``).  ``modes`` (``"vo"``, ``"slam"``) runs every feature once per mode; a
    ``"slam"`` cell is labelled ``<feature>+slam`` (:func:`mode_label`).  ``device``: where the network features
    run (:mod:`dmtrack.features.device`; None: their default).
    """
    from dmtrack.odometry.config import VOConfig

    cell_seeds = seed_list(seed, seeds)
    if not features:
        raise InputError("no features given")
    if not sequences:
        raise InputError("no sequences given")
    if len(set(features)) != len(features):
        raise InputError(f"a feature is listed twice: {list(features)}")
    modes = check_modes(modes)
    cfg = config if config is not None else VOConfig()
    if overrides:
        cfg = cfg.with_overrides(*overrides)
    cfg_dict = normalise(cfg.to_dict())
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
            for mode in modes:
                for s in cell_seeds:
                    spec = make_spec(
                        rs, f, start=start, max_frames=max_frames, seed=s, r_l=r_l, format=format,
                        intrinsics=intrinsics, config=_mode_config(cfg_dict, mode), overrides=overrides,
                        depth_images=depth_images, pointcloud=pointcloud, device=device, slam=mode == "slam",
                        window=mode == "window",
                    )  # fmt: skip
                    sub = seed_dir_name(s) if len(cell_seeds) > 1 and s is not None else None
                    tasks.append(RunTask(bench_dir, rs.name, mode_label(f, mode), spec, rs.dataset, threads_per_job,
                                         rs.unit, sub))  # fmt: skip
    return tasks, resolved


#: The modes of a bench cell: the odometry as configured, with the SLAM back end (docs/slam.md), or with the sliding
#: window (docs/window.md; the configuration's ``window.size``, or :data:`WINDOW_SIZE` when it has none).
MODES = ("vo", "slam", "window")

#: The window size of a ``window`` cell whose configuration has none.
WINDOW_SIZE = 5


def _mode_config(cfg: dict[str, Any], mode: str) -> dict[str, Any]:
    """The configuration of a cell of ``mode``: a ``window`` cell has its window on."""
    if mode != "window" or cfg["window"]["size"]:
        return cfg
    return {**cfg, "window": {**cfg["window"], "size": WINDOW_SIZE}}


def check_modes(modes: Sequence[str]) -> tuple[str, ...]:
    """``modes`` validated (known, not repeated, at least one)."""
    out = tuple(str(m).strip().lower() for m in modes)
    if not out:
        raise InputError("no mode given (vo, slam, window)")
    bad = [m for m in out if m not in MODES]
    if bad or len(set(out)) != len(out):
        raise InputError(f"modes must be distinct values of {', '.join(MODES)}, got {list(modes)}")
    return out


def mode_label(feature: str, mode: str) -> str:
    """The cell's name in the bench (its folder, its rows): ``feature``, or ``feature+slam`` for SLAM."""
    return feature if mode == "vo" else f"{feature}+{mode}"


def seed_list(seed: int | None, seeds: Sequence[int] | str | None) -> list[int | None]:
    """The seeds of every cell: ``[seed]`` (``None``: the configuration's) or the parsed ``seeds``."""
    if seeds is None:
        return [seed]
    if seed is not None:
        raise InputError("give either seed (one seed) or seeds (several), not both")
    return list(parse_seeds(seeds))
