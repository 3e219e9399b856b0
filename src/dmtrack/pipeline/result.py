"""What a run produced (:class:`RunResult`) and its ``metrics.json`` (:func:`metrics_dict`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from dmtrack import __version__
from dmtrack.datasets.base import Sequence
from dmtrack.errors import DmtrackError, Interrupted, OutputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.trajectory import Trajectory
from dmtrack.odometry._target import kernel_target
from dmtrack.odometry.config import VOConfig

if TYPE_CHECKING:
    from dmtrack.odometry.vo import VOResult  # the odometry's kernels: not imported with the results

#: Default r_l (longest RPE length / path length) per dataset format (paper §3.1).
R_L_BY_FORMAT = {"kitti": 1.0 / 20.0, "tsukuba": 1.0 / 20.0}
DEFAULT_R_L = 1.0 / 3.0


@dataclass
class RunResult:
    """Everything a run produced.

    Attributes
    ----------
    trajectory
        Tracked frames' T_wc with the dataset's timestamps.
    keyframes
        Keyframes' T_wc.
    frame_indices
        Dataset frame index of each trajectory pose.
    total_frames, tracked_frames
        Frames given to the odometry, frames with a pose.
    lost_at, lost_reason
        First frame (dataset index) where tracking was lost, and why; ``None`` if never.
    timings_ms
        Mean per frame: ``io`` (reading/decoding), ``feature`` (feature extraction) — both measured on
        the prefetch thread, where they overlap with the odometry of earlier frames — ``pyramid``,
        ``tracking``, ``mapping``; and ``wall_s`` (whole loop).
    metrics
        The ``metrics.json`` contents (see :func:`metrics_dict`).
    vo
        The odometry's own summary.
    groundtruth
        The sequence's ground truth over the frames given to the odometry (``None`` without one);
        written as ``groundtruth.txt`` by :func:`run_to_directory`.
    halted_by
        Why the run stopped before its last frame other than a tracking loss — an interrupt
        (:class:`KeyboardInterrupt`, :class:`~dmtrack.errors.Interrupted` for SIGTERM) or an output that could
        not be written (:class:`~dmtrack.errors.OutputError`); ``None`` for a run that went to its end.
        :func:`track` and :func:`run_to_directory` re-raise it once the finished frames are saved.
    dropped_frames
        Frames of a ``realtime`` run that the odometry skipped because a newer one had come.
    realtime
        Whether the run was a ``realtime`` one.
    compile_s
        Seconds :func:`warm_up` took before the first frame (numba compiling or loading the kernels;
        0 when this process had warmed up the feature and configuration already, or without warm-up).
    startup
        Where the time before the first frame went, ``metrics.json``'s ``startup``: ``import_s`` (the process's age
        when dmtrack's run modules had been imported: interpreter and imports, numba's aside), ``run_s`` (its age
        when the run began: also the command line and opening the sequence), ``odometry_import_s`` (the odometry
        built: numba and the kernels' modules imported, beside the start), ``warmup_s`` (the kernels compiled or
        loaded from numba's cache), ``start_s`` (the geometric start beyond the import and the warm-up it runs
        beside) and ``first_frame_s``
        (the process's age when the odometry had finished its first frame). Ages are seconds since the process
        started (:func:`dmtrack.io.machine.process_age_s`; ``None`` off Linux): for ``dmtrack run``, since it was
        launched.
    init
        How the first map was made: ``metrics.json``'s ``init*`` keys
        (:meth:`~dmtrack.initialization.run_start.RunStart.metrics`).
    slam
        The SLAM back end of a ``slam=`` run (:class:`~dmtrack.slam.backend.ThreadedSlam`), else ``None``;
        ``trajectory`` is then its optimised trajectory (the odometry's when the back end failed:
        ``slam.error``), and ``vo_trajectory`` the odometry's.
    """

    trajectory: Trajectory
    keyframes: Trajectory
    frame_indices: np.ndarray
    total_frames: int
    tracked_frames: int
    lost_at: int | None
    lost_reason: str | None
    timings_ms: dict[str, float]
    metrics: dict[str, Any] = field(default_factory=dict)
    vo: VOResult | None = None
    groundtruth: Trajectory | None = None
    halted_by: BaseException | None = None
    dropped_frames: int = 0
    realtime: bool = False
    compile_s: float = 0.0
    startup: dict[str, float | None] = field(default_factory=dict)
    init: dict[str, Any] = field(default_factory=dict)
    slam: Any = None
    vo_trajectory: Trajectory | None = None


def _finite(x: float | None) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _interrupt_name(e: BaseException | None) -> str | None:
    if isinstance(e, Interrupted):
        return e.signal_name
    return "SIGINT" if isinstance(e, KeyboardInterrupt) else None


def metrics_dict(
    result: RunResult,
    seq: Sequence,
    feature: Any,
    config: VOConfig,
    camera: PinholeCamera,
    start: int,
    r_l: float,
) -> dict[str, Any]:
    """The ``metrics.json`` contents (keys of conventions.md, plus more).

    ``fps`` is frames processed per second of the whole loop (reading, features, tracking, mapping), and
    ``compile_s`` the seconds before it spent compiling or loading the kernels (:func:`warm_up`);
    ``dropped_frames`` counts the frames a ``realtime`` run skipped (0 otherwise);
    ``*_ms`` are means per processed frame; ``feature_ms`` includes building the feature pyramid.
    RPE values are per unit of the ground truth's length (metres for every real dataset here; centimetres for
    New Tsukuba).
    """
    t = result.timings_ms
    processed = result.vo.total_frames if result.vo is not None else result.total_frames
    m: dict[str, Any] = {
        "feature": getattr(feature, "name", str(feature)),
        "sequence": seq.name,
        "format": seq.format,
        "total_frames": int(result.total_frames),
        "tracked_frames": int(result.tracked_frames),
        "lost_at": None if result.lost_at is None else int(result.lost_at),
        "lost_reason": result.lost_reason,
        "processed_frames": int(processed),
        "dropped_frames": int(result.dropped_frames),
        "realtime": bool(result.realtime),
        "interrupted": _interrupt_name(result.halted_by),
        "output_error": str(result.halted_by) if isinstance(result.halted_by, OutputError) else None,
        "fps": _finite(processed / t["wall_s"]) if t["wall_s"] > 0 else None,
        "feature_ms": t["feature"] + t["pyramid"],
        "tracking_ms": t["tracking"],
        "mapping_ms": t["mapping"],
        "io_ms": t["io"],
        "pyramid_ms": t["pyramid"],
        "wall_s": t["wall_s"],
        "compile_s": float(result.compile_s),
        "startup": {k: None if v is None else round(float(v), 4) for k, v in result.startup.items()},
        "keyframes": len(result.keyframes),
        **_loss_metrics(result.vo),
        "start": int(start),
        "width": camera.width,
        "height": camera.height,
        "channels": int(getattr(feature, "channels", 0)),
        "feature_scale": _finite(getattr(feature, "scale", None)),
        "device": str(getattr(feature, "device", "cpu")),
        "gpu": _gpu_name(feature),
        "seed": int(config.seed),
        "channel_cost": config.channel_cost,
        "energy_channels": _finite(config.energy_channels),
        "info_channels": _finite(config.info_channels),
        "noise_energy_channels": _finite(config.noise_energy_channels),
        "r_l": r_l,
        **(result.init or {"init": config.init}),
        "dmtrack_version": __version__,
        **kernel_target(),
    }
    window = getattr(result.vo, "window", None)
    if window is not None:
        m["window"] = window
    if result.slam is not None:
        m.update(_slam_metrics(result.slam))
    gt = seq.groundtruth
    if gt is not None and len(m["segments"]) > 1:
        _segment_metrics(m, gt, result, r_l)
    if gt is not None:
        from dmtrack.evaluation import evaluate

        try:
            ev = evaluate(gt, result.trajectory, max_diff=0.01, r_l=r_l, align="sim3")
            for k in ("ate_rmse", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "matched_poses", "ate_scale",
                      "rotation_gain"):
                m[k] = ev[k]
            if result.slam is not None and result.vo_trajectory is not None:
                ev = evaluate(gt, result.vo_trajectory, max_diff=0.01, r_l=r_l, align="sim3")
                for k in ("ate_rmse", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m"):
                    m[f"vo_{k}"] = ev[k]
        except (DmtrackError, ValueError) as e:
            m.update(ate_rmse=None, rpe_rot_deg_per_m=None, rpe_trans_angle_deg_per_m=None, matched_poses=0)
            m["evaluation_error"] = str(e)
    return m


def _loss_metrics(vo: VOResult | None) -> dict[str, Any]:
    """``lost_frames`` (frames without a pose after tracking was lost) and ``lost_spans`` (their runs, [first, last]
    frame), ``before_start`` (frames before the geometric start's reference frame), ``relocalisations`` and
    ``relocalised`` (frame, timestamp, keyframe found on, frame at which it had been lost), ``segments`` (first frame
    and first keyframe of each map the odometry began)."""
    if vo is None:
        return {"lost_frames": 0, "lost_spans": [], "before_start": 0, "relocalisations": 0, "relocalised": [],
                "segments": []}  # fmt: skip
    spans: list[list[int]] = []
    for i, _ in vo.lost:
        if spans and i == spans[-1][1] + 1:
            spans[-1][1] = int(i)
        else:
            spans.append([int(i), int(i)])
    time_of = dict(zip(vo.indices.tolist(), vo.timestamps.tolist(), strict=True))
    return {
        "lost_frames": len(vo.lost),
        "lost_spans": spans,
        "before_start": int(vo.before_start),
        "relocalisations": len(vo.relocalisations),
        "relocalised": [{"frame": f, "timestamp": time_of.get(f), "keyframe": k, "lost_since": s}
                        for f, k, s in vo.relocalisations],  # fmt: skip
        "segments": [{"first_frame": f, "first_keyframe": k} for f, k in vo.segments],
    }


def _segment_metrics(m: dict[str, Any], gt: Trajectory, result: RunResult, r_l: float) -> None:
    """Each segment evaluated on its own (its own Sim(3) alignment): segments share no frame of reference."""
    from dmtrack.evaluation import evaluate

    firsts = [s["first_frame"] for s in m["segments"]] + [np.iinfo(np.int64).max]
    idx = np.asarray(result.frame_indices)
    for seg, (a, b) in zip(m["segments"], zip(firsts[:-1], firsts[1:], strict=True), strict=True):
        rows = np.nonzero((idx >= a) & (idx < b))[0]
        seg["tracked_frames"] = int(len(rows))
        seg["ate_rmse"] = None
        if len(rows) >= 3:
            try:
                ev = evaluate(gt, result.trajectory[rows], max_diff=0.01, r_l=r_l, align="sim3")
                seg["ate_rmse"] = ev["ate_rmse"]
            except (DmtrackError, ValueError):
                pass


def _gpu_name(feature: Any) -> str | None:
    """The name of the GPU the feature (or a reduced feature's base) runs on, None on the CPU."""
    runner = getattr(feature, "runner", None) or getattr(getattr(feature, "base", None), "runner", None)
    return getattr(runner, "name", None)


def _slam_metrics(slam: Any) -> dict[str, Any]:
    """``slam``, ``loop_closures``, ``graph_edges``, ``loop_candidates_tested``, ``optimisation_ms``,
    ``alignment_ms``, ``slam_error`` of a SLAM run."""
    st = slam.backend.stats
    return {
        "slam": True,
        "loop_closures": int(st.loop_closures),
        "graph_edges": len(slam.backend.graph.edges),
        "loop_candidates_tested": int(st.tested),
        "optimisation_ms": float(st.optimisation_ms),
        "alignment_ms": float(st.alignment_ms),
        "slam_error": None if slam.error is None else f"{type(slam.error).__name__}: {slam.error}",
    }
