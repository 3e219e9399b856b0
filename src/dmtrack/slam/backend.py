"""The SLAM back end: each finished keyframe enters a keyframe graph; constraints by reciprocal Sim(3) alignment;
the graph optimised by gtsam; every frame's pose recomposed from its keyframe's optimised pose.

:class:`SlamBackend` is an :class:`~dmtrack.odometry.sink.OutputSink` (plus ``on_frame_info``): the odometry does not
know it exists. For each keyframe it

1. builds the keyframe's feature pyramid (the run's feature on the keyframe's image) and tracking reference (its
   final inverse depth);
2. adds the odometry edge to the keyframe before it: the odometry's relative pose, with the information of the
   Sim(3) terms of the parent's points in the new keyframe at that pose (LSD-SLAM instead re-aligns the pair both
   ways, its forced parent constraint; the odometry has aligned these frames already, and one evaluation costs 2 ms
   where the reciprocal test costs 50);
3. looks for loop candidates (:mod:`~dmtrack.slam.candidates`) among the keyframes at least ``min_gap`` before it
   and tests each from the graph's current poses; every accepted pair adds two edges;
4. optimises the graph after new loop edges (at most every ``optimise_every`` keyframes), and once at the end,
   and tells its listeners (:mod:`~dmtrack.slam.listener`: a viewer) the optimised poses and the accepted edges.

The trajectory of the run is then every frame's pose relative to the keyframe it was tracked against, composed
with that keyframe's optimised pose (:meth:`trajectory`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dmtrack.geometry.lie import SE3, SO3, Sim3
from dmtrack.io.trajectory import Trajectory
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.frame import build_frame
from dmtrack.odometry.sink import KeyframeSnapshot
from dmtrack.odometry.tracker import TrackingReference
from dmtrack.slam.candidates import CandidateSearch
from dmtrack.slam.constraints import Constraint, KeyframeView, reciprocal_test
from dmtrack.slam.listener import GraphListener, OptimisedGraph
from dmtrack.slam.pose_graph import PoseGraph
from dmtrack.slam.sim3_tracker import Sim3Tracker


@dataclass(frozen=True)
class SlamConfig:
    """Parameters of the back end (LSD-SLAM's where it has them).

    ``strictness`` is ``loopclosureStrictness``; ``min_gap`` the keyframes between a loop candidate and the new
    keyframe (LSD-SLAM: graph distance ≥ 4); ``max_candidates`` the candidates tested per keyframe (LSD-SLAM's
    ``maxLoopClosureCandidates`` is 10); ``convergence_eps`` the Sim(3) alignment's stopping ratio (the odometry's
    tracker: 0.999); ``optimise_every``: after a new loop edge the graph is optimised once at least this many
    keyframes have entered it since the last optimisation (and always at the end); ``view_cache_mb``: the memory
    for keyframes' feature pyramids kept between alignments (others are computed again when needed).
    """

    strictness: float = 1.5
    min_gap: int = 4
    max_candidates: int = 3
    optimise_iterations: int = 100
    convergence_eps: float = 0.99
    optimise_every: int = 3
    view_cache_mb: float = 1024.0


@dataclass
class SlamKeyframe:
    """A keyframe in the graph: its odometry pose (Sim3, keyframe units → world), its image and final inverse
    depth; :attr:`view` (its feature pyramid and tracking reference) is built on demand and cached by the back end
    within a memory budget (dense SIFT's pyramid is about 60 MB a keyframe)."""

    kf_id: int
    frame_index: int
    timestamp: float
    vo_pose: Sim3
    image: np.ndarray
    idepth: np.ndarray
    idepth_var: np.ndarray
    camera: Any
    mean_idepth: float
    points: np.ndarray | None = None  # (M, 3) semi-dense points in keyframe units, for the optimised point cloud
    colours: np.ndarray | None = None  # (M, 3) uint8
    load_view: Any = field(default=None, repr=False)  # () → KeyframeView
    parent_id: int | None = None  # the odometry's parent (the keyframe before, or where a relocalisation found it)

    @property
    def view(self) -> KeyframeView:
        return self.load_view(self)


@dataclass
class GraphEdge:
    """An edge as written to ``graph.json``: ``i → j`` measured ``T_ij``; kind ``odometry`` or ``loop``."""

    i: int
    j: int
    kind: str
    accepted: bool
    T_ij: Sim3 | None
    consistency: tuple[float, ...]
    reason: str | None = None


@dataclass
class SlamStats:
    loop_closures: int = 0
    tested: int = 0
    optimisation_ms: float = 0.0
    alignment_ms: float = 0.0
    optimisations: int = 0
    edges: list[GraphEdge] = field(default_factory=list)


def _nbytes(view: KeyframeView) -> int:
    total = 0
    for level in view.frame.levels[1:]:
        total += level.feat.nbytes + (2 * level.feat.nbytes if level._gx is not None else 0)
    return total


def sim3_of(snapshot: KeyframeSnapshot) -> Sim3:
    """The keyframe's odometry pose as a Sim3 (keyframe units → world)."""
    T = np.asarray(snapshot.T_wc, dtype=np.float64)
    return Sim3(SO3.from_matrix(T[:3, :3], orthonormalize=True), T[:3, 3], float(snapshot.scale))


class SlamBackend:
    """Keyframe graph, constraints and pose-graph optimisation over a run (see the module docstring).

    Parameters
    ----------
    feature : the run's Feature (its maps of the keyframes' images are aligned).
    config : the run's odometry configuration (pyramid, tracker settings, channel rule).
    slam : :class:`SlamConfig`.
    listeners : :class:`~dmtrack.slam.listener.GraphListener` s told of every optimisation (e.g. the viewer); one
        that raises is dropped, its error kept in :attr:`listener_errors`, and the back end goes on.
    """

    def __init__(
        self, feature: Any, config: VOConfig, slam: SlamConfig | None = None, max_point_var: float | None = None,
        listeners: Iterable[GraphListener] = (),
    ) -> None:
        self.feature = feature
        self.max_point_var = max_point_var
        self.config = config
        self.slam = slam or SlamConfig()
        self.graph = PoseGraph(max_iterations=self.slam.optimise_iterations)  # raises without gtsam, before a frame
        tracker = dataclasses.replace(config.tracker, convergence_eps=self.slam.convergence_eps)
        self.tracker = Sim3Tracker(tracker, config.channel_cost, config.energy_channels)
        self.search = CandidateSearch()
        self.keyframes: dict[int, SlamKeyframe] = {}
        self.frames: list[tuple[int, float, np.ndarray]] = []
        self.keyframe_of: dict[int, int] = {}
        self.stats = SlamStats()
        self._last_odometry_info: np.ndarray | None = None
        self._views: dict[int, KeyframeView] = {}  # kf_id → view, least recently used first
        self._pending_loops = 0  # loop edges added since the last optimisation
        self._last_optimised = 0  # the newest keyframe at the last optimisation
        self.listeners: list[GraphListener] = list(listeners)
        self.listener_errors: list[str] = []

    # -- the sink ----------------------------------------------------------------------------------------------------

    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        self.frames.append((int(frame_index), float(timestamp), np.array(T_wc, dtype=np.float64)))

    def on_frame_info(self, info: Any) -> None:
        if info.tracked:
            self.keyframe_of[int(info.frame_index)] = int(info.keyframe_id)

    def on_lost(self, frame_index: int, reason: str) -> None:
        pass

    def on_keyframe(
        self, keyframe_id: int, frame_index: int, timestamp: float, T_wc: np.ndarray, snapshot: KeyframeSnapshot
    ) -> None:
        kf = self._keyframe(snapshot)
        self.keyframes[kf.kf_id] = kf
        self.graph.add_keyframe(kf.kf_id, self._graph_pose_of_new(kf))
        if kf.parent_id is not None and kf.parent_id in self.keyframes:
            self._odometry_edge(self.keyframes[kf.parent_id], kf)
        self._pending_loops += self._loop_edges(kf)
        if self._pending_loops and kf.kf_id - self._last_optimised >= self.slam.optimise_every:
            self._optimise()

    def close(self) -> None:
        if len(self.keyframes) > 1:
            self._optimise(final=True)

    # -- keyframes and edges -----------------------------------------------------------------------------------------

    def _keyframe(self, snap: KeyframeSnapshot) -> SlamKeyframe:
        if snap.image is None:
            raise ValueError(f"keyframe {snap.keyframe_id} has no image: the back end aligns the keyframes' features")
        valid = snap.idepth_var > 0
        mean_idepth = float(snap.idepth[valid].mean()) if valid.any() else 1.0
        pose = sim3_of(snap)
        pts, col = snap.points_world(self.max_point_var)
        inv = pose.inverse()
        # float32 in keyframe units: a 640×480 keyframe has ~10⁵ points, kept until the end
        local = (np.einsum("nk,jk->nj", pts, inv.scale * np.asarray(inv.rotation.matrix())) + inv.translation)
        local = local.astype(np.float32)
        return SlamKeyframe(snap.keyframe_id, snap.frame_index, snap.timestamp, pose, snap.image, snap.idepth,
                            snap.idepth_var, snap.camera, mean_idepth, local, np.array(col), self._view,
                            snap.parent_id)

    def _view(self, kf: SlamKeyframe) -> KeyframeView:
        """The keyframe's pyramid and tracking reference, from the cache or built (the oldest views leave the
        cache once it holds more than ``SlamConfig.view_cache_mb``)."""
        view = self._views.pop(kf.kf_id, None)
        if view is None:
            view = self._build_view(kf)
        self._views[kf.kf_id] = view  # the newest last
        budget = self.slam.view_cache_mb * 2**20
        while len(self._views) > 2 and sum(_nbytes(v) for v in self._views.values()) > budget:
            self._views.pop(next(iter(self._views)))
        return view

    def _build_view(self, kf: SlamKeyframe) -> KeyframeView:
        cfg = self.config
        recompute = getattr(self.feature, "pyramid", "downsample") == "recompute"
        image = kf.image
        fmap = self.feature.compute_pyramid(image, cfg.pyramid_levels) if recompute else self.feature.compute(image)
        frame = build_frame(kf.frame_index, kf.timestamp, image, fmap, kf.camera, cfg.pyramid_levels)
        ref = TrackingReference.from_keyframe(frame, kf.idepth, kf.idepth_var, levels=())
        # the alignment never reads level 0: a zero-byte stand-in of its shape keeps the pyramid's geometry
        level0 = frame.levels[0]
        level0.feat = np.broadcast_to(np.float32(0), level0.feat.shape)
        return KeyframeView(frame, ref)

    def _graph_pose_of_new(self, kf: SlamKeyframe) -> Sim3:
        """The new keyframe's pose in the graph: the odometry's relative pose to its parent, composed with the
        parent's (possibly optimised) graph pose."""
        parent = None if kf.parent_id is None else self.keyframes.get(kf.parent_id)
        if parent is None or parent.kf_id not in self.graph.poses:
            return kf.vo_pose
        return self.graph.poses[parent.kf_id] @ parent.vo_pose.inverse() @ kf.vo_pose

    def _odometry_edge(self, parent: SlamKeyframe, kf: SlamKeyframe) -> None:
        """The odometry's relative pose, with the information of the Sim(3) terms of the parent's points in the new
        keyframe at that pose (one evaluation at level 1: the odometry has aligned these frames already)."""
        T_pk = parent.vo_pose.inverse() @ kf.vo_pose  # the pose of kf in the parent
        S_pk = T_pk.inverse()  # parent → kf coordinates
        t0 = time.perf_counter()
        H = self.tracker.information(parent.view.reference, kf.view.frame, kf.view.idepth_pyramid, S_pk, level=1)
        self.stats.alignment_ms += 1e3 * (time.perf_counter() - t0)
        reason = None
        if H[6, 6] > 0 and H[0, 0] > 0:
            # S_pk = exp(δ) Ŝ_pk gives T_pk = S_pk⁻¹ = T̂_pk exp(−δ): the edge's right perturbation is −δ, its
            # information H itself
            info = H
            self._last_odometry_info = info
        else:
            info = self._last_odometry_info if self._last_odometry_info is not None else np.eye(7) * 1e4
            reason = "no depth overlap: the information of the last odometry edge"
        self.graph.add_edge(parent.kf_id, kf.kf_id, T_pk, info, kind="odometry")
        self.stats.edges.append(GraphEdge(parent.kf_id, kf.kf_id, "odometry", True, T_pk, (), reason))

    def _loop_edges(self, kf: SlamKeyframe) -> int:
        older = [k for k in self.keyframes.values() if k.kf_id <= kf.kf_id - self.slam.min_gap]
        added = 0
        linked: list[int] = []  # keyframes this one is now tied to: their neighbours add little
        for cand in self.search.candidates(kf, older, self.graph.poses)[: self.slam.max_candidates]:
            if any(abs(cand.kf_id - k) <= 1 for k in linked):
                continue
            S_init = self.search.initial_estimate(kf, cand)  # cand → kf from the ORB matches, if they say
            if S_init is None:
                S_init = self.graph.poses[kf.kf_id].inverse() @ self.graph.poses[cand.kf_id]
            c = self._test(cand, kf, S_init, strictness=self.slam.strictness)
            self.stats.tested += 1
            if c.accepted:
                self._add_pair(cand, kf, c, "loop")
                linked.append(cand.kf_id)
                added += 1
            else:
                self.stats.edges.append(GraphEdge(cand.kf_id, kf.kf_id, "loop", False, None, c.consistency, c.reason))
        self.stats.loop_closures += added
        return added

    def _test(self, a: SlamKeyframe, b: SlamKeyframe, S_ab: Sim3, strictness: float) -> Constraint:
        t0 = time.perf_counter()
        try:
            return reciprocal_test(self.tracker, a.view, b.view, S_ab, strictness)
        finally:
            self.stats.alignment_ms += 1e3 * (time.perf_counter() - t0)

    def _add_pair(self, a: SlamKeyframe, b: SlamKeyframe, c: Constraint, kind: str) -> None:
        # S_ab maps a → b coordinates: the pose of a in b (edge b → a); S_ba the pose of b in a (edge a → b)
        self.graph.add_edge(a.kf_id, b.kf_id, c.S_ba, c.information_ba, kind=kind)
        self.graph.add_edge(b.kf_id, a.kf_id, c.S_ab, c.information_ab, kind=kind)
        self.stats.edges.append(GraphEdge(a.kf_id, b.kf_id, kind, True, c.S_ba, c.consistency))

    def _optimise(self, final: bool = False) -> None:
        self._pending_loops = 0
        self._last_optimised = max(self.keyframes, default=0)
        result = self.graph.optimise()
        self.stats.optimisation_ms += result.ms
        self.stats.optimisations += 1
        if self.listeners:
            self._tell_listeners(final)

    def _tell_listeners(self, final: bool) -> None:
        """Hand the optimised graph to every listener; one that raises is dropped (never the back end)."""
        graph = self.optimised_graph(final)
        for listener in list(self.listeners):
            try:
                listener.on_graph_optimised(graph)
            except Exception as e:  # noqa: BLE001 - a viewer's failure must not stop the back end
                self.listeners.remove(listener)
                message = f"{type(listener).__name__}.on_graph_optimised: {type(e).__name__}: {e}"
                self.listener_errors.append(message)
                with contextlib.suppress(Exception):  # warnings turned into errors: the error is kept above
                    warnings.warn(f"SLAM graph listener dropped: {message}", RuntimeWarning, stacklevel=2)

    # -- results -----------------------------------------------------------------------------------------------------

    def optimised_graph(self, final: bool = False) -> OptimisedGraph:
        """The keyframes in the graph at their current (optimised) poses and the accepted edges."""
        poses = self.graph.poses
        ids = sorted(k for k in poses if k in self.keyframes)
        T = np.tile(np.eye(4), (len(ids), 1, 1))
        for r, k in enumerate(ids):
            T[r, :3, :3] = poses[k].rotation.matrix()
            T[r, :3, 3] = poses[k].translation
        return OptimisedGraph(
            keyframe_ids=np.array(ids, dtype=np.int64),
            frame_indices=np.array([self.keyframes[k].frame_index for k in ids], dtype=np.int64),
            timestamps=np.array([self.keyframes[k].timestamp for k in ids], dtype=np.float64),
            poses=T,
            scales=np.array([poses[k].scale for k in ids], dtype=np.float64),
            edges=tuple((e.i, e.j, e.kind) for e in self.stats.edges if e.accepted),
            optimisation=self.stats.optimisations,
            final=final,
        )

    def keyframe_poses(self) -> dict[int, Sim3]:
        """Optimised Sim3 pose (keyframe units → world) of every keyframe in the graph."""
        return dict(self.graph.poses)

    def keyframe_trajectory(self) -> Trajectory:
        """The keyframes' optimised poses as SE(3) camera-to-world (the scale dropped), in keyframe order."""
        poses = self.graph.poses
        ids = sorted(poses)
        return Trajectory(
            np.array([self.keyframes[k].timestamp for k in ids], dtype=np.float64),
            np.array([SE3(poses[k].rotation, poses[k].translation).matrix() for k in ids]).reshape(-1, 4, 4),
        )

    def point_cloud(self) -> tuple[np.ndarray, np.ndarray]:
        """The keyframes' semi-dense points placed by their optimised poses, and their colours."""
        pts, cols = [np.zeros((0, 3))], [np.zeros((0, 3), np.uint8)]
        for k in sorted(self.keyframes):
            kf = self.keyframes[k]
            P = self.graph.poses.get(k, kf.vo_pose)
            if kf.points is None or kf.colours is None:
                continue
            local = kf.points.astype(np.float64)
            pts.append(np.einsum("nk,jk->nj", local, P.scale * np.asarray(P.rotation.matrix())) + P.translation)
            cols.append(kf.colours)
        return np.concatenate(pts), np.concatenate(cols)

    def trajectory(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(frame indices, timestamps, (n, 4, 4) SE(3) camera-to-world poses) of every tracked frame, each composed
        from its keyframe's optimised pose (frames whose keyframe never entered the graph keep the odometry's)."""
        poses = self.graph.poses
        idx, ts, out = [], [], []
        for i, t, T in self.frames:
            k = self.keyframe_of.get(i)
            kf = self.keyframes.get(k) if k is not None else None
            if kf is None or k not in poses:
                pose = T
            else:
                rel = kf.vo_pose.inverse() @ Sim3(SO3.from_matrix(T[:3, :3], orthonormalize=True), T[:3, 3], 1.0)
                S = poses[k] @ rel
                pose = SE3(S.rotation, S.translation).matrix()
            idx.append(i)
            ts.append(t)
            out.append(pose)
        return np.array(idx, dtype=np.int64), np.array(ts, dtype=np.float64), np.array(out).reshape(-1, 4, 4)


class ThreadedSlam:
    """A :class:`SlamBackend` run on its own thread, as the odometry's sink: frames are recorded at once,
    keyframes queued and processed in order (the same graph as on the caller's thread, whatever the timing).

    An error of the back end (a failed optimisation, a bad constraint) stops the back end, never the odometry:
    :attr:`error` holds it and the run keeps its odometry trajectory.
    """

    def __init__(self, backend: SlamBackend) -> None:
        import queue
        import threading

        self.backend = backend
        self.error: BaseException | None = None
        self._queue: queue.Queue[tuple[Any, ...] | None] = queue.Queue()
        self._thread = threading.Thread(target=self._work, name="dmtrack-slam", daemon=True)
        self._thread.start()
        self._closed = False

    def _work(self) -> None:
        while (item := self._queue.get()) is not None:
            if self.error is None:
                try:
                    self.backend.on_keyframe(*item)
                except Exception as e:  # noqa: BLE001 - kept and reported; the odometry goes on
                    self.error = e

    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        self.backend.on_frame(frame_index, timestamp, T_wc)

    def on_frame_info(self, info: Any) -> None:
        self.backend.on_frame_info(info)

    def on_lost(self, frame_index: int, reason: str) -> None:
        self.backend.on_lost(frame_index, reason)

    def on_keyframe(
        self, keyframe_id: int, frame_index: int, timestamp: float, T_wc: np.ndarray, snapshot: KeyframeSnapshot
    ) -> None:
        self._queue.put((keyframe_id, frame_index, timestamp, T_wc, snapshot))

    def close(self) -> None:
        """Wait for the queued keyframes, then the final optimisation."""
        if self._closed:
            return
        self._closed = True
        self._queue.put(None)
        self._thread.join()
        if self.error is None:
            try:
                self.backend.close()
            except Exception as e:  # noqa: BLE001
                self.error = e
