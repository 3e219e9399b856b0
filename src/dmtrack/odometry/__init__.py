"""dmtrack.odometry: semi-dense direct visual odometry on N-channel feature maps (LSD-SLAM style).

Main entry point: :class:`VisualOdometry`. Pieces: :func:`build_frame` (feature pyramid), :class:`Tracker`
(SE(3) coarse-to-fine LM tracking), :class:`DepthMap` (keyframe inverse depth), configuration dataclasses
and the :class:`OutputSink` protocol.
"""

from dmtrack.odometry.config import DepthConfig, KeyframeConfig, TrackerConfig, VOConfig
from dmtrack.odometry.depthmap import DepthMap
from dmtrack.odometry.frame import Frame, Level, build_frame
from dmtrack.odometry.sink import KeyframeSnapshot, OutputSink
from dmtrack.odometry.tracker import ReferenceLevel, Tracker, TrackingReference, TrackResult
from dmtrack.odometry.vo import FrameResult, KeyframeRecord, VisualOdometry, VOResult, keyframe_score

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
