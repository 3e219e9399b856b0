"""Output sinks of the visual odometry: where poses, keyframes and tracking losses go.

:class:`~dmtrack.odometry.vo.VisualOdometry` calls an :class:`OutputSink` (any object with these four
methods):

* ``on_frame`` once per tracked frame, in frame order, with the camera-to-world pose T_wc (SE(3), world units);
* ``on_keyframe`` once per keyframe, when its depth map is final — i.e. when the next keyframe replaces it, and
  for the last keyframe when the odometry finishes — with a :class:`KeyframeSnapshot` (copied arrays);
* ``on_lost`` when tracking of a frame is lost (diverged, or not good after the first keyframes);
* ``close`` once at the end.

A sink may also have the **optional** method ``on_frame_info(info)``: it is then called once per processed frame
(tracked or lost; not for the frames skipped after a loss), after that frame's ``on_frame`` / ``on_lost`` and
``on_keyframe`` calls, with a :class:`FrameInfo` — the tracker's numbers, the timings and read-only references to
the frame's image and to the current keyframe's inverse depth, for viewers. The odometry looks the method up once,
when it is created: a sink without it costs nothing and changes nothing. Likewise the optional
``on_initial_map(snapshot)`` is called once, when the first keyframe is created, with a :class:`KeyframeSnapshot`
of its map as the start left it (random, geometric or ground truth), before any frame was mapped into it. And the
optional ``on_relocalised(frame_index, timestamp, keyframe_id, lost_since, T_wc)`` is called when a run that went on
after a loss finds the camera again (after that frame's ``on_frame``): the frame, the keyframe it was found on, the
frame at which tracking had been lost, and the pose found.

The protocol and the snapshot type belong to the odometry (it calls them); the sinks themselves — the run-folder
writer, :class:`~dmtrack.outputs.memory.MemorySink`, :class:`~dmtrack.outputs.memory.MultiSink` — live in
:mod:`dmtrack.outputs`, a layer above, so the odometry never imports a writer or a viewer.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True, eq=False)
class KeyframeSnapshot:
    """A keyframe's final semi-dense depth, copied out of the depth map.

    Attributes
    ----------
    keyframe_id : int
        0, 1, 2, … in creation order.
    frame_index, timestamp
        The frame that became this keyframe.
    T_wc : np.ndarray
        (4, 4) float64 SE(3) camera-to-world pose of the keyframe (world units).
    scale : float
        Sim(3) scale s of the keyframe: a point X_k in keyframe units (depth = 1/idepth) lies at
        s·R·X_k + t in the world (R, t from ``T_wc``). Keyframe maps are normalised to mean inverse depth 1.
    idepth, idepth_var : np.ndarray
        (H, W) float32 smoothed inverse depth (keyframe units) and its variance; −1 (both) where there is no
        usable hypothesis (invalid, or idepth < −0.05). Negative inverse depths above −0.05 are kept.
    image : np.ndarray | None
        The keyframe's source uint8 image ((H, W) grey or (H, W, 3) RGB) for colours.
    camera : Any
        The level-0 :class:`~dmtrack.geometry.camera.PinholeCamera`.
    n_updates : int
        Frames that were mapped into this keyframe.
    parent_id : int | None
        The keyframe whose map this one's was propagated from (the one before it, or after a relocalisation the
        keyframe the camera was found on); None for the first keyframe of a segment.
    segment : int
        0, or the number of times the odometry started a new map after a loss it could not recover from
        (keyframes of different segments share no frame of reference).
    """

    keyframe_id: int
    frame_index: int
    timestamp: float
    T_wc: np.ndarray
    scale: float
    idepth: np.ndarray
    idepth_var: np.ndarray
    image: np.ndarray | None
    camera: Any
    n_updates: int = 0
    parent_id: int | None = None
    segment: int = 0
    _points: list[Any] = field(default_factory=list, init=False, repr=False)  # the last points_world result

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool: pixels with a hypothesis (var > 0)."""
        return self.idepth_var > 0

    @property
    def T_wc_sim3(self) -> np.ndarray:
        """(4, 4) Sim(3) matrix [[s·R, t], [0, 1]] mapping keyframe-unit coordinates to the world."""
        S = np.array(self.T_wc, dtype=np.float64, copy=True)
        S[:3, :3] *= self.scale
        return S

    def points_world(self, max_var: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """World points of the pixels with positive inverse depth, and their colours.

        Both arrays are read-only: the result of the last call is kept, so that several sinks (the run folder and
        a viewer) compute it once.

        Parameters
        ----------
        max_var : float, optional
            Keep only hypotheses with idepth_var ≤ max_var (keyframe units).

        Returns
        -------
        points : np.ndarray
            (M, 3) float64, world coordinates.
        colours : np.ndarray
            (M, 3) uint8 RGB (grey repeated; mid-grey when there is no image).
        """
        if self._points and self._points[0] == max_var:
            return self._points[1], self._points[2]
        from dmtrack.odometry._cloud import points_world_numba

        cam = self.camera
        pts, col = points_world_numba(self.idepth, self.idepth_var, self.image, max_var,
                                      (cam.fx, cam.fy, cam.cx, cam.cy), self.T_wc_sim3)  # fmt: skip
        pts.flags.writeable = False
        col.flags.writeable = False
        self._points[:] = [max_var, pts, col]
        return pts, col


@dataclass(frozen=True, eq=False)
class FrameInfo:
    """What a viewer shows of one processed frame (the argument of the optional ``on_frame_info``).

    The arrays are read-only views of the odometry's own arrays, valid during the call: a sink that keeps one
    copies it.

    Attributes
    ----------
    frame_index, timestamp
        The frame.
    image : np.ndarray | None
        The frame's source uint8 image ((H, W) grey or (H, W, 3) RGB), as given to the odometry.
    camera : Any
        The level-0 :class:`~dmtrack.geometry.camera.PinholeCamera`.
    T_wc : np.ndarray | None
        (4, 4) SE(3) camera-to-world pose; ``None`` when tracking of the frame was lost.
    tracked, is_keyframe
        The frame has a pose; it became a keyframe (the first frame is both).
    keyframe_id : int
        The keyframe the frame was tracked against, or the one it became.
    lost_reason : str | None
        Why tracking was lost, ``None`` when it was not.
    residual : float
        The tracker's error of the last accepted step (``TrackResult.last_residual``); NaN for the first frame.
    good_count, bad_count : int
        Good and bad in-image points of the tracker's last evaluation at the finest level (0 for the first frame).
    point_usage : float
        The tracker's point usage (NaN for the first frame).
    pyramid_ms, tracking_ms, mapping_ms : float
        Wall time of the frame's stages, milliseconds.
    keyframe_idepth, keyframe_idepth_var : np.ndarray
        (H, W) float32 inverse depth (keyframe units) and variance of the current keyframe's map after this frame
        was mapped, as the tracker sees it: −1 (both) where there is no usable hypothesis.
    keyframe_image : np.ndarray | None
        The current keyframe's source image.
    keyframe_frame_index : int
        The frame that became the current keyframe.
    """

    frame_index: int
    timestamp: float
    image: np.ndarray | None
    camera: Any
    T_wc: np.ndarray | None
    tracked: bool
    is_keyframe: bool
    keyframe_id: int
    lost_reason: str | None
    residual: float
    good_count: int
    bad_count: int
    point_usage: float
    pyramid_ms: float
    tracking_ms: float
    mapping_ms: float
    keyframe_idepth: np.ndarray
    keyframe_idepth_var: np.ndarray
    keyframe_image: np.ndarray | None
    keyframe_frame_index: int

    @property
    def keyframe_valid(self) -> np.ndarray:
        """(H, W) bool: pixels of the current keyframe with a hypothesis (var > 0)."""
        return self.keyframe_idepth_var > 0


@runtime_checkable
class OutputSink(Protocol):
    """What the odometry calls with its outputs (see the module docstring for when)."""

    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        """A tracked frame's camera-to-world pose (4×4 float64 SE(3))."""

    def on_keyframe(
        self,
        keyframe_id: int,
        frame_index: int,
        timestamp: float,
        T_wc: np.ndarray,
        depthmap_snapshot: KeyframeSnapshot,
    ) -> None:
        """A finished keyframe with its final depth."""

    def on_lost(self, frame_index: int, reason: str) -> None:
        """Tracking was lost at ``frame_index``."""

    def close(self) -> None:
        """No more calls follow."""

    # optional: def on_frame_info(self, info: FrameInfo) -> None — see the module docstring
    # optional: def on_initial_map(self, snapshot: KeyframeSnapshot) -> None — see the module docstring
