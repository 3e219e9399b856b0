"""The files of a SLAM run (``dmtrack run --slam``), written when the run ends.

During the run the odometry's own files are written as usual, under ``trajectory_vo.txt``, ``keyframes_vo.txt``
and ``pointcloud_vo.ply`` (:class:`~dmtrack.outputs.run_directory.RunDirectorySink` with ``suffix="_vo"``): a back
end that fails, or a run that is stopped, never loses the odometry's trajectory. At the end:

``trajectory.txt``   every tracked frame's pose relative to its keyframe, composed with that keyframe's optimised
                     pose (TUM, T_wc);
``keyframes.txt``    the keyframes' optimised poses;
``pointcloud.ply``   the keyframes' semi-dense points placed by their optimised poses;
``graph.json``       the keyframe graph: keyframes (id, frame, timestamp, optimised Sim(3) as a 4×4 matrix) and every
                     edge tried (its kind ``odometry``/``loop``, accepted or not and why, the relative Sim(3) ``T_ij``
                     = pose of j in i, the reciprocal consistencies).

When the back end failed (``slam_error`` in metrics.json), the plain names get the odometry's files instead.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from dmtrack.geometry.lie import Sim3
from dmtrack.io.atomic import write_text
from dmtrack.io.ply import write_ply
from dmtrack.io.trajectory import write_tum


def _matrix(S: Sim3 | None) -> list[list[float]] | None:
    return None if S is None else [[float(v) for v in row] for row in S.matrix()]


def graph_dict(backend: Any) -> dict[str, Any]:
    """``graph.json``'s contents."""
    poses = backend.keyframe_poses()
    kfs = [
        {"id": k, "frame": kf.frame_index, "timestamp": kf.timestamp, "sim3": _matrix(poses.get(k)),
         "vo_sim3": _matrix(kf.vo_pose)}
        for k, kf in sorted(backend.keyframes.items())
    ]
    edges = [
        {"i": e.i, "j": e.j, "kind": e.kind, "accepted": e.accepted, "T_ij": _matrix(e.T_ij),
         "consistency": [float(c) for c in e.consistency], "reason": e.reason}
        for e in backend.stats.edges
    ]
    return {"keyframes": kfs, "edges": edges}


def write_slam_outputs(out: Path, result: Any) -> None:
    """Write the files above for a finished :class:`~dmtrack.pipeline.RunResult` with a SLAM back end."""
    slam = result.slam
    if slam is None:
        return
    if slam.error is not None:
        for name in ("trajectory", "keyframes"):
            if (out / f"{name}_vo.txt").exists():
                shutil.copyfile(out / f"{name}_vo.txt", out / f"{name}.txt")
        if (out / "pointcloud_vo.ply").exists():
            shutil.copyfile(out / "pointcloud_vo.ply", out / "pointcloud.ply")
        return
    backend = slam.backend
    write_tum(out / "trajectory.txt", result.trajectory)
    write_tum(out / "keyframes.txt", result.keyframes)
    if (out / "pointcloud_vo.ply").exists():
        write_ply(out / "pointcloud.ply", *backend.point_cloud())
    g = graph_dict(backend)
    # one keyframe or edge per line: readable, and diffable between runs
    parts = [f'"{k}": [\n' + ",\n".join(json.dumps(item) for item in g[k]) + "\n]" for k in ("keyframes", "edges")]
    write_text(out / "graph.json", "{" + ",\n".join(parts) + "}\n")
