"""Check every accepted edge of a SLAM run's keyframe graph against the ground truth.

For each edge i → j of ``graph.json`` (``T_ij``, the pose of keyframe j in keyframe i), the rotation of ``T_ij`` is
compared with the ground truth's relative rotation of the two keyframes' frames (matched by timestamp in the run's
``groundtruth.txt``). Prints every loop edge, the worst rotation disagreement of all accepted edges, and the loop
edges that join a keyframe after frame ``--late`` to one before frame ``--early`` (issue 31: 450 and 330 on 7-Scenes).

    python benchmarks/slam_edges.py out/7scenes-slam [--late 450 --early 330] [--json edges.json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from dmtrack.geometry.lie import SO3
from dmtrack.io.trajectory import read_tum


def edge_errors(run: Path) -> list[dict]:
    graph = json.loads((run / "graph.json").read_text())
    gt = read_tum(run / "groundtruth.txt")
    frame_of = {k["id"]: (k["frame"], k["timestamp"]) for k in graph["keyframes"]}
    vo_of = {k["id"]: np.asarray(k["vo_sim3"], dtype=np.float64) for k in graph["keyframes"]}

    def gt_rotation(t: float) -> np.ndarray:
        i = int(np.argmin(np.abs(gt.timestamps - t)))
        if abs(gt.timestamps[i] - t) > 0.01:
            raise SystemExit(f"{run}/groundtruth.txt has no pose within 10 ms of keyframe timestamp {t}")
        return gt.poses[i][:3, :3]

    rows = []
    for e in graph["edges"]:
        if not e["accepted"] or e["T_ij"] is None:
            continue
        M = np.asarray(e["T_ij"], dtype=np.float64)
        s = np.cbrt(np.linalg.det(M[:3, :3]))
        R_est = M[:3, :3] / s
        (fi, ti), (fj, tj) = frame_of[e["i"]], frame_of[e["j"]]
        R_true = gt_rotation(ti).T @ gt_rotation(tj)
        err = SO3.from_matrix(R_est.T @ R_true, orthonormalize=True).angle()
        # the odometry's own relative rotation of the same two keyframes, for comparison
        Vi, Vj = (v[:3, :3] / np.cbrt(np.linalg.det(v[:3, :3])) for v in (vo_of[e["i"]], vo_of[e["j"]]))
        vo_err = SO3.from_matrix((Vi.T @ Vj).T @ R_true, orthonormalize=True).angle()
        rows.append({"i": e["i"], "j": e["j"], "frame_i": fi, "frame_j": fj, "kind": e["kind"],
                     "rotation_error_deg": float(np.degrees(err)), "vo_rotation_error_deg": float(np.degrees(vo_err)),
                     "true_rotation_deg": float(np.degrees(SO3.from_matrix(R_true, orthonormalize=True).angle()))})
    return rows


def closing(rows: list[dict], late: int, early: int) -> list[dict]:
    """The loop edges between a keyframe after frame ``late`` and one before frame ``early``."""
    return [r for r in rows if r["kind"] == "loop" and max(r["frame_i"], r["frame_j"]) > late
            and min(r["frame_i"], r["frame_j"]) < early]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path, help="a run folder of dmtrack run --slam (graph.json, groundtruth.txt)")
    ap.add_argument("--late", type=int, default=450, help="a loop edge 'closes' from after this frame …")
    ap.add_argument("--early", type=int, default=330, help="… to before this frame")
    ap.add_argument("--json", type=Path, help="write the rows here")
    a = ap.parse_args(argv)
    rows = edge_errors(a.run)
    if not rows:
        print(f"{a.run}: no accepted edge")
        return 1
    loops = [r for r in rows if r["kind"] == "loop"]
    for r in loops:
        print(f"loop kf {r['i']:3d} (frame {r['frame_i']:4d}) → kf {r['j']:3d} (frame {r['frame_j']:4d}): "
              f"relative rotation {r['true_rotation_deg']:6.2f}°, error {r['rotation_error_deg']:.3f}° "
              f"(the odometry's: {r['vo_rotation_error_deg']:.3f}°)")
    worst = max(rows, key=lambda r: r["rotation_error_deg"])
    print(f"{len(rows)} accepted edges ({len(loops)} loop edges); worst rotation error "
          f"{worst['rotation_error_deg']:.3f}° ({worst['kind']} kf {worst['i']} → kf {worst['j']}, frames "
          f"{worst['frame_i']} → {worst['frame_j']}; the odometry's between them: "
          f"{worst['vo_rotation_error_deg']:.3f}°)")
    n = len(closing(rows, a.late, a.early))
    print(f"loop edges between a keyframe after frame {a.late} and one before frame {a.early}: {n}")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
