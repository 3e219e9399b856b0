"""How the odometry uses a window that optimises its newest keyframes jointly (:mod:`dmtrack.window` implements
it; the odometry knows only the :class:`KeyframeWindow` interface, as it knows its sinks only as
:class:`~dmtrack.odometry.sink.OutputSink`).

With a window, a keyframe is emitted to the sink when it leaves the window (or at the end), with its optimised pose
and scale, instead of when the next keyframe is made; the current keyframe's pose and scale — what the next frames'
poses are chained from — are the window's; and the run's trajectory (:meth:`VisualOdometry.result`) places every
frame by its pose relative to its keyframe and that keyframe's final pose, as a SLAM back end's trajectory does.
What the sink was told frame by frame (``on_frame``, the live trajectory) stays the pose known at that moment; a sink
with an ``on_window(frame_index, timestamp, poses)`` method (a viewer) is told the window's keyframe poses (id → T_wc)
after each optimisation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from dmtrack.geometry.exact import matmul
from dmtrack.odometry.records import _inv_se3, _se3_part, _sim3

__all__ = ["KeyframeWindow", "WindowUpdate", "WindowedKeyframes"]


@dataclass
class WindowUpdate:
    """What the window changed: new (T_wc, scale) per keyframe id, and the ids that left it (oldest first)."""

    poses: dict[int, tuple[np.ndarray, float]] = field(default_factory=dict)
    left: list[int] = field(default_factory=list)


class KeyframeWindow(Protocol):
    """A window of the newest keyframes, optimised jointly."""

    @property
    def keyframe_ids(self) -> list[int]:
        """Ids of the keyframes in the window, oldest first."""

    def start(self, keyframe_id: int, frame: Any, T_wc: np.ndarray, scale: float) -> WindowUpdate:
        """Begin anew with this keyframe (the first of a map, or one made after a loss); every keyframe held leaves."""

    def advance(self, finished_id: int, idepth: np.ndarray, var: np.ndarray, keyframe_id: int, frame: Any,
                T_wc: np.ndarray) -> WindowUpdate:  # fmt: skip
        """The current keyframe ``finished_id`` is finished (its final tracking depth ``idepth``, ``var``) and
        ``frame``, tracked at ``T_wc``, becomes keyframe ``keyframe_id``: optimise. The update's poses include the
        new keyframe's (its scale is not known yet: :meth:`set_scale`)."""

    def set_scale(self, keyframe_id: int, scale: float) -> None:
        """The new keyframe's map has been made: its units are ``scale`` world units."""

    def clear(self) -> WindowUpdate:
        """Let every keyframe leave."""

    def summary(self) -> dict[str, Any]:
        """What the window did over the run (``VOResult.window``, ``metrics.json``'s ``window``)."""


class FinishedMap:
    """What the emission of a finished keyframe reads of its depth map (:meth:`tracking_depth`, ``n_updates``), kept
    while the window holds the keyframe instead of the map itself (the map is final: nothing changes it)."""

    __slots__ = ("_idepth", "_var", "n_updates")

    def __init__(self, idepth: np.ndarray, var: np.ndarray, n_updates: int) -> None:
        self._idepth, self._var, self.n_updates = idepth, var, int(n_updates)

    def tracking_depth(self) -> tuple[np.ndarray, np.ndarray]:
        return self._idepth, self._var


class WindowedKeyframes:
    """The odometry's side of the window (a mixin of :class:`~dmtrack.odometry.vo.VisualOdometry`)."""

    _window: KeyframeWindow | None
    _held: dict[int, tuple[Any, Any]]
    _pose_refs: list[tuple[int, np.ndarray]]
    _moved: set[int]

    def _window_apply(self, update: WindowUpdate) -> None:
        """Take the window's poses (the current keyframe's becomes the chain's) and emit the keyframes that left."""
        for kf_id, (T_wc, scale) in update.poses.items():
            self._moved.add(kf_id)
            rec = self._keyframes[kf_id]  # type: ignore[attr-defined]
            rec.T_wc = np.array(T_wc, np.float64)
            rec.scale = float(scale)
            if kf_id == self._kf_id:  # type: ignore[attr-defined]
                self._S_wk = _sim3(rec.T_wc, rec.scale)
                self._s_wk = rec.scale
        self._emit_left(update.left)

    def _emit_left(self, left: list[int]) -> None:
        for kf_id in left:
            held = self._held.pop(kf_id, None)
            if held is not None:
                self._emit_keyframe(kf_id, *held)  # type: ignore[attr-defined]

    def _window_restart(self) -> None:
        """The current keyframe begins a new window (a map's first keyframe, or one made after a loss)."""
        if self._window is None:
            return
        rec = self._keyframes[self._kf_id]  # type: ignore[attr-defined]
        self._window_apply(self._window.start(self._kf_id, self._kf, rec.T_wc, rec.scale))  # type: ignore[attr-defined]

    def _window_flush(self) -> None:
        """Every keyframe still held leaves the window (before the current one is finished and emitted)."""
        if self._window is not None:
            self._window_apply(self._window.clear())
            for kf_id in sorted(self._held):
                self._emit_keyframe(kf_id, *self._held.pop(kf_id))  # type: ignore[attr-defined]

    def _window_switch(self, frame: Any, res: Any) -> None:
        """A keyframe change with a window: the current keyframe is finished, the window (with ``frame`` as its new
        keyframe, at its tracked pose) optimised, and the finished map propagated into ``frame`` along the optimised
        relative pose; the finished keyframe is held until it leaves the window."""
        assert self._window is not None
        old_dm, old_kf, old_id = self._dm, self._kf, self._kf_id  # type: ignore[attr-defined]
        old_dm.finalize()
        idepth, var = old_dm.tracking_depth()
        new_id = len(self._keyframes)  # type: ignore[attr-defined]
        T_wc_new = _se3_part(matmul(self._S_wk, _inv_se3(res.T_fk)), self._s_wk)  # type: ignore[attr-defined]
        update = self._window.advance(old_id, idepth, var, new_id, frame, T_wc_new)
        new_pose = update.poses.pop(new_id, None)
        self._window_apply(update)  # the finished keyframe is still the current one: its pose and scale are the chain's
        T_new_old = np.array(res.T_fk, np.float64)
        if new_pose is not None:  # the optimised relative pose, its translation in the finished keyframe's units
            T_new_old = matmul(_inv_se3(new_pose[0]), self._keyframes[old_id].T_wc)  # type: ignore[attr-defined]
            T_new_old[:3, 3] /= self._s_wk  # type: ignore[attr-defined]
        new_dm = old_dm.create_keyframe(frame, T_new_old, res.ref_pixel_was_good, finalize=False)
        rho = float(new_dm.scale_from_parent)
        S_wk, s_wk = self._S_wk, self._s_wk  # type: ignore[attr-defined]
        self._start_keyframe(frame, new_dm, matmul(S_wk, _sim3(_inv_se3(T_new_old), rho)), s_wk * rho, rho,  # type: ignore[attr-defined]
                             parent=old_id, regular=True)  # fmt: skip
        self._window.set_scale(new_id, s_wk * rho)
        if new_pose is not None:  # placed by the window, not where its frame was tracked
            self._moved.add(new_id)
        # held until it leaves: what its emission reads, not the map's working state (ten (H, W) arrays) nor its
        # full-resolution gradients (the window reads its coarser levels)
        self._held[old_id] = (old_kf, FinishedMap(idepth, var, old_dm.n_updates))  # the window only read them
        old_kf.levels[0].release_gradients()
        self._emit_left(update.left)  # the finished keyframe too when the window began anew (a rejected optimisation)
        on_window = getattr(self.sink, "on_window", None)  # type: ignore[attr-defined]
        if on_window is not None:  # the window's keyframes as it left them (a viewer)
            recs = self._keyframes  # type: ignore[attr-defined]
            on_window(int(frame.index), float(frame.timestamp),
                      {k: recs[k].T_wc.copy() for k in self._window.keyframe_ids})  # fmt: skip

    def _refined_poses(self) -> np.ndarray:
        """T_wc of every recorded frame from its pose relative to its keyframe and that keyframe's pose now (the pose
        recorded at the time where the window never moved the keyframe: the same bytes)."""
        out = np.array(self._poses, dtype=np.float64).reshape(-1, 4, 4)  # type: ignore[attr-defined]
        for i, (kf_id, T_fk) in enumerate(self._pose_refs):
            if kf_id in self._moved:
                rec = self._keyframes[kf_id]  # type: ignore[attr-defined]
                out[i] = _se3_part(matmul(_sim3(rec.T_wc, rec.scale), _inv_se3(T_fk)), rec.scale)
        return out
