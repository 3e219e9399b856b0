"""Speed of the whole `dmtrack run` command, as a user sees it (issue 14's benchmark).

Usage::

    python benchmarks/speed_cli.py [--sequence ../shared/data/7scenes-0000-0699] [--features gray,bitplanes,dsift]
                                   [--frames 700] [--repeat 3] [--out out/benchmarks/speed_cli.json]

What it measures, per feature
-----------------------------
* ``compile_s``: the numba compilation a first run pays. ``dmtrack run`` on 5 frames with an empty
  ``NUMBA_CACHE_DIR`` (everything is compiled) minus the same command with a warm cache (median of 3 each).
* ``--repeat`` runs of ``dmtrack run SEQUENCE --feature F --max-frames N --out TMP`` with the default outputs on
  (trajectory, point cloud, depth pictures, metrics), in a fresh process each, on a warm cache:

  - ``cli_fps``: frames / wall time of the whole process (interpreter start, imports, reading, every output);
  - ``loop_fps``: the run's own ``metrics.json`` ``fps`` (the frame loop only);
  - ``peak_mb``: the process's peak resident memory (``wait4`` rusage of that child only).

  min / median / max over the repeats are reported. The trajectory's SHA-256 must be the same in every repeat.

``--busy K`` keeps K other processes busy (a pure-Python loop each) during the timed runs: the speed on a machine
that other work shares. ``--env KEY=VALUE`` (repeatable) sets an environment variable of the timed ``dmtrack``
processes, for A/B comparisons (e.g. ``OMP_WAIT_POLICY=active`` against dmtrack's default, passive).

The references are LSD-SLAM's VO (53 fps) and DSO without threads (42 fps) on this kind of machine, 640×480,
from ../shared/design/lsd-slam-spec.md §6. The load average is recorded: on a shared machine, compare like with like.
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
DEFAULT_SEQUENCE = REPO.parent / "shared" / "data" / "7scenes-0000-0699"
REFERENCES_FPS = {"LSD-SLAM VO (C++)": 53.0, "DSO (no threads)": 42.0}


def _dmtrack() -> list[str]:
    exe = Path(sys.executable).with_name("dmtrack")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "dmtrack.cli"]


_BUSY_LOOP = "while True:\n    pass\n"


class Busy:
    """K busy-loop processes while the block runs (``--busy``)."""

    def __init__(self, k: int):
        self.k = int(k)
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> Busy:
        self.procs = [subprocess.Popen([sys.executable, "-c", _BUSY_LOOP]) for _ in range(self.k)]
        return self

    def __exit__(self, *exc: object) -> None:
        for p in self.procs:
            p.kill()
            p.wait()


def run_once(args: list[str], env: dict[str, str] | None = None) -> tuple[float, float]:
    """Run one command; return (wall seconds, peak RSS in MB of that process alone)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
    if proc.returncode != 0:
        raise SystemExit(f"command failed ({proc.returncode}): {' '.join(args)}\n{err}")
    return wall, usage.ru_maxrss / 1024.0  # Linux: kilobytes


def _stats(values: list[float]) -> dict[str, float]:
    return {"min": min(values), "median": statistics.median(values), "max": max(values)}


def compile_seconds(sequence: Path, feature: str, tmp: Path) -> dict[str, float]:
    cmd = [*_dmtrack(), "run", str(sequence), "--feature", feature, "--max-frames", "5", "--out", str(tmp / "c")]
    cold, warm = [], []
    for i in range(3):
        env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp / f"numba-cold-{i}"))
        cold.append(run_once(cmd, env)[0])
        warm.append(run_once(cmd)[0])
    return {"cold_s": statistics.median(cold), "warm_s": statistics.median(warm),
            "compile_s": statistics.median(cold) - statistics.median(warm)}


def measure(sequence: Path, feature: str, frames: int, repeat: int, tmp: Path, env: dict[str, str] | None = None,
            busy: int = 0) -> dict:
    out = tmp / f"run-{feature}"
    cmd = [*_dmtrack(), "run", str(sequence), "--feature", feature, "--max-frames", str(frames), "--out", str(out)]
    run_once([*_dmtrack(), "run", str(sequence), "--feature", feature, "--max-frames", "5", "--out",
              str(tmp / "warm")])  # numba's cache is warm before anything is timed
    walls, peaks, loop_fps, hashes = [], [], [], set()
    for _ in range(repeat):
        with Busy(busy):
            wall, peak = run_once(cmd, env)
        metrics = json.loads((out / "metrics.json").read_text())
        n = metrics["processed_frames"]
        walls.append(n / wall)
        peaks.append(peak)
        loop_fps.append(metrics["fps"])
        hashes.add(hashlib.sha256((out / "trajectory.txt").read_bytes()).hexdigest()[:16])
    return {
        "frames": n,
        "tracked_frames": metrics["tracked_frames"],
        "cli_fps": _stats(walls),
        "loop_fps": _stats(loop_fps),
        "peak_mb": _stats(peaks),
        "trajectory_sha256": sorted(hashes),
        "deterministic": len(hashes) == 1,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sequence", type=Path, default=DEFAULT_SEQUENCE)
    ap.add_argument("--features", default="gray,bitplanes,dsift")
    ap.add_argument("--frames", type=int, default=700)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-compile", action="store_true", help="skip the cold-compile measurement")
    ap.add_argument("--busy", type=int, default=0, help="other processes kept busy during the timed runs")
    ap.add_argument("--env", action="append", default=[], metavar="KEY=VALUE",
                    help="environment variable of the timed dmtrack processes (repeatable)")
    ap.add_argument("--out", type=Path, default=REPO / "out" / "benchmarks" / "speed_cli.json")
    a = ap.parse_args(argv)
    extra = {}
    for item in a.env:
        key, sep, value = item.partition("=")
        if not sep or not key:
            ap.error(f"--env {item!r}: expected KEY=VALUE")
        extra[key] = value
    env = dict(os.environ, **extra) if extra else None
    if not a.sequence.exists():
        raise SystemExit(f"sequence not found: {a.sequence} (the shared data; pass --sequence)")
    result: dict = {
        "sequence": str(a.sequence.name),
        "machine": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                    "python": platform.python_version()},
        "load_before": os.getloadavg(),
        "references_fps": REFERENCES_FPS,
        "busy_processes": a.busy,
        "env": extra,
        "features": {},
    }
    with tempfile.TemporaryDirectory(prefix="dmtrack-speed-") as td:
        tmp = Path(td)
        for feature in [f.strip() for f in a.features.split(",") if f.strip()]:
            r = measure(a.sequence, feature, a.frames, a.repeat, tmp, env, a.busy)
            if not a.no_compile:
                r["compile"] = compile_seconds(a.sequence, feature, tmp)
            result["features"][feature] = r
            c = r["cli_fps"]
            print(f"{feature:10s} cli {c['median']:6.1f} fps (min {c['min']:.1f}, max {c['max']:.1f})  "
                  f"loop {r['loop_fps']['median']:6.1f} fps  peak {r['peak_mb']['max']:6.0f} MB  "
                  f"compile {r.get('compile', {}).get('compile_s', float('nan')):5.1f} s  "
                  f"deterministic={r['deterministic']}", flush=True)
    result["load_after"] = os.getloadavg()
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"references: {', '.join(f'{k} {v:.0f} fps' for k, v in REFERENCES_FPS.items())}; written {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
