"""``report.html`` of a bench folder: the tables of ``report.md`` as HTML and its figures as interactive plots.

Everything is computed by the modules ``report.md`` uses — the runs by :mod:`dmtrack.evaluation.records`, the
per-cell medians over the seeds and the paper's Tables 2–7 by :mod:`dmtrack.evaluation.rankings`, the table
text by :mod:`dmtrack.evaluation.tables`, the RPE curves, the median-seed runs and the aligned trajectories by
:mod:`dmtrack.evaluation.report` — so the two reports show the same numbers.  Per dataset: rankings, overall
averages, processing times, per-sequence results, grouped bars of RPE and ATE per sequence and feature (median
over the seeds, min–max error bars) and accuracy against time; per sequence: RPE against path length and a top
view of the median-seed trajectory of each feature against the ground truth.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack import __version__
from dmtrack.errors import InputError
from dmtrack.evaluation.html.figures import Curve, Line, rpe_figure, topview_figure
from dmtrack.evaluation.html.page import (
    SUBPLOT_MARGIN,
    Page,
    axis_basis_text,
    base_layout,
    colour,
    esc,
    md_table_html,
    table,
)
from dmtrack.evaluation.rankings import (
    CRITERIA,
    aggregate_seeds,
    group_rows,
    ordered_unique,
    overall_averages,
    ranking_table,
    sequence_ranks,
    timing_table,
)
from dmtrack.evaluation.records import RunRecord, collect_runs, feature_order, results_rows
from dmtrack.evaluation.tables import averages_md, best_text, cell_status, cell_value, fmt_value, plural, ranking_md
from dmtrack.io.bench_layout import BENCH_JSON, format_seeds, read_json

#: Metrics of the grouped bar charts: (cell key, axis title with ``{unit}``, digits in the hover text).
BAR_METRICS = (
    ("rpe_rot_deg_per_m", "RPE rot. [deg/{unit}]", 3),
    ("rpe_trans_angle_deg_per_m", "RPE trans. ang. [deg/{unit}]", 3),
    ("ate_rmse", "ATE [{unit}]", 4),
)


def _first_line(text: Any) -> str:
    lines = str(text or "").splitlines()
    return lines[0] if lines else ""


def _feature_colours(features: Sequence[str]) -> dict[str, str]:
    return {f: colour(i) for i, f in enumerate(features)}


def _bars_figure(drows: Sequence[dict[str, Any]], dseqs: list[str], dfeatures: list[str], colours: dict[str, str],
                 unit: str, seeded: bool) -> tuple[Any, str] | None:  # fmt: skip
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    by = {(c["sequence"], c["feature"]): c for c in drows}
    if not any(c.get(k) is not None for c in drows for k, _, _ in BAR_METRICS):
        return None
    fig = make_subplots(rows=len(BAR_METRICS), cols=1, shared_xaxes=True, vertical_spacing=0.06)
    for row, (key, title, digits) in enumerate(BAR_METRICS, start=1):
        for f in dfeatures:
            cs = [by.get((s, f)) for s in dseqs]
            y = np.array([np.nan if c is None or c.get(key) is None else float(c[key]) for c in cs])
            err = None
            if seeded:
                lo = np.array([np.nan if c is None or c.get(f"{key}_min") is None else c[f"{key}_min"] for c in cs])
                hi = np.array([np.nan if c is None or c.get(f"{key}_max") is None else c[f"{key}_max"] for c in cs])
                err = {"type": "data", "symmetric": False, "array": np.nan_to_num(hi - y, nan=0.0),
                       "arrayminus": np.nan_to_num(y - lo, nan=0.0), "thickness": 1.2, "width": 3}  # fmt: skip
            hover = [esc(f"{s} · {f}: " + ("no value" if c is None else cell_value(c, key, digits))
                         + (f" · seeds {format_seeds(c['seeds'])}" if c is not None and seeded else ""))
                     for s, c in zip(dseqs, cs, strict=True)]  # fmt: skip
            fig.add_trace(go.Bar(x=[esc(s) for s in dseqs], y=y, name=esc(f), legendgroup=esc(f), showlegend=row == 1,
                                 marker_color=colours[f], error_y=err, hovertext=hover,
                                 hovertemplate="%{hovertext}<extra></extra>"), row=row, col=1)  # fmt: skip
        fig.update_yaxes(title_text=esc(title.format(unit=unit)), rangemode="tozero", row=row, col=1)
    fig.update_layout(**base_layout("Accuracy per sequence and feature", 260 + 180 * len(BAR_METRICS),
                                    barmode="group"))  # fmt: skip
    return fig, (
        "RPE rotation and translation-angle errors and ATE per sequence, one bar per feature"
        + (": the median over the seeds, error bars from the minimum to the maximum over the seeds." if seeded
           else ".")
        + " A missing bar: the run failed or has no value (no ground truth, too few poses)."
    )  # fmt: skip


def _speed_figure(drows: Sequence[dict[str, Any]], dfeatures: list[str], colours: dict[str, str], unit: str,
                  seeded: bool) -> tuple[Any, str] | None:  # fmt: skip
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    from dmtrack.evaluation.report import common_sequences, mean_range

    averages = overall_averages(drows, dfeatures)
    timings = timing_table(drows, dfeatures)
    common = common_sequences(drows, dfeatures)
    fig = make_subplots(rows=1, cols=2, horizontal_spacing=0.1,
                        subplot_titles=("RPE rotation error", "RPE translation-angle error"))  # fmt: skip
    drawn = 0
    for a, t in zip(averages, timings, strict=True):
        if not t.total_ms:
            continue
        mine = [c for c in drows if c["feature"] == a.feature]
        used = [c for c in mine if c["sequence"] in common] if a.n_common else mine
        ms_range = mean_range(mine, "total_ms", weighted=True) if seeded else None
        pairs = ((a.common_rpe_rot if a.n_common else a.rpe_rot, "rpe_rot_deg_per_m"),
                 (a.common_rpe_trans if a.n_common else a.rpe_trans, "rpe_trans_angle_deg_per_m"))  # fmt: skip
        for col, (v, key) in enumerate(pairs, start=1):
            if v is None:
                continue
            rng = mean_range(used, key) if seeded else None
            fig.add_trace(go.Scatter(
                x=[t.total_ms], y=[v], mode="markers+text", text=[esc(a.feature)], textposition="top center",
                name=esc(a.feature), legendgroup=esc(a.feature), showlegend=col == 1,
                marker={"color": colours[a.feature], "size": 11},
                error_y=None if rng is None else {"type": "data", "symmetric": False, "array": [max(0.0, rng[1] - v)],
                                                  "arrayminus": [max(0.0, v - rng[0])]},
                error_x=None if ms_range is None else {"type": "data", "symmetric": False,
                                                       "array": [max(0.0, ms_range[1] - t.total_ms)],
                                                       "arrayminus": [max(0.0, t.total_ms - ms_range[0])]},
                hovertemplate=f"{esc(a.feature)}<br>%{{x:.1f}} ms/frame<br>%{{y:.3f}} deg/{esc(unit)}<extra></extra>",
            ), row=1, col=col)  # fmt: skip
            drawn += 1
    if not drawn:
        return None
    fig.update_layout(**base_layout("Accuracy against processing time", 460, margin=SUBPLOT_MARGIN))
    fig.update_xaxes(title_text="total time per frame [ms]", rangemode="tozero")
    fig.update_yaxes(title_text=f"error [deg/{esc(unit)}]", rangemode="tozero")
    n_common = averages[0].n_common if averages else 0
    return fig, (
        "Mean RPE errors against the mean total time per frame, one point per feature (paper Figure 5); errors "
        + (f"averaged over the {plural(n_common, 'sequence')} where every feature has them" if n_common
           else "averaged over the runs that have them")
        + ("; points from the per-cell medians over the seeds, bars from the per-cell minima and maxima averaged "
           "the same way" if seeded else "") + "."
    )  # fmt: skip


def _sequence_figures(page: Page, s: str, recs: list[RunRecord], colours: dict[str, str], unit: str,
                      seeded: bool) -> None:  # fmt: skip
    from dmtrack.evaluation.report import representatives, rpe_curves, trajectory_inputs
    from dmtrack.viz.plots import topview_basis

    def feature_of(label: str) -> str:
        return label.split(" ", 1)[0]

    def rpe() -> tuple[Any, str] | None:
        curves = rpe_curves(recs)
        if not curves:
            return None
        fig = rpe_figure([Curve(c, colours.get(feature_of(c.label), colour(i))) for i, c in enumerate(curves)],
                         f"{s}: RPE against path length", unit)  # fmt: skip
        return fig, (f"RPE rotation and translation-angle errors of {s} against the path length (paper Figure 1); "
                     "tracked frames in brackets" + ("; the median over the seeds at each length with min–max error "
                                                     "bars" if seeded else "") + ".")  # fmt: skip

    def trajectories() -> tuple[Any, str] | None:
        reps = representatives(recs) if seeded else recs
        gt, estimates = trajectory_inputs(reps, seeded)
        if not estimates:
            return None
        lines = [Line("ground truth", gt, "#222222", dash="dash")] if gt is not None else []
        lines += [Line(label, p, colours.get(feature_of(label), colour(i))) for i, (label, p) in enumerate(estimates)]
        ref = gt if gt is not None and len(gt) >= 3 else np.concatenate([p for _, p in estimates])
        basis = topview_basis(ref)
        fig = topview_figure(lines, basis, f"{s}: trajectories (Sim(3)-aligned)", unit)
        return fig, (f"Top view of {s}: per feature the estimate after Sim(3) alignment to the ground truth (dashed)"
                     + ("; the run of the seed with the median RPE rotation error" if seeded else "")
                     + f". View: the two principal axes of the ground-truth positions, {axis_basis_text(basis)} "
                     "(world axes).")  # fmt: skip

    page.try_figure(rpe, f"RPE figure ({s})")
    page.try_figure(trajectories, f"trajectory figure ({s})")


_SEQ_COLUMNS: tuple[tuple[str, str, Any], ...] = (
    ("Status", "l", lambda c, rk: cell_status(c)),
    ("Tracked", "r", lambda c, rk: cell_value(c, "tracked_frames", 1, f"/{fmt_value(c['total_frames'])}")),
    ("Rank", "r", lambda c, rk: fmt_value(rk.get("tracked_frames"))),
    ("RPE rot. (deg/{unit})", "r", lambda c, rk: cell_value(c, "rpe_rot_deg_per_m", 3)),
    ("Rank", "r", lambda c, rk: fmt_value(rk.get("rpe_rot_deg_per_m"))),
    ("RPE trans. ang. (deg/{unit})", "r", lambda c, rk: cell_value(c, "rpe_trans_angle_deg_per_m", 3)),
    ("Rank", "r", lambda c, rk: fmt_value(rk.get("rpe_trans_angle_deg_per_m"))),
    ("ATE ({unit})", "r", lambda c, rk: cell_value(c, "ate_rmse", 4)),
    ("Total (ms)", "r", lambda c, rk: cell_value(c, "total_ms", 1)),
    ("fps", "r", lambda c, rk: cell_value(c, "fps", 1)),
)
_TIMING_FIELDS = (("Feature (ms)", "feature_ms"), ("I/O (ms)", "io_ms"), ("Tracking (ms)", "tracking_ms"),
                  ("Mapping (ms)", "mapping_ms"), ("Total (ms)", "total_ms"), ("Total (fps)", "fps"),
                  ("Wall fps", "wall_fps"))  # fmt: skip


def _dataset(page: Page, dataset: str, drows: list[dict[str, Any]], records: list[RunRecord], features: list[str],
             colours: dict[str, str], seeded: bool, table_no: int) -> int:  # fmt: skip
    """One dataset's section; returns the number of its last table."""
    dseqs = ordered_unique(r["sequence"] for r in drows)
    dfeatures = [f for f in features if f in {r["feature"] for r in drows}]
    dunits = ordered_unique(r.unit for r in records if r.sequence in dseqs)  # the ground truths' length units
    unit = dunits[0] if len(dunits) == 1 else "unit"
    dseeds = format_seeds({s for c in drows for s in c["seeds"]})
    ranking = ranking_table(drows, dfeatures)
    ranks = sequence_ranks(drows, dfeatures)
    page.heading(2, dataset, toc=True)
    page.text(f"{plural(len(dseqs), 'sequence')}: {', '.join(dseqs)}. "
              + (f"Ground-truth lengths in {unit}; errors in deg/{unit}." if len(dunits) == 1 else
                 f"Warning: its sequences use different length units ({', '.join(dunits)}).")
              + (f" Per cell: median over seeds {dseeds} (min–max in brackets); the tables use those medians."
                 if seeded else ""))  # fmt: skip
    page.heading(3, "Rankings")
    page.add(md_table_html(ranking_md(ranking)))
    page.text(f"Table {table_no + 1}. Experimental rankings for the {dataset} dataset ({plural(len(dseqs), 'sequence')}"
              + (f", ranked by the medians over seeds {dseeds}" if seeded else "") + "). "
              + "; ".join(f"{c.label} — {best_text(ranking, c.key)}" for c in CRITERIA) + ".", "caption")  # fmt: skip
    page.heading(3, "Overall averages")
    page.add(md_table_html(averages_md(overall_averages(drows, dfeatures), unit)))
    page.text(f"Table {table_no + 2}. Overall averages among the {plural(len(dseqs), 'sequence')} of {dataset} "
              + ("of the per-cell medians over the seeds (n = cells with a value)." if seeded
                 else "(n = runs with a value)."), "caption")  # fmt: skip
    page.heading(3, "Processing times")
    timings = timing_table(drows, dfeatures)
    channels = {r["feature"]: r.get("channels") for r in drows if r.get("channels")}
    page.add(table(["Feature", "Channels"] + [h for h, _ in _TIMING_FIELDS] + ["Frames"],
                   [[t.feature, channels.get(t.feature, "–")] + [fmt_value(getattr(t, k), 1) for _, k in _TIMING_FIELDS]
                    + [t.frames] for t in timings]))  # fmt: skip
    page.text(f"Table {table_no + 3}. Average times per frame on {dataset}, frame-weighted over "
              f"{plural(sum(t.runs for t in timings), 'cell' if seeded else 'run')}.", "caption")  # fmt: skip
    page.heading(3, "Per-sequence results")
    headers = ["Sequence", "Feature"] + (["Seeds"] if seeded else [])
    headers += [h.format(unit=unit) for h, _, _ in _SEQ_COLUMNS]
    rows = [[c["sequence"], c["feature"]] + ([format_seeds(c["seeds"]) or "–"] if seeded else [])
            + [fn(c, ranks[c["sequence"]][c["feature"]]) for _, _, fn in _SEQ_COLUMNS] for c in drows]  # fmt: skip
    page.add(table(headers, rows, ("lll" if seeded else "ll") + "".join(a for _, a, _ in _SEQ_COLUMNS)))
    if seeded:
        page.text("Per cell: median over the seeds, min–max in brackets ([k of n]: only k of the n seeds have a "
                  "value); ranks of the medians. Status: how many seeds tracked to the end, lost tracking or failed, "
                  "and the worst seed.", "caption")  # fmt: skip
    page.heading(3, "Figures")
    page.try_figure(lambda: _bars_figure(drows, dseqs, dfeatures, colours, unit, seeded), f"bars ({dataset})")
    page.try_figure(lambda: _speed_figure(drows, dfeatures, colours, unit, seeded), f"accuracy vs time ({dataset})")
    for s in dseqs:
        recs = [r for r in records if r.sequence == s]
        page.heading(3, s)
        _sequence_figures(page, s, recs, colours, unit, seeded)
    return table_no + 3


def bench_page(root: Path, page: Page) -> str:
    """Fill ``page`` with the report of the bench folder ``root``; returns the subtitle."""
    from dmtrack.evaluation.report import machine_text

    records = collect_runs(root)
    if not records:
        raise InputError("no finished runs in runs/ (nothing to report)", path=root)
    bench = read_json(root / BENCH_JSON) or {}
    bench = bench if isinstance(bench, dict) else {}
    features = feature_order(records, root)
    colours = _feature_colours(features)
    cells = aggregate_seeds(results_rows(records))
    seeded = any(c["runs"] > 1 for c in cells)
    by_dataset = group_rows(cells, "dataset")
    seqs = ordered_unique(r.sequence for r in records)
    all_seeds = sorted({s for c in cells for s in c["seeds"]})
    page.title = f"dmtrack benchmark: {root.resolve().name}"
    page.heading(2, "Summary", toc=True)
    counts = {s: sum(r.status == s for r in records) for s in ("ok", "lost", "failed")}
    page.text(f"dmtrack {__version__}. {len(records)} finished runs: {len(seqs)} sequence(s) from "
              f"{len(by_dataset)} dataset(s) ({', '.join(by_dataset)}) × {len(features)} feature(s) "
              f"({', '.join(features)}); {counts['ok']} tracked to the end, {counts['lost']} lost tracking, "
              f"{counts['failed']} failed.")  # fmt: skip
    if seeded:
        page.text(f"Several seeds: the {len(cells)} (sequence, feature) cells were run with "
                  f"{plural(len(all_seeds), 'seed')} of the random depth initialisation ({format_seeds(all_seeds)}). "
                  "Every table gives per cell the median over the seeds and the min–max in brackets; rankings, wins, "
                  "averages and timings are computed on the per-cell medians.", "note")  # fmt: skip
    page.text(machine_text(records, bench))
    page.text("Accuracy: the paper's scale-free RPE (§3.1) over 8 path lengths up to r_l of the ground-truth path, "
              "in degrees per ground-truth length unit, and the ATE after a Sim(3) alignment. Ranks: standard "
              "competition ranking per sequence (tracked frames: more is better; errors: less is better); a run "
              "without a value ranks last.", "caption")  # fmt: skip
    if len(by_dataset) > 1:
        overall = ranking_table(cells, features)
        page.heading(2, "All datasets", toc=True)
        page.add(md_table_html(ranking_md(overall)))
        page.text(f"Rankings over all {plural(len(seqs), 'sequence')} of the {len(by_dataset)} datasets "
                  "(ranks are unitless, so datasets can be pooled; errors and times cannot). "
                  + "; ".join(f"{c.label} — {best_text(overall, c.key)}" for c in CRITERIA) + ".",
                  "caption")  # fmt: skip
    table_no = 0
    for dataset, drows in by_dataset.items():
        table_no = _dataset(page, dataset, drows, records, features, colours, seeded, table_no)
    lost = [r for r in records if r.status == "lost"]
    failed = [r for r in records if r.status == "failed"]
    if lost or failed:
        page.heading(2, "Failures and tracking losses", toc=True)
        who = {r.key: f"{r.sequence} / {r.feature}" + (f" / seed {r.seed}" if seeded else "") for r in records}
        page.items([f"{who[r.key]}: tracking lost at frame {(r.metrics or {}).get('lost_at')} "
                    f"({(r.metrics or {}).get('lost_reason') or 'no reason given'})" for r in lost]
                   + [f"{who[r.key]}: failed — {(r.error or {}).get('type', 'error')}: "
                      f"{_first_line((r.error or {}).get('message'))} (traceback in runs/{r.key}/error.json)"
                      for r in failed])  # fmt: skip
    return f"Bench folder {root} · {len(records)} runs"


__all__ = ["bench_page"]
