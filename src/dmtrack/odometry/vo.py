"""Single-process, deterministic semi-dense visual odometry (LSD-SLAM's VO with single-threaded mapping).

Per frame (:meth:`VisualOdometry.process`):

1. build the feature pyramid (:func:`~dmtrack.odometry.frame.build_frame`);
2. the first frame becomes keyframe 0 (pose identity) with a seeded random depth map (``init="random"``), the
   map of the geometric start (:class:`~dmtrack.odometry.initial_map.InitialMap`, made by
   :mod:`dmtrack.initialization` before this frame is processed) or the dataset's depth;
3. every later frame is tracked against the current keyframe (:class:`~dmtrack.odometry.tracker.Tracker`),
   starting from the previous frame's pose relative to that keyframe (constant position), and against the
   keyframe's map as it was ``map_lag`` frames earlier (see *Schedule*);
4. tracking is *lost* when the tracker diverged, or — once more than ``keyframe.loss_not_good_after``
   keyframes exist — when its quality test fails; the frame gets no pose, is not mapped, and (with
   ``stop_on_loss``) the odometry stops;
5. new keyframe when the current one had been mapped more than ``keyframe.min_mapped`` times and
   (|t_kf|·meanIdepth)²·KFDistWeight² + (1 − pointUsage)²·KFUsageWeight² > ``keyframe.threshold``
   (t_kf = frame position in keyframe coordinates; mapped count and meanIdepth of that same lagged map):
   the frame becomes the keyframe, its depth is propagated from the old one
   (:meth:`DepthMap.create_keyframe`), and its pose chains as Sim(3): S_w,new = S_w,old · Sim3(T_fk⁻¹, ρ) with ρ
   the new map's mean-inverse-depth normalisation; otherwise the frame is mapped into the keyframe
   (:meth:`DepthMap.update`).

Schedule: frames are processed one after the other, and the map changes only by mapping (frame i is mapped
before frame i+1 is tracked). With ``map_lag = 1`` (default) frame i+1 is nevertheless tracked — and takes its
keyframe decision — against the keyframe's map as mapped through frame i−1 (or as created, for a younger
keyframe). That is LSD-SLAM's VO with single-threaded, "blocking" mapping: its mapping thread takes frame i
off the queue before mapping it, which releases the tracker, so frame i+1 is read and tracked while frame i is
still being mapped (observed with the oracle in ``tools/lsd_oracle``; it also gives LSD-SLAM's keyframe cadence,
at least 8 frames apart). ``map_lag = 0`` is the strictly sequential variant. The map each frame sees depends
only on the frame index, never on timing, so results are deterministic.

Overlap: because frame i+1 needs only the map through frame i−1 (``map_lag = 1``), frame i is mapped on a worker
thread while the calling thread builds frame i+1's pyramid and tracks it (``overlap=True``; off by default: on
two cores it measured no faster, the kernels already keep both busy). The calling thread waits for that mapping
before frame i+1's own mapping or keyframe creation (which build on it), and only then records the map snapshot
it left; a keyframe creation runs in the calling thread. The worker touches only the current depth map; the
tracker reads snapshots taken before, so what each frame sees is the same as in line and the results are byte-
identical (tested). An exception in the worker is raised by the next :meth:`VisualOdometry.process` (or
:meth:`~VisualOdometry.finish`). A sink is always called from the calling thread; a :class:`FrameInfo` sink
makes each frame wait for its own mapping (it shows the map after the frame).

Threads: inside tracking and mapping the numba kernels can use several threads (``parallel``, ``threads``):
the tracker's point blocks and the depth map's pixel rows are independent and every sum is formed per fixed
block and combined in order, so the results are byte-identical for any thread count. On a machine whose cores
are busy with other work the threads wait passively (``import dmtrack`` sets ``OMP_WAIT_POLICY=PASSIVE`` unless the
user set it); there one thread (``threads=1`` or ``NUMBA_NUM_THREADS=1``) can still be faster.

Frame poses: T_wc = S_wk · T_fk⁻¹ reduced to SE(3) (rotation without the scale, translation in world units);
the world unit is the first keyframe's (mean inverse depth 1), up to the drift of the monocular scale.
"""

from __future__ import annotations

import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numba
import numpy as np

from dmtrack.errors import InputError
from dmtrack.geometry.exact import matmul
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.depthmap import DepthMap
from dmtrack.odometry.frame import Frame, build_frame
from dmtrack.odometry.initial_map import InitialMap
from dmtrack.odometry.losses import LossHandling
from dmtrack.odometry.records import (
    FrameResult,
    KeyframeRecord,
    StoredKeyframe,
    VOResult,
    _inv_se3,
    _se3_part,
    _sim3,
    keyframe_score,
)
from dmtrack.odometry.relocalisation_quality import relocalisation_failure
from dmtrack.odometry.sink import FrameInfo, KeyframeSnapshot, OutputSink
from dmtrack.odometry.tracker import Tracker, TrackingReference, TrackResult
from dmtrack.odometry.windowing import KeyframeWindow, WindowedKeyframes

if TYPE_CHECKING:  # pragma: no cover
    from dmtrack.geometry.camera import PinholeCamera

__all__ = ["FrameResult", "KeyframeRecord", "StoredKeyframe", "VOResult", "VisualOdometry", "keyframe_score"]


_CONCURRENT_LAYERS = ("tbb", "omp")


def _concurrent_kernels_ok() -> bool:
    """Whether numba's threading layer lets two Python threads launch parallel kernels at once (``workqueue``
    does not: it aborts the process)."""
    try:
        from numba.np.ufunc import parallel as _parallel

        _parallel._launch_threads()  # choose the layer now (it is chosen at the first parallel launch otherwise)
        return numba.threading_layer() in _CONCURRENT_LAYERS
    except Exception:  # noqa: BLE001 - unknown numba internals: stay sequential
        return False


def _read_only(a: np.ndarray | None) -> np.ndarray | None:
    """A read-only view of ``a`` (no copy), so that a sink cannot change the odometry's arrays."""
    if a is None:
        return None
    v = a.view()
    v.flags.writeable = False
    return v


@dataclass
class _MapSnapshot:
    """The current keyframe's map as the tracker and the keyframe test see it, taken after a mapping step."""

    frame: int  # processing ordinal (0, 1, …) of the frame whose mapping (or keyframe creation) produced it
    idepth: np.ndarray
    var: np.ndarray
    n_updates: int
    mean_idepth: float
    ref: TrackingReference | None = None

    @classmethod
    def of(cls, dm: DepthMap, frame: int) -> _MapSnapshot:
        """The snapshot of ``dm`` as it is now, after the ``frame``-th processed frame."""
        idepth, var, mean_idepth = dm.tracking_snapshot()
        return cls(frame, idepth, var, dm.n_updates, mean_idepth)


class VisualOdometry(LossHandling, WindowedKeyframes):
    """Deterministic single-process semi-dense VO over N-channel feature maps.

    Parameters
    ----------
    camera : PinholeCamera
        Level-0 intrinsics; the feature maps must be camera.width × camera.height (multiples of
        2^(pyramid_levels−1)).
    config : VOConfig, optional
        Parameters (LSD-SLAM defaults).
    sink : OutputSink, optional
        Receives poses, keyframes and losses as they happen; also a :class:`~dmtrack.odometry.sink.FrameInfo` per
        processed frame when it has the optional ``on_frame_info`` method (looked up here, once).
    use_numba : bool
        Numba kernels (default) or numpy references (slow; tests only).
    parallel : bool, optional
        Multi-threaded numba kernels in the tracker (levels with enough points) and the depth map (observe,
        fill holes, regularize). Results are bit-identical to serial, whatever the thread count. Default: on
        when more than one numba thread is used.
    threads : int, optional
        Numba threads for this odometry's kernels (set around every :meth:`process` / :meth:`finish` call and
        restored afterwards); default: numba's current setting (``NUMBA_NUM_THREADS``, the core count, or
        what ``numba.set_num_threads`` set in the calling thread).
    overlap : bool
        Map frame n on a worker thread while frame n + 1 is tracked and tested for a keyframe (see *Overlap* in
        the module docstring). Results are byte-identical either way. Off by default: on two cores, where the
        kernels already use both, it measured no faster (grey 7-Scenes 700 frames: 60.3 against 61.6 fps).
        Needs ``map_lag`` ≥ 1; with numba's ``workqueue`` threading layer (which aborts when two threads launch
        kernels at once) it is switched off.
    window : KeyframeWindow, optional
        Optimises the newest keyframes jointly at each keyframe change (:mod:`dmtrack.window`,
        :mod:`dmtrack.odometry.windowing`); None (default): LSD-SLAM's odometry, every keyframe final once made.

    Raises
    ------
    InputError
        If ``threads`` is not in 1 … ``numba.config.NUMBA_NUM_THREADS``.
    """

    def __init__(
        self,
        camera: PinholeCamera,
        config: VOConfig | None = None,
        sink: OutputSink | None = None,
        use_numba: bool = True,
        parallel: bool | None = None,
        threads: int | None = None,
        overlap: bool = False,
        window: KeyframeWindow | None = None,
    ):
        if threads is not None and not 1 <= int(threads) <= numba.config.NUMBA_NUM_THREADS:
            raise InputError(f"threads must be in 1..{numba.config.NUMBA_NUM_THREADS}, got {threads}")
        self.threads = None if threads is None else int(threads)
        if parallel is None:
            n_threads = self.threads if self.threads is not None else numba.get_num_threads()
            parallel = use_numba and n_threads > 1
        self.camera = camera
        self.config = config if config is not None else VOConfig()
        if overlap and self.config.map_lag < 1:
            raise InputError("overlap needs map_lag >= 1, got map_lag = 0")
        self.overlap = bool(overlap) and (not use_numba or _concurrent_kernels_ok())
        self._pool: ThreadPoolExecutor | None = None
        self._pending: tuple[Future, FrameResult] | None = None  # the mapping in flight and its frame's result
        self.sink = sink
        self._on_frame_info = getattr(sink, "on_frame_info", None)  # optional sink method (viewers)
        self._on_initial_map = getattr(sink, "on_initial_map", None)  # optional: the first keyframe's map at start
        self._on_relocalised = getattr(sink, "on_relocalised", None)  # optional: where a lost run was found again
        self.use_numba = use_numba
        self.parallel = bool(parallel)
        self.tracker = Tracker(
            self.config.tracker,
            use_numba=use_numba,
            parallel=self.parallel,
            channel_cost=self.config.channel_cost,
            energy_channels=self.config.energy_channels,
            noise_energy_channels=self.config.noise_energy_channels,
        )
        self._levels = tuple(self.config.tracker.levels)
        # state of the current keyframe
        self._kf: Frame | None = None
        self._dm: DepthMap | None = None
        self._kf_id = -1
        self._S_wk = np.eye(4)  # Sim(3) keyframe → world
        self._s_wk = 1.0
        self._T_fk_last = np.eye(4)
        self._snaps: list[_MapSnapshot] = []  # snapshots of the current keyframe's map, oldest first
        self._stopped_at: int | None = None
        self._finished = False
        # history
        self._indices: list[int] = []
        self._timestamps: list[float] = []
        self._poses: list[np.ndarray] = []
        self._keyframes: list[KeyframeRecord] = []
        self._lost: list[tuple[int, str]] = []
        self._lost_since: int | None = None  # the frame at which tracking was lost, while it has not resumed
        self._residuals: deque[float] = deque(maxlen=max(1, self.config.keyframe.loss_history))
        self._bad_seen = False  # a tracked frame of the run had a bad point (LossHandling.residual_limit)
        self._before_start = 0
        self._relocalisations: list[tuple[int, int, int]] = []
        self._segments: list[tuple[int, int]] = []
        self._segment = 0
        self._n_frames = 0
        self._t_sum = {"pyramid": 0.0, "tracking": 0.0, "mapping": 0.0}
        self._window = window
        self._held = {}  # finished keyframes still in the window: id → (frame, depth map), emitted when they leave
        self._pose_refs = []  # with a window: (keyframe id, T_fk) of every recorded pose
        self._moved = set()  # keyframes whose pose the window changed

    # ------------------------------------------------------------------ properties
    @property
    def n_keyframes(self) -> int:
        """Keyframes created so far."""
        return len(self._keyframes)

    @property
    def depth_map(self) -> DepthMap | None:
        """The current keyframe's depth map (with the mapping in flight finished first)."""
        self._join_mapping()
        return self._dm

    @property
    def keyframe(self) -> Frame | None:
        """The current keyframe."""
        return self._kf

    @property
    def stopped(self) -> bool:
        """True after a tracking loss with ``stop_on_loss`` (further frames are skipped)."""
        return self._stopped_at is not None

    @property
    def lost(self) -> bool:
        """Tracking was lost and has not resumed: the frames since have no pose (``stop_on_loss`` off)."""
        return self._lost_since is not None

    @property
    def lost_since(self) -> int | None:
        """The frame at which tracking was lost, while it has not resumed."""
        return self._lost_since

    @property
    def last_pose(self) -> np.ndarray | None:
        """T_wc of the last frame with a pose (None before the first)."""
        return self._poses[-1] if self._poses else None

    @property
    def keyframe_id(self) -> int:
        """The current keyframe's id (−1 before the first)."""
        return self._kf_id

    def frame_of(self, index: int, timestamp: float, image: np.ndarray | None, feature_map: np.ndarray) -> Frame:
        """The odometry's :class:`~dmtrack.odometry.frame.Frame` (feature pyramid) of a frame, as :meth:`process`
        builds it."""
        return build_frame(index, timestamp, image, feature_map, self.camera, self.config.pyramid_levels,
                           self.use_numba)  # fmt: skip

    def _threads(self, fn, *args):  # type: ignore[no-untyped-def]
        """``fn(*args)`` with ``threads`` numba threads, if given."""
        if self.threads is None:
            return fn(*args)
        prev = numba.get_num_threads()
        numba.set_num_threads(self.threads)
        try:
            return fn(*args)
        finally:
            numba.set_num_threads(prev)

    # ------------------------------------------------------------------ main loop
    def process(
        self,
        index: int,
        timestamp: float,
        image: np.ndarray | None,
        feature_map: np.ndarray,
        depth: np.ndarray | None = None,
        initial_map: InitialMap | None = None,
    ) -> FrameResult:
        """Process one frame (see :meth:`_process`; runs with ``threads`` numba threads if given)."""
        result = self._threads(self._process, index, timestamp, image, feature_map, depth, initial_map)
        if self._on_frame_info is not None and result.keyframe_id >= 0:
            self._join_mapping()  # the viewer shows the map after this frame was mapped
            self._on_frame_info(self._frame_info(result, image))
        return result

    def _process(
        self,
        index: int,
        timestamp: float,
        image: np.ndarray | None,
        feature_map: np.ndarray,
        depth: np.ndarray | None = None,
        initial_map: InitialMap | None = None,
    ) -> FrameResult:
        """Process one frame.

        Parameters
        ----------
        index : int
            Frame index (increasing).
        timestamp : float
            Frame timestamp.
        image : np.ndarray | None
            Source uint8 image (grey or RGB), kept with keyframes for point-cloud colours.
        feature_map : np.ndarray
            (H, W, N) (or (H, W)) float feature map, grey = 0..255.
        depth : np.ndarray, optional
            (H, W) true depth (0 or NaN = unknown) of the first frame, used with ``config.init = "groundtruth"``.
        initial_map : InitialMap, optional
            The first keyframe's map with ``config.init = "geometric"`` (given with the first frame; the start
            made it from this and the following frames, :mod:`dmtrack.initialization`).

        Raises
        ------
        InputError
            If the feature map does not fit the camera or changes its channel count.
        RuntimeError
            If called after :meth:`finish`.
        """
        if self._finished:
            raise RuntimeError("process() called after finish()")
        self._n_frames += 1
        if self._stopped_at is not None:
            return FrameResult(
                index, timestamp, None, False, False, -1, f"stopped: tracking was lost at frame {self._stopped_at}"
            )
        t0 = time.perf_counter()
        frame = build_frame(
            index, timestamp, image, feature_map, self.camera, self.config.pyramid_levels, self.use_numba
        )
        t1 = time.perf_counter()
        pyramid_ms = 1e3 * (t1 - t0)
        self._t_sum["pyramid"] += pyramid_ms

        if self._kf is None:
            return self._initialize(frame, pyramid_ms, depth, initial_map)

        assert self._dm is not None
        # ---- tracking, against the map as of map_lag frames earlier (see _snapshot_for)
        t1 = time.perf_counter()
        ordinal = self._n_frames - 1  # frames given to process() before this one
        if self.config.map_lag < 1:
            self._join_mapping()
        snap = self._snapshot_for(ordinal)
        if snap.ref is None:
            snap.ref = TrackingReference.from_keyframe(self._kf, snap.idepth, snap.var, self._levels, self.use_numba)
        reference_ms = 1e3 * (time.perf_counter() - t1)
        res = self.tracker.track(snap.ref, frame, self._T_fk_last)
        t2 = time.perf_counter()
        tracking_ms = 1e3 * (t2 - t1)
        self._t_sum["tracking"] += tracking_ms

        reason = None
        if res.diverged:
            reason = res.reason
        elif self._lost_since is not None:  # after a loss: the quality a relocalisation needs, not that of tracking
            reason = relocalisation_failure(res, self.config.relocalisation, residual_limit=self.residual_limit())
        else:
            limit = self.config.keyframe.loss_not_good_after
            if limit is not None and self.n_keyframes > limit and not res.good:
                reason = res.reason
            else:
                reason = self._jumped(res)
        if reason is not None:
            self._record_lost(index, reason)
            if self.config.stop_on_loss:
                self._stopped_at = int(index)
            return FrameResult(
                index, timestamp, None, False, False, self._kf_id, reason, res, pyramid_ms, tracking_ms,
                reference_ms=reference_ms,
            )  # fmt: skip
        if self._lost_since is not None:  # found again on the current keyframe
            self._relocalisations.append((int(index), self._kf_id, self._lost_since))
            if self._on_relocalised is not None:
                T_wc_found = _se3_part(matmul(self._S_wk, _inv_se3(res.T_fk)), self._s_wk)
                self._on_relocalised(int(index), float(timestamp), self._kf_id, self._lost_since, T_wc_found)
            self._lost_since = None
        self._residuals.append(float(res.last_residual))

        T_fk = res.T_fk
        T_wc = _se3_part(matmul(self._S_wk, _inv_se3(T_fk)), self._s_wk)
        self._record_pose(index, timestamp, T_wc, T_fk)

        # ---- keyframe selection and mapping
        kcfg = self.config.keyframe
        new_kf = False
        if snap.n_updates > kcfg.min_mapped:
            score = keyframe_score(T_fk, snap.mean_idepth, res.point_usage, kcfg.kf_dist_weight, kcfg.kf_usage_weight)
            new_kf = score > kcfg.threshold
        self._join_mapping()  # the map through the previous frame: what a new keyframe or this update builds on
        if new_kf:
            t3 = time.perf_counter()
            self._switch_keyframe(frame, res)
            if self._window is not None:  # the frame is the new keyframe: placed by the keyframe's own pose
                self._pose_refs[-1] = (self._kf_id, np.eye(4))
            mapping_ms = 1e3 * (time.perf_counter() - t3)
            self._t_sum["mapping"] += mapping_ms
            return FrameResult(
                index, timestamp, T_wc, True, True, self._kf_id, None, res, pyramid_ms, tracking_ms, mapping_ms,
                reference_ms,
            )  # fmt: skip
        self._T_fk_last = T_fk
        result = FrameResult(
            index, timestamp, T_wc, True, False, self._kf_id, None, res, pyramid_ms, tracking_ms, 0.0, reference_ms
        )
        good = res.ref_pixel_was_good
        if self.overlap:
            good = good.copy()  # the worker's own: nothing the calling thread does next can touch it
        args = (self._dm, frame, T_fk, good, res.initial_tracked_residual, ordinal)
        if not self.overlap:
            self._apply_mapping(result, self._map(*args))
            return result
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="dmtrack-mapping")
        n_threads = self.threads if self.threads is not None else numba.get_num_threads()
        self._pending = (self._pool.submit(self._map_in_worker, n_threads, *args), result)
        return result

    # ------------------------------------------------------------------ mapping (in line or on the worker)
    def _map(
        self, dm: DepthMap, frame: Frame, T_fk: np.ndarray, good: np.ndarray, residual: float, ordinal: int
    ) -> tuple[_MapSnapshot, float]:
        """Map a tracked frame into its keyframe; return the snapshot of the map it leaves and the time it took.

        Touches nothing of the odometry but ``dm``: on the worker thread it runs beside the tracking of the next
        frame, which reads only snapshots taken earlier."""
        t0 = time.perf_counter()
        dm.update(frame, T_fk, good, residual)
        snap = _MapSnapshot.of(dm, ordinal)
        return snap, 1e3 * (time.perf_counter() - t0)

    def _map_in_worker(self, n_threads: int, *args: object) -> tuple[_MapSnapshot, float]:
        numba.set_num_threads(n_threads)  # numba's thread count is per calling thread
        return self._map(*args)  # type: ignore[arg-type]

    def _apply_mapping(self, result: FrameResult, done: tuple[_MapSnapshot, float]) -> None:
        snap, mapping_ms = done
        self._keep_snapshot(snap)
        result.mapping_ms = mapping_ms
        self._t_sum["mapping"] += mapping_ms

    def _join_mapping(self) -> None:
        """Wait for the mapping in flight (if any) and take its snapshot; re-raises what it raised."""
        if self._pending is None:
            return
        future, result = self._pending
        self._pending = None
        self._apply_mapping(result, future.result())

    def _initialize(
        self, frame: Frame, pyramid_ms: float, depth: np.ndarray | None = None, initial: InitialMap | None = None
    ) -> FrameResult:
        t0 = time.perf_counter()
        dm = self._depth_map()
        if self.config.init == "geometric":
            if initial is None:
                raise InputError(
                    "init='geometric' needs the first keyframe's map (dmtrack.initialization.GeometricInitializer; "
                    "dmtrack.track makes it)"
                )
            if initial.frame_index != frame.index:
                raise InputError(f"the initial map is of frame {initial.frame_index}, the first frame is {frame.index}")
            dm.initialize_from_map(frame, initial)
        elif self.config.init == "groundtruth":
            if depth is None:
                raise InputError("init='groundtruth' needs the first frame's depth image")
            d = np.asarray(depth, dtype=np.float64)
            with np.errstate(divide="ignore", invalid="ignore"):
                idepth = np.where(np.isfinite(d) & (d > 0), 1.0 / d, np.nan)
            dm.initialize_from_depth(frame, idepth)
        else:
            dm.initialize_random(frame, self.config.seed)
        self._start_keyframe(frame, dm, np.eye(4), 1.0, 1.0, parent=None)
        if self._on_initial_map is not None:
            self._on_initial_map(self._snapshot(0, frame, dm))
        mapping_ms = 1e3 * (time.perf_counter() - t0)
        self._t_sum["mapping"] += mapping_ms
        T_wc = np.eye(4)
        self._record_pose(frame.index, frame.timestamp, T_wc)
        return FrameResult(frame.index, frame.timestamp, T_wc, True, True, 0, None, None, pyramid_ms, 0.0, mapping_ms)

    def _switch_keyframe(self, frame: Frame, res: TrackResult) -> None:
        assert self._dm is not None and self._kf is not None
        if self._window is not None:  # optimised with the window first; held while it is in the window
            self._window_switch(frame, res)
            return
        old_dm, old_kf, old_id = self._dm, self._kf, self._kf_id
        new_dm = old_dm.create_keyframe(frame, res.T_fk, res.ref_pixel_was_good)  # finalises old_dm in place
        rho = float(new_dm.scale_from_parent)
        self._start_keyframe(frame, new_dm, matmul(self._S_wk, _sim3(_inv_se3(res.T_fk), rho)), self._s_wk * rho, rho,
                             parent=old_id, regular=True)  # fmt: skip
        # emitted once the odometry has moved on: if the sink raises, finish() emits the new keyframe, not this
        # one a second time
        self._emit_keyframe(old_id, old_kf, old_dm)

    def _take_snapshot(self, ordinal: int) -> None:
        """Record the current keyframe's map after creating it at the ``ordinal``-th processed frame (0-based);
        keep what a later frame may still use (mapped frames add theirs in :meth:`_apply_mapping`)."""
        assert self._dm is not None
        self._keep_snapshot(_MapSnapshot.of(self._dm, ordinal))

    def _keep_snapshot(self, snap: _MapSnapshot) -> None:
        """Add ``snap``, the newest, and drop those no later frame can use."""
        self._snaps.append(snap)
        del self._snaps[: -(self.config.map_lag + 1)]

    def _snapshot_for(self, ordinal: int) -> _MapSnapshot:
        """The map the ``ordinal``-th processed frame (0-based) is tracked against and its keyframe test sees.

        The newest snapshot taken after mapping a frame processed ≤ ordinal − 1 − map_lag (frames that were lost
        were not mapped and left none); when the keyframe is younger than that, its snapshot at creation. With
        map_lag = 1 this is LSD-SLAM's VO with blockUntilMapped: the mapping thread releases the tracker as soon
        as it has taken frame n from its queue, so frame n + 1 is tracked (and its keyframe test reads
        numMappedOnThisTotal and meanIdepth) while frame n is still being mapped, i.e. against the map through
        frame n − 1 (or the new keyframe's, which is complete before the next frame is tracked).
        """
        limit = ordinal - 1 - self.config.map_lag
        for snap in reversed(self._snaps):
            if snap.frame <= limit:
                return snap
        return self._snaps[0]

    def _emit_keyframe(self, kf_id: int, kf: Frame, dm: DepthMap) -> None:
        if self.sink is None:
            return
        rec = self._keyframes[kf_id]
        self.sink.on_keyframe(kf_id, kf.index, kf.timestamp, rec.T_wc.copy(), self._snapshot(kf_id, kf, dm))

    def _snapshot(self, kf_id: int, kf: Frame, dm: DepthMap) -> KeyframeSnapshot:
        """The keyframe's depth as it is now (copied arrays)."""
        rec = self._keyframes[kf_id]
        idepth, var = dm.tracking_depth()
        return KeyframeSnapshot(
            keyframe_id=kf_id,
            frame_index=kf.index,
            timestamp=kf.timestamp,
            T_wc=rec.T_wc.copy(),
            scale=rec.scale,
            idepth=idepth,
            idepth_var=var,
            image=kf.image,
            camera=kf.camera,
            n_updates=dm.n_updates,
            parent_id=rec.parent_id,
            segment=rec.segment,
        )

    def _frame_info(self, r: FrameResult, image: np.ndarray | None) -> FrameInfo:
        """The :class:`FrameInfo` of a processed frame: its numbers, and read-only views of the live arrays."""
        assert self._kf is not None
        snap = self._snaps[-1]  # the current keyframe's map after this frame was mapped
        t = r.track
        return FrameInfo(
            frame_index=int(r.index),
            timestamp=float(r.timestamp),
            image=_read_only(image),
            camera=self.camera,
            T_wc=_read_only(r.T_wc),
            tracked=r.tracked,
            is_keyframe=r.is_keyframe,
            keyframe_id=r.keyframe_id,
            lost_reason=r.lost_reason,
            residual=float("nan") if t is None else float(t.last_residual),
            good_count=0 if t is None else int(t.good_count),
            bad_count=0 if t is None else int(t.bad_count),
            point_usage=float("nan") if t is None else float(t.point_usage),
            pyramid_ms=r.pyramid_ms,
            tracking_ms=r.tracking_ms,
            mapping_ms=r.mapping_ms,
            keyframe_idepth=_read_only(snap.idepth),
            keyframe_idepth_var=_read_only(snap.var),
            keyframe_image=_read_only(self._kf.image),
            keyframe_frame_index=int(self._kf.index),
        )

    def _record_pose(self, index: int, timestamp: float, T_wc: np.ndarray, T_fk: np.ndarray | None = None) -> None:
        if self._window is not None:
            self._pose_refs.append((self._kf_id, np.eye(4) if T_fk is None else np.array(T_fk, np.float64)))
        self._indices.append(int(index))
        self._timestamps.append(float(timestamp))
        self._poses.append(T_wc)
        if self.sink is not None:
            self.sink.on_frame(int(index), float(timestamp), T_wc.copy())

    # ------------------------------------------------------------------ end
    def finish(self) -> VOResult:
        """Finalise the last keyframe (fill holes, regularise), emit it, close the sink; return :meth:`result`.

        Idempotent; :meth:`process` may not be called afterwards.
        """
        if not self._finished:
            self._finished = True
            try:
                try:
                    self._join_mapping()
                finally:
                    if self._pool is not None:
                        self._pool.shutdown(wait=True)
                        self._pool = None
                if self._dm is not None and self._kf is not None:
                    prev = numba.get_num_threads()
                    if self.threads is not None:
                        numba.set_num_threads(self.threads)
                    try:
                        self._dm.finalize()
                    finally:
                        numba.set_num_threads(prev)
                    self._window_flush()
                    self._emit_keyframe(self._kf_id, self._kf, self._dm)
            finally:
                if self.sink is not None:
                    self.sink.close()  # also when emitting the last keyframe failed: flush what is finished
        return self.result()

    def result(self) -> VOResult:
        """Summary of everything processed so far (no side effects)."""
        n = max(self._n_frames, 1)
        timings = {k: v / n for k, v in self._t_sum.items()}
        timings["total"] = sum(timings.values())
        if self._window is not None and self._pose_refs:
            poses = self._refined_poses()
        else:
            poses = np.array(self._poses, dtype=np.float64).reshape(-1, 4, 4)
        return VOResult(
            indices=np.array(self._indices, dtype=np.int64),
            timestamps=np.array(self._timestamps, dtype=np.float64),
            poses=poses,
            keyframes=list(self._keyframes),
            lost=list(self._lost),
            lost_at=self._lost[0][0] if self._lost else None,
            total_frames=self._n_frames,
            tracked_frames=len(self._indices),
            timings_ms=timings,
            before_start=self._before_start,
            relocalisations=list(self._relocalisations),
            segments=list(self._segments),
            window=None if self._window is None else self._window.summary(),
        )

    def __repr__(self) -> str:
        return (
            f"VisualOdometry(frames={self._n_frames}, tracked={len(self._indices)}, "
            f"keyframes={self.n_keyframes}, lost={len(self._lost)})"
        )
