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

The package: this module is the facade; :mod:`~dmtrack.pipeline.run` holds the run loop
(:class:`~dmtrack.pipeline.run.SequenceRun`, which owns the sequence, the odometries, their sinks and the start) and
:func:`warm_up`; :mod:`~dmtrack.pipeline.result` :class:`RunResult` and :func:`metrics_dict`;
:mod:`~dmtrack.pipeline.signals` the guard that stops a run between frames.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from dmtrack.datasets.base import Sequence
from dmtrack.datasets.selection import select_frames
from dmtrack.datasets.stream import live_source
from dmtrack.errors import InputError, OutputError
from dmtrack.io.atomic import prepare_folder, write_text
from dmtrack.io.trajectory import write_tum
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.sink import OutputSink
from dmtrack.outputs.memory import MultiSink
from dmtrack.pipeline.result import DEFAULT_R_L, R_L_BY_FORMAT, RunResult, metrics_dict
from dmtrack.pipeline.run import SequenceRun, for_feature, warm_up

__all__ = [
    "DEFAULT_R_L", "R_L_BY_FORMAT", "RunResult", "SequenceRun", "metrics_dict", "run_to_directory", "track",
    "track_many", "warm_up",
]
_for_feature = for_feature  # the name benchmarks and tools import

#: Written at the end of a SLAM run (stale ones are removed first), and its odometry files (removed before a VO run).
SLAM_FILES = ("trajectory.txt", "keyframes.txt", "pointcloud.ply", "graph.json")
VO_FILES = ("trajectory_vo.txt", "keyframes_vo.txt", "pointcloud_vo.ply", "graph.json")
#: First line of a run folder's ``groundtruth.txt``.
GROUNDTRUTH_HEADER = "ground truth of the run's frames (camera-to-world, TUM format, the dataset's units)"


def _open(sequence: str | Path | Sequence, format: str | None, intrinsics: str | Path | None) -> Sequence:
    if isinstance(sequence, (str, Path)):
        from dmtrack.datasets import open_sequence

        return open_sequence(sequence, format=format, intrinsics=intrinsics)
    return sequence


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
    slam: Any = None,
    device: str | None = None,
    frames: str | None = None,
) -> RunResult:
    """Track ``sequence`` with ``feature``.

    Parameters
    ----------
    sequence
        A path (any format :func:`dmtrack.datasets.open_sequence` reads, a live source ``camera:N`` /
        ``rtsp://…`` included) or a Sequence.
    feature
        A registry name (``dmtrack features``) or a Feature object.
    config
        Odometry parameters (LSD-SLAM defaults when None).
    start
        First frame to process: frames ``start … start + max_frames − 1`` are processed.
    max_frames
        How many frames to process (None: to the end; of a live source: the frames it delivers, until it ends).
    seed
        Seed of the random depth initialisation (overrides ``config.seed``).
    init
        How the first keyframe's map is made, ``"random"``, ``"geometric"`` or ``"groundtruth"`` (overrides
        ``config.init``; see :class:`~dmtrack.odometry.config.VOConfig` and docs/initialization.md).
    sink
        Receives poses / keyframes / losses as they happen (e.g. :class:`RunDirectorySink`).
    intrinsics
        ``"fx,fy,cx,cy"`` or a calibration file (see :func:`dmtrack.datasets.open_sequence`).
    r_l
        RPE length ratio for the metrics (default: 1/20 for KITTI, 1/3 otherwise).
    progress
        Show a progress bar (None: only on a terminal).
    realtime
        Track at the speed frames come: a grabber thread reads them (a live source as fast as it
        delivers, a recorded sequence played at its timestamps against the wall clock) and the odometry always
        takes the newest one; frames it had no time for are dropped and counted (``dropped_frames``).  Which
        frames are dropped depends on the machine and its load, so realtime runs are **not** deterministic
        (without it, results are byte-identical run to run).
    warmup
        First compile or load the kernels (:func:`warm_up`; ``compile_s``), so that ``fps`` measures
        tracking only; results are the same either way.
    slam
        True or a :class:`~dmtrack.slam.backend.SlamConfig`: the keyframes also enter a keyframe graph with loop
        closures, optimised by gtsam (``pip install 'dmtrack[slam]'``); the result's trajectory is then the
        optimised one (docs/slam.md).
    device
        Where a network feature given by name runs: ``"auto"`` (a CUDA GPU when PyTorch sees one, else the
        CPU), ``"cpu"``, ``"cuda"`` or ``"cuda:N"`` (:mod:`dmtrack.features.device`); None: the feature's
        default (``"auto"``). The hand-crafted features always run on the CPU.
    frames
        Run on these frames of the sequence only, e.g. ``"0-349,500-699"`` (inclusive ranges, ``A:B`` half-open
        ones, single frames; increasing): they become frames 0, 1, … of the run (``start`` and ``max_frames`` then
        count in them). Leaving frames out makes a camera that jumps: a kidnapped camera.

    Raises
    ------
    InputError
        Bad sequence, missing intrinsics, bad arguments.
    """
    result = _track(
        sequence, feature, config, start=start, max_frames=max_frames, seed=seed, init=init, sink=sink,
        format=format, intrinsics=intrinsics, r_l=r_l, progress=progress, realtime=realtime, warmup=warmup,
        slam=slam, device=device, frames=frames,
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
    device: str | None = None,
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
        intrinsics=intrinsics, r_l=r_l, progress=progress, realtime=realtime, warmup=warmup, device=device,
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
    slam: Any = None,
    device: str | None = None,
    frames: str | None = None,
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
        seq = select_frames(seq, frames)
        run = SequenceRun(seq, feature, configs, sinks, start=start, max_frames=max_frames, realtime=realtime,
                          slam=slam, device=device)
        return run.run(warmup=warmup, progress=progress, r_l=r_l)
    finally:
        live = live_source(seq)
        if live is not None:
            live.close()  # the device is free again, however the run ended


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

    if kwargs.get("slam"):
        from dmtrack.slam.pose_graph import gtsam_module

        gtsam_module()  # without gtsam: one line naming the extra, before any file is written
    out = prepare_folder(out_dir)  # before any frame: an --out that is a file fails here, in one line
    (out / "metrics.json").unlink(missing_ok=True)  # a stale metrics.json must not describe this run
    config = _with_start(config or VOConfig(), kwargs.pop("seed", None), kwargs.pop("init", None))
    write_text(out / "config.yaml", yaml.safe_dump(_plain(config.to_dict()), sort_keys=False))
    (out / "groundtruth.txt").unlink(missing_ok=True)  # a stale one must not describe this run
    slam = kwargs.get("slam")
    # a SLAM run writes the odometry's files as *_vo and the optimised ones at its end (outputs/slam_files.py)
    for stale in (SLAM_FILES if slam else VO_FILES):
        (out / stale).unlink(missing_ok=True)
    files = RunDirectorySink(out, depth_images=depth_images, pointcloud=pointcloud, suffix="_vo" if slam else "")
    sink: OutputSink = MultiSink(files, *extra_sinks) if extra_sinks else files
    result = _track(sequence, feature, config, sink=sink, realtime=realtime, **kwargs)
    if result.slam is not None:
        from dmtrack.outputs.slam_files import write_slam_outputs

        try:
            write_slam_outputs(out, result)
        except OutputError:
            if result.halted_by is None:
                raise
    if result.slam is None and result.vo is not None and result.vo.window is not None and len(result.trajectory):
        # with a window the frames are placed by their keyframes' final poses: the live file had the poses known then
        try:
            write_tum(out / "trajectory.txt", result.trajectory)
        except OutputError:
            if result.halted_by is None:
                raise
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
