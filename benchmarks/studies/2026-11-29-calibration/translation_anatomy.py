"""Where the short-length RPE translation angle of a run comes from (issue 38): run folders in, one line each.

    python translation_anatomy.py RUN_DIR [RUN_DIR ...] [--json FILE]

A run folder is what ``dmtrack run`` writes (``trajectory.txt`` and ``groundtruth.txt``). For the pairs of the RPE's
shortest length (L₁ = 1/24 of the ground truth's path, conventions.md) and, for the anisotropy, also its 4th and 8th:

* ``err``: the mean angle between the estimate's and the ground truth's translation over the pair (degrees);
* **the coupling to the rotation error.** In the first camera's axes, the rotation error of the pair δω (the
  rotation vector of Q_ijᵀ·P_ij's rotation) and the translation error δt (the estimate scaled to the ground truth's
  median length, minus the ground truth). Turning about x tilts the view as moving along y does, at the scene's
  depth Z; so δt_y is fitted as Z_y·δω_x and δt_x as Z_x·δω_y (one slope each, through 0). ``R2`` is the share of
  δt_x, δt_y that those slopes explain, ``err_without`` the mean angle once the fitted part is taken away: what a
  rotation made exact would leave at most, if the translation moved with it;
* **the anisotropy.** Per axis, the least-squares slope of the estimate's translation on the ground truth's (after
  the median scale): 1 everywhere when the only error is noise; below 1 on an axis the run moves along too little.

Nothing here is fitted across runs: two slopes per run (Z_x, Z_y), read as the scene's depth.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dmtrack.evaluation.metrics import _relative, rpe_pairs
from dmtrack.geometry.lie import so3_log
from dmtrack.io.trajectory import Trajectory, read_tum


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c = (a * b).sum(1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def _pairs(run: Path) -> tuple[np.ndarray, np.ndarray, list]:
    gt, est = read_tum(run / "groundtruth.txt"), read_tum(run / "trajectory.txt")
    idx = np.clip(np.searchsorted(gt.timestamps, est.timestamps), 0, len(gt) - 1)
    G = gt.poses[idx]
    return G, est.poses, rpe_pairs(Trajectory(est.timestamps, G), 1.0 / 3.0, 8)


def anatomy(run: Path) -> dict:
    G, E, pairs = _pairs(run)
    out: dict = {"run": run.name}
    lengths = []
    for k in (0, 3, 7):
        L, i, j = pairs[k]
        Rq, tq = _relative(G, i, j)
        Rp, tp = _relative(E, i, j)
        tp = tp * np.median(np.linalg.norm(tq, axis=1) / np.linalg.norm(tp, axis=1))
        slopes = [float(tp[:, a] @ tq[:, a] / (tq[:, a] @ tq[:, a])) for a in range(3)]
        lengths.append({"L": float(L), "err_deg": float(_angle_deg(tq, tp).mean()), "axis_slope": slopes})
        if k == 0:
            dw = so3_log(np.swapaxes(Rq, -1, -2) @ Rp)
            dt = tp - tq
            zx = float(dt[:, 0] @ dw[:, 1] / (dw[:, 1] @ dw[:, 1]))
            zy = float(dt[:, 1] @ dw[:, 0] / (dw[:, 0] @ dw[:, 0]))
            fit = np.zeros_like(dt)
            fit[:, 0], fit[:, 1] = zx * dw[:, 1], zy * dw[:, 0]
            r2 = [float(1 - ((dt[:, a] - fit[:, a]) ** 2).sum() / (dt[:, a] ** 2).sum()) for a in (0, 1)]
            out.update(L=float(L), pairs=int(i.size), err_deg=lengths[0]["err_deg"],
                       err_without_deg=float(_angle_deg(tq, tp - fit).mean()), z_x=zx, z_y=zy, r2_x=r2[0], r2_y=r2[1],
                       rot_err_deg=np.degrees(np.sqrt((dw**2).mean(0))).tolist(),
                       turn_deg=np.degrees(np.sqrt((so3_log(Rq) ** 2).mean(0))).tolist())  # fmt: skip
    out["lengths"] = lengths
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    rows = [anatomy(r) for r in a.runs]
    for r in rows:
        aniso = "  ".join(f"{x['L'] * 100:.0f} cm: {x['axis_slope'][0]:.2f} {x['axis_slope'][1]:.2f} "
                          f"{x['axis_slope'][2]:.2f}" for x in r["lengths"])  # fmt: skip
        print(f"{r['run']:14s} L₁ {r['L'] * 100:4.1f} cm  err {r['err_deg']:5.1f}° → {r['err_without_deg']:5.1f}°  "
              f"Z x {r['z_x']:+.2f} y {r['z_y']:+.2f} m  R² x {r['r2_x']:.2f} y {r['r2_y']:.2f}  "
              f"rot err {' '.join(f'{v:.2f}' for v in r['rot_err_deg'])}°  turn "
              f"{' '.join(f'{v:.1f}' for v in r['turn_deg'])}°  | axis slopes x y z  {aniso}")
    keys = ("err_deg", "err_without_deg", "r2_x", "r2_y", "z_x", "z_y")
    med = {k: float(np.median([r[k] for r in rows])) for k in keys}
    print("median: err {err_deg:.1f}° → {err_without_deg:.1f}°, R² x {r2_x:.2f} y {r2_y:.2f}, "
          "Z x {z_x:+.2f} y {z_y:+.2f} m".format(**med))  # fmt: skip
    if a.json:
        a.json.write_text(json.dumps({"runs": rows, "median": med}, indent=1) + "\n")


if __name__ == "__main__":
    main()
