"""Speed of a whole `dmtrack run` with one start against another, interleaved (issue 30's speed criterion).

Usage::

    python benchmarks/start_speed.py [--sequence ../shared/data/7scenes-0000-0699] [--feature gray] [--frames 700]
        [--inits random,geometric] [--repeat 3] [--out out/benchmarks/start_speed.json]

Runs ``dmtrack run SEQUENCE --feature F --init I --max-frames N --out TMP`` (default outputs on: trajectory, point
cloud, depth pictures, metrics) in a fresh process each, alternating the starts (A B A B …) on a warm numba cache
after one untimed run of each, and reports per start the whole process's wall time and frames per second
(``cli_fps``: interpreter start, imports, reading, the start itself, every output), the run's own loop ``fps``
(``metrics.json``, which includes the geometric start's ``init_s`` but not the kernels' compile time) and ``init_s``
— min / median / max over the repeats. Every repeat of a start must give the same trajectory (SHA-256).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DMTRACK = str(Path(sys.executable).with_name("dmtrack"))


def _run(sequence: Path, feature: str, init: str, frames: int, out: Path) -> dict:
    cmd = [DMTRACK, "run", str(sequence), "--feature", feature, "--init", init, "--max-frames", str(frames),
           "--out", str(out), "--no-progress"]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    m = json.loads((out / "metrics.json").read_text())
    digest = hashlib.sha256((out / "trajectory.txt").read_bytes()).hexdigest()
    return {"wall_s": wall, "cli_fps": m["processed_frames"] / wall, "loop_fps": m["fps"],
            "init_s": m.get("init_s", 0.0), "rpe_rot": m.get("rpe_rot_deg_per_m"), "sha256": digest}


def _stats(values: list[float]) -> dict:
    return {"min": round(min(values), 3), "median": round(statistics.median(values), 3), "max": round(max(values), 3)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sequence", type=Path, default=REPO.parent / "shared" / "data" / "7scenes-0000-0699")
    ap.add_argument("--feature", default="gray")
    ap.add_argument("--frames", type=int, default=700)
    ap.add_argument("--inits", default="random,geometric")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, default=REPO / "out" / "benchmarks" / "start_speed.json")
    a = ap.parse_args(argv)
    inits = a.inits.split(",")
    runs: dict[str, list[dict]] = {i: [] for i in inits}
    with tempfile.TemporaryDirectory() as tmp:
        for init in inits:  # untimed: numba's cache warm for both
            _run(a.sequence, a.feature, init, min(a.frames, 60), Path(tmp) / f"warm-{init}")
        for r in range(a.repeat):
            for init in inits:
                runs[init].append(_run(a.sequence, a.feature, init, a.frames, Path(tmp) / f"{init}-{r}"))
                print(f"{init} repeat {r}: {runs[init][-1]}", flush=True)
    result = {
        "sequence": str(a.sequence), "feature": a.feature, "frames": a.frames, "repeat": a.repeat,
        "machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
        "loadavg_end": os.getloadavg(),
        "starts": {},
    }
    for init, rs in runs.items():
        if len({x["sha256"] for x in rs}) != 1:
            raise SystemExit(f"{init}: the repeats gave different trajectories")
        result["starts"][init] = {k: _stats([x[k] for x in rs]) for k in ("wall_s", "cli_fps", "loop_fps", "init_s")}
        result["starts"][init]["rpe_rot_deg_per_m"] = rs[0]["rpe_rot"]
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(result, indent=1) + "\n")
    for init, st in result["starts"].items():
        print(f"{init:>10}: whole process {st['cli_fps']['median']:.2f} fps (wall {st['wall_s']['median']:.2f} s), "
              f"loop {st['loop_fps']['median']:.2f} fps, start {st['init_s']['median']:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
