"""``report.html`` of one run folder (``dmtrack run … --out DIR``, or one run of a bench).

The page shows what ``metrics.json`` says (the numbers formatted as in ``report.md``) — for a SLAM run also the
odometry against SLAM (:mod:`.slam`) — and draws, from the run's files, the time per frame, a top view of the
trajectory with its keyframes — Sim(3)-aligned to ``groundtruth.txt`` by :func:`dmtrack.evaluation.metrics.ate`
when the run has one — the position error of the aligned estimate against the distance travelled along the ground
truth, the paper's RPE per path length (:func:`dmtrack.evaluation.metrics.evaluate`), and up to
:data:`MAX_DEPTH_PICTURES` keyframe depth pictures scaled down and embedded as PNG.  A file that is missing or
unreadable is said on the page; only an unreadable ``metrics.json`` stops the report.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dmtrack.errors import DmtrackError, InputError
from dmtrack.evaluation.html.figures import Curve, Line, rpe_figure, topview_figure
from dmtrack.evaluation.html.losses import has_losses, losses_section, lost_summary, relocalised_line
from dmtrack.evaluation.html.page import Page, axis_basis_text, base_layout, colour, esc, key_value_table, thin
from dmtrack.evaluation.html.slam import SlamTracks, is_slam_run, slam_section
from dmtrack.evaluation.html.window import window_section
from dmtrack.evaluation.rankings import value_of
from dmtrack.evaluation.tables import fmt_value
from dmtrack.io.bench_layout import GROUNDTRUTH_TXT, METRICS_JSON, RUN_INFO_JSON, TRAJECTORY_TXT, length_unit, read_json

#: At most this many keyframe depth pictures are embedded (evenly spaced over the run).
MAX_DEPTH_PICTURES = 12
#: Width (pixels) the embedded depth pictures are scaled down to.
DEPTH_PICTURE_WIDTH = 320
#: Timestamp tolerance (seconds) matching the estimate to the ground truth, as ``dmtrack run`` evaluates.
MAX_DIFF = 0.01
KEYFRAMES_TXT = "keyframes.txt"

if TYPE_CHECKING:
    from dmtrack.io.trajectory import Trajectory


def read_metrics(folder: Path) -> dict[str, Any]:
    """``metrics.json`` of a run folder; an :class:`InputError` naming it when it is not a JSON object."""
    path = folder / METRICS_JSON
    m = read_json(path)
    if not isinstance(m, dict):
        raise InputError("cannot read the run's metrics (not a JSON object, or unreadable)", path=path)
    return m


def _machine(m: dict[str, Any], info: dict[str, Any]) -> str:
    parts = []
    cpu = m.get("cpu") or info.get("cpu")
    if cpu:
        parts.append(str(cpu) + (f" ({info['cpu_count']} logical CPUs)" if info.get("cpu_count") else ""))
    if m.get("kernel_target"):
        parts.append(f"numba kernels for {m['kernel_target']}" + (f" ({m['simd']})" if m.get("simd") else ""))
    for key, label in (("host", "host "), ("platform", ""), ("python", "Python ")):
        if info.get(key):
            parts.append(f"{label}{info[key]}")
    return "; ".join(parts) or "not recorded"


def _header(page: Page, m: dict[str, Any], info: dict[str, Any], unit: str, has_gt: bool) -> None:
    lost = m.get("lost_at")
    lost_text = "never" if lost is None else f"frame {lost}"
    if lost is not None and m.get("lost_reason"):
        lost_text += f" ({m['lost_reason']})"
    if has_losses(m):
        lost_text += f"; {lost_summary(m)}"
    items = [
        ("Sequence", f"{m.get('sequence', '–')} ({m.get('format') or 'format not recorded'})"),
        ("Feature", f"{m.get('feature', '–')}" + (f" ({m['channels']} channels)" if m.get("channels") else "")),
        ("Frames tracked / total", f"{fmt_value(m.get('tracked_frames'))} / {fmt_value(m.get('total_frames'))}"
         + (f" (from frame {m['start']})" if m.get("start") else "")),  # fmt: skip
        ("Tracking lost", lost_text),
        ("Seed", fmt_value(m.get("seed"))),
        ("Keyframes, points", f"{fmt_value(m.get('keyframes'))}, {fmt_value(m.get('points'))}"),
        ("Image size", f"{m['width']}×{m['height']}" if m.get("width") else "–"),
        ("Ground truth", f"yes (lengths in {unit})" if has_gt else "no ground truth"),
        ("Machine", _machine(m, info)),
        ("dmtrack", str(m.get("dmtrack_version") or "–")),
    ]
    if m.get("interrupted"):
        items.insert(4, ("Interrupted", f"by {m['interrupted']} (the numbers describe the finished frames)"))
    if m.get("output_error"):
        items.insert(4, ("Output error", str(m["output_error"])))
    page.heading(2, "Run", toc=True)
    page.add(key_value_table(items))


def _gain(gain: list[float | None] | None) -> str:
    """``rotation_gain`` as "x / y / z" (– for an axis without a turn, or without the key)."""
    return " / ".join(fmt_value(g, 2) for g in gain) if gain else "–"


def _metrics(page: Page, m: dict[str, Any], unit: str, has_gt: bool) -> None:
    page.heading(2, "Metrics", toc=True)
    parts = [value_of(m, k) for k in ("io_ms", "feature_ms", "tracking_ms", "mapping_ms")]
    total = sum(p for p in parts if p is not None) if any(p is not None for p in parts) else None
    items = [
        (f"RPE rotation (deg/{unit})", fmt_value(m.get("rpe_rot_deg_per_m"), 3)),
        (f"RPE translation angle (deg/{unit})", fmt_value(m.get("rpe_trans_angle_deg_per_m"), 3)),
        (f"ATE RMSE ({unit}, Sim(3)-aligned)", fmt_value(m.get("ate_rmse"), 4)),
        ("Sim(3) scale of the alignment", fmt_value(m.get("ate_scale"), 3)),
        ("Rotation gain x / y / z (estimate's turn over the ground truth's)", _gain(m.get("rotation_gain"))),
        ("Matched poses", fmt_value(m.get("matched_poses"))),
        ("RPE length ratio r_l", fmt_value(value_of(m, "r_l"), 4)),
        ("fps (processed frames per wall-clock second)", fmt_value(m.get("fps"), 1)),
        ("Total time per frame (ms)", fmt_value(total, 1)),
        ("Wall-clock time (s)", fmt_value(m.get("wall_s"), 2)),
    ]
    page.add(key_value_table(items))
    if not has_gt:
        page.text("No ground truth: this run has no groundtruth.txt, so there is no RPE or ATE and the trajectory "
                  "is shown as estimated (its own frame and scale).", "note")  # fmt: skip
    elif m.get("evaluation_error"):
        page.text(f"The run could not be evaluated: {m['evaluation_error']}", "note")
    page.text("RPE: the paper's scale-free relative pose error (§3.1) over 8 path lengths up to r_l of the "
              "ground-truth path, per ground-truth length unit; ATE: RMSE of the positions after a 7-DoF Umeyama "
              "alignment. Rotation gain: per camera axis, how much of the ground truth's turn the estimate shows over "
              "15 poses; below about 0.9 about x and y with z near 1 is the signature of a focal length that is too "
              "long or of distortion left in the images.", "caption")  # fmt: skip
    page.try_figure(lambda: _timing_figure(m), "time per frame")


def _timing_figure(m: dict[str, Any]) -> tuple[Any, str] | None:
    import plotly.graph_objects as go

    parts = [("image I/O", "io_ms"), ("features (with pyramid)", "feature_ms"), ("tracking", "tracking_ms"),
             ("mapping", "mapping_ms")]  # fmt: skip
    values = [(label, value_of(m, k)) for label, k in parts]
    if all(v is None for _, v in values):
        return None
    fig = go.Figure()
    for i, (label, v) in enumerate(values):
        if v is None:
            continue
        fig.add_trace(go.Bar(y=["per frame"], x=[v], name=esc(label), orientation="h", marker_color=colour(i),
                             text=[fmt_value(v, 1)], textposition="inside",
                             hovertemplate=f"{esc(label)}: %{{x:.1f}} ms<extra></extra>"))  # fmt: skip
    total = sum(v for _, v in values if v is not None)
    fig.update_layout(**base_layout(f"Time per frame: {fmt_value(total, 1)} ms", 230, barmode="stack",
                                  legend={"orientation": "h", "traceorder": "normal", "x": 1, "xanchor": "right",
                                          "y": 1.02, "yanchor": "bottom"}))
    fig.update_xaxes(title_text="ms per processed frame (mean)")
    fps = value_of(m, "fps")
    return fig, (
        "Mean time per processed frame by stage" + (f" (1000 / total = {1000.0 / total:.1f} frames/s)" if total else "")
        + (f"; the run's fps, processed frames per wall-clock second: {fmt_value(fps, 1)}." if fps else ".")
    )  # fmt: skip


class _Tracks:
    """The run's trajectories for the figures: estimate, keyframes, ground truth, and the evaluation."""

    def __init__(self, folder: Path, m: dict[str, Any], page: Page) -> None:
        from dmtrack.io.trajectory import data_lines, read_tum

        self.est: Trajectory | None = None
        self.keyframes: Trajectory | None = None
        self.gt: Trajectory | None = None
        self.aligned = False
        self.errors: tuple[np.ndarray, np.ndarray] | None = None  # (distance along gt, position error)
        self.evaluation: dict[str, Any] | None = None
        self._T = np.eye(4)
        for name, attr in ((TRAJECTORY_TXT, "est"), (KEYFRAMES_TXT, "keyframes"), (GROUNDTRUTH_TXT, "gt")):
            path = folder / name
            if not path.is_file():
                continue
            try:
                if data_lines(path):  # a run lost or stopped at its first frame has no pose: not a problem
                    setattr(self, attr, read_tum(path))
            except (DmtrackError, ValueError) as e:
                page.problem(name, e)
        if self.est is None or self.gt is None or len(self.est) == 0:
            return
        self._evaluate(folder, m, page)

    def _evaluate(self, folder: Path, m: dict[str, Any], page: Page) -> None:
        from dmtrack.evaluation.metrics import ate, evaluate
        from dmtrack.io.association import associate_trajectories

        r_l = value_of(m, "r_l") or 1.0 / 3.0
        try:  # the same evaluation as `dmtrack run` (its checks name the files), then the per-pose errors
            self.evaluation = evaluate(self.gt, self.est, max_diff=MAX_DIFF, r_l=r_l, align="sim3",
                                       gt_name=folder / GROUNDTRUTH_TXT, est_name=folder / TRAJECTORY_TXT)  # fmt: skip
            gt_m, est_m = associate_trajectories(self.gt, self.est, max_diff=MAX_DIFF)
            a = ate(gt_m, est_m, "sim3")
        except (DmtrackError, ValueError, np.linalg.LinAlgError) as e:
            page.problem("evaluation against groundtruth.txt", e)
            return
        self._T = a.alignment  # applied to the positions of every pose (also the unmatched ones) in positions()
        self.aligned = True
        self.errors = (gt_m.distances(), a.errors)

    def positions(self, traj: Any) -> np.ndarray:
        """Camera centres of ``traj``, mapped by the Sim(3) alignment when there is one."""
        return self.map_points(traj.positions)

    def map_points(self, p: np.ndarray) -> np.ndarray:
        """``(N, 3)`` points of the estimate's frame, mapped by the Sim(3) alignment when there is one."""
        if self.aligned:
            p = p @ self._T[:3, :3].T + self._T[:3, 3]
        return p


def _trajectory(page: Page, tracks: _Tracks, m: dict[str, Any], unit: str, slam: SlamTracks | None = None) -> None:
    from dmtrack.viz.plots import topview_basis

    page.heading(2, "Trajectory", toc=True)
    if tracks.est is None or len(tracks.est) == 0:
        page.text("No trajectory: trajectory.txt is missing or empty.", "note")
        return
    lines = []
    if tracks.gt is not None and tracks.aligned:
        lines.append(Line("ground truth", tracks.gt.positions, "#222222", dash="dash"))
    label = f"{m.get('feature', 'estimate')} [{fmt_value(m.get('tracked_frames'))}]"
    lines.append(Line(("SLAM: " if slam is not None else "") + label, tracks.positions(tracks.est), colour(0)))
    if slam is not None:
        lines += slam.lines(tracks)
    if tracks.keyframes is not None and len(tracks.keyframes):
        lines.append(Line(f"keyframes ({len(tracks.keyframes)})", tracks.positions(tracks.keyframes), colour(3),
                          markers=True))  # fmt: skip
    reloc = relocalised_line(m, tracks.est, tracks.positions)
    if reloc is not None:
        lines.append(reloc)
    ref = tracks.gt.positions if tracks.aligned else tracks.est.positions
    basis = topview_basis(ref)
    if tracks.aligned:
        how = "the estimate after the Sim(3) (7-DoF Umeyama) alignment to the ground truth (dashed)"
        title = "Top view (Sim(3)-aligned to the ground truth)"
    elif tracks.gt is not None:
        how = "the estimate as written, in its own frame and scale (it could not be aligned to the ground truth)"
        title = "Top view (not aligned: see the problems below)"
    else:
        how = "the estimate as written, in its own frame and scale (no ground truth to align it to)"
        title = "Top view (no ground truth)"
    page.try_figure(
        lambda: (topview_figure(lines, basis, title, unit if tracks.aligned else "units"),
                 f"Top view of {how}, keyframes as diamonds, the start of each line as a circle. The view is the "
                 f"plane of the two principal axes of the {'ground-truth' if tracks.aligned else 'estimated'} "
                 f"positions (the two directions of largest extent): {axis_basis_text(basis)} (world axes)."
                 + (slam.caption() if slam is not None else "")),
        "trajectory figure",
    )  # fmt: skip


def _errors(page: Page, tracks: _Tracks, m: dict[str, Any], unit: str) -> None:
    if not tracks.aligned or tracks.errors is None or tracks.evaluation is None:
        return
    page.heading(2, "Error over the path", toc=True)
    dist, err = tracks.errors
    page.try_figure(lambda: _position_error_figure(dist, err, unit), "position error figure")

    def rpe() -> tuple[Any, str]:
        from dmtrack.viz.plots import RpeCurve

        ev = tracks.evaluation or {}
        arr = [np.asarray(ev[k], dtype=float) for k in ("rpe_lengths", "rpe_rot_per_length", "rpe_trans_per_length")]
        curve = RpeCurve(f"{m.get('feature', 'estimate')} [{fmt_value(m.get('tracked_frames'))}]", *arr)
        pairs = ", ".join(str(p) for p in ev.get("rpe_pairs_per_length", []))
        return (rpe_figure([Curve(curve, colour(0))], "RPE against the path length", unit),
                f"The paper's RPE at each path length L_k = k/8 · r_l · (ground-truth path of "
                f"{fmt_value(ev.get('gt_path_length'), 2)} {unit}), k = 1..8: mean rotation and translation-angle "
                f"errors of the pairs at that length divided by L_k (pairs per length: {pairs}); their means are "
                "the RPE values above.")  # fmt: skip

    page.try_figure(rpe, "RPE figure")


def _position_error_figure(dist: np.ndarray, err: np.ndarray, unit: str) -> tuple[Any, str]:
    import plotly.graph_objects as go

    xy = thin(np.stack([dist, err], axis=1))
    fig = go.Figure(go.Scatter(x=xy[:, 0], y=xy[:, 1], mode="lines", name="position error",
                               line={"color": colour(0), "width": 1.6},
                               hovertemplate=f"%{{x:.3f}} {esc(unit)} travelled<br>error %{{y:.4f}} {esc(unit)}"
                               "<extra></extra>"))  # fmt: skip
    fig.update_layout(**base_layout("Position error of the aligned estimate", 380, showlegend=False))
    fig.update_xaxes(title_text=f"distance travelled along the ground truth [{esc(unit)}]")
    fig.update_yaxes(title_text=f"position error [{esc(unit)}]", rangemode="tozero")
    rmse = float(np.sqrt(np.mean(err**2))) if len(err) else float("nan")
    return fig, (
        f"Translation error |p_gt − (s R p_est + t)| of each of the {len(err)} matched poses after the Sim(3) "
        f"alignment, against the ground-truth path length from the first matched pose (RMSE {fmt_value(rmse, 4)} "
        f"{unit}, max {fmt_value(float(err.max()) if len(err) else None, 4)} {unit})."
    )


def _depth_pictures(page: Page, folder: Path) -> None:
    from dmtrack.evaluation.html.page import png_data_uri
    from dmtrack.evaluation.report import KEYFRAME_PICTURE_RE

    found = []
    for p in sorted((folder / "depth").glob("kf_*.png")):
        mt = KEYFRAME_PICTURE_RE.search(p.name)
        if mt:
            found.append((int(mt.group(2)), int(mt.group(1)), p))
    page.heading(2, "Keyframe depth", toc=True)
    initial = folder / "depth" / "initial_map.png"
    if not found and not initial.is_file():
        page.text("No keyframe depth pictures (depth/ is empty or missing: run without --no-depth-images).", "note")
        return
    found.sort()
    pick = np.unique(np.linspace(0, len(found) - 1, min(MAX_DEPTH_PICTURES, len(found))).round().astype(int))
    cells = []
    if initial.is_file():
        try:
            uri = png_data_uri(initial, DEPTH_PICTURE_WIDTH)
            cells.append(f'<figure><img src="{uri}" alt="initial_map.png" width="{DEPTH_PICTURE_WIDTH}">'
                         f"<figcaption>initial map ({esc(_start_caption(folder))})</figcaption></figure>")
        except ValueError as e:
            page.problem("depth/initial_map.png", e)
    for i in pick:
        frame, kf, path = found[int(i)]
        try:
            uri = png_data_uri(path, DEPTH_PICTURE_WIDTH)
        except ValueError as e:
            page.problem(f"depth/{path.name}", e)
            continue
        cells.append(f'<figure><img src="{uri}" alt="{esc(path.name)}" width="{DEPTH_PICTURE_WIDTH}">'
                     f"<figcaption>keyframe {kf} (frame {frame})</figcaption></figure>")  # fmt: skip
    page.add('<div class="pictures">' + "".join(cells) + "</div>")
    page.text(f"Inverse depth of {len(pick) if found else 0} of the run's {len(found)} keyframes (evenly spaced; "
              f"scaled down to {DEPTH_PICTURE_WIDTH} pixels wide) over the dimmed image: red near, blue far; magenta "
              "marks negative inverse depths. The first picture is the first keyframe's map as the start made it, "
              "before any frame was mapped into it.", "caption")  # fmt: skip


def _start_caption(folder: Path) -> str:
    """How the first map was made, from ``metrics.json``: e.g. "geometric, accepted at frame 41"."""
    try:
        m = read_metrics(folder)
    except InputError:
        return "how it was made is not recorded"
    init = m.get("init") or "random"
    if m.get("init_fallback"):
        return f"{init} refused: {m['init_fallback']}"
    if m.get("init_accepted_frame") is not None:
        return f"{init}, accepted at frame {m['init_accepted_frame']}"
    return f"{init}, seed {m['seed']}" if init == "random" and "seed" in m else str(init)


def run_page(folder: Path, page: Page) -> str:
    """Fill ``page`` with the report of the run folder ``folder``; returns the subtitle."""
    m = read_metrics(folder)
    info = read_json(folder / RUN_INFO_JSON) or {}
    info = info if isinstance(info, dict) else {}
    unit = str(info.get("unit") or length_unit(m.get("format"), m.get("sequence")))
    page.title = f"dmtrack run: {m.get('sequence', folder.name)} · {m.get('feature', '?')}"
    has_gt = (folder / GROUNDTRUTH_TXT).is_file()
    _header(page, m, info, unit, has_gt)
    _metrics(page, m, unit, has_gt)
    window_section(page, m)
    tracks = _Tracks(folder, m, page)
    slam = SlamTracks(folder, tracks, page) if is_slam_run(folder, m) else None
    if slam is not None:
        slam_section(page, m, unit, slam)
    _trajectory(page, tracks, m, unit, slam)
    losses_section(page, m)
    _errors(page, tracks, m, unit)
    _depth_pictures(page, folder)
    files = [p.name for p in sorted(folder.iterdir()) if p.is_file() and not p.name.startswith(".")]
    page.heading(2, "Files")
    page.add("<p>" + ", ".join(f'<a href="{esc(n)}">{esc(n)}</a>' for n in files if n != "report.html")
             + (", depth/" if (folder / "depth").is_dir() else "") + "</p>")  # fmt: skip
    return f"Run folder {folder}"


__all__ = ["MAX_DEPTH_PICTURES", "read_metrics", "run_page"]
