"""The keyframes a run made, kept to find the camera again after a loss.

:class:`KeyframeStore` is an output sink of the odometry (it takes each finished keyframe's snapshot) and keeps, per
keyframe, what an alignment needs — the image, the final tracking depth, the Sim(3) pose — within a memory budget
(the oldest keyframes leave first). A keyframe's feature pyramid and tracking reference (:attr:`RelocKeyframe.view`)
are built from its image with the run's feature when first needed and cached, least recently used first out.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.frame import build_frame
from dmtrack.odometry.records import StoredKeyframe
from dmtrack.odometry.sink import KeyframeSnapshot
from dmtrack.odometry.tracker import TrackingReference
from dmtrack.slam.constraints import KeyframeView

__all__ = ["KeyframeStore", "RelocKeyframe"]


@dataclass(eq=False)
class RelocKeyframe:
    """A kept keyframe (the attributes :class:`~dmtrack.slam.candidates.CandidateSearch` reads included)."""

    kf_id: int
    frame_index: int
    timestamp: float
    image: np.ndarray
    idepth: np.ndarray
    idepth_var: np.ndarray
    camera: Any
    T_wc: np.ndarray
    scale: float
    mean_idepth: float
    parent_id: int | None
    segment: int
    load_view: Any = field(default=None, repr=False)  # (RelocKeyframe) -> KeyframeView

    @property
    def view(self) -> KeyframeView:
        """Its feature pyramid and tracking reference (built on first use, cached by the store)."""
        return self.load_view(self)

    def stored(self) -> StoredKeyframe:
        """What :meth:`~dmtrack.odometry.vo.VisualOdometry.relocalise` takes."""
        return StoredKeyframe(self.kf_id, self.view.frame, self.idepth, self.idepth_var, self.T_wc, self.scale,
                              self.segment)  # fmt: skip

    @property
    def nbytes(self) -> int:
        return int(self.image.nbytes + self.idepth.nbytes + self.idepth_var.nbytes)


class KeyframeStore:
    """Keyframes of a run for relocalisation (an :class:`~dmtrack.odometry.sink.OutputSink`).

    Parameters
    ----------
    feature : the run's Feature (the keyframes' pyramids are computed with it when needed).
    config : the run's odometry configuration (pyramid levels, tracker levels, ``relocalisation.store_mb``).
    view_cache : keyframe pyramids kept built at once.
    """

    def __init__(self, feature: Any, config: VOConfig, view_cache: int = 6) -> None:
        self.feature = feature
        self.config = config
        self.keyframes: OrderedDict[int, RelocKeyframe] = OrderedDict()
        self._views: OrderedDict[int, KeyframeView] = OrderedDict()
        self._view_cache = int(view_cache)
        self._bytes = 0

    # -- the sink ----------------------------------------------------------------------------------------------------
    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        pass

    def on_lost(self, frame_index: int, reason: str) -> None:
        pass

    def on_keyframe(
        self, keyframe_id: int, frame_index: int, timestamp: float, T_wc: np.ndarray, snapshot: KeyframeSnapshot
    ) -> None:
        if snapshot.image is None:
            return  # nothing to align to
        valid = snapshot.idepth_var > 0
        if not valid.any():
            return
        kf = RelocKeyframe(
            int(keyframe_id), int(frame_index), float(timestamp), snapshot.image, snapshot.idepth,
            snapshot.idepth_var, snapshot.camera, np.array(T_wc, np.float64), float(snapshot.scale),
            float(snapshot.idepth[valid].mean()), snapshot.parent_id, int(snapshot.segment), self._view,
        )  # fmt: skip
        self.keyframes[kf.kf_id] = kf
        self._bytes += kf.nbytes
        budget = self.config.relocalisation.store_mb * 2**20
        while self._bytes > budget and len(self.keyframes) > 1:
            _, old = self.keyframes.popitem(last=False)
            self._bytes -= old.nbytes
            self._views.pop(old.kf_id, None)

    def close(self) -> None:
        pass

    # -- views -------------------------------------------------------------------------------------------------------
    def _view(self, kf: RelocKeyframe) -> KeyframeView:
        view = self._views.pop(kf.kf_id, None)
        if view is None:
            cfg = self.config
            recompute = getattr(self.feature, "pyramid", "downsample") == "recompute"
            fmap = (self.feature.compute_pyramid(kf.image, cfg.pyramid_levels) if recompute
                    else self.feature.compute(kf.image))  # fmt: skip
            frame = build_frame(kf.frame_index, kf.timestamp, kf.image, fmap, kf.camera, cfg.pyramid_levels)
            view = KeyframeView(frame, TrackingReference.from_keyframe(frame, kf.idepth, kf.idepth_var,
                                                                       tuple(cfg.tracker.levels)))  # fmt: skip
        self._views[kf.kf_id] = view
        while len(self._views) > self._view_cache:
            self._views.popitem(last=False)
        return view

    def neighbours(self, kf_id: int) -> list[RelocKeyframe]:
        """The kept keyframes next to ``kf_id`` in the odometry's chain: its parent, the one made before it and the
        one made after it (LSD-SLAM checks a relocalisation on the keyframe's graph neighbours)."""
        kf = self.keyframes.get(kf_id)
        ids = {kf_id - 1, kf_id + 1}
        if kf is not None and kf.parent_id is not None:
            ids.add(kf.parent_id)
        ids.update(k for k, other in self.keyframes.items() if other.parent_id == kf_id)
        ids.discard(kf_id)
        return [self.keyframes[i] for i in sorted(ids) if i in self.keyframes]
