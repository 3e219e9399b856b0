"""Matplotlib figures of a benchmark (the paper's Figures 1, 4 and 5, and top-view trajectories).

Headless and side-effect free: figures are :class:`matplotlib.figure.Figure` objects rendered with the Agg
canvas — pyplot and its global state are never used, no backend is switched — and matplotlib is imported
inside the functions, so importing this module (or dmtrack) never imports matplotlib.

Every ``save_*`` function writes one PNG and returns its path.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

DPI = 110


def _figure(width: float, height: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Any, path: str | Path) -> Path:
    from dmtrack.io.atomic import atomic_open

    p = Path(path)
    with atomic_open(p, "wb") as f:
        fig.savefig(f, dpi=DPI, format=p.suffix.lstrip(".").lower() or None)
    return p


# ------------------------------------------------------------------------------------- Figure 1: RPE(L)
@dataclass(frozen=True)
class RpeCurve:
    """Per-length RPE of one run, or the median of several seeds' runs with their min–max.

    Attributes
    ----------
    label : legend text (the paper: ``"Gray [1234]"`` with the tracked frames in brackets).
    lengths : (K,) path lengths L_k, ground-truth length unit.
    rot, trans : (K,) mean rotation / translation-angle error at each length, degrees per length unit
        (NaN where a length has no pair); with several seeds, the median over them.
    rot_lo, rot_hi, trans_lo, trans_hi : (K,) minimum and maximum over the seeds (drawn as error bars), or
        ``None`` for one run.
    """

    label: str
    lengths: np.ndarray
    rot: np.ndarray
    trans: np.ndarray
    rot_lo: np.ndarray | None = None
    rot_hi: np.ndarray | None = None
    trans_lo: np.ndarray | None = None
    trans_hi: np.ndarray | None = None


def _yerr(y: np.ndarray, lo: np.ndarray | None, hi: np.ndarray | None, ok: np.ndarray) -> np.ndarray | None:
    """Asymmetric error bars ``(2, n)`` from bounds (missing bounds: no bar), never negative."""
    if lo is None or hi is None:
        return None
    lo = np.asarray(lo, dtype=float)[ok]
    hi = np.asarray(hi, dtype=float)[ok]
    err = np.stack([y - lo, hi - y])
    return np.clip(np.nan_to_num(err, nan=0.0), 0.0, None)


def save_rpe_vs_length(path: str | Path, curves: Sequence[RpeCurve], title: str, unit: str = "m") -> Path:
    """Figure 1: RPE rotation and translation-angle errors against the path length, one line per run (or per
    feature: the median over seeds, with min–max error bars)."""
    fig = _figure(10.0, 3.8)
    ax_rot, ax_trans = fig.subplots(1, 2)
    for i, c in enumerate(curves):
        x = np.asarray(c.lengths, dtype=float)
        for ax, y, lo, hi in ((ax_rot, c.rot, c.rot_lo, c.rot_hi), (ax_trans, c.trans, c.trans_lo, c.trans_hi)):
            y = np.asarray(y, dtype=float)
            ok = np.isfinite(x) & np.isfinite(y)
            yerr = _yerr(y[ok], lo, hi, ok)
            if yerr is None:
                ax.plot(x[ok], y[ok], marker="o", markersize=3, linewidth=1.3, label=c.label, color=f"C{i % 10}")
            else:
                ax.errorbar(x[ok], y[ok], yerr=yerr, marker="o", markersize=3, linewidth=1.3, capsize=3,
                            label=c.label, color=f"C{i % 10}")  # fmt: skip
    ax_rot.set_title("RPE rotation error")
    ax_trans.set_title("RPE translation angle error")
    for ax in (ax_rot, ax_trans):
        ax.set_xlabel(f"path length [{unit}]")
        ax.set_ylabel(f"error [deg/{unit}]")
        ax.grid(True, alpha=0.3)
    if curves:
        ax_rot.legend(fontsize=8)
    fig.suptitle(title)
    return _save(fig, path)


# ---------------------------------------------------------------------------- Figure 5: accuracy vs time
@dataclass(frozen=True)
class SpeedAccuracy:
    """One feature's point of Figure 5: mean total time per frame (ms) and mean RPE errors.

    ``rot_range``, ``trans_range``, ``ms_range``: ``(low, high)`` drawn as error bars (several seeds: the
    minima and maxima over the seeds averaged like the point), or ``None``.
    """

    label: str
    total_ms: float
    rot: float | None
    trans: float | None
    rot_range: tuple[float, float] | None = None
    trans_range: tuple[float, float] | None = None
    ms_range: tuple[float, float] | None = None


def _bar(v: float, rng: tuple[float, float] | None) -> Any:
    if rng is None:
        return None
    return [[max(0.0, v - rng[0])], [max(0.0, rng[1] - v)]]


def save_accuracy_vs_time(
    path: str | Path, points: Sequence[SpeedAccuracy], title: str, unit: str = "m", note: str = ""
) -> Path:
    """Figure 5: average RPE errors against the average total processing time per frame, one point per
    feature (log time axis; with error bars where the points give ranges)."""
    fig = _figure(10.0, 3.8)
    axes = fig.subplots(1, 2)
    for ax, attr, name in ((axes[0], "rot", "rotation"), (axes[1], "trans", "translation angle")):
        for i, p in enumerate(points):
            y = getattr(p, attr)
            if y is None or not np.isfinite(y) or not p.total_ms or p.total_ms <= 0:
                continue
            ax.scatter([p.total_ms], [y], color=f"C{i % 10}", s=30, zorder=3)
            yerr, xerr = _bar(y, getattr(p, f"{attr}_range")), _bar(p.total_ms, p.ms_range)
            if yerr is not None or xerr is not None:
                ax.errorbar([p.total_ms], [y], yerr=yerr, xerr=xerr, fmt="none", ecolor=f"C{i % 10}", capsize=3,
                            linewidth=1.0, zorder=2)  # fmt: skip
            ax.annotate(p.label, (p.total_ms, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
        ax.set_xscale("log")
        ax.set_xlabel("total time per frame [ms]")
        ax.set_ylabel(f"RPE {name} error [deg/{unit}]")
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(title + (f"\n{note}" if note else ""), fontsize=10)
    return _save(fig, path)


# ------------------------------------------------------------------------------- Figure 4: depth maps
@dataclass(frozen=True)
class DepthCell:
    """One picture of the depth grid: an image file (or ``None`` for an empty cell) and its caption."""

    image: Path | None
    caption: str


def save_depth_grid(
    path: str | Path,
    rows: Sequence[tuple[str, Sequence[DepthCell]]],
    column_titles: Sequence[str],
    title: str,
) -> Path:
    """Figure 4: keyframe inverse-depth pictures (``depth/*.png`` of the runs), one row per feature.

    Parameters
    ----------
    rows : ``(feature, cells)``; every row has ``len(column_titles)`` cells.
    column_titles : e.g. ``"t = 120"`` (the frame each column shows the reference keyframe for).
    """
    from dmtrack.io.images import read_image

    n_rows = max(1, len(rows))
    n_cols = max(1, len(column_titles))
    aspect = 0.75
    for _, cells in rows:
        for c in cells:
            if c.image is not None:
                img = read_image(c.image)
                aspect = img.shape[0] / img.shape[1]
                break
    cell_w = 3.2
    fig = _figure(cell_w * n_cols + 0.8, (cell_w * aspect + 0.45) * n_rows + 0.5)
    axes = np.atleast_2d(fig.subplots(n_rows, n_cols, squeeze=False))
    for r, (feature, cells) in enumerate(rows):
        for c in range(n_cols):
            ax = axes[r, c]
            ax.set_xticks([])
            ax.set_yticks([])
            cell = cells[c] if c < len(cells) else DepthCell(None, "")
            if cell.image is not None:
                ax.imshow(read_image(cell.image))
            else:
                ax.set_facecolor("0.9")
                ax.text(0.5, 0.5, "no keyframe", ha="center", va="center", transform=ax.transAxes, fontsize=8)
            ax.set_xlabel(cell.caption, fontsize=7)
            if c == 0:
                ax.set_ylabel(feature, fontsize=9)
            if r == 0 and c < len(column_titles):
                ax.set_title(column_titles[c], fontsize=9)
    fig.suptitle(title + "\n(inverse depth: red near, blue far; magenta: negative)", fontsize=10)
    return _save(fig, path)


# ------------------------------------------------------------------------------- top-view trajectories
def topview_basis(positions: np.ndarray) -> np.ndarray:
    """(2, 3) orthonormal rows spanning the plane of largest spread of ``positions`` (N, 3).

    The two principal axes of the positions: the ground plane for a car, the plane of largest motion for a
    hand-held camera.  Signs are fixed (each axis' largest component positive) so the view is stable.
    """
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if p.shape[0] < 3:
        return np.eye(3)[:2]
    centred = p - p.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    if s[0] <= 0:
        return np.eye(3)[:2]
    basis = vt[:2].copy()
    for k in range(2):
        if basis[k, np.argmax(np.abs(basis[k]))] < 0:
            basis[k] = -basis[k]
    return basis


def save_trajectories_topview(
    path: str | Path,
    groundtruth: np.ndarray | None,
    estimates: Sequence[tuple[str, np.ndarray]],
    title: str,
    unit: str = "m",
) -> Path:
    """Top view of Sim(3)-aligned estimated trajectories against the ground truth.

    Parameters
    ----------
    groundtruth : (N, 3) ground-truth camera centres (or ``None``).
    estimates : ``(label, (M, 3) aligned camera centres)`` per run.
    """
    ref = groundtruth if groundtruth is not None and len(groundtruth) >= 3 else None
    if ref is None:
        non_empty = [e for _, e in estimates if len(e)]
        ref = np.concatenate(non_empty) if non_empty else np.zeros((0, 3))
    basis = topview_basis(ref)
    fig = _figure(6.0, 5.2)
    ax = fig.subplots()
    if groundtruth is not None and len(groundtruth):
        g = np.asarray(groundtruth) @ basis.T
        ax.plot(g[:, 0], g[:, 1], color="k", linestyle="--", linewidth=1.6, label="ground truth")
        ax.plot(g[:1, 0], g[:1, 1], "ko", markersize=4)
    for i, (label, pos) in enumerate(estimates):
        if len(pos) == 0:
            continue
        e = np.asarray(pos) @ basis.T
        ax.plot(e[:, 0], e[:, 1], color=f"C{i % 10}", linewidth=1.2, label=label)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"principal axis 1 [{unit}]")
    ax.set_ylabel(f"principal axis 2 [{unit}]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    return _save(fig, path)
