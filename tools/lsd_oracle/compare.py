#!/usr/bin/env python3
"""Run LSD-SLAM (the oracle) and dmtrack on the same frames from the same initial depth, and line the traces up.

    python tools/lsd_oracle/compare.py run SEQUENCE --out DIR [--frames N] [--seed S] [--grey lsd|dmtrack]
        [--lsd tools/lsd_oracle/_build/lsd_oracle] [--set section.key=value ...]
    python tools/lsd_oracle/compare.py traces LSD_TRACE.jsonl DMTRACK_TRACE.jsonl [--every K]
    python tools/lsd_oracle/compare.py eval SEQUENCE TRAJECTORY.txt [--r-l 1/3]

``run`` writes DIR/images.txt and DIR/calib.txt (LSD-SLAM's pinhole calibration; sizes that are not multiples of
16 are cropped as dmtrack crops them, into DIR/images/), runs ``lsd_oracle`` (VO mode, single-threaded
mapping) with ``srand(seed)`` and lets it export its random initial inverse depth, runs
``dmtrack_trace.py`` from that same map, then compares the traces and evaluates both trajectories.

``traces`` prints the two traces side by side (every K-th frame and every frame where they part) and, for
each quantity, the first frame where they part and by how much: the keyframe decisions, the tracked pose
(rotation angle and translation of the difference), the good/bad point counts and residual of the tracker, and
the depth map after mapping (valid hypotheses, mean inverse depth, variance histogram).

A developer tool (never imported by the package, never run by CI). See README.md.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def load_trace(path: str | Path) -> dict[int, dict]:
    out = {}
    for line in Path(path).read_text().splitlines():
        if line.strip():
            r = json.loads(line)
            out[int(r["frame"])] = r
    return out


def _mapping(r: dict) -> dict | None:
    return r.get("update") or r.get("created")


def _pose_diff(a: dict, b: dict) -> tuple[float, float, float]:
    """(rotation angle ° of the difference, |Δt|, |t| of a) of two keyframe→frame poses."""
    Ta = np.array(a["T_fk"], float).reshape(3, 4)
    Tb = np.array(b["T_fk"], float).reshape(3, 4)
    R = Ta[:, :3].T @ Tb[:, :3]
    ang = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(R) - 1) / 2))))
    return ang, float(np.linalg.norm(Ta[:, 3] - Tb[:, 3])), float(np.linalg.norm(Ta[:, 3]))


def compare_traces(
    lsd: dict[int, dict], dm: dict[int, dict], every: int = 10, rot_tol: float = 0.05, rel_tol: float = 0.02
) -> dict[str, tuple[int, str] | None]:
    """Print the side-by-side table and return, per quantity, (first frame where the traces part, how)."""
    frames = sorted(set(lsd) & set(dm))
    kf_l = [f for f in frames if lsd[f].get("keyframe")]
    kf_d = [f for f in frames if dm[f].get("keyframe")]
    print(f"keyframes  LSD-SLAM ({len(kf_l)}): {kf_l}")
    print(f"           dmtrack  ({len(kf_d)}): {kf_d}")
    first: dict[str, tuple[int, str] | None] = {"keyframe": None, "pose": None, "tracking": None, "map": None}

    def mark(key: str, f: int, how: str) -> bool:
        if first[key] is None:
            first[key] = (f, how)
            return True
        return False

    hdr = (
        f"{'frame':>5} {'kf L/D':>9} {'dR°':>7} {'|dt|/|t|':>8} {'good L/D':>13} {'bad L/D':>11} "
        f"{'residual L/D':>13} {'valid L/D':>15} {'mean idepth L/D':>15}"
    )
    print(hdr)
    for f in frames:
        a, b = lsd[f], dm[f]
        notes = []
        if bool(a.get("keyframe")) != bool(b.get("keyframe")):
            if mark("keyframe", f, f"keyframe: LSD-SLAM {bool(a.get('keyframe'))}, dmtrack {bool(b.get('keyframe'))}"):
                notes.append("KF")
        row = f"{f:>5} {a.get('parent', '-'):>4}/{b.get('parent', '-'):<4}"
        if "T_fk" in a and "T_fk" in b:
            ang, dt, tn = _pose_diff(a, b)
            rel = dt / tn if tn > 0 else 0.0
            if ang > rot_tol and mark("pose", f, f"pose: rotation differs by {ang:.3f}°, translation by {rel:.1%}"):
                notes.append("POSE")
            gl, gd = a["good"], b["good"]
            if abs(gl - gd) > rel_tol * max(gl, 1) and mark("tracking", f, f"good points {gl:.0f} vs {gd:.0f}"):
                notes.append("TRACK")
            row += (
                f" {ang:7.3f} {rel:8.1%} {gl:6.0f}/{gd:<6.0f} {a['bad']:5.0f}/{b['bad']:<5.0f}"
                f" {a['residual']:6.3f}/{b['residual']:<6.3f}"
            )
        else:
            row += " " * 58
        ma, mb = _mapping(a), _mapping(b)
        if ma and mb:
            dv = abs(ma["valid"] - mb["valid"]) / max(ma["valid"], 1)
            dmi = abs(ma["mean_idepth"] - mb["mean_idepth"]) / max(abs(ma["mean_idepth"]), 1e-9)
            if (dv > rel_tol or dmi > rel_tol) and mark(
                "map", f, f"map: valid {ma['valid']} vs {mb['valid']}, mean idepth {ma['mean_idepth']:.4f} vs "
                f"{mb['mean_idepth']:.4f}"
            ):
                notes.append("MAP")
            row += f" {ma['valid']:7d}/{mb['valid']:<7d} {ma['mean_idepth']:7.4f}/{mb['mean_idepth']:<7.4f}"
        if notes or f % every == 0:
            print(row + ("   <- " + ",".join(notes) if notes else ""))
    print("\nfirst frame where the traces part:")
    for key, v in first.items():
        print(f"  {key:9s} " + ("never (within tolerance)" if v is None else f"frame {v[0]}: {v[1]}"))
    return first


def evaluate_file(sequence: str, traj: str, r_l: float | None = None, intrinsics: str | None = None) -> dict:
    """Metrics of a trajectory whose timestamps are frame indices (lsd_oracle / dmtrack_trace output)."""
    from dmtrack.datasets import open_sequence
    from dmtrack.evaluation.metrics import evaluate
    from dmtrack.io.trajectory import Trajectory, read_tum

    seq = open_sequence(sequence, intrinsics=intrinsics)
    est = read_tum(traj)
    est = Trajectory(np.asarray(seq.timestamps)[est.timestamps.astype(int)], est.poses)
    if r_l is None:
        r_l = 1 / 20 if seq.format in ("kitti", "tsukuba") or "tsukuba" in seq.name else 1 / 3
    return evaluate(seq.groundtruth, est, r_l=r_l)


def _fraction(s: str) -> float:
    num, _, den = s.partition("/")
    return float(num) / float(den) if den else float(num)


def cmd_run(a: argparse.Namespace) -> int:
    import cv2

    from dmtrack.datasets import open_sequence
    from dmtrack.geometry.camera import crop_image

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    seq = open_sequence(a.sequence, intrinsics=a.intrinsics)
    cam, box = seq.camera.crop_to_multiple(16)
    n = len(seq) if a.frames is None else min(a.frames, len(seq))
    files = []
    native = (seq.width, seq.height) == (cam.width, cam.height)
    for i in range(n):
        p = seq[i].path if native else None
        if p is None:
            (out / "images").mkdir(exist_ok=True)
            src = seq[i].path
            img = cv2.imread(str(src), cv2.IMREAD_GRAYSCALE) if src else seq[i].image
            if img.ndim == 3:
                img = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
            p = out / "images" / f"{i:06d}.png"
            cv2.imwrite(str(p), crop_image(img, box))
        files.append(str(Path(p).resolve()))
    (out / "images.txt").write_text("\n".join(files) + "\n")
    w, h = cam.width, cam.height
    (out / "calib.txt").write_text(
        f"{cam.fx / w:.12g} {cam.fy / h:.12g} {(cam.cx + 0.5) / w:.12g} {(cam.cy + 0.5) / h:.12g} 0\n"
        f"{w} {h}\nnone\n{w} {h}\n"
    )
    lsd_bin = Path(a.lsd)
    if not lsd_bin.exists():
        sys.exit(f"compare.py: {lsd_bin} not found — build the oracle first (tools/lsd_oracle/build.sh)")
    init = out / "init_idepth.bin"
    cmd = [str(lsd_bin), f"files={out / 'images.txt'}", f"calib={out / 'calib.txt'}", f"out={out / 'lsd'}",
           f"seed={a.seed}", f"dumpinit={init}"]  # fmt: skip
    print("$", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    # dmtrack reads the same image files (or the same crops of the same decoded pixels)
    cmd = [sys.executable, str(HERE / "dmtrack_trace.py"), a.sequence, "--out", str(out / "dmtrack"),
           "--end", str(n), "--initdepth", str(init), "--grey", a.grey]  # fmt: skip
    if a.intrinsics:
        cmd += ["--intrinsics", a.intrinsics]
    for s in ["depth.update_variance=smoothed", *a.set]:  # LSD-SLAM's rule unless overridden
        cmd += ["--set", s]
    print("$", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)
    compare_traces(load_trace(out / "lsd_trace.jsonl"), load_trace(out / "dmtrack_trace.jsonl"), a.every)
    r_l = _fraction(a.r_l) if a.r_l else None
    print()
    for name in ("lsd", "dmtrack"):
        m = evaluate_file(a.sequence, str(out / f"{name}.txt"), r_l, a.intrinsics)
        print(
            f"{name:8s} poses {m['matched_poses']:4d}  RPE rot {m['rpe_rot_deg_per_m']:.3f}  trans-angle "
            f"{m['rpe_trans_angle_deg_per_m']:.2f}  ATE {m['ate_rmse']:.4f}  (r_l {m['r_l']:.4g})"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run both from the same initial depth and compare")
    r.add_argument("sequence")
    r.add_argument("--out", required=True)
    r.add_argument("--frames", type=int, default=None)
    r.add_argument("--seed", type=int, default=1, help="srand() seed of LSD-SLAM's random initial depth")
    r.add_argument("--grey", choices=("lsd", "dmtrack"), default="lsd")
    r.add_argument("--lsd", default=str(HERE / "_build" / "lsd_oracle"))
    r.add_argument("--intrinsics", default=None)
    r.add_argument(
        "--set", action="append", default=[],
        help="dmtrack config override (default adds depth.update_variance=smoothed, LSD-SLAM's rule)",
    )
    r.add_argument("--every", type=int, default=10)
    r.add_argument("--r-l", default=None)
    t = sub.add_parser("traces", help="compare two trace files")
    t.add_argument("lsd")
    t.add_argument("dmtrack")
    t.add_argument("--every", type=int, default=10)
    t.add_argument("--rot-tol", type=float, default=0.05, help="pose difference that counts as parting (degrees)")
    t.add_argument("--rel-tol", type=float, default=0.02, help="relative difference of counts that counts")
    e = sub.add_parser("eval", help="metrics of a frame-index trajectory")
    e.add_argument("sequence")
    e.add_argument("trajectory")
    e.add_argument("--r-l", default=None)
    e.add_argument("--intrinsics", default=None)
    a = ap.parse_args(argv)
    if a.cmd == "run":
        return cmd_run(a)
    if a.cmd == "traces":
        compare_traces(load_trace(a.lsd), load_trace(a.dmtrack), a.every, a.rot_tol, a.rel_tol)
        return 0
    m = evaluate_file(a.sequence, a.trajectory, _fraction(a.r_l) if a.r_l else None, a.intrinsics)
    print(json.dumps({k: m[k] for k in ("matched_poses", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m",
                                          "ate_rmse", "r_l")}, indent=1))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
