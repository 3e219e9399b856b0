"""dmtrack against LSD-SLAM's C++ VO on the same machine, in one command (issue 39's table).

Usage::

    python benchmarks/speed_vs_lsd.py [--sequence ../shared/data/7scenes-0000-0699] [--frames 700]
        [--features gray,bitplanes] [--windows 0,5] [--rounds 3] [--lsd tools/lsd_oracle/_build/lsd_oracle]
        [--out out/benchmarks/speed-vs-lsd-DATE] [--readme README.md]

What it runs
------------
* **LSD-SLAM**: ``tools/lsd_oracle`` (build it first: ``tools/lsd_oracle/build.sh``, about 10 minutes), VO mode,
  single-threaded mapping, the ROS start-up parameters, ``srand(1)``, without its trace hooks (``trace=0``), on the
  same image files (a list and a
  calibration written into the output folder as ``tools/lsd_oracle/compare.py run`` writes them).
* **dmtrack**: ``dmtrack run SEQUENCE --feature F --max-frames N --out TMP`` with the default outputs (trajectory,
  point cloud, depth pictures, metrics) and, per ``--windows`` value K > 0, ``--window K``; numba's cache is warmed
  by one untimed run of each variant first.

Each round runs every variant once, in order (interleaved, so that a machine's slow minute touches all of them);
each run is a fresh whole process. Per run: wall time (``perf_counter`` around the process), CPU time (user + system)
and peak resident memory (``wait4``'s rusage of that process alone), and for dmtrack its own ``metrics.json``
start-up times (``startup``) and loop speed. Runs are appended to ``runs.jsonl`` as they finish (an interrupted
benchmark keeps them); ``summary.json`` and ``table.md`` hold the medians. ``--readme`` replaces the part of that file
between ``<!-- speed-vs-lsd:begin -->`` and ``<!-- speed-vs-lsd:end -->`` with the table.

Speed is LSD-SLAM's median wall time over dmtrack's (> 1: dmtrack is faster).
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEFAULT_SEQUENCE = Path(os.environ.get("DMTRACK_SHARED", REPO.parent / "shared")) / "data" / "7scenes-0000-0699"
DEFAULT_LSD = Path(os.environ.get("LSD_ORACLE", REPO / "tools" / "lsd_oracle" / "_build" / "lsd_oracle"))
BEGIN, END = "<!-- speed-vs-lsd:begin -->", "<!-- speed-vs-lsd:end -->"


def _dmtrack() -> list[str]:
    exe = Path(sys.executable).with_name("dmtrack")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "dmtrack.cli"]


def _rss_parts(pid: int, peaks: dict[str, float], done: threading.Event) -> None:
    """Until ``done``: the largest anonymous and file-backed resident memory (MB) of ``pid`` seen every 10 ms
    (``/proc/PID/status``: RssAnon, RssFile; Linux)."""
    while not done.is_set():
        try:
            with open(f"/proc/{pid}/status", encoding="ascii") as fh:
                for line in fh:
                    key = line.split(":", 1)[0]
                    if key in ("RssAnon", "RssFile"):
                        mb = int(line.split()[1]) / 1024.0
                        peaks[key] = max(peaks.get(key, 0.0), mb)
        except (OSError, ValueError, IndexError):
            return
        done.wait(0.01)


def run_process(args: list[str], env: dict[str, str] | None = None) -> dict[str, float]:
    """Run one command to its end; wall, CPU (user + system) seconds and peak RSS (MB) of that process alone, and
    (Linux, sampled every 10 ms) the peaks of its anonymous memory — what only this process holds: heap, stacks,
    the JIT's code — and of its file-backed memory — libraries' and files' pages, shared and given back by the
    system as it needs them."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    peaks: dict[str, float] = {}
    done = threading.Event()
    sampler = threading.Thread(target=_rss_parts, args=(proc.pid, peaks, done), daemon=True)
    sampler.start()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    done.set()
    sampler.join()
    code = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
    if code != 0:
        raise SystemExit(f"command failed ({code}): {' '.join(args)}\n{err[-2000:]}")
    return {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime, "user_s": usage.ru_utime,
            "sys_s": usage.ru_stime, "peak_mb": usage.ru_maxrss / 1024.0,
            "peak_anon_mb": peaks.get("RssAnon"), "peak_file_mb": peaks.get("RssFile")}


def lsd_inputs(sequence: Path, frames: int, out: Path) -> tuple[Path, Path, int]:
    """images.txt and calib.txt for the oracle (the sequence's own files; sizes that are multiples of 16)."""
    sys.path.insert(0, str(REPO / "src"))
    from dmtrack.datasets import open_sequence

    seq = open_sequence(sequence)
    cam, _ = seq.camera.crop_to_multiple(16)
    if (seq.width, seq.height) != (cam.width, cam.height):
        raise SystemExit(f"{sequence}: {seq.width}x{seq.height} is not a multiple of 16; use "
                         "tools/lsd_oracle/compare.py run to write cropped images first")
    n = min(frames, len(seq))
    files = [str(Path(seq[i].path).resolve()) for i in range(n)]
    images, calib = out / "images.txt", out / "calib.txt"
    images.write_text("\n".join(files) + "\n")
    w, h = cam.width, cam.height
    calib.write_text(f"{cam.fx / w:.12g} {cam.fy / h:.12g} {(cam.cx + 0.5) / w:.12g} {(cam.cy + 0.5) / h:.12g} 0\n"
                     f"{w} {h}\nnone\n{w} {h}\n")
    return images, calib, n


def _median(rows: list[dict], key: str) -> float:
    return float(statistics.median(r[key] for r in rows))


def summarise(runs: list[dict]) -> dict:
    names = list(dict.fromkeys(r["variant"] for r in runs))
    out: dict = {}
    for name in names:
        rows = [r for r in runs if r["variant"] == name]
        s = {k: _median(rows, k) for k in ("wall_s", "cpu_s", "peak_mb")}
        for k in ("peak_anon_mb", "peak_file_mb"):
            if all(r.get(k) is not None for r in rows):
                s[k] = _median(rows, k)
        s["rounds"] = len(rows)
        s["wall_all"] = [round(r["wall_s"], 2) for r in rows]
        s["peak_max_mb"] = max(r["peak_mb"] for r in rows)
        if "loop_fps" in rows[0]:
            s["loop_fps"] = _median(rows, "loop_fps")
            s["trajectories"] = sorted({r["trajectory_sha256"] for r in rows})
            for k in ("import_s", "first_frame_s"):
                vals = [r["startup"][k] for r in rows if r.get("startup", {}).get(k) is not None]
                if vals:
                    s[k] = float(statistics.median(vals))
        out[name] = s
    lsd = out.get("LSD-SLAM")
    if lsd:
        for s in out.values():
            s["speed_vs_lsd"] = lsd["wall_s"] / s["wall_s"]
            s["cpu_vs_lsd"] = s["cpu_s"] / lsd["cpu_s"]
            s["peak_vs_lsd"] = s["peak_mb"] / lsd["peak_mb"]
    return out


def table(summary: dict, frames: int, machine: str, date: str) -> str:
    lines = [
        f"Whole process, {frames} frames, medians of {max(s['rounds'] for s in summary.values())} interleaved rounds "
        f"({machine}, {date}; `benchmarks/speed_vs_lsd.py`):",
        "",
        "| | wall | speed vs LSD-SLAM | CPU (user + sys) | peak memory | of it: anonymous / file-backed (peaks) "
        "| dmtrack's loop | first frame after launch |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, s in summary.items():
        loop = f"{s['loop_fps']:.1f} fps" if "loop_fps" in s else "–"
        first = f"{s['first_frame_s']:.2f} s" if "first_frame_s" in s else "–"
        parts = f"{s['peak_anon_mb']:.0f} / {s['peak_file_mb']:.0f} MB" if "peak_anon_mb" in s else "–"
        lines.append(f"| {name} | {s['wall_s']:.1f} s | {s.get('speed_vs_lsd', float('nan')):.2f}× | "
                     f"{s['cpu_s']:.1f} s | {s['peak_mb']:.0f} MB | {parts} | {loop} | {first} |")
    return "\n".join(lines) + "\n"


def update_readme(path: Path, text: str) -> None:
    doc = path.read_text()
    if BEGIN not in doc or END not in doc:
        raise SystemExit(f"{path}: no {BEGIN} … {END} block to replace")
    head, rest = doc.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    path.write_text(f"{head}{BEGIN}\n{text}{END}{tail}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sequence", type=Path, default=DEFAULT_SEQUENCE)
    ap.add_argument("--frames", type=int, default=700)
    ap.add_argument("--features", default="gray,bitplanes")
    ap.add_argument("--windows", default="0", help="window sizes: 0 = the odometry alone, K = --window K")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--lsd", type=Path, default=DEFAULT_LSD, help="the oracle's binary (tools/lsd_oracle/build.sh)")
    ap.add_argument("--no-lsd", action="store_true", help="dmtrack only (no ratios)")
    ap.add_argument("--out", type=Path, default=None, help="default: out/benchmarks/speed-vs-lsd-DATE")
    ap.add_argument("--readme", type=Path, default=None, help="replace this file's speed-vs-lsd block")
    ap.add_argument("--baseline", type=Path, default=None, metavar="SRC",
                    help="another dmtrack source tree (its src/ folder, e.g. a git worktree of an older commit): its "
                         "grey run joins the rounds as 'dmtrack gray (baseline)', with its own numba cache")
    a = ap.parse_args(argv)
    date = datetime.date.today().isoformat()
    out = a.out or REPO / "out" / "benchmarks" / f"speed-vs-lsd-{date}"
    out.mkdir(parents=True, exist_ok=True)
    if not a.sequence.exists():
        raise SystemExit(f"sequence not found: {a.sequence} (the shared data; pass --sequence)")
    if not a.no_lsd and not a.lsd.exists():
        raise SystemExit(f"{a.lsd} not found: build LSD-SLAM first (tools/lsd_oracle/build.sh), pass --lsd, "
                         "or --no-lsd")
    images, calib, n = lsd_inputs(a.sequence, a.frames, out)
    tmp = Path(tempfile.mkdtemp(prefix="speed-vs-lsd-"))
    variants: list[tuple[str, list[str], Path | None, dict[str, str] | None]] = []
    if not a.no_lsd:
        variants.append(("LSD-SLAM", [str(a.lsd), f"files={images}", f"calib={calib}", f"out={tmp / 'lsd'}",
                                      "seed=1", "trace=0"], None, None))  # fmt: skip
    for feature in [f.strip() for f in a.features.split(",") if f.strip()]:
        for k in [int(w) for w in a.windows.split(",")]:
            name = f"dmtrack {feature}" + (f" window {k}" if k else "")
            run_dir = tmp / name.replace(" ", "-")
            cmd = [*_dmtrack(), "run", str(a.sequence), "--feature", feature, "--max-frames", str(n),
                   "--out", str(run_dir)]  # fmt: skip
            if k:
                cmd += ["--window", str(k)]
            variants.append((name, cmd, run_dir, None))
    if a.baseline is not None:
        env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
        env.update(PYTHONPATH=str(a.baseline.resolve()), NUMBA_CACHE_DIR=str(tmp / "numba-baseline"))
        run_dir = tmp / "baseline"
        variants.append(("dmtrack gray (baseline)", [sys.executable, "-m", "dmtrack.cli", "run", str(a.sequence),
                         "--feature", "gray", "--max-frames", str(n), "--out", str(run_dir)], run_dir, env))
    for _, cmd, run_dir, env in variants:
        if run_dir is not None:  # numba's cache warm before anything is timed
            i = cmd.index("--max-frames")
            run_process([*cmd[: i + 1], "5", *cmd[i + 2 :]], env)
    from dmtrack.io.machine import cpu_model

    machine = f"{os.cpu_count()} cores, {cpu_model()}"
    runs: list[dict] = []
    with (out / "runs.jsonl").open("w") as log:
        for r in range(a.rounds):
            for name, cmd, run_dir, env in variants:
                row = {"round": r, "variant": name, "load": os.getloadavg()[0], **run_process(cmd, env)}
                if run_dir is not None:
                    m = json.loads((run_dir / "metrics.json").read_text())
                    row.update(loop_fps=m["fps"], frames=m["processed_frames"], startup=m.get("startup", {}),
                               trajectory_sha256=hashlib.sha256((run_dir / "trajectory.txt").read_bytes())
                               .hexdigest()[:16])  # fmt: skip
                runs.append(row)
                log.write(json.dumps(row) + "\n")
                log.flush()
                print(f"round {r + 1}/{a.rounds}  {name:28s} wall {row['wall_s']:6.2f} s  cpu {row['cpu_s']:6.2f} s"
                      f"  peak {row['peak_mb']:6.0f} MB", flush=True)
    summary = summarise(runs)
    (out / "summary.json").write_text(json.dumps({
        "sequence": a.sequence.name, "frames": n, "rounds": a.rounds, "machine": machine, "date": date,
        "python": platform.python_version(), "variants": summary}, indent=2) + "\n")
    text = table(summary, n, machine, date)
    (out / "table.md").write_text(text)
    print(text)
    if a.readme is not None:
        update_readme(a.readme, text)
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
