"""Losses, relocalisation and new maps of the visual odometry (:class:`LossHandling`, a base of
:class:`~dmtrack.odometry.vo.VisualOdometry`).

A frame is *lost* when the tracker diverged, when its quality test fails once more than
``keyframe.loss_not_good_after`` keyframes exist (LSD-SLAM's), or when its residual jumps to
``keyframe.loss_residual_jump`` times the last frames' median with fewer than ``keyframe.loss_jump_good_ratio`` good
points (:meth:`LossHandling._jumped`: the camera jumped and the tracker settled on a wrong pose it still half
explains). With ``stop_on_loss`` the odometry then stops; otherwise it stays *lost* until a frame is found again:
on the current keyframe by :meth:`~dmtrack.odometry.vo.VisualOdometry.process` itself (under the relocaliser's
stricter test, :func:`~dmtrack.odometry.relocalisation_quality.relocalisation_failure`), or on any keyframe the run
kept, by a relocaliser above the odometry that then calls :meth:`LossHandling.relocalise`. Frames in between get no
pose (:meth:`LossHandling.skip`). :meth:`LossHandling.new_segment` begins a new map when no relocalisation comes.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from dmtrack.geometry.exact import matmul
from dmtrack.odometry.depthmap import DepthMap
from dmtrack.odometry.initial_map import InitialMap
from dmtrack.odometry.records import FrameResult, KeyframeRecord, StoredKeyframe, _inv_se3, _se3_part, _sim3
from dmtrack.odometry.tracker import TrackingReference, TrackResult

if TYPE_CHECKING:  # pragma: no cover
    from dmtrack.odometry.frame import Frame

__all__ = ["LossHandling"]


class LossHandling:
    """The loss, relocalisation and new-map methods of :class:`~dmtrack.odometry.vo.VisualOdometry` (which holds
    the state they use)."""

    def current_keyframe(self) -> tuple[StoredKeyframe, TrackingReference, np.ndarray] | None:
        """The current keyframe as a relocaliser's first candidate: its map as it is now, its tracking reference and
        the last pose (``T_fk``) on it; None before the first keyframe."""
        if self._kf is None:
            return None
        self._join_mapping()
        snap = self._snaps[-1]
        if snap.ref is None:
            snap.ref = TrackingReference.from_keyframe(self._kf, snap.idepth, snap.var, self._levels, self.use_numba)
        rec = self._keyframes[self._kf_id]
        stored = StoredKeyframe(self._kf_id, self._kf, snap.idepth, snap.var, rec.T_wc, rec.scale, rec.segment)
        return stored, snap.ref, self._T_fk_last.copy()

    def rewind_lost(self, first: int) -> int:
        """Forget the lost frames from ``first`` on (they are about to be processed again, e.g. by a new map that
        begins at ``first``); returns how many."""
        keep = [(i, r) for i, r in self._lost if i < first]
        n = len(self._lost) - len(keep)
        self._lost = keep
        self._n_frames -= n
        return n

    # ------------------------------------------------------------------ losses and relocalisation
    def _jumped(self, res: TrackResult) -> str | None:
        """``keyframe.loss_residual_jump``'s test: why the frame counts as lost (None if it does not)."""
        kcfg = self.config.keyframe
        self._bad_seen = self._bad_seen or res.bad_count > 0
        if kcfg.loss_residual_jump is None or len(self._residuals) * 2 < self._residuals.maxlen:
            return None
        n = res.good_count + res.bad_count
        ratio = res.good_count / n if n > 0 else 0.0
        typical = float(np.median(np.asarray(self._residuals)))
        if ratio < kcfg.loss_jump_good_ratio and res.last_residual > kcfg.loss_residual_jump * typical:
            return (f"tracking jumped: residual {res.last_residual:.2f}, {res.last_residual / typical:.1f}× the last "
                    f"frames' median, with {100 * ratio:.0f} % good points")  # fmt: skip
        limit = self.residual_limit()
        if limit is not None and res.bad_count == 0 and res.last_residual > limit:
            return (f"tracking jumped: residual {res.last_residual:.2f}, {res.last_residual / typical:.1f}× the last "
                    f"frames' median, with no point bad (the feature's good ratio cannot fall)")  # fmt: skip
        return None

    def residual_limit(self) -> float | None:
        """``keyframe.loss_residual_jump_without_bad`` × the median residual of the last tracked frames: the residual
        above which a frame with no bad point counts as lost, or is not found again. None — not used — when it is
        off, in a run that stops at a loss, before enough frames were tracked, and once any frame of the run had a
        bad point: the feature can then show a jump in its good ratio (a clean rendered grey frame may have no bad
        point, and a tiny residual that doubles)."""
        factor = self.config.keyframe.loss_residual_jump_without_bad
        if (factor is None or self.config.stop_on_loss or self._bad_seen
                or len(self._residuals) * 2 < self._residuals.maxlen):  # fmt: skip
            return None
        return factor * float(np.median(np.asarray(self._residuals)))

    def _record_lost(self, index: int, reason: str) -> None:
        self._lost.append((int(index), str(reason)))
        if self._lost_since is None:
            self._lost_since = int(index)
        if self.sink is not None:
            self.sink.on_lost(int(index), str(reason))

    def skip(self, index: int, timestamp: float, reason: str) -> FrameResult:
        """Count a frame that gets no pose without being tracked: one before the first keyframe (a geometric start
        whose reference frame comes later), or one given to a relocaliser while tracking is lost (recorded as
        lost)."""
        if self._finished:
            raise RuntimeError("skip() called after finish()")
        self._n_frames += 1
        if self._kf is None:
            self._before_start += 1
        else:
            self._record_lost(index, reason)
        return FrameResult(index, timestamp, None, False, False, -1, reason)

    def relocalise(self, frame: Frame, keyframe: StoredKeyframe, T_fk: np.ndarray,
                   good: np.ndarray | None = None) -> FrameResult:  # fmt: skip
        """Resume after a loss at ``frame``, found at ``T_fk`` (``keyframe`` → frame) on a keyframe the run made
        earlier: the current keyframe is finished and emitted as on a keyframe change, ``frame`` becomes a new
        keyframe whose map is propagated from ``keyframe``'s (LSD-SLAM's relocaliser continues on the old keyframe
        itself; a new one keeps every keyframe's map final once emitted), its Sim(3) pose chained from
        ``keyframe``'s, and the next frames are tracked against it. ``good``: the tracker's level-1 flags of that
        alignment (see :meth:`DepthMap.create_keyframe`)."""
        return self._threads(self._relocalise, frame, keyframe, T_fk, good)

    def _relocalise(self, frame: Frame, kf: StoredKeyframe, T_fk: np.ndarray, good: np.ndarray | None) -> FrameResult:
        if self._finished:
            raise RuntimeError("relocalise() called after finish()")
        t0 = time.perf_counter()
        self._n_frames += 1
        lost_since = self._lost_since if self._lost_since is not None else int(frame.index)
        self._finish_keyframe()
        old = self._depth_map()
        valid = kf.idepth_var > 0
        validity = np.where(valid, np.float32(self.config.depth.random_init_validity), np.float32(0))
        old.initialize_from_map(kf.frame, InitialMap(kf.frame.index, kf.frame.index, valid, kf.idepth, kf.idepth_var,
                                                     kf.idepth, kf.idepth_var, validity))  # fmt: skip
        new_dm = old.create_keyframe(frame, np.asarray(T_fk, np.float64), good, finalize=False)
        rho = float(new_dm.scale_from_parent)
        S_old = _sim3(np.asarray(kf.T_wc, np.float64), float(kf.scale))
        self._start_keyframe(frame, new_dm, matmul(S_old, _sim3(_inv_se3(T_fk), rho)), float(kf.scale) * rho, rho,
                             parent=kf.keyframe_id)  # fmt: skip
        self._relocalisations.append((int(frame.index), kf.keyframe_id, lost_since))
        self._lost_since = None
        mapping_ms = 1e3 * (time.perf_counter() - t0)
        self._t_sum["mapping"] += mapping_ms
        T_wc = _se3_part(self._S_wk, self._s_wk)
        self._record_pose(frame.index, frame.timestamp, T_wc)
        if self._on_relocalised is not None:
            self._on_relocalised(int(frame.index), float(frame.timestamp), kf.keyframe_id, lost_since, T_wc.copy())
        return FrameResult(frame.index, frame.timestamp, T_wc, True, True, self._kf_id, None, None, 0.0, 0.0,
                           mapping_ms)  # fmt: skip

    def new_segment(self, index: int, timestamp: float, image: np.ndarray | None, feature_map: np.ndarray,
                    initial_map: InitialMap | None) -> FrameResult:  # fmt: skip
        """Begin a new map at this frame after a loss no relocalisation recovered from: the current keyframe is
        finished and emitted, the frame becomes the first keyframe of the next segment with ``initial_map`` (a new
        geometric start's; None: LSD-SLAM's random map), placed at the last tracked pose with the last keyframe's
        scale (the segments share no frame of reference: the placement only keeps the trajectory continuous)."""
        return self._threads(self._new_segment, index, timestamp, image, feature_map, initial_map)

    def _new_segment(self, index: int, timestamp: float, image: np.ndarray | None, feature_map: np.ndarray,
                     initial_map: InitialMap | None) -> FrameResult:  # fmt: skip
        if self._kf is None:
            raise RuntimeError("new_segment() before the first keyframe: process() the first frame instead")
        t0 = time.perf_counter()
        self._n_frames += 1
        frame = self.frame_of(index, timestamp, image, feature_map)
        self._finish_keyframe()
        dm = self._depth_map()
        if initial_map is not None:
            dm.initialize_from_map(frame, initial_map)
        else:
            dm.initialize_random(frame, self.config.seed)
        last = self._poses[-1] if self._poses else np.eye(4)
        self._segment += 1
        self._start_keyframe(frame, dm, _sim3(last, self._s_wk), self._s_wk, 1.0, parent=None)
        self._lost_since = None
        mapping_ms = 1e3 * (time.perf_counter() - t0)
        self._t_sum["mapping"] += mapping_ms
        T_wc = _se3_part(self._S_wk, self._s_wk)
        self._record_pose(index, timestamp, T_wc)
        return FrameResult(index, timestamp, T_wc, True, True, self._kf_id, None, None, 0.0, 0.0, mapping_ms)

    def _finish_keyframe(self) -> None:
        """Finalise the current keyframe's map (fill holes, regularise) and emit it, as a keyframe change does."""
        self._join_mapping()
        if self._dm is not None and self._kf is not None:
            self._dm.finalize()
            self._window_flush()
            self._emit_keyframe(self._kf_id, self._kf, self._dm)

    def _depth_map(self) -> DepthMap:
        return DepthMap(self.config.depth, use_numba=self.use_numba, parallel=self.parallel,
                        channel_cost=self.config.channel_cost, info_channels=self.config.info_channels,
                        energy_channels=self.config.energy_channels)  # fmt: skip

    def _start_keyframe(self, frame: Frame, dm: DepthMap, S_wk: np.ndarray, s_wk: float, rho: float,
                        parent: int | None, regular: bool = False) -> None:  # fmt: skip
        """Make ``frame`` the current keyframe with map ``dm`` and Sim(3) pose ``S_wk`` (scale ``s_wk``)."""
        if parent is None:
            self._segments.append((int(frame.index), len(self._keyframes)))
        self._kf, self._dm = frame, dm
        self._kf_id = len(self._keyframes)
        self._S_wk = S_wk
        self._s_wk = s_wk
        self._T_fk_last = np.eye(4)
        self._snaps = []
        self._take_snapshot(self._n_frames - 1)
        self._keyframes.append(KeyframeRecord(self._kf_id, frame.index, frame.timestamp, _se3_part(S_wk, s_wk), s_wk,
                                              rho, parent, self._segment))  # fmt: skip
        if not regular:  # a map's first keyframe, or one made after a loss: a new window (the switch advances it)
            self._window_restart()
