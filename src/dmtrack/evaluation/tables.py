"""The report's tables: the CSV files of a bench folder and the markdown tables of ``report.md``.

The column lists of ``tables/*.csv`` (:data:`RANKING_COLUMNS`, :data:`AVERAGE_COLUMNS`,
:data:`TIMING_COLUMNS`, :data:`RANKS_PER_SEQUENCE_COLUMNS`, :data:`CELL_COLUMNS`), :func:`write_csv`, the rows
of those files and the text of ``report.md``'s cells and tables (numbers, medians with their min–max over the
seeds, statuses).  The values come from :mod:`dmtrack.evaluation.rankings`.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from dmtrack.evaluation.rankings import CRITERIA, SEED_METRICS, FeatureAverages, FeatureRanking
from dmtrack.io.atomic import write_text
from dmtrack.io.bench_layout import format_seeds

RANKING_COLUMNS = (
    ("dataset", "feature")
    + tuple(f"{c.key}_{s}" for c in CRITERIA for s in ("wins", "average_rank", "sequences"))
    + ("seeds",)
)
# ``runs`` in averages.csv / timings.csv counts cells (sequences): with several seeds, a cell is the median of
# its seeds' runs.  ``seeds`` (last column of every table) lists the seeds the values are medians over.
AVERAGE_COLUMNS = ("dataset", "feature", "runs", "tracked_fraction", "n_tracked", "tracked_frames", "rpe_rot",
                   "n_rpe_rot", "rpe_trans", "n_rpe_trans", "ate", "n_ate", "common_rpe_rot", "common_rpe_trans",
                   "n_common", "seeds")  # fmt: skip
TIMING_COLUMNS = ("dataset", "feature", "runs", "frames", "feature_ms", "io_ms", "tracking_ms", "mapping_ms",
                  "total_ms", "fps", "wall_fps", "seeds")  # fmt: skip
RANKS_PER_SEQUENCE_COLUMNS = ("dataset", "sequence", "feature") + tuple(f"{c.key}_rank" for c in CRITERIA) + ("seeds",)
#: Columns of ``tables/cells.csv``: one row per (sequence, feature) cell; per metric of
#: :data:`~dmtrack.evaluation.rankings.SEED_METRICS` its median, min and max over the seeds and n (seeds with a
#: value); ``worst_*`` describe the worst seed (a failed one, else the fewest tracked frames).
CELL_COLUMNS = ("dataset", "sequence", "feature", "seeds", "runs", "n_ok", "n_lost", "n_failed", "total_frames",
                "worst_seed", "worst_status", "worst_tracked_frames", "worst_lost_at") + tuple(
    f"{m}_{s}" for m in SEED_METRICS for s in ("median", "min", "max", "n")
)  # fmt: skip


# ============================================================================================ CSV files
def _csv_value(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(v)
    return v


def write_csv(path: str | Path, rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> Path:
    """Write ``rows`` as CSV with ``columns`` (missing → empty cell); atomically."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([_csv_value(r.get(c)) for c in columns])
    p = Path(path)
    write_text(p, buf.getvalue())
    return p


def ranking_csv_rows(
    dataset: str, table: Sequence[FeatureRanking], seeds: dict[str, str] | None = None
) -> list[dict[str, Any]]:
    """The rows of ``tables/rankings.csv`` for one ranking table (``seeds``: per feature, its seed list)."""
    out = []
    for fr in table:
        row: dict[str, Any] = {"dataset": dataset, "feature": fr.feature, "seeds": (seeds or {}).get(fr.feature)}
        for c in CRITERIA:
            row[f"{c.key}_wins"] = fr.wins[c.key]
            row[f"{c.key}_average_rank"] = fr.average_rank[c.key]
            row[f"{c.key}_sequences"] = fr.sequences[c.key]
        out.append(row)
    return out


def cell_csv_rows(cells: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of ``tables/cells.csv`` (:data:`CELL_COLUMNS`) from the cells of ``aggregate_seeds``."""
    out = []
    for c in cells:
        row = {k: c.get(k) for k in CELL_COLUMNS if k in c}
        row["seeds"] = format_seeds(c["seeds"])
        for m in SEED_METRICS:
            row[f"{m}_median"] = c.get(m)
        out.append(row)
    return out


def dataclass_rows(dataset: str, items: Sequence[Any], seeds: dict[str, str] | None = None) -> list[dict[str, Any]]:
    """CSV rows of per-feature dataclasses (averages, timings), with the dataset first and the seeds last."""
    return [{"dataset": dataset, **asdict(x), "seeds": (seeds or {}).get(x.feature)} for x in items]


# ========================================================================================= markdown text
def fmt_value(v: Any, digits: int = 2) -> str:
    """A table cell: a float with ``digits`` decimals, ``–`` for a missing or non-finite value."""
    if v is None:
        return "–"
    if isinstance(v, float):
        if not math.isfinite(v):
            return "–"
        return f"{v:.{digits}f}"
    return str(v)


def md_table(headers: Sequence[str], rows: Sequence[Sequence[Any]], align: str | None = None) -> str:
    """A markdown table; ``align`` has one letter per column (``l``, ``r``, ``c``; default: first left)."""
    align = align or "l" + "r" * (len(headers) - 1)
    marks = {"l": ":---", "r": "---:", "c": ":---:"}
    lines = ["| " + " | ".join(headers) + " |", "| " + " | ".join(marks[a] for a in align) + " |"]
    for r in rows:
        lines.append("| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |")
    return "\n".join(lines)


def plural(n: int, word: str) -> str:
    """``"1 seed"``, ``"3 seeds"``."""
    return f"{n} {word}" + ("" if n == 1 else "s")


def cell_value(c: dict[str, Any], key: str, digits: int, after: str = "") -> str:
    """A cell's median of ``key`` (then ``after``), with several seeds followed by ``(min–max)`` and, when
    only some seeds have a value, ``[k of n]``."""
    med = c.get(key)
    if med is None:
        return "–"
    text = fmt_value(med, digits) + after
    if c.get("runs", 1) > 1:
        n = c.get(f"{key}_n", 0)
        if n > 1:
            text += f" ({fmt_value(c[f'{key}_min'], digits)}–{fmt_value(c[f'{key}_max'], digits)})"
        if n < c["runs"]:
            text += f" [{n} of {c['runs']}]"
    return text


def cell_status(c: dict[str, Any]) -> str:
    """``ok`` / ``lost @N`` / ``failed`` for one run; with several seeds the counts and the worst seed, e.g.
    ``2 ok, 1 lost; worst: seed 2 lost @14, 14/25 tracked``."""
    if c.get("runs", 1) <= 1:
        return str(c["status"]) + (f" @{c['lost_at']}" if c.get("lost_at") is not None else "")
    if c["n_ok"] == c["runs"]:
        return f"ok ({c['runs']} of {c['runs']})"
    counts = ", ".join(f"{c[f'n_{s}']} {s}" for s in ("ok", "lost", "failed") if c[f"n_{s}"])
    if c["worst_status"] == "failed":
        worst = f"seed {c['worst_seed']} failed"
    else:
        worst = (f"seed {c['worst_seed']} lost @{c['worst_lost_at']}, "
                 f"{fmt_value(c['worst_tracked_frames'])}/{fmt_value(c['total_frames'])} tracked")  # fmt: skip
    return f"{counts}; worst: {worst}"


def best_text(table: Sequence[FeatureRanking], key: str) -> str:
    """Who has the most wins and the best average rank for the criterion ``key``."""
    counted = [fr for fr in table if fr.average_rank[key] is not None]
    if not counted:
        return "no values"
    most = max(fr.wins[key] for fr in counted)
    winners = [fr.feature for fr in counted if fr.wins[key] == most]
    best_avg = min(fr.average_rank[key] for fr in counted)  # type: ignore[type-var]
    leaders = [fr.feature for fr in counted if fr.average_rank[key] == best_avg]
    return (f"most wins: {', '.join(winners)} ({most} of {counted[0].sequences[key]}); best average rank: "
            f"{', '.join(leaders)} ({best_avg:.2f})")  # fmt: skip


def ranking_md(table: Sequence[FeatureRanking]) -> str:
    """A ranking table (Tables 2–5 layout: wins and average ranking per criterion)."""
    hdr = ["Feature"] + [f"{c.label}: {w}" for c in CRITERIA for w in ("Wins Count", "Average Ranking")]
    body = [[fr.feature] + [x for c in CRITERIA for x in (fr.wins[c.key], fmt_value(fr.average_rank[c.key]))]
            for fr in table]  # fmt: skip
    return md_table(hdr, body)


def averages_md(averages: Sequence[FeatureAverages], unit: str) -> str:
    """The overall averages (Table 6 layout: features as columns)."""

    def with_n(v: float | None, n: int, digits: int = 2) -> str:
        return "–" if v is None else f"{v:.{digits}f} (n={n})"

    hdr = ["Average metric"] + [a.feature for a in averages]
    rows = [
        ["Tracked-frame fraction"] + [with_n(a.tracked_fraction, a.n_tracked, 3) for a in averages],
        ["Number of tracked frames"] + [fmt_value(a.tracked_frames, 1) for a in averages],
        [f"RPE rotation error (deg/{unit})"] + [with_n(a.rpe_rot, a.n_rpe_rot) for a in averages],
        [f"RPE trans. angle error (deg/{unit})"] + [with_n(a.rpe_trans, a.n_rpe_trans) for a in averages],
        [f"RPE rotation, common sequences (deg/{unit})"] + [with_n(a.common_rpe_rot, a.n_common) for a in averages],
        [f"RPE trans. angle, common sequences (deg/{unit})"]
        + [with_n(a.common_rpe_trans, a.n_common) for a in averages],
        [f"ATE ({unit})"] + [with_n(a.ate, a.n_ate, 4) for a in averages],
    ]
    return md_table(hdr, rows)


__all__ = [
    "AVERAGE_COLUMNS",
    "CELL_COLUMNS",
    "RANKING_COLUMNS",
    "RANKS_PER_SEQUENCE_COLUMNS",
    "TIMING_COLUMNS",
    "averages_md",
    "best_text",
    "cell_csv_rows",
    "cell_status",
    "cell_value",
    "dataclass_rows",
    "fmt_value",
    "md_table",
    "plural",
    "ranking_csv_rows",
    "ranking_md",
    "write_csv",
]
