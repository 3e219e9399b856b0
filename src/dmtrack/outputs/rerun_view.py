"""``dmtrack view RUN_DIR``: a finished run folder in the Rerun viewer, or in an .rrd file.

Reads the files :class:`~dmtrack.outputs.run_directory.RunDirectorySink` and ``dmtrack run`` write and logs them
with the entity paths of the live :class:`~dmtrack.outputs.rerun_sink.RerunSink` where they mean the same:

================================  =====================================================================================
``world/camera``                  the camera pose of every line of ``trajectory.txt`` (Transform3D and axes)
``world/trajectory/estimate``     the whole estimated path
``world/trajectory/groundtruth``  ``groundtruth.txt``, Sim(3)-aligned to the estimate (with ``align``, when at least
                                  3 poses match in time)
``world/keyframes``               the keyframe positions of ``keyframes.txt``
``world/points``                  ``pointcloud.ply`` (all keyframes, world frame)
``keyframe/depth``                ``depth/kf_*.png``, each at its keyframe's frame
``keyframe/initial_map``          ``depth/initial_map.png``: the first keyframe's map as the start made it
``run/metrics``, ``run/config``   ``metrics.json`` as a table and ``config.yaml``
================================  =====================================================================================

A SLAM run folder (``dmtrack run --slam``: ``graph.json`` and ``trajectory_vo.txt`` in it) is drawn as both
trajectories, the optimised one and the odometry's, and the keyframe graph:

================================  =====================================================================================
``world/trajectory/slam``         ``trajectory.txt``, the optimised path (instead of ``world/trajectory/estimate``;
                                  ``world/camera`` and the ground truth's alignment follow it)
``world/trajectory/odometry``     ``trajectory_vo.txt``, the odometry's own path
``world/keyframes``               the odometry's keyframes (``keyframes_vo.txt``)
``world/slam/keyframes``,         ``graph.json``: the keyframes at their optimised poses, joined in order, and the
``world/slam/trajectory``,        accepted edges as segments, odometry edges grey, loop closures magenta (as the
``world/slam/edges/odometry``,    live viewer draws them)
``world/slam/edges/loop``
================================  =====================================================================================

The path, the keyframes, the points and the documents are static (shown at every time); the camera moves along the
``frame`` timeline. The run folder holds no intrinsics, so the camera is drawn as axes, not as a frustum. Frame
indices come from ``metrics.json`` when the run tracked its frames without a gap (``start`` … ``start + n − 1``);
otherwise ``frame`` counts the poses.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack.errors import InputError
from dmtrack.io.files import read_bytes, read_text_file
from dmtrack.io.ply import read_ply
from dmtrack.io.trajectory import Trajectory, read_tum
from dmtrack.outputs.rerun_sink import (
    SLAM_COLOUR,
    Aligner,
    Recording,
    aligned_groundtruth,
    import_rerun,
    log_graph,
)
from dmtrack.outputs.slam_files import read_graph

_DEPTH_NAME = re.compile(r"kf_(\d+)_frame_(\d+)\.png")
_UNIX_TIME = 1e8


def _metrics(run: Path) -> dict[str, Any]:
    path = run / "metrics.json"
    if not path.is_file():
        return {}
    try:
        data = json.loads(read_text_file(path, "metrics file"))
    except json.JSONDecodeError as e:
        raise InputError(f"not valid JSON: {e.msg} (line {e.lineno})", path) from None
    if not isinstance(data, dict):
        raise InputError("not a JSON object", path)
    return data


def _frame_indices(n: int, metrics: dict[str, Any]) -> tuple[np.ndarray, bool]:
    """Frame index of each pose (and True) when the metrics show the run tracked ``start`` … ``start + n − 1``;
    otherwise 0 … n − 1 (and False)."""
    start, lost_at = metrics.get("start"), metrics.get("lost_at")
    consecutive = (
        isinstance(start, int)
        and metrics.get("tracked_frames") == n
        and not metrics.get("dropped_frames")
        and (lost_at is None or lost_at == start + n)
    )
    return (np.arange(n) + (start if consecutive else 0)), bool(consecutive)


def _markdown_table(metrics: dict[str, Any]) -> str:
    def cell(v: Any) -> str:
        text = f"{v:.6g}" if isinstance(v, float) else json.dumps(v) if isinstance(v, (dict, list)) else str(v)
        return text.replace("|", "\\|").replace("\n", " ")

    rows = [f"| {k} | {cell(v)} |" for k, v in metrics.items()]
    return "\n".join(["| metric | value |", "|---|---|", *rows]) + "\n"


def _read_ply(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    try:
        return read_ply(path)
    except Exception as e:  # noqa: BLE001 - plyfile raises its own error types, ValueError, KeyError, OSError
        raise InputError(f"not a readable PLY point cloud ({type(e).__name__}: {e})", path) from None


def _time_column(rr: Any, times: np.ndarray) -> Any:
    kind = "timestamp" if len(times) and float(times[0]) > _UNIX_TIME else "duration"
    return rr.TimeColumn("time", **{kind: np.asarray(times, dtype=np.float64)})


def log_run_folder(
    run_dir: str | Path,
    *,
    spawn: bool = False,
    rrd: str | Path | None = None,
    align: Aligner | None = None,
    recording_id: str | None = None,
    axis_length: float = 0.1,
) -> dict[str, Any]:
    """Log the run folder ``run_dir`` to a spawned viewer and/or the .rrd file ``rrd`` (see the module docstring).

    Parameters
    ----------
    align : the similarity fit for the ground truth (``dmtrack.evaluation.alignment.umeyama``); without it the
        ground truth is not drawn.
    axis_length : length of the camera axes (world units).

    Returns
    -------
    dict with ``poses``, ``keyframes``, ``points``, ``depth_images`` (counts), ``frames_are_indices``,
    ``groundtruth`` (``"aligned"``, ``"not aligned"`` or ``"none"``) and ``slam``: ``None``, or for a SLAM run
    folder the counts of ``graph.json``'s ``keyframes`` and accepted edges by kind (``odometry``, ``loop``).

    Raises
    ------
    InputError
        ``run_dir`` is not a folder or has no ``trajectory.txt``; a file of it cannot be read; rerun-sdk is missing.
    """
    run = Path(run_dir)
    if not run.is_dir():
        raise InputError("not a folder" if run.exists() else "no such folder", run)
    if not (run / "trajectory.txt").is_file():
        raise InputError("not a run folder (no trajectory.txt)", run)
    import_rerun()  # before reading large files: a missing rerun-sdk fails at once
    traj = read_tum(run / "trajectory.txt")
    no_keyframes = Trajectory(np.zeros(0), np.zeros((0, 4, 4)))
    slam = (run / "graph.json").is_file() and (run / "trajectory_vo.txt").is_file()
    vo = read_tum(run / "trajectory_vo.txt") if slam else None
    graph = read_graph(run / "graph.json") if slam else None
    kf_file = run / ("keyframes_vo.txt" if slam and (run / "keyframes_vo.txt").is_file() else "keyframes.txt")
    kfs = read_tum(kf_file) if kf_file.is_file() else no_keyframes
    gt = read_tum(run / "groundtruth.txt") if (run / "groundtruth.txt").is_file() else None
    metrics = _metrics(run)
    config = read_text_file(run / "config.yaml", "run configuration") if (run / "config.yaml").is_file() else None
    points, colours = _read_ply(run / "pointcloud.ply") if (run / "pointcloud.ply").is_file() else (None, None)
    frames, are_indices = _frame_indices(len(traj), metrics)
    depth: list[tuple[int, int, bytes]] = []  # (frame, pose ordinal, PNG) of each depth picture
    for png in sorted((run / "depth").glob("kf_*.png")):
        m = _DEPTH_NAME.fullmatch(png.name)
        if m is None or int(m.group(1)) >= len(kfs) or len(traj) == 0:
            continue
        k = int(np.argmin(np.abs(traj.timestamps - kfs.timestamps[int(m.group(1))])))  # the keyframe's pose
        depth.append((int(frames[k]), k, read_bytes(png, "depth picture")))
    initial_png = run / "depth" / "initial_map.png"
    initial = read_bytes(initial_png, "depth picture") if initial_png.is_file() else None
    gt_positions = None if gt is None or align is None else aligned_groundtruth(
        traj.timestamps, traj.positions, gt, align
    )  # fmt: skip

    recording = Recording(spawn=spawn, rrd=rrd, recording_id=recording_id, live=False)
    rr, stream = recording.rr, recording.stream
    try:
        stream.log("world", rr.ViewCoordinates.RDF, static=True)
        if len(traj):
            index = [rr.TimeColumn("frame", sequence=frames), _time_column(rr, traj.timestamps)]
            q = traj.quaternions()
            stream.send_columns(
                "world/camera", indexes=index, columns=rr.Transform3D.columns(translation=traj.positions, quaternion=q)
            )
            stream.log("world/camera", rr.TransformAxes3D(axis_length), static=True)
            stream.log(
                "world/trajectory/slam" if slam else "world/trajectory/estimate",
                rr.LineStrips3D([traj.positions], colors=[SLAM_COLOUR if slam else (230, 80, 40)], radii=[-1.5]),
                static=True,
            )
        if vo is not None and len(vo):
            stream.log("world/trajectory/odometry",
                       rr.LineStrips3D([vo.positions], colors=[[230, 80, 40]], radii=[-1.5]), static=True)  # fmt: skip
        if graph is not None:
            log_graph(rr, stream, graph.positions, graph.segments, static=True)
        if gt_positions is not None:
            stream.log(
                "world/trajectory/groundtruth",
                rr.LineStrips3D([gt_positions], colors=[[60, 200, 60]], radii=[-1.5]),
                static=True,
            )
        if len(kfs):
            keyframes = rr.Points3D(kfs.positions, colors=[[80, 140, 255]], radii=[-4.0])
            stream.log("world/keyframes", keyframes, static=True)
        relocs = [r["timestamp"] for r in metrics.get("relocalised") or [] if r.get("timestamp") is not None]
        if relocs and len(traj):  # where a lost run was found again (metrics.json), magenta as in a live view
            rows = [int(np.argmin(np.abs(traj.timestamps - t))) for t in relocs]
            stream.log("world/relocalisations", rr.Points3D(traj.positions[rows], colors=[[255, 0, 255]],
                                                            radii=[-6.0]), static=True)  # fmt: skip
        if points is not None:
            stream.log("world/points", rr.Points3D(points, colors=colours), static=True)
        if depth:
            stream.send_columns(
                "keyframe/depth",
                indexes=[
                    rr.TimeColumn("frame", sequence=[d[0] for d in depth]),
                    _time_column(rr, traj.timestamps[[d[1] for d in depth]]),
                ],
                columns=rr.EncodedImage.columns(blob=[d[2] for d in depth], media_type=["image/png"] * len(depth)),
            )
        if initial is not None:
            stream.log("keyframe/initial_map", rr.EncodedImage(contents=initial, media_type="image/png"), static=True)
        if metrics:
            table = rr.TextDocument(_markdown_table(metrics), media_type="text/markdown")
            stream.log("run/metrics", table, static=True)
        if config is not None:
            stream.log(
                "run/config", rr.TextDocument(f"```yaml\n{config}```\n", media_type="text/markdown"), static=True
            )
    except BaseException:
        recording.discard()
        raise
    recording.close()
    return {
        "poses": len(traj),
        "keyframes": len(kfs),
        "points": 0 if points is None else len(points),
        "depth_images": len(depth),
        "initial_map": initial is not None,
        "frames_are_indices": are_indices,
        "groundtruth": "none" if gt is None else "aligned" if gt_positions is not None else "not aligned",
        "slam": None if graph is None else {"keyframes": len(graph.positions),
                                            **{k: len(v) for k, v in graph.segments.items()}},
    }
