"""The SLAM part of a run folder's ``report.html`` (``dmtrack run --slam``): the odometry against SLAM.

A SLAM run folder has ``graph.json`` and ``trajectory_vo.txt`` beside the optimised ``trajectory.txt``
(:mod:`dmtrack.outputs.slam_files`). Its report gains a table of the odometry's errors against the optimised
trajectory's (``vo_ate_rmse``, ``vo_rpe_*`` and the main keys of ``metrics.json``), the graph's numbers, and in the
top view the odometry's own trajectory — Sim(3)-aligned to the ground truth by its own alignment, as its metrics
are — and the accepted loop edges between the optimised keyframes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from dmtrack.errors import DmtrackError
from dmtrack.evaluation.html.figures import Line
from dmtrack.evaluation.html.page import Page, table
from dmtrack.evaluation.tables import fmt_value
from dmtrack.io.bench_layout import GROUNDTRUTH_TXT

GRAPH_JSON = "graph.json"
TRAJECTORY_VO_TXT = "trajectory_vo.txt"
#: Colours of the top view's SLAM lines (the odometry's, the loop edges), apart from the palette's first (SLAM).
ODOMETRY_COLOUR = "#ff7f0e"
LOOP_COLOUR = "#e020c0"


def is_slam_run(folder: Path, m: dict[str, Any]) -> bool:
    """Whether ``folder`` is a SLAM run: ``slam`` in its metrics, or its ``graph.json`` / ``trajectory_vo.txt``."""
    return bool(m.get("slam")) or (folder / GRAPH_JSON).is_file() or (folder / TRAJECTORY_VO_TXT).is_file()


class SlamTracks:
    """The odometry's trajectory (``trajectory_vo.txt``) and the graph (``graph.json``) of a SLAM run folder; a file
    that cannot be read is a problem on the page."""

    def __init__(self, folder: Path, tracks: Any, page: Page) -> None:
        from dmtrack.io.trajectory import data_lines, read_tum
        from dmtrack.outputs.slam_files import read_graph

        self.vo = None
        self.vo_positions: np.ndarray | None = None  # aligned to the ground truth when the run's estimate is
        self.graph = None
        path = folder / TRAJECTORY_VO_TXT
        try:
            if path.is_file() and data_lines(path):
                self.vo = read_tum(path)
        except (DmtrackError, ValueError) as e:
            page.problem(TRAJECTORY_VO_TXT, e)
        try:
            if (folder / GRAPH_JSON).is_file():
                self.graph = read_graph(folder / GRAPH_JSON)
        except DmtrackError as e:
            page.problem(GRAPH_JSON, e)
        if self.vo is not None and len(self.vo):
            self.vo_positions = self.vo.positions
            if tracks.aligned and tracks.gt is not None:
                self._align(folder, tracks, page)

    def _align(self, folder: Path, tracks: Any, page: Page) -> None:
        from dmtrack.evaluation.metrics import ate
        from dmtrack.io.association import associate_trajectories

        try:
            gt_m, vo_m = associate_trajectories(tracks.gt, self.vo, max_diff=0.01)
            T = ate(gt_m, vo_m, "sim3").alignment
        except (DmtrackError, ValueError, np.linalg.LinAlgError) as e:
            page.problem(f"alignment of {TRAJECTORY_VO_TXT} to {GROUNDTRUTH_TXT}", e)
            self.vo_positions = None
            return
        self.vo_positions = self.vo.positions @ T[:3, :3].T + T[:3, 3]

    def lines(self, tracks: Any) -> list[Line]:
        """The top view's extra lines: the odometry's trajectory and the accepted loop edges (in the optimised
        trajectory's alignment)."""
        out = []
        if self.vo_positions is not None:
            out.append(Line(f"odometry [{len(self.vo_positions)}]", self.vo_positions, ODOMETRY_COLOUR, dash="dot"))
        loops = None if self.graph is None else self.graph.segments.get("loop")
        if loops is not None and len(loops):
            ends = tracks.map_points(loops.reshape(-1, 3)).reshape(-1, 2, 3)
            out.append(Line(f"loop edges ({len(loops)})", ends, LOOP_COLOUR, segments=True))
        return out

    def caption(self) -> str:
        parts = []
        if self.vo_positions is not None:
            parts.append("the odometry's own trajectory (trajectory_vo.txt, dotted; aligned to the ground truth by "
                         "its own Sim(3), as its metrics are)")  # fmt: skip
        if self.graph is not None and len(self.graph.segments.get("loop", ())):
            parts.append("the accepted loop edges of graph.json between the optimised keyframes")
        return (" With " + " and ".join(parts) + ".") if parts else ""


def slam_section(page: Page, m: dict[str, Any], unit: str, slam: SlamTracks) -> None:
    """The odometry against SLAM: errors side by side and the graph's numbers."""
    page.heading(2, "Odometry against SLAM", toc=True)
    rows = [
        (f"ATE RMSE ({unit}, Sim(3)-aligned)", "ate_rmse", 4),
        (f"RPE rotation (deg/{unit})", "rpe_rot_deg_per_m", 3),
        (f"RPE translation angle (deg/{unit})", "rpe_trans_angle_deg_per_m", 3),
    ]
    page.add(table(["", "odometry", "SLAM"],
                   [(label, fmt_value(m.get(f"vo_{k}"), d), fmt_value(m.get(k), d)) for label, k, d in rows],
                   cls="slam"))  # fmt: skip
    g = slam.graph
    items = [
        ("Keyframes in the graph", fmt_value(len(g.keyframe_ids) if g is not None else None)),
        ("Loop closures (accepted pairs)", fmt_value(m.get("loop_closures"))),
        ("Loop candidates tested", fmt_value(m.get("loop_candidates_tested"))),
        ("Odometry edges", fmt_value(len(g.segments.get("odometry", ())) if g is not None else None)),
        ("Graph factors (a loop pair adds two)", fmt_value(m.get("graph_edges"))),
        ("Optimisation (ms, all)", fmt_value(m.get("optimisation_ms"), 1)),
    ]
    page.add(table(["graph", ""], items, cls="slam-graph"))
    if m.get("slam_error"):
        page.text(f"The SLAM back end failed ({m['slam_error']}): trajectory.txt is the odometry's.", "note")
    page.text("The odometry column is the odometry's own trajectory (trajectory_vo.txt), the SLAM column the "
              "trajectory recomposed from the optimised keyframe graph (trajectory.txt); each is aligned to the "
              "ground truth by its own Sim(3).", "caption")  # fmt: skip


__all__ = ["SlamTracks", "is_slam_run", "slam_section"]
