"""Interleaved A/B speed of two source trees of dmtrack on the same machine (``dmtrack run``, whole process).

Usage::

    python benchmarks/ab_speed.py --a /path/to/old/src --b src [--sequence ../shared/data/7scenes-0000-0699]
                                  [--features gray,bitplanes] [--frames 300] [--rounds 5] [--out FILE.json]

Each tree runs with its own warm numba cache (one untimed warm-up run per tree and feature first), then the rounds
alternate A, B, A, B, … per feature (A first in even rounds, B first in odd ones), each a fresh ``python -m
dmtrack.cli run`` process with ``PYTHONPATH`` set to the tree. Reported per tree and feature: the run's own
``metrics.json`` ``fps`` (the frame loop) and the wall time of the whole process, median and min/max over the
rounds, and the ratio B/A of the median loop fps. Interleaving cancels slow drifts of a shared machine; the load
average before and after is recorded. The trajectories' SHA-256 of each tree are listed (they must not vary
between the rounds of one tree).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _run(src: Path, cache: Path, sequence: str, feature: str, frames: int, out: Path, extra: list[str]) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(PYTHONPATH=str(src), NUMBA_CACHE_DIR=str(cache))
    cmd = [sys.executable, "-m", "dmtrack.cli", "run", sequence, "--feature", feature, "--max-frames", str(frames),
           "--out", str(out), "--no-progress", *extra]  # fmt: skip
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{src} {feature}: dmtrack run failed:\n{proc.stderr[-2000:]}")
    metrics = json.loads((out / "metrics.json").read_text())
    digest = hashlib.sha256((out / "trajectory.txt").read_bytes()).hexdigest()
    return {"fps": metrics["fps"], "wall_s": wall, "sha256": digest}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--a", required=True, type=Path, help="src folder of tree A (the baseline)")
    ap.add_argument("--b", required=True, type=Path, help="src folder of tree B")
    ap.add_argument("--sequence", default=str(REPO.parent / "shared" / "data" / "7scenes-0000-0699"))
    ap.add_argument("--features", default="gray,bitplanes")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--extra", default="", help="more arguments of dmtrack run, e.g. '--init random'")
    args = ap.parse_args(argv)
    trees = {"A": args.a.resolve(), "B": args.b.resolve()}
    features = args.features.split(",")
    work = Path(tempfile.mkdtemp(prefix="dmtrack-ab-"))
    caches = {k: work / f"cache-{k}" for k in trees}
    load_before = os.getloadavg()
    runs: dict[str, dict[str, list[dict]]] = {k: {f: [] for f in features} for k in trees}
    for feature in features:
        for k, src in trees.items():  # warm-up: compile into the tree's cache
            _run(src, caches[k], args.sequence, feature, 5, work / "warm", args.extra.split())
        for r in range(args.rounds):
            for k in ("A", "B") if r % 2 == 0 else ("B", "A"):
                res = _run(trees[k], caches[k], args.sequence, feature, args.frames, work / f"{k}-{feature}-{r}",
                           args.extra.split())
                runs[k][feature].append(res)
                print(f"{feature} round {r} {k}: {res['fps']:.2f} fps, {res['wall_s']:.2f} s", flush=True)
    summary = {}
    for feature in features:
        row = {}
        for k in trees:
            fps = [x["fps"] for x in runs[k][feature]]
            wall = [x["wall_s"] for x in runs[k][feature]]
            row[k] = {"fps_median": statistics.median(fps), "fps_min": min(fps), "fps_max": max(fps),
                      "wall_median_s": statistics.median(wall),
                      "sha256": sorted({x["sha256"] for x in runs[k][feature]})}  # fmt: skip
        row["b_over_a_fps"] = row["B"]["fps_median"] / row["A"]["fps_median"]
        row["b_over_a_wall"] = row["B"]["wall_median_s"] / row["A"]["wall_median_s"]
        summary[feature] = row
        print(f"{feature}: A {row['A']['fps_median']:.2f} fps, B {row['B']['fps_median']:.2f} fps, "
              f"B/A {row['b_over_a_fps']:.3f} (wall B/A {row['b_over_a_wall']:.3f})")  # fmt: skip
    result = {"trees": {k: str(v) for k, v in trees.items()}, "sequence": args.sequence, "frames": args.frames,
              "extra": args.extra,
              "rounds": args.rounds, "cpu": _cpu(), "load_before": load_before, "load_after": os.getloadavg(),
              "summary": summary, "runs": runs}  # fmt: skip
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=1) + "\n")


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


if __name__ == "__main__":
    main()
