"""The plotly figures of ``report.html`` shared by the run and the bench pages.

Each function returns a ``plotly.graph_objects.Figure`` (plotly is imported inside it).  Text shown by plotly
(titles, legend names, hover text) goes through :func:`~dmtrack.evaluation.html.page.esc`: plotly reads it as
a small subset of HTML and turns the entities back into the characters.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dmtrack.evaluation.html.page import SUBPLOT_MARGIN, base_layout, esc, thin


@dataclass(frozen=True)
class Line:
    """One trajectory of a top view: ``(N, 3)`` camera centres in the world frame, a label and a colour;
    ``segments``: ``positions`` are ``(M, 2, 3)`` end points of separate segments (e.g. a graph's edges)."""

    label: str
    positions: np.ndarray
    colour: str
    dash: str = "solid"
    markers: bool = False
    segments: bool = False


def topview_figure(lines: Sequence[Line], basis: np.ndarray, title: str, unit: str) -> Any:
    """Top view: the ``lines`` projected on the two rows of ``basis`` ((2, 3), e.g.
    :func:`dmtrack.viz.plots.topview_basis`), equal axis scales; a marker lines is drawn as points only."""
    import plotly.graph_objects as go

    fig = go.Figure()
    for ln in lines:
        if len(ln.positions) == 0:
            continue
        if ln.segments:
            _add_segments(fig, ln, basis)
            continue
        p = thin(np.asarray(ln.positions, dtype=np.float64) @ np.asarray(basis).T)
        fig.add_trace(go.Scatter(
            x=p[:, 0], y=p[:, 1], name=esc(ln.label), mode="markers" if ln.markers else "lines",
            line={"color": ln.colour, "width": 1.6, "dash": ln.dash},
            marker={"color": ln.colour, "size": 8, "symbol": "diamond", "line": {"width": 1, "color": "#fff"}},
            hovertemplate=esc(ln.label) + "<br>(%{x:.3f}, %{y:.3f})<extra></extra>",
        ))  # fmt: skip
        if not ln.markers:  # the start of each line
            fig.add_trace(go.Scatter(x=p[:1, 0], y=p[:1, 1], mode="markers", showlegend=False, hoverinfo="skip",
                                     marker={"color": ln.colour, "size": 7, "symbol": "circle-open"}))  # fmt: skip
    fig.update_layout(**base_layout(title, 560))
    fig.update_xaxes(title_text=f"axis 1 [{esc(unit)}]", zeroline=False)
    fig.update_yaxes(title_text=f"axis 2 [{esc(unit)}]", scaleanchor="x", scaleratio=1, zeroline=False)
    return fig


def _add_segments(fig: Any, ln: Line, basis: np.ndarray) -> None:
    import plotly.graph_objects as go

    ends = np.asarray(ln.positions, dtype=np.float64).reshape(-1, 2, 3) @ np.asarray(basis).T  # (M, 2, 2)
    gaps = np.full((len(ends), 1, 2), np.nan)
    p = np.concatenate([ends, gaps], axis=1).reshape(-1, 2).astype(np.float32)  # a gap after each segment
    fig.add_trace(go.Scatter(x=p[:, 0], y=p[:, 1], name=esc(ln.label), mode="lines", connectgaps=False,
                             line={"color": ln.colour, "width": 1.2, "dash": ln.dash},
                             hovertemplate=esc(ln.label) + "<br>(%{x:.3f}, %{y:.3f})<extra></extra>"))  # fmt: skip


@dataclass(frozen=True)
class Curve:
    """Per-length RPE of one run or one feature (see :class:`dmtrack.viz.plots.RpeCurve`) and its colour."""

    curve: Any
    colour: str


def _error_bars(y: np.ndarray, lo: Any, hi: Any) -> dict[str, Any] | None:
    if lo is None or hi is None:
        return None
    up = np.clip(np.nan_to_num(np.asarray(hi, dtype=float) - y, nan=0.0), 0.0, None)
    down = np.clip(np.nan_to_num(y - np.asarray(lo, dtype=float), nan=0.0), 0.0, None)
    return {"type": "data", "symmetric": False, "array": up.astype(np.float32),
            "arrayminus": down.astype(np.float32), "thickness": 1.2, "width": 4}  # fmt: skip


def rpe_figure(curves: Sequence[Curve], title: str, unit: str) -> Any:
    """The paper's Figure 1: RPE rotation and translation-angle errors against the path length L_k, one line
    per curve, with min–max error bars where the curve has bounds (several seeds)."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    fig = make_subplots(rows=1, cols=2, horizontal_spacing=0.1,
                        subplot_titles=("RPE rotation error", "RPE translation-angle error"))  # fmt: skip
    for c in curves:
        x = np.asarray(c.curve.lengths, dtype=float)
        for col, (y, lo, hi) in enumerate(((c.curve.rot, c.curve.rot_lo, c.curve.rot_hi),
                                           (c.curve.trans, c.curve.trans_lo, c.curve.trans_hi)), start=1):  # fmt: skip
            y = np.asarray(y, dtype=float)
            fig.add_trace(go.Scatter(
                x=x.astype(np.float32), y=y.astype(np.float32), name=esc(c.curve.label), legendgroup=esc(c.curve.label),
                showlegend=col == 1, mode="lines+markers", line={"color": c.colour, "width": 1.6},
                marker={"size": 6}, error_y=_error_bars(y, lo, hi),
                hovertemplate=f"{esc(c.curve.label)}<br>L = %{{x:.3f}} {esc(unit)}<br>%{{y:.3f}} deg/{esc(unit)}"
                "<extra></extra>",
            ), row=1, col=col)  # fmt: skip
    fig.update_layout(**base_layout(title, 450, margin=SUBPLOT_MARGIN))
    fig.update_xaxes(title_text=f"path length [{esc(unit)}]")
    fig.update_yaxes(title_text=f"error [deg/{esc(unit)}]", rangemode="tozero")
    return fig


__all__ = ["Curve", "Line", "rpe_figure", "topview_figure"]
