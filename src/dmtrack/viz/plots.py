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
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p, dpi=DPI)
    return p


# ------------------------------------------------------------------------------------- Figure 1: RPE(L)
@dataclass(frozen=True)
class RpeCurve:
    """Per-length RPE of one run.

    Attributes
    ----------
    label : legend text (the paper: ``"Gray [1234]"`` with the tracked frames in brackets).
    lengths : (K,) path lengths L_k, ground-truth length unit.
    rot, trans : (K,) mean rotation / translation-angle error at each length, degrees per length unit
        (NaN where a length has no pair).
    """

    label: str
    lengths: np.ndarray
    rot: np.ndarray
    trans: np.ndarray


def save_rpe_vs_length(path: str | Path, curves: Sequence[RpeCurve], title: str, unit: str = "m") -> Path:
    """Figure 1: RPE rotation and translation-angle errors against the path length, one line per run."""
    fig = _figure(10.0, 3.8)
    ax_rot, ax_trans = fig.subplots(1, 2)
    for c in curves:
        x = np.asarray(c.lengths, dtype=float)
        for ax, y in ((ax_rot, c.rot), (ax_trans, c.trans)):
            y = np.asarray(y, dtype=float)
            ok = np.isfinite(x) & np.isfinite(y)
            ax.plot(x[ok], y[ok], marker="o", markersize=3, linewidth=1.3, label=c.label)
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
    """One feature's point of Figure 5: mean total time per frame (ms) and mean RPE errors."""

    label: str
    total_ms: float
    rot: float | None
    trans: float | None


def save_accuracy_vs_time(
    path: str | Path, points: Sequence[SpeedAccuracy], title: str, unit: str = "m", note: str = ""
) -> Path:
    """Figure 5: average RPE errors against the average total processing time per frame, one point per
    feature (log time axis)."""
    fig = _figure(10.0, 3.8)
    axes = fig.subplots(1, 2)
    for ax, attr, name in ((axes[0], "rot", "rotation"), (axes[1], "trans", "translation angle")):
        for i, p in enumerate(points):
            y = getattr(p, attr)
            if y is None or not np.isfinite(y) or not p.total_ms or p.total_ms <= 0:
                continue
            ax.scatter([p.total_ms], [y], color=f"C{i % 10}", s=30, zorder=3)
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
