"""What the odometry reports: per frame (:class:`FrameResult`), per keyframe (:class:`KeyframeRecord`) and per run
(:class:`VOResult`), with the keyframe score and the small pose helpers the loop shares with its callers."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dmtrack.geometry.exact import dot, matmul
from dmtrack.odometry.tracker import TrackResult

__all__ = ["FrameResult", "KeyframeRecord", "StoredKeyframe", "VOResult", "keyframe_score"]


def keyframe_score(T_fk: np.ndarray, mean_idepth: float, point_usage: float, dist_w: float, usage_w: float) -> float:
    """LSD-SLAM's keyframe score (|t·meanIdepth|²·dist_w² + (1 − usage)²·usage_w²).

    ``t`` is the frame's position in keyframe coordinates (translation of T_fk⁻¹).
    """
    R = T_fk[:3, :3]
    t_kf = -matmul(R.T, T_fk[:3, 3])
    d = t_kf * mean_idepth
    return dot(d, d) * dist_w * dist_w + (1.0 - point_usage) ** 2 * usage_w * usage_w


def _sim3(T: np.ndarray, s: float) -> np.ndarray:
    """4×4 Sim(3) matrix [[s·R, t], [0, 1]] from an SE(3) matrix and a scale."""
    S = np.array(T, dtype=np.float64, copy=True)
    S[:3, :3] *= s
    return S


def _se3_part(S: np.ndarray, s: float) -> np.ndarray:
    """SE(3) part of a Sim(3) matrix of scale ``s``: rotation without the scale, same translation."""
    T = np.array(S, dtype=np.float64, copy=True)
    T[:3, :3] /= s
    return T


def _inv_se3(T: np.ndarray) -> np.ndarray:
    Ti = np.eye(4)
    R = T[:3, :3]
    Ti[:3, :3] = R.T
    Ti[:3, 3] = -matmul(R.T, T[:3, 3])
    return Ti


@dataclass
class FrameResult:
    """What happened to one frame.

    Attributes
    ----------
    index, timestamp
        As passed to :meth:`VisualOdometry.process`.
    T_wc : np.ndarray | None
        (4, 4) SE(3) camera-to-world pose; None when the frame was not tracked.
    tracked : bool
        The frame has a pose (the first frame counts as tracked).
    is_keyframe : bool
        The frame became a keyframe.
    keyframe_id : int
        The keyframe it was tracked against, or the one it became; −1 if not processed.
    lost_reason : str | None
        Why tracking was lost (or "stopped: …" for frames after a loss with ``stop_on_loss``).
    track : TrackResult | None
        The tracker's full result (None for the first frame and for skipped frames).
    pyramid_ms, tracking_ms, mapping_ms : float
        Wall time of the feature pyramid, of tracking (reference rebuild + LM) and of mapping (depth update or
        keyframe creation / initialisation), milliseconds.
    reference_ms : float
        The part of ``tracking_ms`` spent (re)building the tracking reference (0 when it was reused).
    """

    index: int
    timestamp: float
    T_wc: np.ndarray | None
    tracked: bool
    is_keyframe: bool
    keyframe_id: int
    lost_reason: str | None = None
    track: TrackResult | None = None
    pyramid_ms: float = 0.0
    tracking_ms: float = 0.0
    mapping_ms: float = 0.0
    reference_ms: float = 0.0


@dataclass
class KeyframeRecord:
    """A keyframe: id, the frame it came from, SE(3) pose T_wc, Sim(3) scale, its parent's ρ, the parent (None for
    a segment's first keyframe) and its segment."""

    keyframe_id: int
    frame_index: int
    timestamp: float
    T_wc: np.ndarray
    scale: float
    scale_from_parent: float
    parent_id: int | None = None
    segment: int = 0


@dataclass(frozen=True, eq=False)
class StoredKeyframe:
    """A keyframe the odometry made earlier, kept to find the camera again after a loss: its feature pyramid and
    final tracking depth (:meth:`~dmtrack.odometry.depthmap.DepthMap.tracking_depth`), Sim(3) pose and id."""

    keyframe_id: int
    frame: Any  # dmtrack.odometry.frame.Frame
    idepth: np.ndarray
    idepth_var: np.ndarray
    T_wc: np.ndarray
    scale: float
    segment: int = 0


@dataclass
class VOResult:
    """Summary of a run (see :meth:`VisualOdometry.result`).

    Attributes
    ----------
    indices : (n,) int64 — tracked frame indices, in processing order.
    timestamps : (n,) float64.
    poses : (n, 4, 4) float64 — SE(3) T_wc of the tracked frames.
    keyframes : list[KeyframeRecord].
    lost : list[(frame index, reason)]: every frame without a pose after tracking was lost.
    lost_at : first lost frame index, or None.
    total_frames : frames passed to ``process`` (including lost and skipped ones).
    tracked_frames : frames with a pose.
    timings_ms : mean per processed frame of ``pyramid``, ``tracking``, ``mapping`` and ``total``.
    before_start : frames before the first keyframe (the geometric start's reference came later).
    relocalisations : list[(frame index, keyframe id, frame index at which tracking had been lost)].
    segments : list[(first frame index, keyframe id)]: where the odometry began a map (the first, and every new
        map after a loss it did not recover from).
    window : what the sliding window did (its ``stats.as_dict()``: optimisations, time, cost ratio, the intrinsics'
        estimate), or None without a window.
    """

    indices: np.ndarray
    timestamps: np.ndarray
    poses: np.ndarray
    keyframes: list[KeyframeRecord]
    lost: list[tuple[int, str]]
    lost_at: int | None
    total_frames: int
    tracked_frames: int
    timings_ms: dict[str, float] = field(default_factory=dict)
    before_start: int = 0
    relocalisations: list[tuple[int, int, int]] = field(default_factory=list)
    segments: list[tuple[int, int]] = field(default_factory=list)
    window: dict[str, Any] | None = None
