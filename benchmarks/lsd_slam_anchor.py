"""LSD-SLAM's own figures beside dmtrack's (issue 31): upstream LSD-SLAM through ``tools/lsd_oracle``, full system
(``slam=1``: doSlam on, FabMap off) and odometry alone (``slam=0``), on the same frames and from the same initial
depth fields as ``dmtrack run --init random --seed K``.

    python benchmarks/lsd_slam_anchor.py SEQUENCE --seeds 0-4 --out DIR --name NAME [--field dmtrack|lsd]

``--field dmtrack`` (default): the initial inverse depth of seed K is dmtrack's own random map (numpy's generator,
the pixels dmtrack's grey first frame makes valid), exported and given to the oracle (``initdepth=``, the random
initialisation's variance and validity), so each row starts from the map ``benchmarks/slam_study.py --init random
--seeds K`` started from. ``--field lsd``: LSD-SLAM's own ``randomInit`` after ``srand(K)`` (glibc: ``srand(0)`` is
``srand(1)``). The images are the sequence's files as LSD-SLAM reads them (OpenCV's greyscale decoder), the
calibration the pinhole ``compare.py run`` writes, the parameters the driver's defaults (ROS start-up values,
single-threaded mapping). With ``slam=1`` the trajectory is the one after upstream's ``finalize()`` (final
constraint search and optimisation): every frame = its keyframe's optimised pose ∘ its tracked pose.

Each trajectory is evaluated by ``dmtrack eval --json`` (Sim3-aligned ATE RMSE, RPE rotation and translation angle
per metre, r_l 1/3) against the sequence's ground truth. ``loop_closures`` counts the keyframe pairs of LSD-SLAM's
final pose graph other than a keyframe and the keyframe it was tracked on (``PREFIX_graph.txt`` of the driver);
``closing_edges`` those joining a keyframe after frame ``--late`` to one before ``--early`` (as slam_study.py).
Writes NAME.csv and NAME.md (one row per seed, SLAM and ``vo_`` columns as slam_study.py, then the medians); keeps
under ``--work`` (default DIR/runs/NAME) each run's trajectory (``{slam,vo}_seedK.txt``, TUM, timestamp = frame
index), keyframes (``_kf.txt``), pose graph (``_graph.txt``), driver output (``.log``) and ``dmtrack eval`` result
(``_eval.json``), and the ground truth and calibration (``--keep-all``: also the image list, the traces and the
initial maps).
"""

from __future__ import annotations

import argparse
import csv
import json
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
LSD = REPO / "tools" / "lsd_oracle" / "_build" / "lsd_oracle"

COLS = ("seed", "run", "ate_rmse", "vo_ate_rmse", "rpe_rot_deg_per_m", "vo_rpe_rot_deg_per_m",
        "rpe_trans_angle_deg_per_m", "vo_rpe_trans_angle_deg_per_m", "loop_closures", "graph_edges", "closing_edges",
        "keyframes", "vo_keyframes", "tracked_frames", "vo_tracked_frames", "wall_s", "vo_wall_s")


def _seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def _fraction(s: str) -> float:
    num, _, den = s.partition("/")
    return float(num) / float(den) if den else float(num)


def prepare(sequence: Path, work: Path, frames: int | None) -> tuple[object, int]:
    """images.txt and calib.txt (LSD-SLAM's pinhole format, as compare.py run) and the ground truth (TUM)."""
    from dmtrack.datasets import open_sequence
    from dmtrack.io.trajectory import Trajectory, write_tum

    seq = open_sequence(str(sequence))
    cam, _box = seq.camera.crop_to_multiple(16)
    if (seq.width, seq.height) != (cam.width, cam.height):
        sys.exit(f"{sequence}: {seq.width}x{seq.height} is not a multiple of 16 (use compare.py run, which crops)")
    n = len(seq) if frames is None else min(frames, len(seq))
    (work / "images.txt").write_text("".join(f"{Path(seq[i].path).resolve()}\n" for i in range(n)))
    w, h = cam.width, cam.height
    (work / "calib.txt").write_text(
        f"{cam.fx / w:.12g} {cam.fy / h:.12g} {(cam.cx + 0.5) / w:.12g} {(cam.cy + 0.5) / h:.12g} 0\n"
        f"{w} {h}\nnone\n{w} {h}\n"
    )
    gt = seq.groundtruth
    keep = gt.timestamps <= np.asarray(seq.timestamps)[n - 1] + 1e-6
    write_tum(work / "groundtruth.txt", Trajectory(gt.timestamps[keep], gt.poses[keep]))
    return seq, n


def dmtrack_field(seq: object, seed: int, path: Path) -> int:
    """dmtrack's random initial map of ``seed`` on frame 0 (as ``dmtrack run --init random --seed``), H·W float32,
    -1 where dmtrack has no hypothesis. Returns the number of valid pixels."""
    from dmtrack.features import get_feature
    from dmtrack.geometry.camera import crop_image
    from dmtrack.odometry.config import VOConfig
    from dmtrack.odometry.vo import VisualOdometry

    camera, box = seq.camera.crop_to_multiple(16)
    vo = VisualOdometry(camera, VOConfig().with_overrides("init=random", f"seed={seed}"), threads=1)
    img = crop_image(seq[0].image, box)
    vo.process(0, float(seq.timestamps[0]), img, get_feature("gray").compute(img))
    dm = vo.depth_map
    field = np.where(dm.valid, dm.idepth, -1.0).astype(np.float32)
    field.tofile(path)
    return int(dm.valid.sum())


def run_oracle(lsd: Path, work: Path, prefix: Path, slam: bool, seed: int, field: Path | None, mt: int) -> dict:
    """One lsd_oracle run; checks that it started from ``field`` (when given)."""
    cmd = [str(lsd), f"files={work / 'images.txt'}", f"calib={work / 'calib.txt'}", f"out={prefix}",
           f"slam={int(slam)}", f"mt={mt}", f"dumpinit={prefix}_init.bin"]  # fmt: skip
    cmd.append(f"initdepth={field}" if field is not None else f"seed={seed}")
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    Path(f"{prefix}.log").write_text("$ " + " ".join(cmd) + "\n" + p.stdout + p.stderr)
    if p.returncode != 0:
        sys.exit(f"lsd_oracle failed ({p.returncode}), see {prefix}.log")
    if field is not None and not np.array_equal(np.fromfile(field, np.float32),
                                                np.fromfile(f"{prefix}_init.bin", np.float32)):
        sys.exit(f"{prefix}: LSD-SLAM's initial map is not {field}")
    lost = re.search(r"tracking lost at frame (\d+)", p.stderr)
    return {"wall_s": wall, "lost_at": int(lost.group(1)) if lost else None, "log": p.stdout + p.stderr}


def evaluate(seq: object, work: Path, prefix: Path, r_l: str) -> dict:
    """``dmtrack eval --json`` of the oracle's trajectory (frame-index timestamps → the sequence's)."""
    from dmtrack.io.trajectory import Trajectory, read_tum, write_tum

    est = read_tum(f"{prefix}.txt")
    write_tum(f"{prefix}_tum.txt", Trajectory(np.asarray(seq.timestamps)[est.timestamps.astype(int)], est.poses))
    p = subprocess.run([sys.executable, "-m", "dmtrack.cli", "eval", str(work / "groundtruth.txt"),
                        f"{prefix}_tum.txt", "--json", "--r-l", r_l], capture_output=True, text=True, check=True)
    Path(f"{prefix}_eval.json").write_text(p.stdout)
    m = json.loads(p.stdout)
    m["tracked_frames"] = len(est.timestamps)
    m["keyframes"] = sum(1 for ln in Path(f"{prefix}_kf.txt").read_text().splitlines() if ln.strip())
    return m


def graph_counts(prefix: Path, late: int, early: int) -> dict:
    rows = [tuple(int(x) for x in ln.split()) for ln in Path(f"{prefix}_graph.txt").read_text().splitlines()
            if ln.strip() and not ln.startswith("#")]
    loops = [(a, b) for a, b, odo in rows if not odo]
    return {"graph_edges": len(rows), "loop_closures": len(loops),
            "closing_edges": sum(1 for a, b in loops if max(a, b) > late and min(a, b) < early)}


def _fmt(v: object) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return "–" if v is None else str(v)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence", type=Path)
    ap.add_argument("--seeds", type=_seeds, default=[0, 1, 2, 3, 4])
    ap.add_argument("--field", choices=("dmtrack", "lsd"), default="dmtrack",
                    help="initial depth: dmtrack's random map of the seed (default) or LSD-SLAM's srand(seed)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per seed (LSD-SLAM's threads make runs differ)")
    ap.add_argument("--modes", default="slam,vo", help="slam (slam=1), vo (slam=0) or both")
    ap.add_argument("--frames", type=int, default=None, help="first N frames (default all)")
    ap.add_argument("--r-l", default="1/3")
    ap.add_argument("--mt", type=int, default=0, help="the driver's mt= (multi-threaded mapping kernels)")
    ap.add_argument("--late", type=int, default=450)
    ap.add_argument("--early", type=int, default=330)
    ap.add_argument("--lsd", type=Path, default=LSD)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--name", required=True)
    ap.add_argument("--work", type=Path, default=None, help="run files (default OUT/runs/NAME)")
    ap.add_argument("--keep-all", action="store_true", help="keep the traces and the initial maps (1.2 MB each)")
    a = ap.parse_args(argv)
    if not a.lsd.exists():
        sys.exit(f"{a.lsd} not found — build the oracle first (tools/lsd_oracle/build.sh)")
    modes = [m.strip() for m in a.modes.split(",") if m.strip()]
    work = a.work or a.out / "runs" / a.name
    work.mkdir(parents=True, exist_ok=True)
    seq, n = prepare(a.sequence, work, a.frames)
    rows = []
    for seed in a.seeds:
        field = None
        if a.field == "dmtrack":
            field = work / f"field_seed{seed}.bin"
            valid = dmtrack_field(seq, seed, field)
            print(f"seed {seed}: dmtrack's random map, {valid} valid pixels", flush=True)
        for rep in range(a.repeat):
            row: dict = {"seed": seed} if a.repeat == 1 else {"seed": seed, "run": rep}
            for mode in modes:
                pre = "" if mode == "slam" else "vo_"
                prefix = work / (f"{mode}_seed{seed}" + (f"_run{rep}" if a.repeat > 1 else ""))
                r = run_oracle(a.lsd, work, prefix, mode == "slam", seed, field, a.mt)
                m = evaluate(seq, work, prefix, a.r_l)
                for k in ("ate_rmse", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "keyframes",
                          "tracked_frames", "wall_s"):
                    row[pre + k] = m.get(k, r.get(k))
                if mode == "slam":
                    row.update(graph_counts(prefix, a.late, a.early))
                if r["lost_at"] is not None:
                    row[pre + "lost_at"] = r["lost_at"]
                print(f"{prefix.name}: ATE {m['ate_rmse']:.4f}  RPE rot {m['rpe_rot_deg_per_m']:.3f}  "
                      f"trans-angle {m['rpe_trans_angle_deg_per_m']:.2f}  frames {m['tracked_frames']}/{n}  "
                      f"keyframes {m['keyframes']}  {r['wall_s']:.0f} s"
                      + (f"  loops {row['loop_closures']}" if mode == "slam" else "")
                      + (f"  LOST at {r['lost_at']}" if r["lost_at"] is not None else ""), flush=True)
                if not a.keep_all:
                    for tail in ("_trace.jsonl", "_init.bin", "_tum.txt"):
                        Path(f"{prefix}{tail}").unlink(missing_ok=True)
            rows.append(row)
        if field is not None and not a.keep_all:
            field.unlink()
    if not a.keep_all:
        (work / "images.txt").unlink()  # absolute paths of this machine
    cols = [c for c in COLS if any(c in r for r in rows)]
    cols += sorted({k for r in rows for k in r} - set(cols))
    a.out.mkdir(parents=True, exist_ok=True)
    with open(a.out / f"{a.name}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, cols)
        w.writeheader()
        w.writerows(rows)
    start = "dmtrack's random maps" if a.field == "dmtrack" else "LSD-SLAM's srand(seed) maps"
    lines = [f"# {a.name}: LSD-SLAM (tools/lsd_oracle), {a.sequence.name} ({n} frames), {start}, seeds "
             f"{a.seeds[0]}–{a.seeds[-1]}", "",
             "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]  # fmt: skip
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r.get(c)) for c in cols) + " |")
    med = {}
    stats = [c for c in cols if c not in ("seed", "run")]
    for c in stats:
        vals = [r[c] for r in rows if r.get(c) is not None]
        med[c] = statistics.median(vals) if vals else None
    lines.append("| median | " + ("| " if "run" in cols else "") + " | ".join(_fmt(med[c]) for c in stats) + " |")
    (a.out / f"{a.name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
