"""The "Losses and relocalisation" section of a run's ``report.html`` (a run that went on after a loss).

From ``metrics.json``'s ``lost_spans``, ``relocalised`` and ``segments`` (:func:`dmtrack.pipeline.result`): a table of
the spans of frames without a pose and where each ended — the frame, the keyframe the camera was found on — and a
time line of the run (tracked, lost, relocalised, before the start). The positions where the run was found again are
also drawn on the top view (:func:`relocalised_line`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dmtrack.evaluation.html.figures import Line
from dmtrack.evaluation.html.page import Page, base_layout, table

__all__ = ["has_losses", "losses_section", "lost_summary", "relocalised_line"]


def has_losses(m: dict[str, Any]) -> bool:
    """Whether the run lost frames or relocalised (its metrics say so)."""
    return bool(m.get("lost_frames") or m.get("relocalisations") or len(m.get("segments") or []) > 1)


def lost_summary(m: dict[str, Any]) -> str:
    """One line for the run's header: frames without a pose, relocalisations, map segments."""
    parts = [f"{m.get('lost_frames', 0)} frames without a pose", f"{m.get('relocalisations', 0)} relocalisations"]
    if len(m.get("segments") or []) > 1:
        parts.append(f"{len(m['segments'])} map segments")
    return ", ".join(parts)


def losses_section(page: Page, m: dict[str, Any]) -> None:
    """The table of lost spans and the time line (nothing for a run that never lost a frame)."""
    if not has_losses(m):
        return
    page.heading(2, "Losses and relocalisation", toc=True)
    found = {int(r["lost_since"]): r for r in m.get("relocalised") or []}
    rows = []
    for first, last in m.get("lost_spans") or []:
        r = next((r for since, r in found.items() if first <= since <= last), None)
        end = (f"relocalised at frame {r['frame']} on keyframe {r['keyframe']}" if r is not None
               else "no relocalisation (a new map, or the run ended)")  # fmt: skip
        rows.append([f"{first}–{last}", last - first + 1, end])
    page.add(table(["frames without a pose", "frames", "how it ended"], rows))
    segments = m.get("segments") or []
    if len(segments) > 1:
        page.text(
            "The odometry began a new map (a new segment) after a loss it could not recover from, at frames "
            + ", ".join(str(s["first_frame"]) for s in segments[1:])
            + ". Segments share no frame of reference: each is evaluated on its own in metrics.json (segments).",
            "note",
        )
    page.try_figure(lambda: _timeline(m), "time line of the losses")


def _timeline(m: dict[str, Any]) -> tuple[Any, str] | None:
    import plotly.graph_objects as go

    total = int(m.get("total_frames") or 0)
    start = int(m.get("start") or 0)
    if total <= 0:
        return None
    fig = go.Figure()
    before = int(m.get("before_start") or 0)
    bands = [(start, start + before - 1, "before the start", "#999999")] if before else []
    bands += [(a, b, "lost (no pose)", "#d62728") for a, b in m.get("lost_spans") or []]
    for a, b, name, col in bands:
        fig.add_trace(go.Scatter(x=[a - 0.5, b + 0.5, b + 0.5, a - 0.5, a - 0.5], y=[0, 0, 1, 1, 0], fill="toself",
                                 mode="lines", line={"width": 0}, fillcolor=col, name=name, showlegend=False,
                                 hovertemplate=f"{name}: frames {a}–{b}<extra></extra>"))  # fmt: skip
    relocs = m.get("relocalised") or []
    if relocs:
        fig.add_trace(go.Scatter(x=[r["frame"] for r in relocs], y=[0.5] * len(relocs), mode="markers",
                                 marker={"symbol": "diamond", "size": 12, "color": "#e377c2"}, name="relocalised",
                                 hovertemplate="relocalised at frame %{x}<extra></extra>"))  # fmt: skip
    fig.update_layout(**base_layout("Frames of the run", 200, showlegend=bool(relocs)))
    fig.update_xaxes(title_text="frame", range=[start - 0.5, start + total - 0.5])
    fig.update_yaxes(visible=False, range=[0, 1])
    return fig, ("Grey: frames before the geometric start's reference frame; red: frames without a pose after tracking "
                 "was lost; diamonds: where the camera was found again (relocalised). White: tracked frames.")


def relocalised_line(m: dict[str, Any], est: Any, positions: Any) -> Line | None:
    """Markers at the positions of the relocalised frames (by their timestamps in the estimate), for the top view;
    ``positions(traj)`` maps a trajectory's camera centres into the figure's frame."""
    times = [r.get("timestamp") for r in m.get("relocalised") or [] if r.get("timestamp") is not None]
    if not times or est is None or len(est) == 0:
        return None
    ts = np.asarray(est.timestamps, dtype=np.float64)
    rows = [int(np.argmin(np.abs(ts - t))) for t in times]
    rows = [r for r, t in zip(rows, times, strict=True) if abs(ts[r] - t) < 1e-6]
    if not rows:
        return None
    return Line(f"relocalised ({len(rows)})", positions(est[np.array(rows)]), "#e377c2", markers=True)
