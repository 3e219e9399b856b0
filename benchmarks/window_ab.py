"""The sliding window against today's odometry (issue 38), on frames chosen on and frames held back.

Usage::

    python benchmarks/window_ab.py [--features gray,bitplanes] [--sets tune|held|all|NAME,...]
        [--variant NAME=KEY=VALUE;KEY=VALUE ...] [--jobs 2] [--json FILE]

Variants are ``--set`` overrides of ``dmtrack run`` (or options ``--NAME=VALUE``, e.g.
``--intrinsics=579.5,579.5,320,240``); ``off`` (``window.size=0``) is always run. The run sets:

* ``tune``: 7-Scenes 0–349 and two rendered sequences (``synthetic:``) — where the window's settings were chosen;
* ``held``: 7-Scenes 350–699 started at 350; the start scan's starts 50, 100, …, 500 of 7-Scenes, 160 frames each;
  KITTI 06; Tsukuba (the shared data) — frames the settings were not chosen on.

For each (run, feature, variant): RPE rotation and translation angle (°/m), ATE RMSE, tracked frames, fps. The
table gives per set the median over its runs and the change of each variant against ``off``. One process per run,
one numba thread each, ``--jobs`` at a time.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
SEVEN = str(SHARED / "7scenes-0000-0699")
RUNS: dict[str, list[str]] = {
    "7s-0-699": [SEVEN],
    "7s-0-349": [SEVEN, "--max-frames", "350"],
    "7s-350-699": [SEVEN, "--start", "350"],
    **{f"scan-{s}": [SEVEN, "--start", str(s), "--max-frames", "160"] for s in range(50, 501, 50)},
    "kitti06": [str(SHARED / "kitti-odometry" / "sequences" / "06")],
    "tsukuba": [str(SHARED / "tsukuba-150"), "--intrinsics", "615,615,320,240"],
    "syn-1": ["synthetic:n_frames=300,seed=1"],
    "syn-fwd": ["synthetic:n_frames=300,seed=2,motion=forward"],
}
SETS = {
    "tune": ["7s-0-349", "syn-1", "syn-fwd"],
    "held": ["7s-350-699", *[f"scan-{s}" for s in range(50, 501, 50)], "kitti06", "tsukuba"],
}
SETS["all"] = SETS["tune"] + SETS["held"]
KEYS = ("rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "ate_rmse", "tracked_frames", "total_frames", "fps")


def _run(job: tuple[str, str, str, list[str]]) -> dict:
    run, feature, variant, overrides = job
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_NUM")}
    env["NUMBA_NUM_THREADS"] = "1"
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "dmtrack.cli", "run", *RUNS[run], "--feature", feature, "--out", tmp,
               "--no-progress", "--no-pointcloud", "--no-depth-images"]  # fmt: skip
        for o in overrides:  # a --set override, or a raw option --NAME=VALUE
            cmd += o.split("=", 1) if o.startswith("--") else ["--set", o]
        p = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
        mpath = Path(tmp) / "metrics.json"
        m = json.loads(mpath.read_text()) if mpath.exists() else {}
    row = {"run": run, "feature": feature, "variant": variant, "rc": p.returncode}
    row.update({k: m.get(k) for k in KEYS})
    if "window" in m:
        row["window"] = m["window"]
    if p.returncode:
        row["error"] = p.stderr[-400:]
    print(json.dumps(row), flush=True)
    return row


def _median(rows: list[dict], key: str) -> float | None:
    vals = [r[key] for r in rows if r.get(key) is not None]
    return statistics.median(vals) if vals else None


def table(rows: list[dict], sets: list[str]) -> str:
    """Markdown: per set, feature and variant the medians, and the change against ``off``."""
    lines = ["| set | feature | variant | runs | RPE rot °/m | RPE trans-angle °/m | ATE m | fps | rot Δ | trans Δ |",
             "|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for s in sets:
        names = SETS.get(s, [s])
        for feat in dict.fromkeys(r["feature"] for r in rows):
            base = None
            for var in dict.fromkeys(r["variant"] for r in rows):
                sel = [r for r in rows if r["run"] in names and r["feature"] == feat and r["variant"] == var]
                if not sel:
                    continue
                rot, tra = _median(sel, "rpe_rot_deg_per_m"), _median(sel, "rpe_trans_angle_deg_per_m")
                ate, fps = _median(sel, "ate_rmse"), _median(sel, "fps")
                if var == "off":
                    base = (rot, tra)
                d = ["", ""]
                if base and var != "off" and rot and tra and base[0] and base[1]:
                    d = [f"{100 * (rot / base[0] - 1):+.0f} %", f"{100 * (tra / base[1] - 1):+.0f} %"]
                f = (lambda v, p=2: "–" if v is None else f"{v:.{p}f}")  # noqa: E731
                lines.append(f"| {s} | {feat} | {var} | {len(sel)} | {f(rot)} | {f(tra)} | {f(ate, 3)} | {f(fps, 1)} "
                             f"| {d[0]} | {d[1]} |")  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--features", default="gray,bitplanes")
    ap.add_argument("--sets", default="all")
    ap.add_argument("--variant", action="append", default=[], help="NAME=KEY=VALUE;KEY=VALUE")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--skip-off", action="store_true", help="do not run 'off' (its rows from an earlier --json)")
    ap.add_argument("--off-from", type=Path, help="a JSON of an earlier run whose 'off' rows are reused")
    a = ap.parse_args()
    variants = {} if a.skip_off or a.off_from else {"off": ["window.size=0"]}
    for v in a.variant or ["on=window.size=6"]:
        name, _, sets = v.partition("=")
        variants[name] = [s for s in sets.split(";") if s]
    sets = a.sets.split(",")
    runs = list(dict.fromkeys(r for s in sets for r in SETS.get(s, [s])))
    jobs = [(r, f, n, o) for r in runs for f in a.features.split(",") for n, o in variants.items()]
    with ThreadPoolExecutor(a.jobs) as ex:
        rows = list(ex.map(_run, jobs))
    if a.off_from:  # the odometry alone does not depend on the window's code: the same bytes as then
        rows = [r for r in json.loads(a.off_from.read_text())["rows"] if r["variant"] == "off" and r["run"] in runs
                and r["feature"] in a.features.split(",")] + rows  # fmt: skip
    print(table(rows, sets))
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps({"variants": variants, "rows": rows, "table": table(rows, sets)}, indent=1))


if __name__ == "__main__":
    main()
