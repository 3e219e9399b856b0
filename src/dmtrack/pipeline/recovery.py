"""What the run loop does with an odometry whose tracking is lost, in a run that goes on (``stop_on_loss`` off).

:class:`Recovery` belongs to one odometry of a :class:`~dmtrack.pipeline.run.SequenceRun`. It keeps the keyframes
the odometry makes (a :class:`~dmtrack.relocalisation.store.KeyframeStore`, one more sink of it) and, for every frame
while tracking is lost:

1. asks the :class:`~dmtrack.relocalisation.relocaliser.Relocaliser` where the frame is — on the current keyframe,
   on a kept one that looks alike (ORB) or on one near the last pose, under LSD-SLAM's relocaliser's tests — and, if
   it is found, resumes the odometry there (:meth:`~dmtrack.odometry.vo.VisualOdometry.relocalise`): same map, same
   keyframe graph (the new keyframe's parent is the one found);
2. otherwise counts the frame lost (no pose, never a guessed one);
3. without a SLAM back end, once ``relocalisation.new_map_after`` frames are lost, also feeds the frames to a new
   geometric start; when it accepts, the odometry begins a new map (a new *segment*) at the start's reference frame,
   and the frames since are tracked on it (their images were kept by the start; their features are computed
   again). The new segment shares no frame of reference with the old one: ``metrics.json`` lists the segments.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dmtrack.geometry.camera import PinholeCamera
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.vo import VisualOdometry
from dmtrack.relocalisation import KeyframeStore, Relocaliser

__all__ = ["Recovery"]


class Recovery:
    """Relocalisation (and new segments) for one odometry; see the module docstring.

    Parameters
    ----------
    feature : the run's Feature.
    config : the odometry's configuration.
    camera : the odometry's (cropped) camera.
    new_maps : whether a loss that lasts may begin a new map (off with a SLAM back end, which keeps looking).
    """

    def __init__(self, feature: Any, config: VOConfig, camera: PinholeCamera, *, new_maps: bool) -> None:
        from dmtrack.slam.candidates import CandidateSearch

        self.feature = feature
        self.config = config
        self.camera = camera
        self.store = KeyframeStore(feature, config)
        self.search = CandidateSearch()
        self.new_maps = bool(new_maps) and config.relocalisation.new_map_after > 0
        self.relocaliser: Relocaliser | None = None
        self._start: Any = None  # the new map's geometric start, while it collects
        self._start_frames: list[tuple[int, float, np.ndarray]] = []

    def attach(self, vo: VisualOdometry) -> None:
        """Build the relocaliser on ``vo``'s tracker (called once the odometry exists)."""
        self.relocaliser = Relocaliser(self.store, vo.config, vo.tracker, self.search)

    def frame(self, vo: VisualOdometry, index: int, timestamp: float, image: np.ndarray, fmap: Any) -> None:
        """A frame while ``vo`` is lost: relocalise, or count it lost (and feed a new start when it is time)."""
        assert self.relocaliser is not None
        frame = vo.frame_of(index, timestamp, image, fmap)
        found = self.relocaliser.find(frame, vo.last_pose, vo.current_keyframe(), vo.residual_limit())
        if found is not None:
            self._start, self._start_frames = None, []
            vo.relocalise(frame, found.keyframe, found.T_fk, found.good)
            return
        why = self.relocaliser.tried[-1][3] if self.relocaliser.tried else "no keyframe to look on"
        vo.skip(index, timestamp, f"lost since frame {vo.lost_since}, not relocalised: {why}")
        if self.new_maps and vo.lost_since is not None:
            lost_for = sum(1 for i, _ in vo.result().lost if i >= vo.lost_since)
            if lost_for >= self.config.relocalisation.new_map_after:
                self._feed_start(vo, index, timestamp, image)

    def _feed_start(self, vo: VisualOdometry, index: int, timestamp: float, image: np.ndarray) -> None:
        """Give the frame to the new map's start; when it accepts, begin the new segment and catch up to here."""
        from dmtrack.initialization.initializer import GeometricInitializer

        if self._start is None or self._start.state == "refused":
            self._start = GeometricInitializer(self.camera, self.config, parallel=vo.parallel)
            self._start_frames = []
        self._start_frames.append((int(index), float(timestamp), image))
        if not self._start.add(index, timestamp, image) or self._start.initial_map is None:
            return
        m = self._start.initial_map
        frames = [f for f in self._start_frames if f[0] >= m.frame_index]
        self._start, self._start_frames = None, []
        vo.rewind_lost(m.frame_index)
        for k, (i, t, img) in enumerate(frames):
            fmap = self._feature(img)
            if k == 0:
                vo.new_segment(i, t, img, fmap, m)
            else:
                vo.process(i, t, img, fmap)

    def _feature(self, image: np.ndarray) -> Any:
        recompute = getattr(self.feature, "pyramid", "downsample") == "recompute"
        return (self.feature.compute_pyramid(image, self.config.pyramid_levels) if recompute
                else self.feature.compute(image))  # fmt: skip
