"""SLAM against the odometry alone (issue 31): accuracy over starts/seeds, every graph edge against the ground truth,
and the whole-run speed, interleaved.

    python benchmarks/slam_study.py SEQUENCE --feature gray [--init random --seeds 0-4] --out DIR --name NAME
    python benchmarks/slam_study.py SEQUENCE --speed 3 --out DIR --name NAME [more dmtrack run arguments]

Accuracy: one ``dmtrack run --slam`` per seed (one process each, one numba thread, ``--jobs`` at once); each run's
metrics.json has the SLAM trajectory's figures and the odometry's (``vo_*``, the same run's ``trajectory_vo.txt``),
and ``slam_edges.py`` checks its accepted edges. Writes NAME.md and NAME.csv (one row per seed, then the medians).

Speed: ``dmtrack run`` without and with ``--slam``, alternated ``--speed`` times in this order (VO, SLAM, VO, …),
default threads; the wall time of the whole command and ``fps`` of metrics.json (which counts the back end's end:
the run's clock stops when the back end has finished). Writes NAME_speed.json.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from slam_edges import closing, edge_errors  # noqa: E402

KEYS = ("ate_rmse", "vo_ate_rmse", "rpe_rot_deg_per_m", "vo_rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m",
        "vo_rpe_trans_angle_deg_per_m", "loop_closures", "loop_candidates_tested", "graph_edges", "tracked_frames",
        "fps")


def _seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def _dmtrack(args: list[str], threads: int | None) -> float:
    env = dict(os.environ)
    if threads is not None:
        env["NUMBA_NUM_THREADS"] = str(threads)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "dmtrack.cli", *args], check=True, env=env, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def accuracy(a: argparse.Namespace) -> None:
    common = [str(a.sequence), "--feature", a.feature, "--no-depth-images", "--no-pointcloud", "--init", a.init,
              *a.extra]
    runs = {seed: a.out / "runs" / f"{a.name}_seed{seed}" for seed in a.seeds}

    def one(seed: int) -> None:
        _dmtrack(["run", *common, "--seed", str(seed), "--slam", "--out", str(runs[seed])], threads=1)

    with ThreadPoolExecutor(a.jobs) as pool:
        list(pool.map(one, a.seeds))
    rows = []
    for seed, run in runs.items():
        m = json.loads((run / "metrics.json").read_text())
        edges = edge_errors(run)
        loops = [e for e in edges if e["kind"] == "loop"]
        rows.append({"seed": seed, **{k: m.get(k) for k in KEYS},
                     "worst_edge_deg": max((e["rotation_error_deg"] for e in edges), default=None),
                     "worst_loop_edge_deg": max((e["rotation_error_deg"] for e in loops), default=None),
                     "worst_loop_edge_vo_deg": max((e["vo_rotation_error_deg"] for e in loops), default=None),
                     "closing_edges": len(closing(edges, a.late, a.early))})
    cols = list(rows[0])
    with open(a.out / f"{a.name}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, cols)
        w.writeheader()
        w.writerows(rows)
    lines = [f"# {a.name}: {a.sequence.name}, {a.feature}, init {a.init}, seeds {a.seeds[0]}–{a.seeds[-1]}", "",
             "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r[c]) for c in cols) + " |")
    med = {c: statistics.median([r[c] for r in rows if r[c] is not None]) if any(r[c] is not None for r in rows)
           else None for c in cols if c != "seed"}
    lines.append("| median | " + " | ".join(_fmt(med[c]) for c in cols if c != "seed") + " |")
    (a.out / f"{a.name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def _fmt(v: object) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def speed(a: argparse.Namespace) -> None:
    out = a.out / "runs"
    common = [str(a.sequence), "--feature", a.feature, "--no-depth-images", "--no-pointcloud", "--init", a.init,
              *a.extra]
    result: dict[str, list] = {"vo_s": [], "slam_s": [], "vo_fps": [], "slam_fps": []}
    for _ in range(a.speed):
        for kind, extra in (("vo", []), ("slam", ["--slam"])):
            folder = out / f"{a.name}_speed_{kind}"
            result[f"{kind}_s"].append(_dmtrack(["run", *common, *extra, "--out", str(folder)], threads=None))
            result[f"{kind}_fps"].append(json.loads((folder / "metrics.json").read_text())["fps"])
    summary = {k: statistics.median(v) for k, v in result.items()}
    summary["fps_ratio"] = summary["slam_fps"] / summary["vo_fps"]
    (a.out / f"{a.name}_speed.json").write_text(json.dumps({"runs": result, "median": summary}, indent=1) + "\n")
    print(json.dumps(summary, indent=1))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence", type=Path)
    ap.add_argument("--feature", default="gray")
    ap.add_argument("--init", default="geometric")
    ap.add_argument("--seeds", type=_seeds, default=[0])
    ap.add_argument("--late", type=int, default=450)
    ap.add_argument("--early", type=int, default=330)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--speed", type=int, default=0, metavar="N", help="interleaved speed runs instead of accuracy")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--name", required=True)
    a, a.extra = ap.parse_known_args(argv)  # anything else is passed to dmtrack run (e.g. --max-frames 150)
    a.out.mkdir(parents=True, exist_ok=True)
    speed(a) if a.speed else accuracy(a)
    return 0


if __name__ == "__main__":
    sys.exit(main())
