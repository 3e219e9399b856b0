"""Where a run's memory goes, and whether it grows with the run's length (issue 39).

Usage::

    python benchmarks/memory_profile.py [--sequence ../shared/data/7scenes-0000-0699] [--feature gray]
        [--lengths 300,700] [--long synthetic:n_frames=5000] [--out out/benchmarks/memory-DATE]

Three measurements, each in fresh processes:

* **Phases** (``phases.json``): one process imports what ``dmtrack run`` imports step by step and runs the sequence
  (``--phase-frames`` frames, default outputs) while a thread samples its resident memory every 5 ms. The table gives
  the resident memory after each step — the interpreter, numpy, OpenCV, numba, dmtrack's modules, numba's first
  kernel (its typing and lowering registries), the other kernels (the warm-up), the first frame (the start done) —
  and the peak of the loop.
* **Live data** (``live.json``): the same run under ``tracemalloc`` (which numpy reports to), a snapshot at frame
  ``--phase-frames``: the bytes Python and numpy hold, by the part of dmtrack that allocated them.
* **Length** (``length.json``, ``length.png``): ``dmtrack run`` with the default outputs on ``--lengths`` frames of
  ``--sequence`` and on ``--long``, its resident memory sampled every 0.1 s (``/proc/PID/status``) against the frames
  written so far (``trajectory.txt`` lines) and its peak (``wait4``). Flat means: the memory after the first few
  hundred frames stays within a few MB (the outputs go to disk as they are made).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEFAULT_SEQUENCE = Path(os.environ.get("DMTRACK_SHARED", REPO.parent / "shared")) / "data" / "7scenes-0000-0699"

# run in a child: resident memory after each import / phase, and the loop's peak (a sampling thread)
_PHASES = r'''
import json, sys, threading, time
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20
marks = [("interpreter", rss())]
samples, stop = [], False
def sample():
    while not stop:
        samples.append(rss()); time.sleep(0.005)
threading.Thread(target=sample, daemon=True).start()
import numpy; marks.append(("numpy", rss()))
import cv2; marks.append(("OpenCV", rss()))
import numba; marks.append(("numba (LLVM)", rss()))
import dmtrack.api as api; from dmtrack.features import get_feature; import yaml
marks.append(("dmtrack's modules", rss()))
from dmtrack.odometry.frame import _downsample_grey_kernel as k
k(numpy.zeros((4, 4, 1), numpy.float32), numpy.zeros((2, 2, 1), numpy.float32))
marks.append(("numba's first kernel (its registries)", rss()))
from dmtrack.pipeline import warm_up
feature = get_feature(sys.argv[2]); warm_up(feature)
marks.append(("the other kernels (warm-up)", rss()))
class Sink:
    n = 0
    def on_frame(self, *a):
        self.n += 1
        if self.n == 1: marks.append(("first frame (the start done)", rss()))
    def on_keyframe(self, *a): pass
    def on_lost(self, *a): pass
    def close(self): pass
before = len(samples)
api.run_to_directory(sys.argv[1], sys.argv[4], feature=feature, max_frames=int(sys.argv[3]), extra_sinks=(Sink(),))
stop = True
marks.append(("the loop's peak", max(samples[before:])))
import resource
print(json.dumps({"marks": marks, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
'''

_LIVE = r'''
import json, sys, tracemalloc
import dmtrack.api as api
from dmtrack.features import get_feature
feature = get_feature(sys.argv[2])
from dmtrack.pipeline import warm_up
warm_up(feature)
tracemalloc.start(8)
snap = {}
n = int(sys.argv[3])
class Sink:
    i = 0
    def on_frame(self, *a):
        self.i += 1
        if self.i == n: snap["s"] = tracemalloc.take_snapshot()
    def on_keyframe(self, *a): pass
    def on_lost(self, *a): pass
    def close(self): pass
api.run_to_directory(sys.argv[1], sys.argv[4], feature=feature, max_frames=n + 1, extra_sinks=(Sink(),))
parts = {}
for st in snap["s"].statistics("traceback"):
    files = [f.filename.replace("\\", "/") for f in st.traceback]
    ours = [f.split("/src/dmtrack/", 1)[1] for f in files if "/src/dmtrack/" in f]
    key = ours[-1] if ours else ("numba" if any("/numba/" in f for f in files) else "other")
    p = parts.setdefault(key, [0, 0]); p[0] += st.size; p[1] += st.count
print(json.dumps({k: {"mb": v[0] / 2**20, "blocks": v[1]} for k, v in parts.items()}))
'''

# what each allocating module holds, in words (the table's groups)
GROUPS = [
    ("odometry/_depth", "the depth map (hypotheses, regularised copies, propagation buffers)"),
    ("odometry/frame", "frame pyramids (current frame, keyframe, tracking reference)"),
    ("odometry/tracker", "tracking reference points and warps"),
    ("odometry/", "the odometry's other state"),
    ("features/", "feature maps (frames in flight and kept)"),
    ("io/images", "decoded images (frames in flight and kept)"),
    ("datasets/", "the sequence's readers"),
    ("initialization/", "the start's first map (still referenced)"),
    ("outputs/", "outputs (sinks)"),
    ("numba", "numba's Python objects (typing, dispatchers)"),
    ("", "everything else"),
]


def _group(key: str) -> str:
    for prefix, words in GROUPS:
        if key.startswith(prefix):
            return words
    return GROUPS[-1][1]


def _dmtrack() -> list[str]:
    exe = Path(sys.executable).with_name("dmtrack")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "dmtrack.cli"]


def _child(code: str, *args: str) -> dict:
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"child failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def length_run(sequence: str, frames: int | None, feature: str, tmp: Path) -> dict:
    """One ``dmtrack run`` with its resident memory sampled against the frames it has written."""
    run_dir = tmp / f"len-{frames}"
    cmd = [*_dmtrack(), "run", sequence, "--feature", feature, "--out", str(run_dir)]
    if frames is not None:
        cmd += ["--max-frames", str(frames)]
    traj = run_dir / "trajectory.txt"
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    samples: list[tuple[float, int, float]] = []
    t0 = time.perf_counter()
    status_path = Path(f"/proc/{proc.pid}/status")
    while proc.poll() is None:
        try:
            rss = next(int(ln.split()[1]) / 1024 for ln in status_path.read_text().splitlines()
                       if ln.startswith("VmRSS"))  # fmt: skip
            done = max(0, traj.read_text().count("\n") - 1) if traj.exists() else 0
        except (OSError, StopIteration, ValueError):
            break
        samples.append((time.perf_counter() - t0, done, rss))
        time.sleep(0.1)
    _, status, usage = os.wait4(proc.pid, 0) if proc.returncode is None else (0, 0, None)
    if proc.returncode not in (None, 0) or (usage is not None and os.waitstatus_to_exitcode(status) != 0):
        raise SystemExit(f"{' '.join(cmd)} failed:\n{proc.stderr.read().decode()[-2000:] if proc.stderr else ''}")
    m = json.loads((run_dir / "metrics.json").read_text())
    ply = run_dir / "pointcloud.ply"
    return {"sequence": sequence, "frames": m["processed_frames"], "keyframes": m["keyframes"],
            "peak_mb": None if usage is None else usage.ru_maxrss / 1024, "samples": samples,
            "pointcloud_mb": ply.stat().st_size / 2**20 if ply.exists() else 0.0}


def flatness(samples: list[tuple[float, int, float]], after: int = 300) -> dict:
    """Resident memory from frame ``after`` on: its range and its slope (MB per 1,000 frames, least squares)."""
    pts = [(f, r) for _, f, r in samples if f >= after]
    if len(pts) < 3:
        return {}
    n = len(pts)
    mf = sum(f for f, _ in pts) / n
    mr = sum(r for _, r in pts) / n
    var = sum((f - mf) ** 2 for f, _ in pts)
    slope = sum((f - mf) * (r - mr) for f, r in pts) / var if var else 0.0
    return {"from_frame": after, "min_mb": min(r for _, r in pts), "max_mb": max(r for _, r in pts),
            "slope_mb_per_1000_frames": 1000 * slope}


def plot(runs: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.6), dpi=120)
    for r in runs:
        f = [s[1] for s in r["samples"]]
        m = [s[2] for s in r["samples"]]
        ax.plot(f, m, label=f"{Path(r['sequence']).name}, {r['frames']} frames (peak {r['peak_mb']:.0f} MB)")
    ax.set_xlabel("frames written")
    ax.set_ylabel("resident memory (MB)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title("dmtrack run, default outputs: memory against the run's length", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sequence", default=str(DEFAULT_SEQUENCE))
    ap.add_argument("--feature", default="gray")
    ap.add_argument("--phase-frames", type=int, default=200)
    ap.add_argument("--lengths", default="300,700")
    ap.add_argument("--long", default="synthetic:n_frames=5000", help="a long sequence ('' to skip)")
    ap.add_argument("--skip", default="", help="comma-separated parts to skip: phases,live,length")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    out = a.out or REPO / "out" / "benchmarks" / f"memory-{datetime.date.today().isoformat()}"
    out.mkdir(parents=True, exist_ok=True)
    skip = {s.strip() for s in a.skip.split(",") if s.strip()}
    tmp = Path(tempfile.mkdtemp(prefix="dmtrack-memory-"))
    if "phases" not in skip:
        ph = _child(_PHASES, a.sequence, a.feature, str(a.phase_frames), str(tmp / "phases"))
        (out / "phases.json").write_text(json.dumps(ph, indent=2) + "\n")
        print("| after | resident | added |\n|---|---|---|")
        prev = 0.0
        for name, mb in ph["marks"]:
            print(f"| {name} | {mb:.0f} MB | {mb - prev:+.0f} MB |")
            prev = mb
        print(f"| peak (rusage) | {ph['peak_mb']:.0f} MB | |\n")
    if "live" not in skip:
        live = _child(_LIVE, a.sequence, a.feature, str(a.phase_frames), str(tmp / "live"))
        (out / "live.json").write_text(json.dumps(live, indent=2) + "\n")
        groups: dict[str, float] = {}
        for key, v in live.items():
            groups[_group(key)] = groups.get(_group(key), 0.0) + v["mb"]
        print(f"live Python/numpy data at frame {a.phase_frames} (tracemalloc):\n| held by | MB |\n|---|---|")
        for g, mb in sorted(groups.items(), key=lambda kv: -kv[1]):
            print(f"| {g} | {mb:.1f} |")
        print(f"| total | {sum(groups.values()):.1f} |\n")
    if "length" not in skip:
        runs = [length_run(a.sequence, int(n), a.feature, tmp) for n in a.lengths.split(",") if n.strip()]
        if a.long:
            runs.append(length_run(a.long, None, a.feature, tmp))
        for r in runs:
            r["flat"] = flatness(r["samples"])
            f = r["flat"]
            print(f"{Path(r['sequence']).name:28s} {r['frames']:5d} frames  peak {r['peak_mb']:6.1f} MB  "
                  + (f"from frame 300: {f['min_mb']:.0f}–{f['max_mb']:.0f} MB, slope "
                     f"{f['slope_mb_per_1000_frames']:+.2f} MB / 1000 frames" if f else ""), flush=True)
        (out / "length.json").write_text(json.dumps(runs) + "\n")
        plot(runs, out / "length.png")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
