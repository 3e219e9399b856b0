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
:func:`read_graph` reads ``graph.json`` back for the viewer (``dmtrack view``) and the report.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack.errors import InputError
from dmtrack.geometry.lie import Sim3
from dmtrack.io.atomic import write_text
from dmtrack.io.files import read_text_file
from dmtrack.io.ply import write_ply
from dmtrack.io.trajectory import write_tum

#: The kinds of edge in ``graph.json``.
EDGE_KINDS = ("odometry", "loop")


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


@dataclass(frozen=True)
class GraphFile:
    """``graph.json`` read back: ``keyframe_ids`` ``(n,)`` and ``positions`` ``(n, 3)``, the keyframes' optimised
    camera centres (the odometry's for a keyframe the graph never optimised); ``segments``: for each kind of
    :data:`EDGE_KINDS`, the accepted edges' end points ``(m, 2, 3)``; ``rejected``: the loop candidates the
    reciprocal test refused."""

    keyframe_ids: np.ndarray
    positions: np.ndarray
    segments: dict[str, np.ndarray]
    rejected: int


def read_graph(path: Path) -> GraphFile:
    """Read ``graph.json`` (see the module docstring); an :class:`~dmtrack.errors.InputError` naming the file when
    it is not one."""
    try:
        graph = json.loads(read_text_file(path, "SLAM graph"))
        centre: dict[int, np.ndarray] = {}
        for kf in graph["keyframes"]:
            S = kf.get("sim3") or kf.get("vo_sim3")
            if S is not None:
                centre[int(kf["id"])] = np.asarray(S, dtype=np.float64).reshape(4, 4)[:3, 3]
        pairs: dict[str, list[np.ndarray]] = {kind: [] for kind in EDGE_KINDS}
        rejected = 0
        for e in graph["edges"]:
            i, j = int(e["i"]), int(e["j"])
            if not e["accepted"]:
                rejected += 1
            elif i in centre and j in centre:
                pairs.setdefault(str(e["kind"]), []).append(np.stack([centre[i], centre[j]]))
    except json.JSONDecodeError as e:
        raise InputError(f"not valid JSON: {e.msg} (line {e.lineno})", path) from None
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise InputError(f"not a SLAM graph (keyframes and edges): {type(e).__name__}: {e}", path) from None
    ids = sorted(centre)
    return GraphFile(
        np.array(ids, dtype=np.int64),
        np.array([centre[k] for k in ids], dtype=np.float64).reshape(-1, 3),
        {k: np.array(v, dtype=np.float64).reshape(-1, 2, 3) for k, v in pairs.items()},
        rejected,
    )
