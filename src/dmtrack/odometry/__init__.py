"""dmtrack.odometry: semi-dense direct visual odometry on N-channel feature maps (LSD-SLAM style).

Main entry point: :class:`VisualOdometry`. Pieces: :func:`build_frame` (feature pyramid), :class:`Tracker`
(SE(3) coarse-to-fine LM tracking), :class:`DepthMap` (keyframe inverse depth), configuration dataclasses
and the :class:`OutputSink` protocol.
"""

from __future__ import annotations

from dmtrack.io.machine import lazy_exports

# imported on first use (PEP 562): the configuration, the sink protocol and the first map's record are read without
# numba and the kernels' modules (what `dmtrack run` imports before it can start reading frames)
_WHERE = {
    "DepthConfig": "config", "KeyframeConfig": "config", "TrackerConfig": "config", "VOConfig": "config",
    "DepthMap": "depthmap",
    "Frame": "frame", "Level": "frame", "build_frame": "frame",
    "KeyframeSnapshot": "sink", "OutputSink": "sink",
    "ReferenceLevel": "tracker", "Tracker": "tracker", "TrackingReference": "tracker", "TrackResult": "tracker",
    "FrameResult": "vo", "KeyframeRecord": "vo", "VisualOdometry": "vo", "VOResult": "vo", "keyframe_score": "vo",
}  # fmt: skip

__getattr__, __dir__ = lazy_exports(__name__, _WHERE)

__all__ = [
    "DepthConfig",
    "DepthMap",
    "Frame",
    "FrameResult",
    "KeyframeConfig",
    "KeyframeRecord",
    "KeyframeSnapshot",
    "Level",
    "OutputSink",
    "ReferenceLevel",
    "TrackResult",
    "Tracker",
    "TrackerConfig",
    "TrackingReference",
    "VOConfig",
    "VOResult",
    "VisualOdometry",
    "build_frame",
    "keyframe_score",
]
