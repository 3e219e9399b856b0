"""One sequence → one run: the odometry loop driven over a sequence, its metrics, and the run folder.

This is the layer under :mod:`dmtrack.experiments` (which runs many of these) and :mod:`dmtrack.api` (the public
facade that re-exports :func:`track`, :func:`track_many`, :func:`run_to_directory` and :class:`RunResult`).

:func:`track` runs the odometry and returns a :class:`RunResult`; :func:`run_to_directory` also writes the
files of ``dmtrack run`` (``trajectory.txt``, ``keyframes.txt``, ``pointcloud.ply``, ``depth/``,
``metrics.json``).

Live sources (``camera:N``, ``rtsp://…``; :mod:`dmtrack.datasets.stream`) have no length: their frames are read
until the source ends, ``max_frames`` is reached or the run is stopped. ``realtime=True`` runs the odometry on the
newest frame a grabber thread has (a live source as fast as it delivers, a recorded sequence played at its
timestamps) and drops the frames it had no time for.

Compilation is not counted in a run's speed: before its first frame, a run calls :func:`warm_up`, which runs the
odometry with the run's feature and configuration on a tiny in-memory sequence so that numba compiles its kernels
(or loads them from its cache) there; ``compile_s`` in the metrics is that time, ``fps`` and ``wall_s`` start after
it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack import __version__
from dmtrack.datasets.base import Sequence
from dmtrack.datasets.prefetch import PrefetchedFrames
from dmtrack.datasets.stream import EndOfStream, RealtimeFrames, live_source
from dmtrack.errors import DmtrackError, InputError, Interrupted, OutputError
from dmtrack.geometry.camera import PinholeCamera, crop_image
from dmtrack.initialization.run_start import RunStart
from dmtrack.io.atomic import prepare_folder, write_text
from dmtrack.io.trajectory import Trajectory, write_tum
from dmtrack.odometry._fastmath import kernel_target
from dmtrack.odometry.config import CHANNEL_STAT_KEYS, VOConfig
from dmtrack.odometry.sink import OutputSink
from dmtrack.odometry.vo import VisualOdometry, VOResult
from dmtrack.outputs.memory import MultiSink

#: Default r_l (longest RPE length / path length) per dataset format (paper §3.1).
R_L_BY_FORMAT = {"kitti": 1.0 / 20.0, "tsukuba": 1.0 / 20.0}
DEFAULT_R_L = 1.0 / 3.0
#: First line of a run folder's ``groundtruth.txt``.
GROUNDTRUTH_HEADER = "ground truth of the run's frames (camera-to-world, TUM format, the dataset's units)"


class _StopBetweenFrames:
    """While tracking: Ctrl-C (SIGINT) and SIGTERM stop the run *between* frames, never in the middle of one.

    Only signals whose current handler raises (Python's Ctrl-C handler; the CLI's SIGTERM handler) are wrapped;
    default and ignored dispositions are left alone. The first signal is remembered and the loop stops after the
    frame in progress; :meth:`exception` is then what the original handler raises (KeyboardInterrupt,
    :class:`~dmtrack.errors.Interrupted`). A second signal acts at once through the original handler.
    """

    def __enter__(self) -> _StopBetweenFrames:
        import signal
        import threading

        self.pending: int | None = None
        self._old: dict[int, Any] = {}
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, getattr(signal, "SIGTERM", None)):
                if sig is not None and callable(old := signal.getsignal(sig)):
                    self._old[sig] = old
                    signal.signal(sig, self._handler)
        return self

    def _handler(self, signum: int, frame: Any) -> None:
        if self.pending is not None:
            self._old[signum](signum, frame)
        self.pending = signum

    def exception(self) -> BaseException | None:
        if self.pending is None:
            return None
        try:
            self._old[self.pending](self.pending, None)
        except BaseException as e:  # noqa: BLE001 - this is the exception the handler wants raised
            return e
        return None

    def __exit__(self, *exc: object) -> None:
        import signal

        for sig, old in self._old.items():
            signal.signal(sig, old)


@dataclass
class RunResult:
    """Everything a run produced.

    Attributes
    ----------
    trajectory : tracked frames' T_wc with the dataset's timestamps.
    keyframes : keyframes' T_wc.
    frame_indices : dataset frame index of each trajectory pose.
    total_frames, tracked_frames : frames given to the odometry, frames with a pose.
    lost_at, lost_reason : first frame (dataset index) where tracking was lost, and why; ``None`` if never.
    timings_ms : mean per frame: ``io`` (reading/decoding), ``feature`` (feature extraction) — both measured on
        the prefetch thread, where they overlap with the odometry of earlier frames — ``pyramid``,
        ``tracking``, ``mapping``; and ``wall_s`` (whole loop).
    metrics : the ``metrics.json`` contents (see :func:`metrics_dict`).
    vo : the odometry's own summary.
    groundtruth : the sequence's ground truth over the frames given to the odometry (``None`` without one);
        written as ``groundtruth.txt`` by :func:`run_to_directory`.
    halted_by : why the run stopped before its last frame other than a tracking loss — an interrupt
        (:class:`KeyboardInterrupt`, :class:`~dmtrack.errors.Interrupted` for SIGTERM) or an output that could
        not be written (:class:`~dmtrack.errors.OutputError`); ``None`` for a run that went to its end.
        :func:`track` and :func:`run_to_directory` re-raise it once the finished frames are saved.
    dropped_frames : frames of a ``realtime`` run that the odometry skipped because a newer one had come.
    realtime : whether the run was a ``realtime`` one.
    compile_s : seconds :func:`warm_up` took before the first frame (numba compiling or loading the kernels;
        0 when this process had warmed up the feature and configuration already, or without warm-up).
    init : how the first map was made: ``metrics.json``'s ``init*`` keys
        (:meth:`~dmtrack.initialization.run_start.RunStart.metrics`).
    """

    trajectory: Trajectory
    keyframes: Trajectory
    frame_indices: np.ndarray
    total_frames: int
    tracked_frames: int
    lost_at: int | None
    lost_reason: str | None
    timings_ms: dict[str, float]
    metrics: dict[str, Any] = field(default_factory=dict)
    vo: VOResult | None = None
    groundtruth: Trajectory | None = None
    halted_by: BaseException | None = None
    dropped_frames: int = 0
    realtime: bool = False
    compile_s: float = 0.0
    init: dict[str, Any] = field(default_factory=dict)


def _open(sequence: str | Path | Sequence, format: str | None, intrinsics: str | Path | None) -> Sequence:
    if isinstance(sequence, (str, Path)):
        from dmtrack.datasets import open_sequence

        return open_sequence(sequence, format=format, intrinsics=intrinsics)
    return sequence


def _feature(feature: Any) -> Any:
    from dmtrack.features import get_feature

    return get_feature(feature) if isinstance(feature, str) else feature


def track(
    sequence: str | Path | Sequence,
    feature: Any = "gray",
    config: VOConfig | None = None,
    *,
    start: int = 0,
    max_frames: int | None = None,
    seed: int | None = None,
    init: str | None = None,
    sink: OutputSink | None = None,
    format: str | None = None,
    intrinsics: str | Path | None = None,
    r_l: float | None = None,
    progress: bool | None = False,
    realtime: bool = False,
    warmup: bool = True,
) -> RunResult:
    """Track ``sequence`` with ``feature``.

    Parameters
    ----------
    sequence : a path (any format :func:`dmtrack.datasets.open_sequence` reads, a live source ``camera:N`` /
        ``rtsp://…`` included) or a Sequence.
    feature : a registry name (``dmtrack features``) or a Feature object.
    config : odometry parameters (LSD-SLAM defaults when None).
    start, max_frames : process frames ``start … start + max_frames − 1`` (of a live source: the frames it
        delivers, until it ends when ``max_frames`` is None).
    seed : seed of the random depth initialisation (overrides ``config.seed``).
    init : how the first keyframe's map is made, ``"random"``, ``"geometric"`` or ``"groundtruth"`` (overrides
        ``config.init``; see :class:`~dmtrack.odometry.config.VOConfig` and docs/initialization.md).
    sink : receives poses / keyframes / losses as they happen (e.g. :class:`RunDirectorySink`).
    intrinsics : ``"fx,fy,cx,cy"`` or a calibration file (see :func:`dmtrack.datasets.open_sequence`).
    r_l : RPE length ratio for the metrics (default: 1/20 for KITTI, 1/3 otherwise).
    progress : show a progress bar (None: only on a terminal).
    realtime : track at the speed frames come: a grabber thread reads them (a live source as fast as it
        delivers, a recorded sequence played at its timestamps against the wall clock) and the odometry always
        takes the newest one; frames it had no time for are dropped and counted (``dropped_frames``).  Which
        frames are dropped depends on the machine and its load, so realtime runs are **not** deterministic
        (without it, results are byte-identical run to run).
    warmup : first compile or load the kernels (:func:`warm_up`; ``compile_s``), so that ``fps`` measures
        tracking only; results are the same either way.

    Raises
    ------
    InputError
        Bad sequence, missing intrinsics, bad arguments.
    """
    result = _track(
        sequence, feature, config, start=start, max_frames=max_frames, seed=seed, init=init, sink=sink,
        format=format, intrinsics=intrinsics, r_l=r_l, progress=progress, realtime=realtime, warmup=warmup,
    )
    _raise_halt([result])
    return result


def _track(
    sequence: str | Path | Sequence,
    feature: Any = "gray",
    config: VOConfig | None = None,
    *,
    seed: int | None = None,
    init: str | None = None,
    sink: OutputSink | None = None,
    **kwargs: Any,
) -> RunResult:
    """:func:`track` without re-raising ``halted_by`` (the caller saves what was finished first)."""
    config = _with_start(config or VOConfig(), seed, init)
    return _track_many(sequence, feature, [config], sinks=[sink], **kwargs)[0]


def _with_start(config: VOConfig, seed: int | None, init: str | None) -> VOConfig:
    """``config`` with ``seed`` and ``init`` where they are given."""
    if seed is not None:
        config = config.with_overrides(f"seed={int(seed)}")
    if init is not None:
        config = config.with_overrides(f"init={init}")
    return config


def _raise_halt(results: list[RunResult]) -> None:
    for r in results:
        if r.halted_by is not None:
            raise r.halted_by


def track_many(
    sequence: str | Path | Sequence,
    feature: Any,
    configs: list[VOConfig],
    *,
    start: int = 0,
    max_frames: int | None = None,
    sinks: list[OutputSink | None] | None = None,
    format: str | None = None,
    intrinsics: str | Path | None = None,
    r_l: float | None = None,
    progress: bool | None = False,
    realtime: bool = False,
    warmup: bool = True,
) -> list[RunResult]:
    """Track ``sequence`` with one feature and several odometry configurations in lockstep.

    Every frame is read and its feature computed once, then given to one :class:`VisualOdometry` per
    configuration (e.g. seeds 0, 1, 2, or channel rules), in order. Each result is identical to that of
    :func:`track` with the same configuration (the odometries share no state); reading and feature times are
    shared and reported in full by each result. Frames are read until every odometry has stopped.

    ``configs`` give the seeds (``config.seed``); ``energy_channels`` and ``info_channels`` left ``None`` are
    filled in with the feature's measured values. ``sinks`` (optional) pairs one sink with each configuration.
    The other arguments are those of :func:`track`.

    An interrupt (Ctrl-C, SIGTERM) or an output error stops every odometry; their sinks are closed (finished
    frames reach disk) and the interrupt or error is raised.
    """
    results = _track_many(
        sequence, feature, configs, start=start, max_frames=max_frames, sinks=sinks, format=format,
        intrinsics=intrinsics, r_l=r_l, progress=progress, realtime=realtime, warmup=warmup,
    )
    _raise_halt(results)
    return results


def _track_many(
    sequence: str | Path | Sequence,
    feature: Any,
    configs: list[VOConfig],
    *,
    start: int = 0,
    max_frames: int | None = None,
    sinks: list[OutputSink | None] | None = None,
    format: str | None = None,
    intrinsics: str | Path | None = None,
    r_l: float | None = None,
    progress: bool | None = False,
    realtime: bool = False,
    warmup: bool = True,
) -> list[RunResult]:
    """:func:`track_many` without re-raising ``halted_by``; a live source is closed when the run ends."""
    if not configs:
        raise InputError("track_many needs at least one configuration")
    if sinks is None:
        sinks = [None] * len(configs)
    if len(sinks) != len(configs):
        raise InputError(f"{len(sinks)} sinks for {len(configs)} configurations")
    seq = _open(sequence, format, intrinsics)
    try:
        return _track_sequence(seq, feature, configs, start, max_frames, sinks, r_l, progress, realtime, warmup)
    finally:
        live = live_source(seq)
        if live is not None:
            live.close()  # the device is free again, however the run ended


def _track_sequence(
    seq: Sequence,
    feature: Any,
    configs: list[VOConfig],
    start: int,
    max_frames: int | None,
    sinks: list[OutputSink | None],
    r_l: float | None,
    progress: bool | None,
    realtime: bool,
    warmup: bool,
) -> list[RunResult]:
    if seq.camera is None:
        raise InputError(
            f"sequence {seq.name!r} has no intrinsics: pass intrinsics='fx,fy,cx,cy' (--intrinsics) or add camera.txt"
        )
    live = live_source(seq) is not None
    if max_frames is not None and max_frames < 1:
        raise InputError(f"max_frames must be ≥ 1, got {max_frames}")
    stop: int | None
    if live:  # no length: read until the source ends, or max_frames
        if start < 0:
            raise InputError(f"start frame {start} must be ≥ 0")
        stop = None if max_frames is None else start + max_frames
    else:
        n = len(seq)
        if not 0 <= start < n:
            raise InputError(f"start frame {start} is outside the sequence (0..{n - 1})")
        stop = n if max_frames is None else min(n, start + max_frames)
    feat = _feature(feature)
    configs = [_for_feature(c, feat) for c in configs]
    n_levels = configs[0].pyramid_levels
    if any(c.pyramid_levels != n_levels for c in configs):
        raise InputError("track_many: every configuration must use the same pyramid_levels")

    camera, box = seq.camera.crop_to_multiple(16)
    vos = [VisualOdometry(camera, c, sink=s) for c, s in zip(configs, sinks, strict=True)]
    recompute = getattr(feat, "pyramid", "downsample") == "recompute"

    init_depth = any(c.init == "groundtruth" for c in configs)
    if init_depth:
        if not getattr(seq, "has_depth", False):
            raise InputError(f"init='groundtruth' needs depth images, and sequence {seq.name!r} has none")
        if getattr(seq, "details", {}).get("depth_registered_to_colour") is False:
            raise InputError(
                f"init='groundtruth': the depth images of {seq.name!r} are not registered to the colour camera"
            )
    first = [True]  # the first frame prepared is the first one the odometry gets (its depth initialises it)

    def prepare(frame: Any, t0: float) -> tuple[float, np.ndarray, Any, float, float, np.ndarray | None]:
        # crop + feature of a frame whose reading started at perf_counter() == t0 (the io time runs to the end of
        # the crop); cv2 and the numba kernels release the GIL
        image = crop_image(frame.image, box)
        t1 = time.perf_counter()
        fmap = feat.compute_pyramid(image, n_levels) if recompute else feat.compute(image)
        t2 = time.perf_counter()
        depth = None
        if init_depth and first[0]:
            if frame.depth is None:
                raise InputError(f"init='groundtruth': frame {frame.index} of {seq.name!r} has no depth image")
            depth = crop_image(frame.depth, box)
        first[0] = False
        return frame.timestamp, image, fmap, t1 - t0, t2 - t1, depth

    read_frame = getattr(seq, "read_frame", None)

    kept: dict[int, Any] = {}  # frames read for the geometric start, given to the odometry next

    def read(i: int) -> Any:
        # the ground-truth depth is decoded only for init='groundtruth' (of the first frame, or any frame grabbed)
        if i in kept:
            return kept.pop(i)
        if read_frame is None:
            return seq[i]
        return read_frame(i, depth=init_depth and (realtime or i == start))

    def load(i: int) -> tuple[float, np.ndarray, Any, float, float, np.ndarray | None]:
        # read + decode + crop + feature of frame i (on the prefetch thread, overlapping the odometry of the
        # previous frame)
        t0 = time.perf_counter()
        frame = read(i)
        return prepare(frame, t0)

    def prepare_grabbed(frame: Any, read_s: float) -> tuple[float, np.ndarray, Any, float, float, np.ndarray | None]:
        return prepare(frame, time.perf_counter() - read_s)  # read in read_s seconds by the grabber thread

    t_io = t_feat = compile_s = 0.0
    bar = None
    results: list[VOResult] = []
    halted_by: BaseException | None = None
    stops = _StopBetweenFrames().__enter__()
    frames: PrefetchedFrames | RealtimeFrames = (
        RealtimeFrames(seq, read, start, stop, live, prepare_grabbed, lambda: stops.pending is not None,
                       lambda: kept.pop(start, None)) if realtime
        else PrefetchedFrames(load, start, stop)
    )
    run_start = RunStart(camera, configs, parallel=vos[0].parallel)
    t_start = time.perf_counter()
    try:
        # the geometric start (OpenCV, numpy: mostly without the GIL) reads the first frames beside the warm-up;
        # what it takes beyond the warm-up counts in wall_s
        with ThreadPoolExecutor(1, thread_name_prefix="dmtrack-start") as pool:
            starting = pool.submit(_start, run_start, read, kept, box, start, stop, stops)
            try:
                if warmup:
                    compile_s = sum(warm_up(feat, c) for c in configs)
            finally:
                t_start = time.perf_counter()
                starting.result()
        for reason in dict.fromkeys(r for r in (run_start.refusal(c) for c in configs) if r):  # metrics.json has it
            warnings.warn(f"geometric start refused, starting from a random map: {reason}", stacklevel=5)
        vos = [vo if c is vo.config else VisualOdometry(camera, c, sink=vo.sink)
               for vo, c in ((vo, run_start.config_for(vo.config)) for vo in vos)]
        maps = [run_start.initial_map(c) for c in configs]
        bar = _progress(None if stop is None else stop - start, seq.name, feat.name, progress)
        # a signal during the warm-up stops the run before its first frame
        for i, (timestamp, image, fmap, dt_io, dt_feat, depth) in frames if stops.pending is None else ():
            t_io += dt_io
            t_feat += dt_feat
            for vo, m in zip(vos, maps, strict=True):
                if not vo.stopped:
                    vo.process(i, timestamp, image, fmap, depth, m if i == start else None)
            image = fmap = depth = None  # not kept while the next frame is awaited (157 MB for dense SIFT)
            if bar is not None:
                bar.update(i + 1 - start - bar.n)
                bar.set_postfix_str(f"kf {vos[0].n_keyframes}", refresh=False)
            if all(vo.stopped for vo in vos):
                break
            if stops.pending is not None:
                break
    except (KeyboardInterrupt, OutputError) as e:  # stop here; what is finished is saved, then e is re-raised
        halted_by = e
    finally:
        try:
            frames.close()  # the prefetch or grabber thread has ended when this returns
            for vo in vos:
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
    wall = time.perf_counter() - t_start
    # a live source has as many frames as it delivered; a recorded one, those of the range
    total = frames.delivered if live else stop - start
    # the frames read: in order up to the last processed one, or (realtime) up to the last one grabbed
    span = frames.delivered if realtime else max(r.total_frames for r in results)

    if r_l is None:
        r_l = R_L_BY_FORMAT.get(seq.format, DEFAULT_R_L)
    groundtruth = None if live else _groundtruth_span(seq, start, start + span)
    out: list[RunResult] = []
    for config, vo_result in zip(configs, results, strict=True):
        processed = max(vo_result.total_frames, 1)
        tm = vo_result.timings_ms
        timings = {
            "io": 1e3 * t_io / processed,
            "feature": 1e3 * t_feat / processed,
            "pyramid": tm.get("pyramid", 0.0),
            "tracking": tm.get("tracking", 0.0),
            "mapping": tm.get("mapping", 0.0),
            "wall_s": wall,
        }
        traj = Trajectory(vo_result.timestamps, vo_result.poses)
        kfs = Trajectory(
            np.array([k.timestamp for k in vo_result.keyframes], dtype=np.float64),
            np.array([k.T_wc for k in vo_result.keyframes], dtype=np.float64).reshape(-1, 4, 4),
        )
        result = RunResult(
            trajectory=traj,
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
            dropped_frames=int(frames.dropped),
            realtime=bool(realtime),
            compile_s=compile_s,
            init=run_start.metrics(config),
        )
        result.metrics = metrics_dict(result, seq, feat, config, camera, start, r_l)
        out.append(result)
    return out


def _start(
    run_start: RunStart, read: Any, kept: dict[int, Any], box: Any, start: int, stop: int | None, stops: Any
) -> None:
    """Feed the run's first frames to its geometric starts (if any) until each has accepted or refused; the frames
    read are kept in ``kept`` for the odometry."""
    i = start
    while run_start.collecting and (stop is None or i < stop) and stops.pending is None:
        try:
            frame = kept[i] = read(i)
        except EndOfStream:  # a live source ended
            break
        run_start.add(i, frame.timestamp, crop_image(frame.image, box))
        i += 1
    run_start.end(i - start)


def _for_feature(config: VOConfig, feat: Any) -> VOConfig:
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
        feat = _feature(feature)
        config = dataclasses.replace(_for_feature(config or VOConfig(), feat), seed=0, init="random")
        key = (feat.name, config, numba.get_num_threads())
        if key in _WARMED:
            return 0.0
        track(_WarmupSequence(), feat, config, progress=False, warmup=False)
    except Exception:  # the real run raises the same error
        if strict:
            raise
    if key is not None:
        _WARMED.add(key)  # also after a failure: not tried again
    return time.perf_counter() - t0


def _progress(total: int | None, name: str, feature: str, enabled: bool | None):  # noqa: ANN202
    if enabled is False:
        return None
    from tqdm import tqdm

    disable = None if enabled is None else False  # None: tqdm turns itself off when not on a terminal
    if os.environ.get("CI"):
        disable = True
    return tqdm(total=total, desc=f"{name} [{feature}]", unit="frame", disable=disable, dynamic_ncols=True)


def _finite(x: float | None) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _interrupt_name(e: BaseException | None) -> str | None:
    if isinstance(e, Interrupted):
        return e.signal_name
    return "SIGINT" if isinstance(e, KeyboardInterrupt) else None


def _groundtruth_span(seq: Sequence, start: int, stop: int) -> Trajectory | None:
    """The ground-truth poses timed within the frames ``start … stop − 1`` (± 1 µs), or ``None``."""
    gt = seq.groundtruth
    if gt is None or len(gt) == 0 or stop <= start:
        return None
    times = np.asarray(seq.timestamps[start:stop], dtype=np.float64)
    keep = (gt.timestamps >= times.min() - 1e-6) & (gt.timestamps <= times.max() + 1e-6)
    return gt[np.nonzero(keep)[0]] if keep.any() else None


def metrics_dict(
    result: RunResult,
    seq: Sequence,
    feature: Any,
    config: VOConfig,
    camera: PinholeCamera,
    start: int,
    r_l: float,
) -> dict[str, Any]:
    """The ``metrics.json`` contents (keys of conventions.md, plus more).

    ``fps`` is frames processed per second of the whole loop (reading, features, tracking, mapping), and
    ``compile_s`` the seconds before it spent compiling or loading the kernels (:func:`warm_up`);
    ``dropped_frames`` counts the frames a ``realtime`` run skipped (0 otherwise);
    ``*_ms`` are means per processed frame; ``feature_ms`` includes building the feature pyramid.
    RPE values are per unit of the ground truth's length (metres for every real dataset here; centimetres for
    New Tsukuba).
    """
    t = result.timings_ms
    processed = result.vo.total_frames if result.vo is not None else result.total_frames
    m: dict[str, Any] = {
        "feature": getattr(feature, "name", str(feature)),
        "sequence": seq.name,
        "format": seq.format,
        "total_frames": int(result.total_frames),
        "tracked_frames": int(result.tracked_frames),
        "lost_at": None if result.lost_at is None else int(result.lost_at),
        "lost_reason": result.lost_reason,
        "processed_frames": int(processed),
        "dropped_frames": int(result.dropped_frames),
        "realtime": bool(result.realtime),
        "interrupted": _interrupt_name(result.halted_by),
        "output_error": str(result.halted_by) if isinstance(result.halted_by, OutputError) else None,
        "fps": _finite(processed / t["wall_s"]) if t["wall_s"] > 0 else None,
        "feature_ms": t["feature"] + t["pyramid"],
        "tracking_ms": t["tracking"],
        "mapping_ms": t["mapping"],
        "io_ms": t["io"],
        "pyramid_ms": t["pyramid"],
        "wall_s": t["wall_s"],
        "compile_s": float(result.compile_s),
        "keyframes": len(result.keyframes),
        "start": int(start),
        "width": camera.width,
        "height": camera.height,
        "channels": int(getattr(feature, "channels", 0)),
        "feature_scale": _finite(getattr(feature, "scale", None)),
        "seed": int(config.seed),
        "channel_cost": config.channel_cost,
        "energy_channels": _finite(config.energy_channels),
        "info_channels": _finite(config.info_channels),
        "noise_energy_channels": _finite(config.noise_energy_channels),
        "r_l": r_l,
        **(result.init or {"init": config.init}),
        "dmtrack_version": __version__,
        **kernel_target(),
    }
    gt = seq.groundtruth
    if gt is not None:
        from dmtrack.evaluation import evaluate

        try:
            ev = evaluate(gt, result.trajectory, max_diff=0.01, r_l=r_l, align="sim3")
            for k in ("ate_rmse", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "matched_poses", "ate_scale"):
                m[k] = ev[k]
        except (DmtrackError, ValueError) as e:
            m.update(ate_rmse=None, rpe_rot_deg_per_m=None, rpe_trans_angle_deg_per_m=None, matched_poses=0)
            m["evaluation_error"] = str(e)
    return m


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def run_to_directory(
    sequence: str | Path | Sequence,
    out_dir: str | Path,
    feature: Any = "gray",
    config: VOConfig | None = None,
    *,
    depth_images: bool = True,
    pointcloud: bool = True,
    extra_sinks: tuple[OutputSink, ...] = (),
    realtime: bool = False,
    **kwargs: Any,
) -> RunResult:
    """:func:`track` writing the run's files into ``out_dir`` (see :mod:`dmtrack.outputs.run_directory`).

    ``realtime=True`` tracks at the speed frames come and drops the frames the odometry had no time for
    (see :func:`track`; such runs are not deterministic).  ``kwargs`` are those of :func:`track`.
    """
    import yaml

    from dmtrack.outputs.run_directory import RunDirectorySink

    out = prepare_folder(out_dir)  # before any frame: an --out that is a file fails here, in one line
    (out / "metrics.json").unlink(missing_ok=True)  # a stale metrics.json must not describe this run
    config = _with_start(config or VOConfig(), kwargs.pop("seed", None), kwargs.pop("init", None))
    write_text(out / "config.yaml", yaml.safe_dump(_plain(config.to_dict()), sort_keys=False))
    (out / "groundtruth.txt").unlink(missing_ok=True)  # a stale one must not describe this run
    files = RunDirectorySink(out, depth_images=depth_images, pointcloud=pointcloud)
    sink: OutputSink = MultiSink(files, *extra_sinks) if extra_sinks else files
    result = _track(sequence, feature, config, sink=sink, realtime=realtime, **kwargs)
    result.metrics["points"] = files.n_points
    # an interrupted run or one whose point cloud could not be written still gets the metrics of its frames
    try:
        write_text(out / "metrics.json", json.dumps(result.metrics, indent=2) + "\n")
        if result.groundtruth is not None:
            write_tum(out / "groundtruth.txt", result.groundtruth, header=GROUNDTRUTH_HEADER)
    except OutputError:
        if result.halted_by is None:
            raise
        # the run already stopped on an output error (a full disk): that first error is the one to report
    _raise_halt([result])
    return result
