"""The benchmark report: ``report.md``, ``results.csv``, ``tables/*.csv`` and ``figures/*.png`` of a bench folder.

:func:`write_report` reads the finished runs under ``DIR/runs/<sequence>/<feature>/`` and, for a bench with
several seeds, ``DIR/runs/<sequence>/<feature>/seed-<S>/`` (those with a ``metrics.json``, or an
``error.json`` for a crashed run; unfinished folders are ignored) and writes

* ``results.csv`` — one row per run (:data:`~dmtrack.evaluation.records.RESULT_COLUMNS`; ``seed`` says which seed);
* ``tables/cells.csv`` — one row per (sequence, feature) cell: the median, min, max and n over the seeds of
  every metric, the seeds, how many lost tracking or failed and the worst seed
  (:data:`~dmtrack.evaluation.tables.CELL_COLUMNS`);
* ``tables/rankings.csv`` (Tables 2–5), ``tables/ranks_per_sequence.csv``, ``tables/averages.csv``
  (Table 6), ``tables/timings.csv`` (Table 7) — one block of rows per dataset, computed on the per-cell
  medians (:func:`dmtrack.evaluation.rankings.aggregate_seeds`; with one seed, the runs' values), with the
  ``seeds`` they are medians over in their last column;
* ``figures/`` — RPE against path length per sequence (Figure 1), accuracy against time per dataset
  (Figure 5), keyframe depth maps per sequence (Figure 4), top-view trajectories per sequence;
* ``report.md`` — all of it as a results section, figures linked relatively.  With several seeds a cell
  shows ``median (min–max)`` and says how many of its seeds lost tracking and which seed did worst; the
  figures plot the median with min–max error bars, and the trajectory and depth figures show, per feature,
  the run of the seed with the median RPE rotation error.

Sequences are grouped into datasets (one ranking table each) by the ``dataset`` given in the sequences
file, else by format and name (:func:`dmtrack.io.bench_layout.dataset_label`).  Rankings, averages and
timings are computed by :mod:`dmtrack.evaluation.rankings` (missing values are explained there).

The runs are read by :mod:`dmtrack.evaluation.records`, the CSV files and markdown tables made by
:mod:`dmtrack.evaluation.tables`; this module draws the figures and writes ``report.md``.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable, Iterable, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack import __version__
from dmtrack.evaluation.rankings import (
    CRITERIA,
    aggregate_seeds,
    group_rows,
    median_range,
    ordered_unique,
    overall_averages,
    ranking_table,
    sequence_ranks,
    timing_table,
    value_of,
)
from dmtrack.evaluation.records import RESULT_COLUMNS, RunRecord, collect_runs, feature_order, results_rows
from dmtrack.evaluation.tables import (
    AVERAGE_COLUMNS,
    CELL_COLUMNS,
    RANKING_COLUMNS,
    RANKS_PER_SEQUENCE_COLUMNS,
    TIMING_COLUMNS,
    averages_md,
    best_text,
    cell_csv_rows,
    cell_status,
    cell_value,
    dataclass_rows,
    fmt_value,
    md_table,
    plural,
    ranking_csv_rows,
    ranking_md,
    write_csv,
)
from dmtrack.io.atomic import write_text
from dmtrack.io.bench_layout import (
    BENCH_JSON,
    GROUNDTRUTH_TXT,
    TRAJECTORY_TXT,
    format_seeds,
    read_json,
)

#: Name prefixes of the figures the report writes (older ones are deleted when it is rebuilt).
FIGURE_PREFIXES = ("rpe_", "trajectory_", "depth_", "accuracy_vs_time_")


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_") or "x"


# ================================================================================================ figures
def _by_feature(records: Sequence[RunRecord]) -> dict[str, list[RunRecord]]:
    out: dict[str, list[RunRecord]] = {}
    for r in records:
        out.setdefault(r.feature, []).append(r)
    return out


def _range_text(values: Sequence[Any]) -> str:
    """``"12"`` for one value, ``"12; 9–12"`` (median; min–max) for several."""
    med, lo, hi, n = median_range(values)
    if n == 0:
        return "–"
    if n == 1:
        return fmt_value(med, 1)
    return f"{fmt_value(med, 1)}; {fmt_value(lo, 1)}–{fmt_value(hi, 1)}"


def rpe_curves(records: Sequence[RunRecord]) -> list[Any]:
    """One curve per feature: a run's per-length RPE, or with several seeds the per-length median over the
    seeds (lengths L_k matched by k) with the min–max as bounds."""
    from dmtrack.viz.plots import RpeCurve

    curves = []
    for feature, runs in _by_feature(records).items():
        per_run = []
        for r in runs:
            ev = r.evaluation or {}
            if r.metrics is None or "rpe_lengths" not in ev:
                continue
            per_run.append([np.asarray([np.nan if v is None else v for v in ev[k]], dtype=float)
                            for k in ("rpe_lengths", "rpe_rot_per_length", "rpe_trans_per_length")])  # fmt: skip
        if not per_run:
            continue
        tracked = _range_text([r.metrics.get("tracked_frames") for r in runs if r.metrics is not None])
        if len(runs) == 1:
            x, rot, trans = per_run[0]
            curves.append(RpeCurve(f"{feature} [{tracked}]", x, rot, trans))
            continue
        k = min(len(a[0]) for a in per_run)
        stack = np.stack([np.stack([a[i][:k] for a in per_run]) for i in range(3)])  # (3, runs, k)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a length without any value stays NaN
            med = np.nanmedian(stack, axis=1)
            lo, hi = np.nanmin(stack, axis=1), np.nanmax(stack, axis=1)
        label = f"{feature} [{tracked}] · {plural(len(runs), 'seed')}"
        curves.append(RpeCurve(label, med[0], med[1], med[2], lo[1], hi[1], lo[2], hi[2]))
    return curves


def representatives(records: Sequence[RunRecord]) -> list[RunRecord]:
    """Per feature, the run that stands for its cell in the trajectory and depth figures: the only run, or
    with several seeds the finished run with the median RPE rotation error (the lower of the two middle
    ones for an even count; without RPE values, the most tracked frames, then the lowest seed)."""
    out = []
    for runs in _by_feature(records).values():
        done = [r for r in runs if r.metrics is not None]
        if not done:
            continue
        rated = sorted((v, r.seed if r.seed is not None else -1, i) for i, r in enumerate(done)
                       if (v := value_of(r.metrics, "rpe_rot_deg_per_m")) is not None)  # fmt: skip
        if rated:
            out.append(done[rated[(len(rated) - 1) // 2][2]])
        else:
            out.append(max(done, key=lambda r: (value_of(r.metrics, "tracked_frames") or 0, -(r.seed or 0))))
    return out


def _run_label(r: RunRecord, seeded: bool) -> str:
    tracked = (r.metrics or {}).get("tracked_frames")
    return f"{r.feature} seed {r.seed} [{tracked}]" if seeded else f"{r.feature} [{tracked}]"


def _read_positions(path: Path) -> np.ndarray | None:
    from dmtrack.errors import DmtrackError
    from dmtrack.io.trajectory import read_tum

    if not path.is_file():
        return None
    try:
        return read_tum(path).positions
    except (DmtrackError, ValueError):
        return None


def trajectory_inputs(
    records: Sequence[RunRecord], seeded: bool = False
) -> tuple[np.ndarray | None, list[tuple[str, np.ndarray]]]:
    gt = None
    for r in records:
        g = _read_positions(r.path / GROUNDTRUTH_TXT)
        if g is not None and (gt is None or len(g) > len(gt)):
            gt = g
    estimates = []
    for r in records:
        ev = r.evaluation or {}
        if r.metrics is None or "ate_alignment" not in ev:
            continue
        p = _read_positions(r.path / TRAJECTORY_TXT)
        if p is None or len(p) == 0:
            continue
        A = np.asarray(ev["ate_alignment"], dtype=float)
        estimates.append((_run_label(r, seeded), p @ A[:3, :3].T + A[:3, 3]))
    return gt, estimates


KEYFRAME_PICTURE_RE = re.compile(r"kf_(\d+)_frame_(\d+)\.png$")


def _depth_grid(
    records: Sequence[RunRecord], n_cols: int = 4, seeded: bool = False
) -> tuple[list[tuple[str, list[Any]]], list[str]]:
    """Rows (feature, cells) and column titles: the reference keyframe of each run (one per feature) at a few
    frames (``seeded``: rows labelled with the run's seed)."""
    from dmtrack.viz.plots import DepthCell

    kfs: dict[str, list[tuple[int, int, Path]]] = {}
    for r in records:
        if r.metrics is None:
            continue
        items = []
        for p in sorted((r.path / "depth").glob("kf_*.png")):
            m = KEYFRAME_PICTURE_RE.search(p.name)
            if m:
                items.append((int(m.group(2)), int(m.group(1)), p))
        if items:
            kfs[f"{r.feature} (seed {r.seed})" if seeded else r.feature] = sorted(items)
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


def common_sequences(cells: Sequence[dict[str, Any]], features: Sequence[str]) -> set[str]:
    """The sequences where every feature has both RPE values (as in ``overall_averages``)."""
    by = {(c["sequence"], c["feature"]): c for c in cells}
    return {
        s
        for s in ordered_unique(c["sequence"] for c in cells)
        if all(value_of(by.get((s, f)), k) is not None for f in features
               for k in ("rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m"))
    }  # fmt: skip


def mean_range(cells: Sequence[dict[str, Any]], key: str, weighted: bool = False) -> tuple[float, float] | None:
    """The mean over ``cells`` (with a value of ``key``) of their minima and of their maxima over the seeds;
    ``weighted``: frame-weighted like the timings (cells without ``tracking_ms`` left out)."""
    lo_num = hi_num = den = 0.0
    for c in cells:
        lo, hi = value_of(c, f"{key}_min"), value_of(c, f"{key}_max")
        if lo is None or hi is None or (weighted and value_of(c, "tracking_ms") is None):
            continue
        w = (value_of(c, "processed_frames") or value_of(c, "total_frames") or 0.0) if weighted else 1.0
        lo_num, hi_num, den = lo_num + w * lo, hi_num + w * hi, den + w
    return (lo_num / den, hi_num / den) if den > 0 else None


# ================================================================================================ report
def machine_text(records: Sequence[RunRecord], bench: dict[str, Any]) -> str:
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
    root = Path(bench_dir)
    bench = read_json(root / BENCH_JSON) or {}
    records = collect_runs(root)
    features = feature_order(records, root)
    rows = results_rows(records)
    write_csv(root / "results.csv", rows, RESULT_COLUMNS)
    # one row per (sequence, feature) cell: the median over its seeds (the run itself with one seed)
    cells = aggregate_seeds(rows)
    write_csv(root / "tables" / "cells.csv", cell_csv_rows(cells), CELL_COLUMNS)
    seeded = any(c["runs"] > 1 for c in cells)
    all_seeds = sorted({s for c in cells for s in c["seeds"]})
    cell_of = {(c["sequence"], c["feature"]): c for c in cells}

    def seeds_of(cs: Iterable[dict[str, Any]]) -> str:
        return format_seeds({s for c in cs for s in c["seeds"]})

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

    by_dataset = group_rows(cells, "dataset")
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
    if seeded:
        md.append(
            f"**Several seeds:** the {len(cells)} (sequence, feature) cells were run with "
            f"{plural(len(all_seeds), 'seed')} of the random depth initialisation ({format_seeds(all_seeds)}). "
            "Every table gives per cell the **median over the seeds** and the min–max in brackets; rankings, "
            "wins, averages and timings are computed on the per-cell medians. One run per seed is in "
            "`results.csv` and `runs/<sequence>/<feature>/seed-<S>/`; `tables/cells.csv` has the median, min, "
            "max and n of every metric per cell.\n"
        )
    md.append(machine_text(records, bench) + "\n")
    planned = bench.get("runs") or []
    finished = {r.key for r in records}
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
                         f"{fmt_value(frames)} (from {spec.get('start', 0)})", size,
                         fmt_value(value_of(m, "r_l") or value_of(spec, "r_l"), 4),
                         fmt_value(ev.get("gt_path_length"), 2), len(rs)])  # fmt: skip
    md.append(md_table(["Sequence", "Dataset", "Format", "Frames", "Tracked size", "r_l", "GT path", "Runs"],
                        seq_rows, "lllrlrrr") + "\n")  # fmt: skip
    inconsistent = []
    for s in seqs:
        keys = {
            (r.spec.get("start"), r.spec.get("max_frames"), r.spec.get("r_l"),
             str(r.spec.get("config")), r.spec.get("dmtrack_version"))
            for r in rec_by_seq[s]
            if r.spec
        }  # fmt: skip
        seed_sets = {tuple(c["seeds"]) for c in cells if c["sequence"] == s}
        if len(keys) > 1 or len(seed_sets) > 1:
            inconsistent.append(s)
    if inconsistent:
        md.append(f"**Warning:** the runs of {', '.join(inconsistent)} differ in frame range, seeds, r_l, "
                  "configuration or dmtrack version, so their rankings compare unlike runs.\n")  # fmt: skip

    all_rank_rows: list[dict[str, Any]] = []
    if len(by_dataset) > 1:
        overall = ranking_table(cells, features)
        md.append("## All datasets\n")
        md.append(ranking_md(overall) + "\n")
        md.append(f"*Rankings over all {plural(len(seqs), 'sequence')} of the {len(by_dataset)} datasets (each "
                  "sequence counts once; ranks are unitless, so datasets can be pooled — errors and times cannot, "
                  "see the per-dataset tables).* "
                  + (f"Medians over seeds {format_seeds(all_seeds)}. " if seeded else "")
                  + "; ".join(f"{c.label} — {best_text(overall, c.key)}" for c in CRITERIA) + ".\n")  # fmt: skip
        all_rank_rows += ranking_csv_rows("(all datasets)", overall, {f: seeds_of(
            c for c in cells if c["feature"] == f) for f in features})  # fmt: skip

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
        fseeds = {f: seeds_of(c for c in drows if c["feature"] == f) for f in dfeatures}
        dseeds = seeds_of(drows)
        all_rank_rows += ranking_csv_rows(dataset, ranking, fseeds)
        for s, per in ranks.items():
            for f, rk in per.items():
                c = cell_of.get((s, f))
                all_seq_rank_rows.append({"dataset": dataset, "sequence": s, "feature": f,
                                          **{f"{k}_rank": v for k, v in rk.items()},
                                          "seeds": format_seeds(c["seeds"]) if c else None})  # fmt: skip
        all_avg_rows += dataclass_rows(dataset, averages, fseeds)
        all_time_rows += dataclass_rows(dataset, timings, fseeds)
        over = f" Per cell: median over seeds {dseeds}; the tables below use those medians." if seeded else ""

        md.append(f"## {dataset}\n")
        md.append(f"{plural(len(dseqs), 'sequence')}: {', '.join(dseqs)}. "
                  + (f"Ground-truth lengths in {unit}; errors in deg/{unit}." if len(dunits) == 1 else
                     f"**Warning:** its sequences use different length units ({', '.join(dunits)}).")
                  + over + "\n")  # fmt: skip
        # rankings
        table_no += 1
        md.append("### Rankings\n")
        md.append(ranking_md(ranking) + "\n")
        md.append(f"*Table {table_no}. Experimental rankings for the {dataset} dataset "
                  f"({plural(len(dseqs), 'sequence')}"
                  + (f", ranked by the medians over seeds {dseeds}" if seeded else "") + ").* "
                  + "; ".join(f"{c.label} — {best_text(ranking, c.key)}" for c in CRITERIA) + ".\n")  # fmt: skip
        # averages (Table 6 layout: features as columns)
        table_no += 1
        md.append("### Overall averages\n")
        md.append(averages_md(averages, unit) + "\n")
        md.append(f"*Table {table_no}. Overall averages among the {plural(len(dseqs), 'sequence')} of {dataset} "
                  + (f"of the per-cell medians over seeds {dseeds} (n = number of cells with a value).*\n" if seeded
                     else "(n = number of runs with a value).*\n"))  # fmt: skip
        # timings
        table_no += 1
        md.append("### Processing times\n")
        channels = {r["feature"]: r.get("channels") for r in drows if r.get("channels")}
        md.append(md_table(
            ["Feature", "Channels", "Feature (ms)", "I/O (ms)", "Tracking (ms)", "Mapping (ms)", "Total (ms)",
             "Total (fps)", "Wall fps", "Frames"],
            [[t.feature, channels.get(t.feature, "–"), fmt_value(t.feature_ms, 1), fmt_value(t.io_ms, 1),
              fmt_value(t.tracking_ms, 1), fmt_value(t.mapping_ms, 1), fmt_value(t.total_ms, 1), fmt_value(t.fps, 1),
              fmt_value(t.wall_fps, 1), t.frames] for t in timings],
        ) + "\n")  # fmt: skip
        md.append(f"*Table {table_no}. Average times per frame on {dataset} (frame-weighted over "
                  + (f"the per-cell medians over seeds {dseeds} of {sum(t.runs for t in timings)} cells).*\n"
                     if seeded else f"{sum(t.runs for t in timings)} runs).*\n"))  # fmt: skip
        # per-sequence results
        md.append("### Per-sequence results\n")
        prow = []
        for c in drows:
            rk = ranks[c["sequence"]][c["feature"]]
            prow.append([c["sequence"], c["feature"]] + ([format_seeds(c["seeds"]) or "–"] if seeded else [])
                        + [cell_status(c), cell_value(c, "tracked_frames", 1, f"/{fmt_value(c['total_frames'])}"),
                           fmt_value(rk.get("tracked_frames")), cell_value(c, "rpe_rot_deg_per_m", 3),
                           fmt_value(rk.get("rpe_rot_deg_per_m")), cell_value(c, "rpe_trans_angle_deg_per_m", 3),
                           fmt_value(rk.get("rpe_trans_angle_deg_per_m")), cell_value(c, "ate_rmse", 4),
                           cell_value(c, "total_ms", 1), cell_value(c, "fps", 1)])  # fmt: skip
        md.append(
            md_table(
                ["Sequence", "Feature"] + (["Seeds"] if seeded else []) + [
                    "Status", "Tracked", "Rank", f"RPE rot. (deg/{unit})", "Rank", f"RPE trans. ang. (deg/{unit})",
                    "Rank", f"ATE ({unit})", "Total (ms)", "fps",
                ],
                prow,
                ("lll" if seeded else "ll") + "lrrrrrrrrr",
            )
            + "\n"
        )  # fmt: skip
        if seeded:
            md.append("*Per cell: median over the seeds, min–max in brackets ([k of n]: only k of the n seeds have "
                      "a value); ranks of the medians. Status: how many seeds tracked to the end, lost tracking or "
                      "failed, and the worst seed. Total: time per frame; fps: processed frames per wall-clock "
                      "second of the run.*\n")  # fmt: skip
        # figures
        if figures:
            md.append("### Figures\n")
            pts = []
            common = common_sequences(drows, dfeatures)
            for a, t in zip(averages, timings, strict=True):
                rot, trans = (a.common_rpe_rot, a.common_rpe_trans) if a.n_common else (a.rpe_rot, a.rpe_trans)
                if t.total_ms:
                    ranges: dict[str, Any] = {}
                    if seeded:
                        mine = [c for c in drows if c["feature"] == a.feature]
                        used = [c for c in mine if c["sequence"] in common] if a.n_common else mine
                        ranges = {"rot_range": mean_range(used, "rpe_rot_deg_per_m"),
                                  "trans_range": mean_range(used, "rpe_trans_angle_deg_per_m"),
                                  "ms_range": mean_range(mine, "total_ms", weighted=True)}  # fmt: skip
                    pts.append(plots.SpeedAccuracy(a.feature, t.total_ms, rot, trans, **ranges))
            note = (
                f"errors averaged over the {plural(averages[0].n_common, 'sequence')} where every feature has them"
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
                md.append(f"*Accuracy against the total time per frame on {dataset} (paper Figure 5); {note}"
                          + ("; points from the per-cell medians over the seeds, bars from the per-cell minima and "
                             "maxima averaged the same way" if seeded else "") + ".*\n")  # fmt: skip
            for s in dseqs:
                recs = rec_by_seq[s]
                curves = rpe_curves(recs)
                if curves:
                    p = figure(lambda s=s, curves=curves, unit=unit: plots.save_rpe_vs_length(
                        root / "figures" / f"rpe_{_slug(s)}.png", curves, f"{s}: RPE against path length", unit),
                        f"RPE figure ({s})")  # fmt: skip
                    if p is not None:
                        md.append(f"![RPE against path length, {s}](figures/{p.name})\n")
                        md.append(f"*RPE rotation and translation-angle errors of {s} against the path length "
                                  "(paper Figure 1); the number of tracked frames in brackets"
                                  + ("; with several seeds the median over the seeds at each length L_k with "
                                     "min–max error bars, and the tracked frames as median; min–max"
                                     if seeded else "") + ".*\n")  # fmt: skip
                reps = representatives(recs) if seeded else recs
                gt, estimates = trajectory_inputs(reps, seeded)
                if estimates:
                    p = figure(lambda s=s, gt=gt, estimates=estimates, unit=unit: plots.save_trajectories_topview(
                        root / "figures" / f"trajectory_{_slug(s)}.png", gt, estimates,
                        f"{s}: trajectories (Sim(3)-aligned)", unit), f"trajectory figure ({s})")  # fmt: skip
                    if p is not None:
                        md.append(f"![trajectories, {s}](figures/{p.name})\n")
                        md.append(f"*Top view of {s}: estimates after Sim(3) alignment to the ground truth "
                                  "(dashed), projected on the two principal axes of the ground-truth positions"
                                  + ("; per feature the run of the seed with the median RPE rotation error"
                                     if seeded else "") + ".*\n")  # fmt: skip
                grid, titles = _depth_grid(reps, seeded=seeded)
                if grid:
                    p = figure(lambda s=s, grid=grid, titles=titles: plots.save_depth_grid(
                        root / "figures" / f"depth_{_slug(s)}.png", grid, titles, f"{s}: keyframe inverse depth"),
                        f"depth figure ({s})")  # fmt: skip
                    if p is not None:
                        md.append(f"![depth maps, {s}](figures/{p.name})\n")
                        md.append(f"*Reference keyframe inverse-depth maps of {s} at a few frames, per feature "
                                  "(paper Figure 4; the keyframes may differ between features; magenta = "
                                  "negative inverse depth"
                                  + ("; per feature the run of the seed with the median RPE rotation error"
                                     if seeded else "") + ").*\n")  # fmt: skip

    write_csv(root / "tables" / "rankings.csv", all_rank_rows, RANKING_COLUMNS)
    write_csv(root / "tables" / "ranks_per_sequence.csv", all_seq_rank_rows, RANKS_PER_SEQUENCE_COLUMNS)
    write_csv(root / "tables" / "averages.csv", all_avg_rows, AVERAGE_COLUMNS)
    write_csv(root / "tables" / "timings.csv", all_time_rows, TIMING_COLUMNS)

    failed = [r for r in records if r.status == "failed"]
    lost = [r for r in records if r.status == "lost"]
    if failed or lost:
        md.append("## Failures and tracking losses\n")

        def who(r: RunRecord) -> str:
            return f"{r.sequence} / {r.feature}" + (f" / seed {r.seed}" if seeded else "")

        for r in lost:
            m = r.metrics or {}
            md.append(
                f"- {who(r)}: tracking lost at frame {m.get('lost_at')} "
                f"({m.get('lost_reason') or 'no reason given'}) after {m.get('tracked_frames')} tracked frames."
            )
        for r in failed:
            e = r.error or {}
            reached = e.get("tracked_frames")
            md.append(f"- {who(r)}: **failed** — {e.get('type', 'error')}: "
                      f"{str(e.get('message', '')).splitlines()[0] if e.get('message') else ''}"
                      + (f" (after {reached} tracked frames)" if reached else "")
                      + f"; traceback in `runs/{r.key}/error.json`.")  # fmt: skip
        md.append("")
    if problems:
        md.append("## Problems while writing this report\n")
        md.extend(f"- {p}" for p in problems)
        md.append("")
    md.append("## Files\n")
    md.append("`results.csv` (one row per run), `tables/cells.csv` (one row per sequence and feature: median, "
              "min, max over the seeds), `tables/rankings.csv`, `tables/ranks_per_sequence.csv`, "
              "`tables/averages.csv`, `tables/timings.csv`; each run's outputs in "
              + ("`runs/<sequence>/<feature>/seed-<S>/`. " if seeded else "`runs/<sequence>/<feature>/`. ")
              + "Rebuild this report with `dmtrack report " + str(root) + "`.\n")  # fmt: skip
    out = root / "report.md"
    write_text(out, "\n".join(md).rstrip() + "\n")
    return out


__all__ = ["FIGURE_PREFIXES", "representatives", "write_report"]
