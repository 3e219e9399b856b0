"""How much of a run's RPE is shared by two independent methods: dmtrack, DSO and the ground truth, three ways.

For each run (the same frames tracked by dmtrack and by DSO, ``tools/dso_oracle/run_dso.py``), over the pairs
(i, j) of the paper's RPE (conventions.md: 8 lengths up to r_l of the ground truth's path, the pairs chosen on the
ground truth), compare the relative poses three ways: dmtrack against the ground truth, DSO against the ground
truth, and dmtrack against DSO. Each comparison gives the paper's figures on those pairs (translation angle and
rotation, degrees per metre of ground-truth path, the same division by L_k for all three) and the RMS angles.

If the three had independent errors, the pairwise mean squares would be sums of two of the three variances, and
each one's own spread follows (the "three-cornered hat" of clock comparisons):
    σ_A² = (d_AG² + d_AB² − d_BG²) / 2,   σ_B² = (d_BG² + d_AB² − d_AG²) / 2,   σ_G² = (d_AG² + d_BG² − d_AB²) / 2.
Two trackers given the same images and the same calibration are not independent: what they share (calibration,
rolling shutter, scene) shows up in σ_G together with the ground truth's own error. So σ_G is the part of the
error *against the ground truth* that neither tracker's own mistakes explain; a negative estimate is reported as 0.

Usage: three_way.py OUT.json NAME:DMTRACK_DIR:DSO_DIR ... (each DMTRACK_DIR with trajectory.txt and
groundtruth.txt as ``dmtrack run`` writes them, DSO_DIR with run_dso.py's trajectory.txt).
"""

from __future__ import annotations

import json
import sys

import numpy as np

from dmtrack.evaluation.metrics import _relative, _rotation_angle_rad, rpe_pairs
from dmtrack.io.association import associate_trajectories
from dmtrack.io.trajectory import Trajectory, read_trajectory


def _angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip((a * b).sum(1), -1.0, 1.0)))


def _hat(ab: float, ag: float, bg: float) -> dict[str, float]:
    own = {"dmtrack": (ag**2 + ab**2 - bg**2) / 2, "dso": (bg**2 + ab**2 - ag**2) / 2,
           "shared": (ag**2 + bg**2 - ab**2) / 2}  # fmt: skip
    return {k: float(np.sqrt(max(v, 0.0))) for k, v in own.items()}


def common_frames(gt: Trajectory, dm: Trajectory, dso: Trajectory, name: str) -> tuple[Trajectory, ...]:
    """The ground truth, dmtrack's and DSO's poses of the frames all three have (DSO poses from its own start on,
    dmtrack from its geometric start's frame on), in that order."""
    b, a = associate_trajectories(dso, dm, max_diff=0.01)
    g, a = associate_trajectories(gt, a, max_diff=0.01)
    b, a = associate_trajectories(b, a, max_diff=0.01)
    g, a = associate_trajectories(g, a, max_diff=0.01)
    if not (len(g) == len(a) == len(b)) or len(g) < 10:
        raise SystemExit(f"{name}: only {len(g)} frames posed by both methods and in the ground truth")
    return g, a, b


def compare(name: str, dm_dir: str, dso_dir: str, r_l: float = 1.0 / 3.0) -> dict:
    """The three comparisons of one run on the frames both methods posed."""
    g, a, b = common_frames(read_trajectory(f"{dm_dir}/groundtruth.txt"), read_trajectory(f"{dm_dir}/trajectory.txt"),
                            read_trajectory(f"{dso_dir}/trajectory.txt"), name)  # fmt: skip
    keys = ("dmtrack_gt", "dso_gt", "dmtrack_dso")
    per_m = {k: {"trans": [], "rot": []} for k in keys}
    pooled = {k: {"trans": [], "rot": []} for k in keys}
    for length, i, j in rpe_pairs(g, r_l, 8):
        if i.size == 0:
            continue
        rel = {}
        for key, traj in (("g", g), ("a", a), ("b", b)):
            rel[key] = _relative(traj.poses, i, j)
        for k, (x, y) in zip(keys, (("g", "a"), ("g", "b"), ("a", "b")), strict=True):
            trans = _angles(rel[x][1], rel[y][1])
            rot = np.degrees(_rotation_angle_rad(np.swapaxes(rel[x][0], -1, -2) @ rel[y][0]))
            per_m[k]["trans"].append(trans.mean() / length)
            per_m[k]["rot"].append(rot.mean() / length)
            pooled[k]["trans"].append(trans)
            pooled[k]["rot"].append(rot)
    out = {"run": name, "frames_compared": len(g)}
    for what in ("trans", "rot"):
        rms = {k: float(np.sqrt(np.mean(np.concatenate(pooled[k][what]) ** 2))) for k in keys}
        out[what] = {
            "deg_per_m": {k: float(np.mean(per_m[k][what])) for k in keys},
            "rms_deg": rms,
            "own_rms_deg": _hat(rms["dmtrack_dso"], rms["dmtrack_gt"], rms["dso_gt"]),
        }
    return out


def main(argv: list[str]) -> None:
    out_path, specs = argv[0], argv[1:]
    rows = [compare(*spec.split(":")) for spec in specs]
    summary = {}
    for what in ("trans", "rot"):
        summary[what] = {
            "median_deg_per_m": {k: float(np.median([r[what]["deg_per_m"][k] for r in rows]))
                                 for k in rows[0][what]["deg_per_m"]},
            "median_own_rms_deg": {k: float(np.median([r[what]["own_rms_deg"][k] for r in rows]))
                                   for k in rows[0][what]["own_rms_deg"]},
        }  # fmt: skip
    with open(out_path, "w") as f:
        json.dump({"runs": rows, "median": summary}, f, indent=1)
    for r in rows:
        t, q = r["trans"], r["rot"]
        print(f"{r['run']:14s} trans °/m dm-GT {t['deg_per_m']['dmtrack_gt']:6.1f} "
              f"DSO-GT {t['deg_per_m']['dso_gt']:6.1f} "
              f"dm-DSO {t['deg_per_m']['dmtrack_dso']:6.1f} | own rms ° dm {t['own_rms_deg']['dmtrack']:4.1f} "
              f"DSO {t['own_rms_deg']['dso']:4.1f} shared {t['own_rms_deg']['shared']:4.1f} || rot °/m dm-GT "
              f"{q['deg_per_m']['dmtrack_gt']:5.2f} DSO-GT {q['deg_per_m']['dso_gt']:5.2f} dm-DSO "
              f"{q['deg_per_m']['dmtrack_dso']:5.2f}")
    print("median", json.dumps(summary))


if __name__ == "__main__":
    main(sys.argv[1:])
