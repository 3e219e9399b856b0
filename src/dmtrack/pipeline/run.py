"""The run loop: one sequence, one feature, one or several odometries in lockstep (:class:`SequenceRun`).

A :class:`SequenceRun` owns what one pass over a sequence needs: the sequence and its crop, the feature, the
odometries and their sinks, the frame source (prefetched, or grabbed in real time), the geometric start and the
signal guard. :func:`dmtrack.pipeline.track` and :func:`~dmtrack.pipeline.track_many` build one and call
:meth:`SequenceRun.run`; a back end that works on the odometry's keyframes (e.g. SLAM) is one more sink of it.

:func:`warm_up` runs the same loop on a tiny in-memory sequence so that numba compiles before a timed run.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
import warnings
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TYPE_CHECKING, Any

import numpy as np

from dmtrack.datasets.base import Sequence
from dmtrack.datasets.prefetch import PrefetchedFrames
from dmtrack.datasets.stream import EndOfStream, RealtimeFrames, live_source
from dmtrack.errors import InputError, OutputError
from dmtrack.geometry.camera import PinholeCamera, crop_image
from dmtrack.initialization.run_start import RunStart
from dmtrack.io.machine import process_age_s, release_free_memory, release_idle_library_pages
from dmtrack.io.trajectory import Trajectory
from dmtrack.odometry.config import CHANNEL_STAT_KEYS, VOConfig
from dmtrack.odometry.sink import OutputSink
from dmtrack.outputs.memory import MultiSink
from dmtrack.pipeline.result import DEFAULT_R_L, R_L_BY_FORMAT, RunResult, metrics_dict
from dmtrack.pipeline.signals import _StopBetweenFrames

if TYPE_CHECKING:
    from dmtrack.odometry.vo import VisualOdometry, VOResult

#: What the frame source yields for frame i: timestamp, cropped image, feature map, io and feature seconds, and
#: the first frame's depth image for ``init="groundtruth"`` (else None).
Prepared = tuple[float, np.ndarray, Any, float, float, "np.ndarray | None"]


def feature_of(feature: Any, device: Any = None) -> Any:
    """A Feature object for a registry name, built on ``device`` when given (or the object itself: ``device`` is
    then an error, the object was built where it runs)."""
    from dmtrack.features import get_feature

    if isinstance(feature, str):
        return get_feature(feature, **({} if device is None else {"device": device}))
    if device is not None:
        raise InputError("device= applies to a feature given by name; build the Feature object with device= instead")
    return feature


def for_feature(config: VOConfig, feat: Any) -> VOConfig:
    """``config`` completed for ``feat``: Gray-A switches on affine brightness; ``energy_channels``,
    ``info_channels`` and ``noise_energy_channels`` left None take the feature's measured values."""
    if getattr(feat, "affine_brightness", False) and not config.tracker.affine:
        config = config.with_overrides("tracker.affine=true")
    for key in CHANNEL_STAT_KEYS:
        if getattr(config, key) is None:
            value = getattr(feat, key, None)
            if value is not None:
                config = dataclasses.replace(config, **{key: float(value)})
    return config


class SequenceRun:
    """One pass of one or several odometries over ``frames start … start + max_frames − 1`` of ``seq``.

    The constructor checks the arguments (a clear :class:`~dmtrack.errors.InputError` before any frame is read);
    :meth:`run` builds the odometries (importing numba and the kernels' modules while the geometric start already
    reads the first frames), drives them and returns one :class:`RunResult` per configuration.
    """

    def __init__(
        self,
        seq: Sequence,
        feature: Any,
        configs: list[VOConfig],
        sinks: list[OutputSink | None],
        *,
        start: int = 0,
        max_frames: int | None = None,
        realtime: bool = False,
        slam: Any = None,
        device: Any = None,
    ) -> None:
        if seq.camera is None:
            raise InputError(
                f"sequence {seq.name!r} has no intrinsics: pass intrinsics='fx,fy,cx,cy' (--intrinsics) or add "
                "camera.txt"
            )
        self.seq, self.start, self.realtime = seq, int(start), bool(realtime)
        self.live = live_source(seq) is not None
        self.stop = self._stop(max_frames)
        self.feature = feat = feature_of(feature, device)
        self.configs = configs = [for_feature(c, feat) for c in configs]
        self.n_levels = configs[0].pyramid_levels
        if any(c.pyramid_levels != self.n_levels for c in configs):
            raise InputError("track_many: every configuration must use the same pyramid_levels")
        self.camera: PinholeCamera
        self.camera, self.box = seq.camera.crop_to_multiple(16)
        self.init_depth = any(c.init == "groundtruth" for c in configs)
        if self.init_depth:
            if not getattr(seq, "has_depth", False):
                raise InputError(f"init='groundtruth' needs depth images, and sequence {seq.name!r} has none")
            if getattr(seq, "details", {}).get("depth_registered_to_colour") is False:
                raise InputError(
                    f"init='groundtruth': the depth images of {seq.name!r} are not registered to the colour camera"
                )
        if self.live:  # a live run goes on after a loss (and finds the camera again), as LSD-SLAM does
            self.configs = configs = [c if not c.stop_on_loss else dataclasses.replace(c, stop_on_loss=False)
                                      for c in configs]  # fmt: skip
        # every check above comes before the back ends' threads start
        self.slams = ([_slam_backend(feat, c, slam, s) for c, s in zip(configs, sinks, strict=True)] if slam
                      else [None] * len(configs))
        # a run that goes on after a loss keeps its keyframes to find the camera again on them
        self.recoveries = [None if c.stop_on_loss else _recovery(feat, c, self.camera, new_maps=not slam)
                           for c in configs]  # fmt: skip
        # the back end first: it closes (its final optimisation, told to a viewer) before the run's sinks close
        sinks = [_sinks(r and r.store, b, s) for s, b, r in zip(sinks, self.slams, self.recoveries, strict=True)]
        # the odometries are built by run(), beside the start: their modules (numba's kernels) are imported then
        self._odometries = [(c, s, _window(c, self.camera)) for c, s in zip(configs, sinks, strict=True)]
        self.vos: list[VisualOdometry] = []
        self._abandon_start = False  # the run failed before its start finished: the start stops reading
        self.recompute = getattr(feat, "pyramid", "downsample") == "recompute"
        self._first = True  # the first frame prepared is the first the odometry gets (its depth initialises it)
        self._read_frame = getattr(seq, "read_frame", None)
        self.kept: dict[int, Any] = {}  # frames read for the geometric start, given to the odometry next
        self.t_io = self.t_feat = self.compile_s = 0.0
        self.t_start = 0.0  # perf_counter() when the run's clock (wall_s, fps) starts: after the warm-up
        self.startup: dict[str, float | None] = {}  # metrics.json's "startup" (run(), _begin(), _loop())
        self.releases_memory = True  # give freed memory and LLVM's idle pages back (not the warm-up's own run: 26 ms)

    def _attach(self) -> None:
        for vo, r in zip(self.vos, self.recoveries, strict=True):
            if r is not None:
                r.attach(vo)

    def _stop(self, max_frames: int | None) -> int | None:
        """One past the last frame to read (None: a live source, until it ends)."""
        if max_frames is not None and max_frames < 1:
            raise InputError(f"max_frames must be ≥ 1, got {max_frames}")
        if self.live:  # no length: read until the source ends, or max_frames
            if self.start < 0:
                raise InputError(f"start frame {self.start} must be ≥ 0")
            return None if max_frames is None else self.start + max_frames
        n = len(self.seq)
        if not 0 <= self.start < n:
            raise InputError(f"start frame {self.start} is outside the sequence (0..{n - 1})")
        return n if max_frames is None else min(n, self.start + max_frames)

    # -- frames ----------------------------------------------------------------------------------------------------

    def _prepare(self, frame: Any, t0: float) -> Prepared:
        # crop + feature of a frame whose reading started at perf_counter() == t0 (the io time runs to the end of
        # the crop); cv2 and the numba kernels release the GIL
        image = crop_image(frame.image, self.box)
        t1 = time.perf_counter()
        fmap = self.feature.compute_pyramid(image, self.n_levels) if self.recompute else self.feature.compute(image)
        t2 = time.perf_counter()
        depth = None
        if self.init_depth and self._first:
            if frame.depth is None:
                raise InputError(f"init='groundtruth': frame {frame.index} of {self.seq.name!r} has no depth image")
            depth = crop_image(frame.depth, self.box)
        self._first = False
        return frame.timestamp, image, fmap, t1 - t0, t2 - t1, depth

    def _read(self, i: int) -> Any:
        # the ground-truth depth is decoded only for init='groundtruth' (of the first frame, or any frame grabbed)
        if i in self.kept:
            item = self.kept.pop(i)
            return item.result() if isinstance(item, Future) else item
        if self._read_frame is None:
            return self.seq[i]
        return self._read_frame(i, depth=self.init_depth and (self.realtime or i == self.start))

    def _load(self, i: int) -> Prepared:
        # read + decode + crop + feature of frame i (on the prefetch thread, overlapping the odometry of the
        # previous frame)
        t0 = time.perf_counter()
        return self._prepare(self._read(i), t0)

    def _prepare_grabbed(self, frame: Any, read_s: float) -> Prepared:
        return self._prepare(frame, time.perf_counter() - read_s)  # read in read_s seconds by the grabber thread

    def _frames(self, stops: _StopBetweenFrames) -> PrefetchedFrames | RealtimeFrames:
        if self.realtime:
            return RealtimeFrames(
                self.seq, self._read, self.start, self.stop, self.live, self._prepare_grabbed,
                lambda: stops.pending is not None, lambda: self.kept.pop(self.start, None),
            )
        return PrefetchedFrames(self._load, self.start, self.stop)

    # -- the run ---------------------------------------------------------------------------------------------------

    def run(self, *, warmup: bool = True, progress: bool | None = False, r_l: float | None = None) -> list[RunResult]:
        """Track every frame; each odometry's sink is closed (finished results on disk) however the run ends.

        An interrupt (between frames) or an output error does not raise here: it is each result's ``halted_by``.
        """
        bar = None
        results: list[VOResult] = []
        halted_by: BaseException | None = None
        stops = _StopBetweenFrames().__enter__()
        watch = getattr(live_source(self.seq), "watch_stop", None)
        if callable(watch):  # a live source that waits for frames (the ROS node's) stops waiting on Ctrl-C
            watch(lambda: stops.pending is not None)
        self.startup = {"import_s": IMPORTED_AT, "run_s": process_age_s(), "odometry_import_s": None,
                        "warmup_s": None, "start_s": None, "first_frame_s": None}
        frames = self._frames(stops)
        run_start = RunStart(self.camera, self.configs, parallel=_kernel_threads() > 1)
        self.t_start = time.perf_counter()
        try:
            self._begin(run_start, stops, warmup)
            bar = _progress(None if self.stop is None else self.stop - self.start, self.seq.name, self.feature.name,
                            progress)
            self._loop(frames, run_start, stops, bar)
        except (KeyboardInterrupt, OutputError) as e:  # stop here; what is finished is saved, then e is re-raised
            halted_by = e
        finally:
            try:
                frames.close()  # the prefetch or grabber thread has ended when this returns
                for vo in self.vos:
                    try:
                        vo.finish()  # closes the sink: finished results reach disk even on an error
                    except OutputError as e:  # e.g. the point cloud on a full disk: keep the poses, report the file
                        halted_by = halted_by or e
                    results.append(vo.result())
                if bar is not None:
                    bar.close()
            finally:
                stops.__exit__()  # the caller's signal handlers are back, whatever happened above
        halted_by = halted_by or stops.exception()
        return self._results(results, run_start, frames, halted_by, time.perf_counter() - self.t_start, r_l)

    def _begin(self, run_start: RunStart, stops: _StopBetweenFrames, warmup: bool) -> None:
        """The odometries built and the warm-up and, beside them, the geometric start (the run's clock, ``t_start``,
        starts after the warm-up); the odometries that could not start geometrically are replaced by their
        fall-back. An error before the start has finished stops it at its next frame."""
        # the geometric start (OpenCV, numpy: mostly without the GIL) reads the first frames beside the warm-up;
        # what it takes beyond the warm-up counts in wall_s
        with ThreadPoolExecutor(1, thread_name_prefix="dmtrack-start") as pool:
            starting = pool.submit(self._start, run_start, stops)
            try:
                t0 = time.perf_counter()
                self._build_odometries()  # imports numba and the kernels while the start reads and tracks (0.15 s)
                self.startup["odometry_import_s"] = time.perf_counter() - t0
                if self.releases_memory:
                    release_idle_library_pages()  # LLVM's pages that numba's import touched; the warm-up reads some
                if warmup:
                    self.compile_s = sum(warm_up(self.feature, c) for c in self.configs)
                    if any(s is not None for s in self.slams):
                        self.compile_s += _warm_up_slam()
                    release_idle_library_pages()  # the kernels are loaded; the start may still read some back
            except BaseException:
                self._abandon_start = True
                raise
            finally:
                self.t_start = time.perf_counter()
                starting.result()
        self.startup.update(warmup_s=self.compile_s if warmup else None, start_s=time.perf_counter() - self.t_start)
        for reason in dict.fromkeys(r for r in (run_start.refusal(c) for c in self.configs) if r):  # in metrics
            warnings.warn(f"geometric start refused, starting from a random map: {reason}", stacklevel=6)
        from dmtrack.odometry.vo import VisualOdometry

        self.vos = [vo if c is vo.config else VisualOdometry(self.camera, c, sink=vo.sink,
                                                             window=_window(c, self.camera))
                    for vo, c in ((vo, run_start.config_for(vo.config)) for vo in self.vos)]  # fmt: skip
        self._attach()

    def _build_odometries(self) -> None:
        from dmtrack.odometry.vo import VisualOdometry

        self.vos = [VisualOdometry(self.camera, c, sink=s, window=w) for c, s, w in self._odometries]
        self._attach()

    def _start(self, run_start: RunStart, stops: _StopBetweenFrames) -> None:
        """Feed the run's first frames to its geometric starts (if any) until each has accepted or refused.

        Frames read from their own image files are read again when the odometry comes to them (the first one and
        those read ahead are kept); other frames — a live source's, a video's or a bag's, rendered ones — are kept
        for the odometry."""
        i = self.start
        if not run_start.collecting:
            return
        # one reader thread decodes the next frames (in order) while this one tracks corners
        with ThreadPoolExecutor(1, thread_name_prefix="dmtrack-start-read") as reader:
            ahead: deque[tuple[int, Any]] = deque()
            nxt = i
            while (run_start.collecting and (self.stop is None or i < self.stop) and stops.pending is None
                   and not self._abandon_start):
                while len(ahead) < 3 and (self.stop is None or nxt < self.stop):
                    ahead.append((nxt, reader.submit(self._read, nxt)))
                    nxt += 1
                try:
                    frame = ahead.popleft()[1].result()
                except EndOfStream:  # a live source ended
                    ahead.clear()  # the reads after it end the same way
                    break
                # a frame of its own image file is read again when the odometry comes to it (tens of frames held
                # were the run's peak of memory); a live source's, a video's (seeking back may land elsewhere) or a
                # rendered one is kept, as is the first
                if self.live or i == self.start or getattr(frame, "path", None) is None:
                    self.kept[i] = frame
                run_start.add(i, frame.timestamp, crop_image(frame.image, self.box))
                i += 1
        # read ahead, not needed by the start: the odometry's next frames (an error reading one is raised when the
        # odometry comes to it, as without read-ahead). Kept only now that the reader has finished them: a read still
        # queued when its future was kept found that future in `kept` and waited on itself (a hang of the run)
        for j, fut in ahead:
            self.kept[j] = fut
        run_start.end(i - self.start)

    def _loop(self, frames: Any, run_start: RunStart, stops: _StopBetweenFrames, bar: Any) -> None:
        maps = [run_start.initial_map(c) for c in self.configs]
        # a signal during the warm-up stops the run before its first frame
        for i, (timestamp, image, fmap, dt_io, dt_feat, depth) in frames if stops.pending is None else ():
            self.t_io += dt_io
            self.t_feat += dt_feat
            for vo, m, recovery in zip(self.vos, maps, self.recoveries, strict=True):
                if vo.stopped:
                    continue
                if m is not None and vo.keyframe_id < 0 and i < m.frame_index:
                    vo.skip(i, timestamp, f"before the start: the geometric start began at frame {m.frame_index}")
                elif vo.lost and recovery is not None:
                    recovery.frame(vo, i, timestamp, image, fmap)
                else:
                    vo.process(i, timestamp, image, fmap, depth, m if m is not None and i == m.frame_index else None)
            image = fmap = depth = None  # not kept while the next frame is awaited (157 MB for dense SIFT)
            if any(m is not None and i >= m.frame_index for m in maps):  # the odometries have copied their maps
                maps = [None if m is not None and i >= m.frame_index else m for m in maps]
                if all(m is None for m in maps):
                    run_start.release_maps()
            if self.startup.get("first_frame_s") is None:
                self.startup["first_frame_s"] = process_age_s()
                # after the first frame, not before it (12 ms): what the warm-up and the start freed (their frames,
                # maps, threads' heaps), and LLVM's pages the start read back (a kernel loaded later reads back what
                # it needs)
                if self.releases_memory:
                    release_free_memory()
                    release_idle_library_pages()
            if bar is not None:
                bar.update(i + 1 - self.start - bar.n)
                bar.set_postfix_str(f"kf {self.vos[0].n_keyframes}", refresh=False)
            if all(vo.stopped for vo in self.vos) or stops.pending is not None:
                break

    def _results(
        self, results: list[VOResult], run_start: RunStart, frames: Any, halted_by: BaseException | None,
        wall: float, r_l: float | None,
    ) -> list[RunResult]:
        seq = self.seq
        # a live source has as many frames as it delivered; a recorded one, those of the range
        total = frames.delivered if self.live else self.stop - self.start
        # the frames read: in order up to the last processed one, or (realtime) up to the last one grabbed
        span = frames.delivered if self.realtime else max(r.total_frames for r in results)
        if r_l is None:
            r_l = R_L_BY_FORMAT.get(seq.format, DEFAULT_R_L)
        groundtruth = None if self.live else _groundtruth_span(seq, self.start, self.start + span)
        out: list[RunResult] = []
        for config, vo_result, slam in zip(self.configs, results, self.slams, strict=True):
            processed = max(vo_result.total_frames, 1)
            tm = vo_result.timings_ms
            timings = {
                "io": 1e3 * self.t_io / processed,
                "feature": 1e3 * self.t_feat / processed,
                "pyramid": tm.get("pyramid", 0.0),
                "tracking": tm.get("tracking", 0.0),
                "mapping": tm.get("mapping", 0.0),
                "wall_s": wall,
            }
            kfs = Trajectory(
                np.array([k.timestamp for k in vo_result.keyframes], dtype=np.float64),
                np.array([k.T_wc for k in vo_result.keyframes], dtype=np.float64).reshape(-1, 4, 4),
            )
            trajectory = vo_trajectory = Trajectory(vo_result.timestamps, vo_result.poses)
            if slam is not None and slam.error is None:  # the optimised trajectory and keyframes
                if vo_result.window is not None:  # frames placed on their keyframes' final poses, as the graph's are
                    slam.backend.frames = list(zip(vo_result.indices.tolist(), vo_result.timestamps.tolist(),
                                                   vo_result.poses, strict=True))  # fmt: skip
                _, ts, poses = slam.backend.trajectory()
                trajectory = Trajectory(ts, poses)
                kfs = slam.backend.keyframe_trajectory()
            result = RunResult(
                trajectory=trajectory,
                keyframes=kfs,
                frame_indices=vo_result.indices,
                total_frames=total,
                tracked_frames=vo_result.tracked_frames,
                lost_at=vo_result.lost_at,
                lost_reason=vo_result.lost[0][1] if vo_result.lost else None,
                timings_ms=timings,
                vo=vo_result,
                halted_by=halted_by,
                groundtruth=groundtruth,
                # a live source that drops frames itself (the ROS node's queue) counts them too
                dropped_frames=int(frames.dropped) + int(getattr(live_source(seq), "dropped", 0)),
                realtime=self.realtime,
                compile_s=self.compile_s,
                startup=dict(self.startup),
                init=run_start.metrics(config),
                slam=slam,
                vo_trajectory=vo_trajectory if slam is not None else None,
            )
            result.metrics = metrics_dict(result, seq, self.feature, config, self.camera, self.start, r_l)
            out.append(result)
        return out


def _kernel_threads() -> int:
    """numba's thread count for this thread's kernels; before numba is imported, the count it will start with
    (``NUMBA_NUM_THREADS``, else the cores this process may run on). It only decides whether the start's first map
    uses threads, which never changes its values."""
    numba = sys.modules.get("numba")
    if numba is not None:
        return int(numba.get_num_threads())
    env = os.environ.get("NUMBA_NUM_THREADS", "")
    if env.isdigit() and int(env) > 0:
        return int(env)
    affinity = getattr(os, "sched_getaffinity", None)  # Linux
    return len(affinity(0)) if affinity is not None else os.cpu_count() or 1


def _window(config: VOConfig, camera: PinholeCamera) -> Any:
    """The sliding window of ``config.window`` (None when its size is 0)."""
    if not config.window.size:
        return None
    from dmtrack.window import SlidingWindow

    return SlidingWindow(config, camera)


def _recovery(feat: Any, config: VOConfig, camera: PinholeCamera, *, new_maps: bool) -> Any:
    from dmtrack.pipeline.recovery import Recovery  # imported only by runs that go on after a loss

    return Recovery(feat, config, camera, new_maps=new_maps)


def _sinks(*sinks: OutputSink | None) -> OutputSink | None:
    """One sink of the given ones (in order; None are left out)."""
    kept = [s for s in sinks if s is not None]
    return None if not kept else kept[0] if len(kept) == 1 else MultiSink(*kept)


def _warm_up_slam() -> float:
    from dmtrack.slam._sim3_kernel import warm_up_kernel

    t0 = time.perf_counter()
    warm_up_kernel()
    return time.perf_counter() - t0


def _slam_backend(feat: Any, config: VOConfig, slam: Any, sink: OutputSink | None = None) -> Any:
    """A SLAM back end on its own thread (``slam``: True or a :class:`~dmtrack.slam.backend.SlamConfig`); the
    sinks in ``sink`` that are graph listeners (the viewer) are told of its optimisations."""
    from dmtrack.slam.backend import SlamBackend, SlamConfig, ThreadedSlam
    from dmtrack.slam.listener import graph_listeners

    cfg = slam if isinstance(slam, SlamConfig) else SlamConfig()
    return ThreadedSlam(SlamBackend(feat, config, cfg, listeners=graph_listeners(sink)))


def _groundtruth_span(seq: Sequence, start: int, stop: int) -> Trajectory | None:
    """The ground-truth poses timed within the frames ``start … stop − 1`` (± 1 µs), or ``None``."""
    gt = seq.groundtruth
    if gt is None or len(gt) == 0 or stop <= start:
        return None
    times = np.asarray(seq.timestamps[start:stop], dtype=np.float64)
    keep = (gt.timestamps >= times.min() - 1e-6) & (gt.timestamps <= times.max() + 1e-6)
    return gt[np.nonzero(keep)[0]] if keep.any() else None


def _progress(total: int | None, name: str, feature: str, enabled: bool | None):  # noqa: ANN202
    if enabled is False:
        return None
    from tqdm import tqdm

    disable = None if enabled is None else False  # None: tqdm turns itself off when not on a terminal
    if os.environ.get("CI"):
        disable = True
    return tqdm(total=total, desc=f"{name} [{feature}]", unit="frame", disable=disable, dynamic_ncols=True)


class _WarmupSequence:
    """Ten small RGB frames of two textured planes, the near one in front of the far one, seen by a camera moving
    sideways (the near plane moves faster: parallax), for :func:`warm_up`. 256×192 gives the threaded tracker
    enough points and the motion a second keyframe, so that a run calls no kernel the warm-up did not."""

    name = "warm-up"
    format = "warm-up"

    def __init__(self, n_frames: int = 10, width: int = 256, height: int = 192, near: int = 5, far: int = 2) -> None:
        import cv2

        from dmtrack.datasets.base import Frame

        rng = np.random.default_rng(0)

        def texture(h: int) -> np.ndarray:
            noise = rng.uniform(0, 255, (h, width + near * n_frames, 3)).astype(np.float32)
            return cv2.normalize(cv2.GaussianBlur(noise, (0, 0), 1.5), None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)

        back, front = texture(height), texture(height // 2)
        top, left = height // 4, width // 4
        self._frames = []
        for k in range(n_frames):
            image = back[:, far * k : far * k + width].copy()
            image[top : top + height // 2, left : width - left] = front[:, near * k + left : near * k + width - left]
            self._frames.append(Frame(k, k / 30.0, image))
        self.camera = PinholeCamera(0.8 * width, 0.8 * width, (width - 1) / 2, (height - 1) / 2, width, height)
        self.width, self.height = width, height
        self.timestamps = np.arange(n_frames, dtype=np.float64) / 30.0
        self.groundtruth = None
        self.has_groundtruth = False

    def __len__(self) -> int:
        return len(self._frames)

    def __getitem__(self, index: int) -> Any:
        return self._frames[index]


_WARMED: set[tuple[str, VOConfig, int]] = set()


def warm_up(feature: Any, config: VOConfig | None = None, *, strict: bool = False) -> float:
    """Run the odometry on a tiny in-memory sequence with ``feature`` (a name or a Feature) and ``config`` so that
    numba's kernels are compiled, or loaded from numba's cache, *before* a timed run; return the seconds spent.

    Once per process for a feature, a configuration (seed and init aside) and a thread count: 0 after that.
    Failures are ignored (the real run reports them) unless ``strict``; an interrupt is raised. A Feature object is
    used as it is (its options, its loaded weights): features keep no state from one image to the next.
    """
    import numba

    t0 = time.perf_counter()
    key = None
    try:
        feat = feature_of(feature)
        config = dataclasses.replace(for_feature(config or VOConfig(), feat), seed=0, init="random")
        key = (feat.name, config, numba.get_num_threads())
        if key in _WARMED:
            return 0.0
        run = SequenceRun(_WarmupSequence(), feat, [config], [None])
        run.releases_memory = False  # the run it warms up does that, after it
        result = run.run(warmup=False, progress=False)[0]
        if result.halted_by is not None:
            raise result.halted_by
        from dmtrack.odometry._cloud import warm_up as warm_up_points

        warm_up_points()  # a keyframe's points, which the run folder's point cloud and the viewers read
    except Exception:  # the real run raises the same error
        if strict:
            raise
    if key is not None:
        _WARMED.add(key)  # also after a failure: not tried again
    return time.perf_counter() - t0


#: Seconds from the process's start to the end of this module's import (with the odometry's and the readers'
#: modules): ``metrics.json``'s ``startup.import_s``.
IMPORTED_AT = process_age_s()
