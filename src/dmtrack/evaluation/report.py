"""The benchmark report: ``report.md``, ``results.csv``, ``tables/*.csv`` and ``figures/*.png`` of a bench folder.

:func:`write_report` reads the finished runs under ``DIR/runs/<sequence>/<feature>/`` (those with a
``metrics.json``, or an ``error.json`` for a crashed run; unfinished folders are ignored) and writes

* ``results.csv`` — one row per run (:data:`RESULT_COLUMNS`);
* ``tables/rankings.csv`` (Tables 2–5), ``tables/ranks_per_sequence.csv``, ``tables/averages.csv``
  (Table 6), ``tables/timings.csv`` (Table 7) — one block of rows per dataset;
* ``figures/`` — RPE against path length per sequence (Figure 1), accuracy against time per dataset
  (Figure 5), keyframe depth maps per sequence (Figure 4), top-view trajectories per sequence;
* ``report.md`` — all of it as a results section, figures linked relatively.

Sequences are grouped into datasets (one ranking table each) by the ``dataset`` given in the sequences
file, else by format and name (:func:`dmtrack.experiments.runner.dataset_label`).  Rankings, averages and
timings are computed by :mod:`dmtrack.evaluation.rankings` (missing values are explained there).
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack import __version__
from dmtrack.evaluation.rankings import (
    CRITERIA,
    FeatureAverages,
    FeatureRanking,
    group_rows,
    ordered_unique,
    overall_averages,
    ranking_table,
    sequence_ranks,
    timing_table,
    tracked_fraction,
    value_of,
)

#: Name prefixes of the figures the report writes (older ones are deleted when it is rebuilt).
FIGURE_PREFIXES = ("rpe_", "trajectory_", "depth_", "accuracy_vs_time_")

#: Columns of ``results.csv`` (one row per run).
RESULT_COLUMNS = (
    "dataset", "sequence", "feature", "status", "total_frames", "processed_frames", "tracked_frames",
    "tracked_fraction", "lost_at", "lost_reason", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "ate_rmse",
    "ate_scale", "matched_poses", "gt_path_length", "r_l", "fps", "feature_ms", "io_ms", "tracking_ms",
    "mapping_ms", "total_ms", "wall_s", "keyframes", "points", "channels", "width", "height", "start", "seed",
    "error", "host", "run_dir",
)  # fmt: skip


# =================================================================================================== runs
@dataclass
class RunRecord:
    """One finished run of a bench folder.

    Attributes
    ----------
    sequence, feature : names (the run folder is ``runs/<sequence>/<feature>``).
    path : the run folder.
    spec, metrics, error, evaluation, info : the contents of ``spec.json``, ``metrics.json``,
        ``error.json``, ``evaluation.json`` and ``run_info.json`` (``None`` / ``{}`` where absent).
    dataset : the dataset group.
    unit : the ground truth's length unit (per-metre values are per this unit).
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

    @property
    def status(self) -> str:
        """``"ok"`` (tracked to the end), ``"lost"`` (tracking lost) or ``"failed"`` (crashed)."""
        if self.metrics is None:
            return "failed"
        return "lost" if self.metrics.get("lost_at") is not None else "ok"


def _read_json(path: Path) -> Any:
    from dmtrack.experiments.runner import read_json

    return read_json(path)


def collect_runs(bench_dir: str | Path) -> list[RunRecord]:
    """The finished runs of a bench folder, in the bench's sequence and feature order.

    A run folder counts when it holds a readable ``metrics.json`` (finished, possibly with a tracking loss)
    or ``error.json`` (crashed); hidden (temporary) folders and unfinished runs are ignored.
    """
    from dmtrack.experiments.runner import dataset_label, length_unit

    root = Path(bench_dir)
    bench = _read_json(root / "bench.json") or {}
    datasets = {s.get("name"): s.get("dataset") for s in bench.get("sequences", []) if isinstance(s, dict)}
    units = {s.get("name"): s.get("unit") for s in bench.get("sequences", []) if isinstance(s, dict)}
    seq_order = [s.get("name") for s in bench.get("sequences", []) if isinstance(s, dict)]
    feat_order = list(bench.get("features", []))
    records = []
    runs = root / "runs"
    if not runs.is_dir():
        return []
    for seq_dir in sorted(runs.iterdir()):
        if not seq_dir.is_dir() or seq_dir.name.startswith("."):
            continue
        for run_dir in sorted(seq_dir.iterdir()):
            if not run_dir.is_dir() or run_dir.name.startswith("."):
                continue
            metrics = _read_json(run_dir / "metrics.json")
            error = _read_json(run_dir / "error.json") if metrics is None else None
            if not isinstance(metrics, dict) and not isinstance(error, dict):
                continue
            spec = _read_json(run_dir / "spec.json") or {}
            info = _read_json(run_dir / "run_info.json") or {}
            evaluation = _read_json(run_dir / "evaluation.json")
            feature = str(spec.get("feature") or (metrics or {}).get("feature") or run_dir.name)
            m = metrics if isinstance(metrics, dict) else {}
            fmt, name = m.get("format") or spec.get("format"), m.get("sequence") or seq_dir.name
            dataset = datasets.get(seq_dir.name) or info.get("dataset") or dataset_label(fmt, name)
            unit = units.get(seq_dir.name) or info.get("unit") or length_unit(fmt, name)
            records.append(
                RunRecord(seq_dir.name, feature, run_dir, spec, metrics if isinstance(metrics, dict) else None,
                          error if isinstance(error, dict) else None,
                          evaluation if isinstance(evaluation, dict) else None, info, str(dataset), str(unit))
            )  # fmt: skip

    def order(name: str, known: list[str]) -> tuple[int, str]:
        return (known.index(name), "") if name in known else (len(known), name)

    records.sort(key=lambda r: (order(r.sequence, seq_order), order(r.feature, feat_order)))
    return records


def feature_order(records: Sequence[RunRecord], bench_dir: str | Path | None = None) -> list[str]:
    """Features in the bench's order (``bench.json``), then any others in order of appearance."""
    known: list[str] = []
    if bench_dir is not None:
        known = list((_read_json(Path(bench_dir) / "bench.json") or {}).get("features", []))
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
        row.update(dataset=r.dataset, sequence=r.sequence, feature=r.feature, status=r.status,
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
            if ev.get("error"):
                row["error"] = f"evaluation: {ev['error']}"
            elif m.get("evaluation_error"):
                row["error"] = f"evaluation: {m['evaluation_error']}"
        rows.append(row)
    return rows


# ================================================================================================ output
def _csv_value(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(v)
    return v


def write_csv(path: str | Path, rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> Path:
    """Write ``rows`` as CSV with ``columns`` (missing → empty cell); atomically."""
    from dmtrack.io.trajectory import _atomic_write

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([_csv_value(r.get(c)) for c in columns])
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    _atomic_write(p, buf.getvalue())
    return p


def _fmt(v: Any, digits: int = 2) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        if not math.isfinite(v):
            return "–"
        return f"{v:.{digits}f}"
    return str(v)


def _md_table(headers: Sequence[str], rows: Sequence[Sequence[Any]], align: str | None = None) -> str:
    align = align or "l" + "r" * (len(headers) - 1)
    marks = {"l": ":---", "r": "---:", "c": ":---:"}
    lines = ["| " + " | ".join(headers) + " |", "| " + " | ".join(marks[a] for a in align) + " |"]
    for r in rows:
        lines.append("| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |")
    return "\n".join(lines)


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_") or "x"


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


# ================================================================================================ figures
def _rpe_curves(records: Sequence[RunRecord]) -> list[Any]:
    from dmtrack.viz.plots import RpeCurve

    curves = []
    for r in records:
        ev = r.evaluation or {}
        if r.metrics is None or "rpe_lengths" not in ev:
            continue
        arr = [np.asarray([np.nan if v is None else v for v in ev[k]], dtype=float)
               for k in ("rpe_lengths", "rpe_rot_per_length", "rpe_trans_per_length")]  # fmt: skip
        curves.append(RpeCurve(f"{r.feature} [{r.metrics.get('tracked_frames')}]", arr[0], arr[1], arr[2]))
    return curves


def _read_positions(path: Path) -> np.ndarray | None:
    from dmtrack.errors import DmtrackError
    from dmtrack.io.trajectory import read_tum

    if not path.is_file():
        return None
    try:
        return read_tum(path).positions
    except (DmtrackError, ValueError):
        return None


def _trajectory_inputs(records: Sequence[RunRecord]) -> tuple[np.ndarray | None, list[tuple[str, np.ndarray]]]:
    gt = None
    for r in records:
        g = _read_positions(r.path / "groundtruth.txt")
        if g is not None and (gt is None or len(g) > len(gt)):
            gt = g
    estimates = []
    for r in records:
        ev = r.evaluation or {}
        if r.metrics is None or "ate_alignment" not in ev:
            continue
        p = _read_positions(r.path / "trajectory.txt")
        if p is None or len(p) == 0:
            continue
        A = np.asarray(ev["ate_alignment"], dtype=float)
        estimates.append((f"{r.feature} [{r.metrics.get('tracked_frames')}]", p @ A[:3, :3].T + A[:3, 3]))
    return gt, estimates


_KF_RE = re.compile(r"kf_(\d+)_frame_(\d+)\.png$")


def _depth_grid(records: Sequence[RunRecord], n_cols: int = 4) -> tuple[list[tuple[str, list[Any]]], list[str]]:
    """Rows (feature, cells) and column titles: the reference keyframe of each feature at a few frames."""
    from dmtrack.viz.plots import DepthCell

    kfs: dict[str, list[tuple[int, int, Path]]] = {}
    for r in records:
        if r.metrics is None:
            continue
        items = []
        for p in sorted((r.path / "depth").glob("kf_*.png")):
            m = _KF_RE.search(p.name)
            if m:
                items.append((int(m.group(2)), int(m.group(1)), p))
        if items:
            kfs[r.feature] = sorted(items)
    if not kfs:
        return [], []
    frames = sorted({f for items in kfs.values() for f, _, _ in items})
    lo, hi = frames[0], max(frames)
    for r in records:  # extend to the last processed frame of any run
        if r.metrics is not None:
            hi = max(hi, int(r.metrics.get("start") or 0) + int(r.metrics.get("total_frames") or 0) - 1)
    k = min(n_cols, len(frames))
    targets = sorted({int(round(t)) for t in np.linspace(lo, hi, k + 1)[1:]} if k > 1 else {hi})
    rows = []
    for feature, items in kfs.items():
        cells = []
        for t in targets:
            ref = [it for it in items if it[0] <= t]
            if ref:
                f, kid, p = ref[-1]
                cells.append(DepthCell(p, f"keyframe {kid} (frame {f})"))
            else:
                cells.append(DepthCell(None, ""))
        rows.append((feature, cells))
    return rows, [f"t = {t}" for t in targets]


# ================================================================================================ tables
def _ranking_csv_rows(dataset: str, table: Sequence[FeatureRanking]) -> list[dict[str, Any]]:
    out = []
    for fr in table:
        row: dict[str, Any] = {"dataset": dataset, "feature": fr.feature}
        for c in CRITERIA:
            row[f"{c.key}_wins"] = fr.wins[c.key]
            row[f"{c.key}_average_rank"] = fr.average_rank[c.key]
            row[f"{c.key}_sequences"] = fr.sequences[c.key]
        out.append(row)
    return out


RANKING_COLUMNS = ("dataset", "feature") + tuple(
    f"{c.key}_{s}" for c in CRITERIA for s in ("wins", "average_rank", "sequences")
)
AVERAGE_COLUMNS = ("dataset", "feature", "runs", "tracked_fraction", "n_tracked", "tracked_frames", "rpe_rot",
                   "n_rpe_rot", "rpe_trans", "n_rpe_trans", "ate", "n_ate", "common_rpe_rot", "common_rpe_trans",
                   "n_common")  # fmt: skip
TIMING_COLUMNS = ("dataset", "feature", "runs", "frames", "feature_ms", "io_ms", "tracking_ms", "mapping_ms",
                  "total_ms", "fps", "wall_fps")  # fmt: skip


def _dc_rows(dataset: str, items: Sequence[Any]) -> list[dict[str, Any]]:
    from dataclasses import asdict

    return [{"dataset": dataset, **asdict(x)} for x in items]


# ================================================================================================ report
def _machine_text(records: Sequence[RunRecord], bench: dict[str, Any]) -> str:
    machines = []
    for r in records:
        i = r.info
        if i.get("platform"):
            key = (i.get("platform"), i.get("cpu"), i.get("cpu_count"), i.get("python"))
            if key not in machines:
                machines.append(key)
    if not machines and isinstance(bench.get("machine"), dict):
        i = bench["machine"]
        machines.append((i.get("platform"), i.get("cpu"), i.get("cpu_count"), i.get("python")))
    if not machines:
        return "The machine that ran the benchmark is not recorded."
    hosts = sorted({r.info.get("host") for r in records if r.info.get("host")})
    parts = [f"{p} with {cpu} ({n} logical CPUs), Python {py}" for p, cpu, n, py in machines]
    text = "The runs were executed on " + "; ".join(parts)
    if len(hosts) > 1:
        text += f" — {len(hosts)} hosts ({', '.join(hosts)})"
    opts = bench.get("options") or {}
    if opts.get("scheduler"):
        text += f", through the Dask scheduler {opts['scheduler']}"
    elif opts.get("jobs") is not None:
        jobs = opts["jobs"]
        text += (f", {jobs} run(s) at a time in separate processes with {opts.get('threads_per_job', 1)} "
                 "numba/OpenCV thread(s) each" if jobs else ", one run at a time in the bench process")  # fmt: skip
    return text + "."


def _best(table: Sequence[FeatureRanking], key: str) -> str:
    counted = [fr for fr in table if fr.average_rank[key] is not None]
    if not counted:
        return "no values"
    most = max(fr.wins[key] for fr in counted)
    winners = [fr.feature for fr in counted if fr.wins[key] == most]
    best_avg = min(fr.average_rank[key] for fr in counted)  # type: ignore[type-var]
    leaders = [fr.feature for fr in counted if fr.average_rank[key] == best_avg]
    return (f"most wins: {', '.join(winners)} ({most} of {counted[0].sequences[key]}); best average rank: "
            f"{', '.join(leaders)} ({best_avg:.2f})")  # fmt: skip


def write_report(
    bench_dir: str | Path,
    *,
    figures: bool = True,
    log: Callable[[str], None] | None = None,
) -> Path:
    """(Re)write ``report.md``, ``results.csv``, ``tables/`` and (with ``figures``) ``figures/`` of a bench
    folder from its finished runs; returns the path of ``report.md``.

    A figure that cannot be drawn is reported in ``report.md`` (and to ``log``) instead of failing the report.
    """
    from dmtrack.io.trajectory import _atomic_write

    root = Path(bench_dir)
    bench = _read_json(root / "bench.json") or {}
    records = collect_runs(root)
    features = feature_order(records, root)
    rows = results_rows(records)
    write_csv(root / "results.csv", rows, RESULT_COLUMNS)
    problems: list[str] = []

    def figure(make: Callable[[], Path], what: str) -> Path | None:
        if not figures:
            return None
        try:
            return make()
        except Exception as e:  # a broken figure must not lose the tables
            msg = f"{what}: {type(e).__name__}: {e}"
            problems.append(msg)
            if log is not None:
                log(f"figure not drawn — {msg}")
            return None

    plots: Any = None
    if figures:
        from dmtrack.viz import plots as plots_module

        plots = plots_module
        for old in (root / "figures").glob("*.png"):  # figures of runs or sequences no longer there
            if old.name.startswith(FIGURE_PREFIXES):
                old.unlink(missing_ok=True)

    by_dataset = group_rows(rows, "dataset")
    rec_by_seq: dict[str, list[RunRecord]] = {}
    for r in records:
        rec_by_seq.setdefault(r.sequence, []).append(r)
    n_ok = sum(r.status == "ok" for r in records)
    n_lost = sum(r.status == "lost" for r in records)
    n_failed = sum(r.status == "failed" for r in records)
    seqs = ordered_unique(r.sequence for r in records)

    md: list[str] = []
    md.append("# Benchmark results\n")
    md.append(
        f"dmtrack {__version__}. {len(records)} finished runs: {len(seqs)} sequence(s) from "
        f"{len(by_dataset)} dataset(s) ({', '.join(by_dataset) or 'none'}) × {len(features)} feature(s) "
        f"({', '.join(features) or 'none'}); {n_ok} tracked to the end, {n_lost} lost tracking, {n_failed} failed. "
        f"Report generated {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}.\n"
    )
    md.append(_machine_text(records, bench) + "\n")
    planned = bench.get("runs") or []
    finished = {f"{r.sequence}/{r.path.name}" for r in records}
    missing = [k for k in planned if k not in finished]
    if missing:
        md.append(f"**{len(missing)} run(s) of the grid have not finished** and are not in this report: "
                  f"{', '.join(missing[:20])}{' …' if len(missing) > 20 else ''}.\n")  # fmt: skip

    md.append("## Evaluation\n")
    md.append(
        "Accuracy is measured with the scale-free relative pose error of the paper (§3.1): for 8 path lengths "
        "L_k = k/8 · r_l · (ground-truth path length), the rotation error (angle of R(Q_ij)ᵀR(P_ij)) and the "
        "translation-angle error (angle between t(Q_ij) and t(P_ij)) of every pair (i, j) whose ground-truth "
        "path from i first reaches L_k, each divided by L_k; the reported value is the mean over the lengths "
        "of the per-length means, in degrees per ground-truth length unit (given per dataset below). "
        "ATE is the RMSE of the positions after a 7-DoF (Sim(3)) Umeyama alignment. "
        "Runs stop at the first tracking loss; *tracked frames* counts the frames with a pose.\n"
    )
    md.append(
        "For each sequence the features are ranked by the number of tracked frames (more is better) and by "
        'the two RPE errors (less is better) with the standard competition ranking ("1224"): equal values '
        "share a rank. A run that failed, or has no value for a criterion (e.g. too few poses to evaluate), "
        "ranks after all runs that have one; a sequence where no run has a value is left out of that "
        "criterion. *Wins* counts first places (ties count for every tied feature); *average ranking* is "
        "the mean rank over the counted sequences. Averages (Table 6 layout) are over the runs where a value "
        "is defined (n given); the *common* RPE averages use only the sequences where every feature has both "
        "errors, so that a feature is not favoured by failing on hard sequences. Times are means per "
        "processed frame, weighted by the frames of each run; *total* adds image reading, feature extraction "
        "(with its pyramid), tracking and mapping.\n"
    )

    # -- sequences
    md.append("## Sequences\n")
    seq_rows = []
    for s in seqs:
        rs = rec_by_seq[s]
        m = next((r.metrics for r in rs if r.metrics), None) or {}
        spec = rs[0].spec
        ev = next((r.evaluation for r in rs if r.evaluation and "gt_path_length" in r.evaluation), None) or {}
        frames = m.get("total_frames", spec.get("max_frames"))
        size = f"{m['width']}×{m['height']}" if m.get("width") else "–"
        seq_rows.append([s, rs[0].dataset, m.get("format") or spec.get("format") or "–",
                         f"{_fmt(frames)} (from {spec.get('start', 0)})", size,
                         _fmt(value_of(m, "r_l") or value_of(spec, "r_l"), 4),
                         _fmt(ev.get("gt_path_length"), 2), len(rs)])  # fmt: skip
    md.append(_md_table(["Sequence", "Dataset", "Format", "Frames", "Tracked size", "r_l", "GT path", "Runs"],
                        seq_rows, "lllrlrrr") + "\n")  # fmt: skip
    inconsistent = []
    for s in seqs:
        keys = {
            (r.spec.get("start"), r.spec.get("max_frames"), r.spec.get("seed"), r.spec.get("r_l"),
             str(r.spec.get("config")), r.spec.get("dmtrack_version"))
            for r in rec_by_seq[s]
            if r.spec
        }  # fmt: skip
        if len(keys) > 1:
            inconsistent.append(s)
    if inconsistent:
        md.append(f"**Warning:** the runs of {', '.join(inconsistent)} differ in frame range, seed, r_l, "
                  "configuration or dmtrack version, so their rankings compare unlike runs.\n")  # fmt: skip

    all_rank_rows: list[dict[str, Any]] = []
    if len(by_dataset) > 1:
        overall = ranking_table(rows, features)
        md.append("## All datasets\n")
        md.append(_ranking_md(overall) + "\n")
        md.append(f"*Rankings over all {_plural(len(seqs), 'sequence')} of the {len(by_dataset)} datasets (each "
                  "sequence counts once; ranks are unitless, so datasets can be pooled — errors and times cannot, "
                  "see the per-dataset tables).* "
                  + "; ".join(f"{c.label} — {_best(overall, c.key)}" for c in CRITERIA) + ".\n")  # fmt: skip
        all_rank_rows += _ranking_csv_rows("(all datasets)", overall)

    all_seq_rank_rows: list[dict[str, Any]] = []
    all_avg_rows: list[dict[str, Any]] = []
    all_time_rows: list[dict[str, Any]] = []
    table_no = 0
    for dataset, drows in by_dataset.items():
        dunits = ordered_unique(r.unit for r in records if r.dataset == dataset)
        unit = dunits[0] if len(dunits) == 1 else "unit"
        dfeatures = [f for f in features if any(r["feature"] == f for r in drows)]
        dseqs = ordered_unique(r["sequence"] for r in drows)
        ranking = ranking_table(drows, dfeatures)
        ranks = sequence_ranks(drows, dfeatures)
        averages = overall_averages(drows, dfeatures)
        timings = timing_table(drows, dfeatures)
        all_rank_rows += _ranking_csv_rows(dataset, ranking)
        for s, per in ranks.items():
            for f, rk in per.items():
                all_seq_rank_rows.append({"dataset": dataset, "sequence": s, "feature": f,
                                          **{f"{k}_rank": v for k, v in rk.items()}})  # fmt: skip
        all_avg_rows += _dc_rows(dataset, averages)
        all_time_rows += _dc_rows(dataset, timings)

        md.append(f"## {dataset}\n")
        md.append(f"{_plural(len(dseqs), 'sequence')}: {', '.join(dseqs)}. "
                  + (f"Ground-truth lengths in {unit}; errors in deg/{unit}.\n" if len(dunits) == 1 else
                     f"**Warning:** its sequences use different length units ({', '.join(dunits)}).\n"))  # fmt: skip
        # rankings
        table_no += 1
        md.append("### Rankings\n")
        md.append(_ranking_md(ranking) + "\n")
        md.append(f"*Table {table_no}. Experimental rankings for the {dataset} dataset "
                  f"({_plural(len(dseqs), 'sequence')}).* "
                  + "; ".join(f"{c.label} — {_best(ranking, c.key)}" for c in CRITERIA) + ".\n")  # fmt: skip
        # averages (Table 6 layout: features as columns)
        table_no += 1
        md.append("### Overall averages\n")
        md.append(_averages_table(averages, unit) + "\n")
        md.append(f"*Table {table_no}. Overall averages among the {_plural(len(dseqs), 'sequence')} of {dataset} "
                  "(n = number of runs with a value).*\n")  # fmt: skip
        # timings
        table_no += 1
        md.append("### Processing times\n")
        channels = {r["feature"]: r.get("channels") for r in drows if r.get("channels")}
        md.append(_md_table(
            ["Feature", "Channels", "Feature (ms)", "I/O (ms)", "Tracking (ms)", "Mapping (ms)", "Total (ms)",
             "Total (fps)", "Wall fps", "Frames"],
            [[t.feature, channels.get(t.feature, "–"), _fmt(t.feature_ms, 1), _fmt(t.io_ms, 1),
              _fmt(t.tracking_ms, 1), _fmt(t.mapping_ms, 1), _fmt(t.total_ms, 1), _fmt(t.fps, 1),
              _fmt(t.wall_fps, 1), t.frames] for t in timings],
        ) + "\n")  # fmt: skip
        md.append(f"*Table {table_no}. Average times per frame on {dataset} (frame-weighted over "
                  f"{sum(t.runs for t in timings)} runs).*\n")  # fmt: skip
        # per-sequence results
        md.append("### Per-sequence results\n")
        prow = []
        for r in drows:
            rk = ranks[r["sequence"]][r["feature"]]
            prow.append([r["sequence"], r["feature"], r["status"] + (f" @{r['lost_at']}" if r["lost_at"] is not None
                                                                    else ""),
                         f"{_fmt(r['tracked_frames'])}/{_fmt(r['total_frames'])}", _fmt(rk.get("tracked_frames")),
                         _fmt(value_of(r, "rpe_rot_deg_per_m"), 3), _fmt(rk.get("rpe_rot_deg_per_m")),
                         _fmt(value_of(r, "rpe_trans_angle_deg_per_m"), 3),
                         _fmt(rk.get("rpe_trans_angle_deg_per_m")), _fmt(value_of(r, "ate_rmse"), 4)])  # fmt: skip
        md.append(
            _md_table(
                [
                    "Sequence",
                    "Feature",
                    "Status",
                    "Tracked",
                    "Rank",
                    f"RPE rot. (deg/{unit})",
                    "Rank",
                    f"RPE trans. ang. (deg/{unit})",
                    "Rank",
                    f"ATE ({unit})",
                ],
                prow,
                "lllrrrrrrr",
            )
            + "\n"
        )
        # figures
        if figures:
            md.append("### Figures\n")
            pts = []
            for a, t in zip(averages, timings, strict=True):
                rot, trans = (a.common_rpe_rot, a.common_rpe_trans) if a.n_common else (a.rpe_rot, a.rpe_trans)
                if t.total_ms:
                    pts.append(plots.SpeedAccuracy(a.feature, t.total_ms, rot, trans))
            note = (
                f"errors averaged over the {_plural(averages[0].n_common, 'sequence')} where every feature has them"
                if averages and averages[0].n_common
                else "errors averaged over the runs that have them"
            )
            p = None
            if any(pt.rot is not None or pt.trans is not None for pt in pts):
                p = figure(
                    lambda pts=pts, dataset=dataset, unit=unit, note=note: plots.save_accuracy_vs_time(
                        root / "figures" / f"accuracy_vs_time_{_slug(dataset)}.png",
                        pts,
                        f"{dataset}: accuracy against processing time",
                        unit,
                        note,
                    ),
                    f"accuracy vs time ({dataset})",
                )
            if p is not None:
                md.append(f"![accuracy vs time, {dataset}](figures/{p.name})\n")
                md.append(f"*Accuracy against the total time per frame on {dataset} (paper Figure 5); {note}.*\n")
            for s in dseqs:
                recs = rec_by_seq[s]
                curves = _rpe_curves(recs)
                if curves:
                    p = figure(lambda s=s, curves=curves, unit=unit: plots.save_rpe_vs_length(
                        root / "figures" / f"rpe_{_slug(s)}.png", curves, f"{s}: RPE against path length", unit),
                        f"RPE figure ({s})")  # fmt: skip
                    if p is not None:
                        md.append(f"![RPE against path length, {s}](figures/{p.name})\n")
                        md.append(f"*RPE rotation and translation-angle errors of {s} against the path length "
                                  "(paper Figure 1); the number of tracked frames in brackets.*\n")  # fmt: skip
                gt, estimates = _trajectory_inputs(recs)
                if estimates:
                    p = figure(lambda s=s, gt=gt, estimates=estimates, unit=unit: plots.save_trajectories_topview(
                        root / "figures" / f"trajectory_{_slug(s)}.png", gt, estimates,
                        f"{s}: trajectories (Sim(3)-aligned)", unit), f"trajectory figure ({s})")  # fmt: skip
                    if p is not None:
                        md.append(f"![trajectories, {s}](figures/{p.name})\n")
                        md.append(f"*Top view of {s}: estimates after Sim(3) alignment to the ground truth "
                                  "(dashed), projected on the two principal axes of the ground-truth "
                                  "positions.*\n")  # fmt: skip
                grid, titles = _depth_grid(recs)
                if grid:
                    p = figure(lambda s=s, grid=grid, titles=titles: plots.save_depth_grid(
                        root / "figures" / f"depth_{_slug(s)}.png", grid, titles, f"{s}: keyframe inverse depth"),
                        f"depth figure ({s})")  # fmt: skip
                    if p is not None:
                        md.append(f"![depth maps, {s}](figures/{p.name})\n")
                        md.append(f"*Reference keyframe inverse-depth maps of {s} at a few frames, per feature "
                                  "(paper Figure 4; the keyframes may differ between features; magenta = "
                                  "negative inverse depth).*\n")  # fmt: skip

    write_csv(root / "tables" / "rankings.csv", all_rank_rows, RANKING_COLUMNS)
    write_csv(
        root / "tables" / "ranks_per_sequence.csv",
        all_seq_rank_rows,
        ("dataset", "sequence", "feature") + tuple(f"{c.key}_rank" for c in CRITERIA),
    )
    write_csv(root / "tables" / "averages.csv", all_avg_rows, AVERAGE_COLUMNS)
    write_csv(root / "tables" / "timings.csv", all_time_rows, TIMING_COLUMNS)

    failed = [r for r in records if r.status == "failed"]
    lost = [r for r in records if r.status == "lost"]
    if failed or lost:
        md.append("## Failures and tracking losses\n")
        for r in lost:
            m = r.metrics or {}
            md.append(
                f"- {r.sequence} / {r.feature}: tracking lost at frame {m.get('lost_at')} "
                f"({m.get('lost_reason') or 'no reason given'}) after {m.get('tracked_frames')} tracked frames."
            )
        for r in failed:
            e = r.error or {}
            reached = e.get("tracked_frames")
            md.append(f"- {r.sequence} / {r.feature}: **failed** — {e.get('type', 'error')}: "
                      f"{str(e.get('message', '')).splitlines()[0] if e.get('message') else ''}"
                      + (f" (after {reached} tracked frames)" if reached else "")
                      + f"; traceback in `runs/{r.sequence}/{r.path.name}/error.json`.")  # fmt: skip
        md.append("")
    if problems:
        md.append("## Problems while writing this report\n")
        md.extend(f"- {p}" for p in problems)
        md.append("")
    md.append("## Files\n")
    md.append("`results.csv` (one row per run), `tables/rankings.csv`, `tables/ranks_per_sequence.csv`, "
              "`tables/averages.csv`, `tables/timings.csv`; each run's outputs in `runs/<sequence>/<feature>/`. "
              "Rebuild this report with `dmtrack report " + str(root) + "`.\n")  # fmt: skip
    out = root / "report.md"
    _atomic_write(out, "\n".join(md).rstrip() + "\n")
    return out


def _ranking_md(table: Sequence[FeatureRanking]) -> str:
    hdr = ["Feature"] + [f"{c.label}: {w}" for c in CRITERIA for w in ("Wins Count", "Average Ranking")]
    body = [[fr.feature] + [x for c in CRITERIA for x in (fr.wins[c.key], _fmt(fr.average_rank[c.key]))]
            for fr in table]  # fmt: skip
    return _md_table(hdr, body)


def _averages_table(averages: Sequence[FeatureAverages], unit: str) -> str:
    def with_n(v: float | None, n: int, digits: int = 2) -> str:
        return "–" if v is None else f"{v:.{digits}f} (n={n})"

    hdr = ["Average metric"] + [a.feature for a in averages]
    rows = [
        ["Tracked-frame fraction"] + [with_n(a.tracked_fraction, a.n_tracked, 3) for a in averages],
        ["Number of tracked frames"] + [_fmt(a.tracked_frames, 1) for a in averages],
        [f"RPE rotation error (deg/{unit})"] + [with_n(a.rpe_rot, a.n_rpe_rot) for a in averages],
        [f"RPE trans. angle error (deg/{unit})"] + [with_n(a.rpe_trans, a.n_rpe_trans) for a in averages],
        [f"RPE rotation, common sequences (deg/{unit})"] + [with_n(a.common_rpe_rot, a.n_common) for a in averages],
        [f"RPE trans. angle, common sequences (deg/{unit})"]
        + [with_n(a.common_rpe_trans, a.n_common) for a in averages],
        [f"ATE ({unit})"] + [with_n(a.ate, a.n_ate, 4) for a in averages],
    ]
    return _md_table(hdr, rows)


__all__ = [
    "AVERAGE_COLUMNS",
    "RANKING_COLUMNS",
    "RESULT_COLUMNS",
    "TIMING_COLUMNS",
    "RunRecord",
    "collect_runs",
    "feature_order",
    "results_rows",
    "write_csv",
    "write_report",
]
