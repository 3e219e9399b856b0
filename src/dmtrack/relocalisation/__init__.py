"""Finding the camera again after tracking was lost (issue 37): the keyframes a run made are kept
(:class:`~dmtrack.relocalisation.store.KeyframeStore`, an output sink of the odometry), and a lost frame is aligned to
those it most likely sees — the current keyframe, those that look alike, those near the last pose — directly, with the
odometry's own tracker, under LSD-SLAM's relocaliser's tests (:class:`~dmtrack.relocalisation.relocaliser.Relocaliser`).
The run loop (:mod:`dmtrack.pipeline`) then resumes the odometry on the keyframe found
(:meth:`~dmtrack.odometry.vo.VisualOdometry.relocalise`), or, after ``relocalisation.new_map_after`` lost frames
without a SLAM back end, begins a new map.
"""

from __future__ import annotations

from dmtrack.relocalisation.relocaliser import Found, Relocaliser
from dmtrack.relocalisation.store import KeyframeStore, RelocKeyframe

__all__ = ["Found", "KeyframeStore", "RelocKeyframe", "Relocaliser"]
