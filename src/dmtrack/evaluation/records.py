"""The runs of a bench folder as records: reading ``runs/`` (:func:`collect_runs`) and one flat row per run.

:func:`collect_runs` reads the finished runs under ``DIR/runs/<sequence>/<feature>/`` and, for a bench with
several seeds, ``DIR/runs/<sequence>/<feature>/seed-<S>/`` (the layout is :mod:`dmtrack.io.bench_layout`):
those with a ``metrics.json``, or an ``error.json`` for a crashed run; unfinished folders are ignored.
:func:`results_rows` makes the rows of ``results.csv`` (:data:`RESULT_COLUMNS`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dmtrack.evaluation.rankings import ordered_unique, tracked_fraction, value_of
from dmtrack.io.bench_layout import (
    BENCH_JSON,
    ERROR_JSON,
    EVALUATION_JSON,
    METRICS_JSON,
    RUN_INFO_JSON,
    RUNS_DIR,
    SEED_DIR,
    SPEC_JSON,
    dataset_label,
    effective_seed,
    length_unit,
    read_json,
)

#: Columns of ``results.csv`` (one row per run).
RESULT_COLUMNS = (
    "dataset", "sequence", "feature", "status", "total_frames", "processed_frames", "tracked_frames",
    "tracked_fraction", "lost_at", "lost_reason", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "ate_rmse",
    "ate_scale", "matched_poses", "rotation_gain_x", "rotation_gain_y", "rotation_gain_z", "gt_path_length", "r_l",
    "fps", "feature_ms", "io_ms", "tracking_ms", "mapping_ms", "total_ms", "wall_s", "keyframes", "points", "channels",
    "width", "height", "start", "seed", "error", "host", "run_dir",
)  # fmt: skip


# =================================================================================================== runs
@dataclass
class RunRecord:
    """One finished run of a bench folder.

    Attributes
    ----------
    sequence, feature : names (the run folder is ``runs/<sequence>/<feature>``, or
        ``runs/<sequence>/<feature>/seed-<S>`` in a bench with several seeds).
    path : the run folder.
    spec, metrics, error, evaluation, info : the contents of ``spec.json``, ``metrics.json``,
        ``error.json``, ``evaluation.json`` and ``run_info.json`` (``None`` / ``{}`` where absent).
    dataset : the dataset group.
    unit : the ground truth's length unit (per-metre values are per this unit).
    seed : the seed of the random depth initialisation the run used (``None`` if not recorded).
    key : the run folder relative to ``runs/`` (``"<sequence>/<feature>[/seed-<S>]"``).
    """

    sequence: str
    feature: str
    path: Path
    spec: dict[str, Any]
    metrics: dict[str, Any] | None
    error: dict[str, Any] | None
    evaluation: dict[str, Any] | None
    info: dict[str, Any]
    dataset: str
    unit: str = "m"
    seed: int | None = None
    key: str = ""

    def __post_init__(self) -> None:
        if not self.key:
            self.key = f"{self.sequence}/{self.path.name}"

    @property
    def status(self) -> str:
        """``"ok"`` (tracked to the end), ``"lost"`` (tracking lost) or ``"failed"`` (crashed)."""
        if self.metrics is None:
            return "failed"
        return "lost" if self.metrics.get("lost_at") is not None else "ok"


def _run_seed(spec: dict[str, Any], metrics: dict[str, Any] | None) -> int | None:
    """The seed a run used: its spec's, else the one its metrics.json records, else its configuration's."""
    for v in (spec.get("seed"), (metrics or {}).get("seed"), effective_seed(spec) if spec else None):
        if v is not None and not isinstance(v, bool):
            try:
                return int(v)
            except (TypeError, ValueError):
                continue
    return None


def collect_runs(bench_dir: str | Path) -> list[RunRecord]:
    """The finished runs of a bench folder, in the bench's sequence and feature order, then by seed.

    A run folder (``runs/<sequence>/<feature>/`` or, with several seeds, ``runs/<sequence>/<feature>/seed-<S>/``)
    counts when it holds a readable ``metrics.json`` (finished, possibly with a tracking loss) or
    ``error.json`` (crashed); hidden (temporary) folders and unfinished runs are ignored.  A feature folder
    that holds both a run and ``seed-<S>/`` runs (benched with one seed and with several) gives the runs of
    the last bench's grid (``bench.json``): the single run if that grid lists it, else the seeds' runs.
    """
    root = Path(bench_dir)
    bench = read_json(root / BENCH_JSON) or {}
    datasets = {s.get("name"): s.get("dataset") for s in bench.get("sequences", []) if isinstance(s, dict)}
    units = {s.get("name"): s.get("unit") for s in bench.get("sequences", []) if isinstance(s, dict)}
    seq_order = [s.get("name") for s in bench.get("sequences", []) if isinstance(s, dict)]
    feat_order = list(bench.get("features", []))
    planned = set(bench.get("runs") or [])
    records = []
    runs = root / RUNS_DIR
    if not runs.is_dir():
        return []

    def load(seq_dir: Path, run_dir: Path, key: str) -> RunRecord | None:
        metrics = read_json(run_dir / METRICS_JSON)
        error = read_json(run_dir / ERROR_JSON) if metrics is None else None
        if not isinstance(metrics, dict) and not isinstance(error, dict):
            return None
        spec = read_json(run_dir / SPEC_JSON) or {}
        spec = spec if isinstance(spec, dict) else {}
        info = read_json(run_dir / RUN_INFO_JSON) or {}
        evaluation = read_json(run_dir / EVALUATION_JSON)
        m = metrics if isinstance(metrics, dict) else {}
        feature = str(spec.get("feature") or m.get("feature") or key.split("/")[1])
        if spec.get("slam"):  # a SLAM cell of a bench with --modes (experiments.grid.mode_label)
            feature += "+slam"
        if spec.get("window"):  # a window cell
            feature += "+window"
        fmt, name = m.get("format") or spec.get("format"), m.get("sequence") or seq_dir.name
        dataset = datasets.get(seq_dir.name) or info.get("dataset") or dataset_label(fmt, name)
        unit = units.get(seq_dir.name) or info.get("unit") or length_unit(fmt, name)
        return RunRecord(seq_dir.name, feature, run_dir, spec, metrics if isinstance(metrics, dict) else None,
                         error if isinstance(error, dict) else None,
                         evaluation if isinstance(evaluation, dict) else None, info, str(dataset), str(unit),
                         _run_seed(spec, m), key)  # fmt: skip

    for seq_dir in sorted(runs.iterdir()):
        if not seq_dir.is_dir() or seq_dir.name.startswith("."):
            continue
        for feat_dir in sorted(seq_dir.iterdir()):
            if not feat_dir.is_dir() or feat_dir.name.startswith("."):
                continue
            key = f"{seq_dir.name}/{feat_dir.name}"
            single = load(seq_dir, feat_dir, key)
            seeded = [
                rec
                for d in sorted(feat_dir.iterdir())
                if d.is_dir() and SEED_DIR.match(d.name)
                for rec in [load(seq_dir, d, f"{key}/{d.name}")]
                if rec is not None
            ]
            if single is not None and seeded:
                if key in planned:
                    seeded = []
                else:
                    single = None
            records += ([single] if single is not None else []) + seeded

    def order(name: str, known: list[str]) -> tuple[int, str]:
        return (known.index(name), "") if name in known else (len(known), name)

    records.sort(key=lambda r: (order(r.sequence, seq_order), order(r.feature, feat_order),
                                (0, r.seed) if r.seed is not None else (1, 0), r.key))  # fmt: skip
    return records


def feature_order(records: Sequence[RunRecord], bench_dir: str | Path | None = None) -> list[str]:
    """Features in the bench's order (``bench.json``), then any others in order of appearance."""
    known: list[str] = []
    if bench_dir is not None:
        known = list((read_json(Path(bench_dir) / BENCH_JSON) or {}).get("features", []))
    present = ordered_unique(r.feature for r in records)
    return [f for f in known if f in present] + [f for f in present if f not in known]


def results_rows(records: Iterable[RunRecord]) -> list[dict[str, Any]]:
    """One flat row per run with the :data:`RESULT_COLUMNS` (missing values are ``None``)."""
    rows = []
    for r in records:
        m = r.metrics or {}
        ev = r.evaluation or {}
        row: dict[str, Any] = {c: None for c in RESULT_COLUMNS}
        row.update({k: m.get(k) for k in RESULT_COLUMNS if k in m})
        row.update(dataset=r.dataset, sequence=r.sequence, feature=r.feature, status=r.status, seed=r.seed,
                   run_dir=str(r.path), host=r.info.get("host"))  # fmt: skip
        if r.metrics is None:
            row["start"] = r.spec.get("start")
            err = r.error or {}
            row["error"] = f"{err.get('type', 'error')}: {err.get('message', '')}".strip()
        else:
            row["processed_frames"] = r.info.get("processed_frames")
            row["tracked_fraction"] = tracked_fraction(m)
            parts = [value_of(m, k) for k in ("feature_ms", "io_ms", "tracking_ms", "mapping_ms")]
            row["total_ms"] = sum(p for p in parts if p is not None) if any(p is not None for p in parts) else None
            row["gt_path_length"] = ev.get("gt_path_length")
            gain = m.get("rotation_gain") or [None, None, None]  # a calibration check (evaluation.rotation_gain)
            row.update(rotation_gain_x=gain[0], rotation_gain_y=gain[1], rotation_gain_z=gain[2])
            if ev.get("error"):
                row["error"] = f"evaluation: {ev['error']}"
            elif m.get("evaluation_error"):
                row["error"] = f"evaluation: {m['evaluation_error']}"
        rows.append(row)
    return rows


__all__ = ["RESULT_COLUMNS", "RunRecord", "collect_runs", "feature_order", "results_rows"]
