"""Rankings and summary tables of a benchmark: the paper's Tables 2–7, as pure functions on tables.

A *table* is a sequence of rows, one row per run, each a mapping with at least ``sequence`` and ``feature``
and the metric columns used (``tracked_frames``, ``total_frames``, ``rpe_rot_deg_per_m``,
``rpe_trans_angle_deg_per_m``, ``ate_rmse``, the ``*_ms`` timings …).  A value is *missing* when it is
``None``, absent, or not a finite number (NaN, ±inf).  A run that crashed has no metrics at all: every one
of its values is missing.

Rankings (paper §3.1, Tables 2–5)
---------------------------------
For every sequence, the features are ranked per criterion with the standard competition ranking ("1224"):
``rank = 1 + (number of features with a strictly better value)``, so tied values share a rank and the next
rank is skipped.  Tracked frames: more is better; RPE rotation and translation-angle errors: less is better.
A feature whose value is missing on a sequence (failed run, no ground truth match, or no row for it) ranks
after every feature that has a value, tied with the other missing ones (rank = 1 + number of present
values).  A sequence where *no* feature has a value for a criterion is left out of that criterion (no wins,
not counted in the averages), since ranking nothing against nothing says nothing.
Per feature and criterion: *wins* = number of sequences where the feature has rank 1 (ties count as a win
for every tied feature, as in the paper where the win counts of a dataset can add up to more than its
number of sequences); *average ranking* = mean rank over the counted sequences.

Overall averages (Table 6)
--------------------------
Per feature, the mean over its runs (sequences) of the tracked-frame fraction (``tracked_frames /
total_frames``), of the number of tracked frames, and of the RPE rotation / translation-angle errors and
the ATE — each over the runs where the value is defined; ``n_*`` says how many.  Missing values are left
out, not counted as zero or as a penalty: a crashed run is not a measurement.  Because leaving values out
lets a feature that fails on hard sequences look better, the RPE errors are also averaged over the
*common* sequences, those where every feature has both RPE values (``common_*``, ``n_common``).

Timings (Table 7)
-----------------
Per feature, frame-weighted means of the per-frame times (ms): ``feature_ms`` (feature extraction and
pyramid), ``io_ms`` (reading and decoding images), ``tracking_ms``, ``mapping_ms``; ``total_ms`` = their
sum (the paper's "feature generation" also counts file I/O); ``fps = 1000 / total_ms``; ``wall_fps`` =
processed frames / wall-clock seconds of the whole runs.  Each run is weighted by its processed frames
(``processed_frames``, else ``total_frames``), so the result is the mean over all frames processed.

Several seeds (:func:`aggregate_seeds`)
---------------------------------------
A bench run with several seeds of the random depth initialisation has several rows per (sequence, feature)
*cell*.  :func:`aggregate_seeds` turns them into one row per cell whose metric values are the **medians
over the seeds** (each over the seeds where the value is defined; the mean of the two middle values for
an even count), with ``<metric>_min``, ``<metric>_max`` and ``<metric>_n`` beside them, the seeds, how many
seeds tracked to the end / lost tracking / failed, and the *worst* seed (a failed one, else the fewest
tracked frames).  All the tables above are then computed on these cell rows — the rankings and wins on the
per-cell medians; with one seed per cell a cell row carries the run's own values.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

Row = Mapping[str, Any]


@dataclass(frozen=True)
class Criterion:
    """A ranking criterion: a column of the table and its direction."""

    key: str
    label: str
    higher_is_better: bool


TRACKED_FRAMES = Criterion("tracked_frames", "Tracked Frames", True)
ROTATION_ERROR = Criterion("rpe_rot_deg_per_m", "Rotation Error", False)
TRANS_ANGLE_ERROR = Criterion("rpe_trans_angle_deg_per_m", "Trans. Ang. Error", False)
#: The paper's three ranking criteria (Tables 2–5), in its column order.
CRITERIA: tuple[Criterion, ...] = (TRACKED_FRAMES, ROTATION_ERROR, TRANS_ANGLE_ERROR)


# ----------------------------------------------------------------------------------------------- values
def value_of(row: Row | None, key: str) -> float | None:
    """``row[key]`` as a float, or ``None`` if the row or the value is missing / not a finite number."""
    if row is None:
        return None
    v = row.get(key)
    if v is None or isinstance(v, bool):
        return None
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def mean_defined(values: Iterable[float | None]) -> tuple[float | None, int]:
    """Mean of the values that are not missing, and how many there were (``(None, 0)`` if none)."""
    xs = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return (sum(xs) / len(xs), len(xs)) if xs else (None, 0)


def competition_rank(values: Sequence[float | None], higher_is_better: bool = False) -> list[int]:
    """Standard competition ranking ("1224") of ``values``.

    Parameters
    ----------
    values : one value per competitor; ``None`` / NaN / inf = missing.
    higher_is_better : True for "more is better" (tracked frames), False for errors.

    Returns
    -------
    list[int]
        ``1 + number of strictly better values`` per competitor; a missing value ranks after all present
        ones: ``1 + number of present values``.

    Examples
    --------
    >>> competition_rank([0.5, 0.2, 0.5, None, 0.9])
    [2, 1, 2, 5, 4]
    >>> competition_rank([10, 30, 30, 20], higher_is_better=True)
    [4, 1, 1, 3]
    """
    xs = [value_of({"v": v}, "v") for v in values]
    present = [x for x in xs if x is not None]
    ranks = []
    for x in xs:
        if x is None:
            ranks.append(1 + len(present))
        elif higher_is_better:
            ranks.append(1 + sum(1 for y in present if y > x))
        else:
            ranks.append(1 + sum(1 for y in present if y < x))
    return ranks


# ------------------------------------------------------------------------------------------------ tables
def ordered_unique(items: Iterable[str]) -> list[str]:
    """The distinct items in order of first appearance."""
    seen: dict[str, None] = {}
    for it in items:
        seen.setdefault(it, None)
    return list(seen)


def _index(rows: Iterable[Row]) -> dict[tuple[str, str], Row]:
    out: dict[tuple[str, str], Row] = {}
    for r in rows:
        key = (str(r["sequence"]), str(r["feature"]))
        if key in out:
            raise ValueError(f"two rows for sequence {key[0]!r} and feature {key[1]!r}")
        out[key] = r
    return out


def _features(rows: Sequence[Row], features: Sequence[str] | None) -> list[str]:
    return list(features) if features is not None else ordered_unique(str(r["feature"]) for r in rows)


def group_rows(rows: Iterable[Row], key: str = "dataset") -> dict[str, list[Row]]:
    """Rows grouped by ``row[key]`` (groups in order of first appearance; ``None`` → ``"unknown"``)."""
    groups: dict[str, list[Row]] = {}
    for r in rows:
        groups.setdefault(str(r.get(key) or "unknown"), []).append(r)
    return groups


def sequence_ranks(
    rows: Sequence[Row],
    features: Sequence[str] | None = None,
    criteria: Sequence[Criterion] = CRITERIA,
) -> dict[str, dict[str, dict[str, int | None]]]:
    """Per-sequence competition ranks.

    Parameters
    ----------
    rows : one row per (sequence, feature) run (a duplicate raises ``ValueError``).
    features : the competitors (default: every feature in ``rows``, in order of appearance); a feature
        without a row for a sequence is missing there.
    criteria : what to rank by.

    Returns
    -------
    dict
        ``ranks[sequence][feature][criterion.key]`` — an int, or ``None`` where no feature has a value
        for that criterion on that sequence.
    """
    feats = _features(rows, features)
    index = _index(rows)
    out: dict[str, dict[str, dict[str, int | None]]] = {}
    for seq in ordered_unique(str(r["sequence"]) for r in rows):
        per_feature: dict[str, dict[str, int | None]] = {f: {} for f in feats}
        for c in criteria:
            vals = [value_of(index.get((seq, f)), c.key) for f in feats]
            if all(v is None for v in vals):
                for f in feats:
                    per_feature[f][c.key] = None
                continue
            for f, rank in zip(feats, competition_rank(vals, c.higher_is_better), strict=True):
                per_feature[f][c.key] = rank
        out[seq] = per_feature
    return out


@dataclass(frozen=True)
class FeatureRanking:
    """One row of Tables 2–5.

    Attributes
    ----------
    feature : the feature's name.
    wins : per criterion key, the number of sequences where the feature ranks first (ties included).
    average_rank : per criterion key, the mean rank over the counted sequences (``None`` if none).
    sequences : per criterion key, the number of sequences counted (those where any feature has a value).
    """

    feature: str
    wins: dict[str, int] = field(default_factory=dict)
    average_rank: dict[str, float | None] = field(default_factory=dict)
    sequences: dict[str, int] = field(default_factory=dict)


def ranking_table(
    rows: Sequence[Row],
    features: Sequence[str] | None = None,
    criteria: Sequence[Criterion] = CRITERIA,
) -> list[FeatureRanking]:
    """Wins count and average ranking per feature and criterion (the layout of the paper's Tables 2–5).

    ``rows`` should hold one dataset's runs; see the module docstring for ties and missing values.
    """
    feats = _features(rows, features)
    ranks = sequence_ranks(rows, feats, criteria)
    out = []
    for f in feats:
        wins: dict[str, int] = {}
        avg: dict[str, float | None] = {}
        counted: dict[str, int] = {}
        for c in criteria:
            rs = [ranks[s][f][c.key] for s in ranks if ranks[s][f][c.key] is not None]
            wins[c.key] = sum(1 for r in rs if r == 1)
            avg[c.key] = sum(rs) / len(rs) if rs else None  # type: ignore[arg-type]
            counted[c.key] = len(rs)
        out.append(FeatureRanking(f, wins, avg, counted))
    return out


@dataclass(frozen=True)
class FeatureAverages:
    """One column of Table 6 (overall averages of a feature over a dataset's sequences).

    Values are means over the runs where they are defined (``n_*`` of them); ``None`` if there is none.
    ``common_rpe_rot`` / ``common_rpe_trans`` average over the ``n_common`` sequences where every feature
    has both RPE values.  Per-metre values are per ground-truth length unit.
    """

    feature: str
    runs: int
    tracked_fraction: float | None
    n_tracked: int
    tracked_frames: float | None
    rpe_rot: float | None
    n_rpe_rot: int
    rpe_trans: float | None
    n_rpe_trans: int
    ate: float | None
    n_ate: int
    common_rpe_rot: float | None
    common_rpe_trans: float | None
    n_common: int


def tracked_fraction(row: Row) -> float | None:
    """``tracked_frames / total_frames`` of a run, ``None`` if either is missing or total is 0."""
    t, n = value_of(row, "tracked_frames"), value_of(row, "total_frames")
    return t / n if t is not None and n is not None and n > 0 else None


def _fraction(row: Row) -> float | None:
    """A row's ``tracked_fraction`` when it has one (a cell row: the median over seeds), else computed."""
    v = value_of(row, "tracked_fraction")
    return v if v is not None else tracked_fraction(row)


def overall_averages(rows: Sequence[Row], features: Sequence[str] | None = None) -> list[FeatureAverages]:
    """Table 6: per-feature averages over the sequences of ``rows`` (see the module docstring); the
    tracked-frame fraction is a row's ``tracked_fraction`` when given, else ``tracked / total``."""
    feats = _features(rows, features)
    index = _index(rows)
    seqs = ordered_unique(str(r["sequence"]) for r in rows)
    common = [
        s
        for s in seqs
        if all(
            value_of(index.get((s, f)), ROTATION_ERROR.key) is not None
            and value_of(index.get((s, f)), TRANS_ANGLE_ERROR.key) is not None
            for f in feats
        )
    ]
    out = []
    for f in feats:
        mine = [index[(s, f)] for s in seqs if (s, f) in index]
        frac, n_frac = mean_defined(_fraction(r) for r in mine)
        frames, _ = mean_defined(value_of(r, "tracked_frames") for r in mine)
        rot, n_rot = mean_defined(value_of(r, ROTATION_ERROR.key) for r in mine)
        trans, n_trans = mean_defined(value_of(r, TRANS_ANGLE_ERROR.key) for r in mine)
        ate, n_ate = mean_defined(value_of(r, "ate_rmse") for r in mine)
        c_rot, _ = mean_defined(value_of(index[(s, f)], ROTATION_ERROR.key) for s in common)
        c_trans, _ = mean_defined(value_of(index[(s, f)], TRANS_ANGLE_ERROR.key) for s in common)
        out.append(
            FeatureAverages(f, len(mine), frac, n_frac, frames, rot, n_rot, trans, n_trans, ate, n_ate,
                            c_rot, c_trans, len(common))
        )  # fmt: skip
    return out


@dataclass(frozen=True)
class FeatureTiming:
    """One row of Table 7: frame-weighted mean times per frame (ms) of a feature.

    ``runs`` = runs with timings, ``frames`` = frames they processed; ``total_ms`` = io + feature +
    tracking + mapping; ``fps`` = 1000 / total_ms; ``wall_fps`` = frames / wall seconds.
    """

    feature: str
    runs: int
    frames: int
    feature_ms: float | None
    io_ms: float | None
    tracking_ms: float | None
    mapping_ms: float | None
    total_ms: float | None
    fps: float | None
    wall_fps: float | None


def _weighted(rows: Sequence[Row], key: str) -> float | None:
    num = den = 0.0
    for r in rows:
        v, w = value_of(r, key), _frames(r)
        if v is not None and w:
            num += v * w
            den += w
    return num / den if den > 0 else None


def _frames(row: Row) -> float:
    w = value_of(row, "processed_frames")
    if w is None:
        w = value_of(row, "total_frames")
    return w or 0.0


def timing_table(rows: Sequence[Row], features: Sequence[str] | None = None) -> list[FeatureTiming]:
    """Table 7: frame-weighted mean per-frame times of each feature over its runs (rows without timings —
    failed runs — are left out)."""
    feats = _features(rows, features)
    out = []
    for f in feats:
        mine = [r for r in rows if str(r["feature"]) == f and value_of(r, "tracking_ms") is not None]
        parts = {k: _weighted(mine, k) for k in ("feature_ms", "io_ms", "tracking_ms", "mapping_ms")}
        present = [v for v in parts.values() if v is not None]
        total = sum(present) if present else None
        frames = int(sum(_frames(r) for r in mine))
        timed = [r for r in mine if value_of(r, "wall_s")]
        wall = sum(value_of(r, "wall_s") or 0.0 for r in timed)
        wall_frames = sum(_frames(r) for r in timed)
        out.append(
            FeatureTiming(
                f, len(mine), frames, parts["feature_ms"], parts["io_ms"], parts["tracking_ms"],
                parts["mapping_ms"], total, 1000.0 / total if total else None,
                wall_frames / wall if wall > 0 else None,
            )
        )  # fmt: skip
    return out


# ------------------------------------------------------------------------------------------ several seeds
#: The metrics :func:`aggregate_seeds` summarises per cell (median, min, max and n over the seeds).
SEED_METRICS: tuple[str, ...] = (
    "tracked_frames", "tracked_fraction", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "ate_rmse", "fps",
    "feature_ms", "io_ms", "tracking_ms", "mapping_ms", "total_ms", "wall_s",
)  # fmt: skip
#: Columns copied from a cell's first row (they do not depend on the seed).
_CELL_CONSTANTS = ("dataset", "channels", "width", "height", "start", "r_l", "gt_path_length")
_STATUS_ORDER = {"failed": 0, "lost": 1, "ok": 2}


def median_range(values: Iterable[float | None]) -> tuple[float | None, float | None, float | None, int]:
    """``(median, min, max, n)`` of the values that are not missing (``(None, None, None, 0)`` if none).

    >>> median_range([3.0, None, 1.0, 2.0, 10.0])
    (2.5, 1.0, 10.0, 4)
    >>> median_range([12, 9, 12])
    (12, 9, 12, 3)
    """
    raw = [v for v in values if value_of({"v": v}, "v") is not None]
    if not raw:
        return None, None, None, 0
    xs = [float(v) for v in raw]
    med, lo, hi = float(statistics.median(xs)), min(xs), max(xs)
    if all(isinstance(v, int) for v in raw):  # counts stay integers where they can
        med, lo, hi = (int(x) if x.is_integer() else x for x in (med, lo, hi))
    return med, lo, hi, len(xs)


def _seed_key(row: Row) -> tuple[int, float]:
    s = value_of(row, "seed")
    return (0, s) if s is not None else (1, 0.0)


def worst_row(rows: Sequence[Row]) -> Row:
    """The worst run of a cell: a failed one, else a lost one with the fewest tracked frames, else the one with
    the fewest tracked frames (ties: the lowest seed)."""

    def badness(r: Row) -> tuple[int, float, tuple[int, float]]:
        tracked = value_of(r, "tracked_frames")
        return (_STATUS_ORDER.get(str(r.get("status")), 0), -1.0 if tracked is None else tracked, _seed_key(r))

    return min(rows, key=badness)


def aggregate_seeds(rows: Iterable[Row], metrics: Sequence[str] = SEED_METRICS) -> list[dict[str, Any]]:
    """One row per (sequence, feature) cell of a table with one row per run and seed (see the module docstring).

    Parameters
    ----------
    rows : runs with ``sequence``, ``feature``, ``seed``, ``status`` (``"ok"``, ``"lost"`` or ``"failed"``) and
        the ``metrics`` (missing values are left out of the medians).
    metrics : the columns to summarise.

    Returns
    -------
    list[dict]
        In order of first appearance: ``sequence``, ``feature``, the seed-independent columns of the first
        row (``dataset``, ``channels``…), ``seeds`` (sorted list), ``runs``, ``n_ok``, ``n_lost``,
        ``n_failed``; per metric ``m``: ``m`` (the median), ``m_min``, ``m_max``, ``m_n``; ``total_frames``
        and ``processed_frames`` (medians); ``status`` and ``lost_at`` of the worst run and ``worst_seed``,
        ``worst_status``, ``worst_tracked_frames``, ``worst_lost_at``.
    """
    cells: dict[tuple[str, str], list[Row]] = {}
    for r in rows:
        cells.setdefault((str(r["sequence"]), str(r["feature"])), []).append(r)
    out = []
    for (seq, feat), runs in cells.items():
        runs = sorted(runs, key=_seed_key)
        cell: dict[str, Any] = {"sequence": seq, "feature": feat}
        for k in _CELL_CONSTANTS:
            cell[k] = next((r.get(k) for r in runs if r.get(k) is not None), None)
        seeds = [r.get("seed") for r in runs]
        cell["seeds"] = sorted(int(s) for s in seeds if value_of({"s": s}, "s") is not None)
        cell["runs"] = len(runs)
        for status in ("ok", "lost", "failed"):
            cell[f"n_{status}"] = sum(1 for r in runs if r.get("status") == status)
        for m in metrics:
            med, lo, hi, n = median_range(r.get(m) for r in runs)
            cell.update({m: med, f"{m}_min": lo, f"{m}_max": hi, f"{m}_n": n})
        for k in ("total_frames", "processed_frames"):
            cell[k] = median_range(r.get(k) for r in runs)[0]
        worst = worst_row(runs)
        cell["worst_seed"] = worst.get("seed")
        cell["worst_status"] = worst.get("status")
        cell["worst_tracked_frames"] = worst.get("tracked_frames")
        cell["worst_lost_at"] = worst.get("lost_at")
        cell["status"] = worst.get("status")
        cell["lost_at"] = worst.get("lost_at")
        out.append(cell)
    return out
