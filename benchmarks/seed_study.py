"""Accuracy over random initialisations: run one configuration with several seeds and report medians and ranges.

Usage::

    python benchmarks/seed_study.py SEQUENCE [--seeds 0-9] [--feature gray] [--set section.key=value ...]
        [--jobs 2] [--max-frames N] [--r-l 1/3] [--intrinsics FX,FY,CX,CY] [--out DIR] [--name NAME]
        [--trajectories]

It studies the random start (``init="random"``, the paper's and LSD-SLAM's; ``--set init=geometric`` runs the
default start, which does not depend on the seed). A monocular run from a random initial depth can land in
different basins: on 7-Scenes one seed's RPE differs
2–3× from the next (LSD-SLAM itself does the same, ``docs/lsd-slam-fidelity.md``). A claim that something is
more or less accurate is therefore a median over seeds (and its range), never one run. This script runs
:func:`dmtrack.track` for every seed (one process per run, one numba thread each, ``--jobs`` at a time; results
do not depend on it), and writes ``NAME.csv`` (one row per seed: tracked frames, keyframes, RPE rotation and
translation angle, ATE) and ``NAME.md`` (the rows, then median and range of each metric, and the median over
the first three seeds) into ``--out`` (default ``out/benchmarks``). ``--trajectories`` also writes every seed's
estimated trajectory (``NAME_seedS.txt``, TUM) and the ground truth (``NAME_groundtruth.txt``) there, e.g. for
``benchmarks/orientation_drift.py``.
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
METRICS = ("rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "ate_rmse")


def _fraction(text: str | None) -> float | None:
    if text is None:
        return None
    num, _, den = text.partition("/")
    return float(num) / float(den) if den else float(num)


def _run(job: tuple) -> dict:
    sequence, feature, overrides, seed, max_frames, r_l, intrinsics, traj_prefix = job
    os.environ["NUMBA_NUM_THREADS"] = "1"
    import dmtrack
    from dmtrack.odometry.config import VOConfig

    t0 = time.perf_counter()
    res = dmtrack.track(
        sequence,
        feature=feature,
        config=VOConfig(init="random").with_overrides(*overrides),  # seeds: the random start (--set init=geometric)
        seed=seed,
        max_frames=max_frames,
        r_l=r_l,
        intrinsics=intrinsics,
    )
    if traj_prefix is not None:
        from dmtrack.io.trajectory import write_tum

        write_tum(f"{traj_prefix}_seed{seed}.txt", res.trajectory)
        if res.groundtruth is not None:
            write_tum(f"{traj_prefix}_groundtruth.txt", res.groundtruth)
    m = res.metrics
    row = {"seed": seed, "tracked": m["tracked_frames"], "total": m["total_frames"], "keyframes": m["keyframes"]}
    row.update({k: m.get(k) for k in METRICS})
    row["wall_s"] = round(time.perf_counter() - t0, 1)
    return row


def _summary(rows: list[dict], key: str) -> str:
    vals = [r[key] for r in rows if r[key] is not None]
    if not vals:
        return "–"
    return f"{statistics.median(vals):.4g} ({min(vals):.4g}–{max(vals):.4g})"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence")
    ap.add_argument("--seeds", default="0-9", help="e.g. 0-9 or 0,1,2 (default 0-9)")
    ap.add_argument("--feature", default="gray")
    ap.add_argument("--set", action="append", default=[], help="config override section.key=value (repeatable)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--r-l", default=None, help="RPE length ratio, e.g. 1/20 (default: per dataset)")
    ap.add_argument("--intrinsics", default=None)
    ap.add_argument("--out", default=str(REPO / "out" / "benchmarks"))
    ap.add_argument("--name", default=None)
    ap.add_argument("--trajectories", action="store_true", help="also write each seed's trajectory and the truth")
    a = ap.parse_args(argv)
    from dmtrack.io.bench_layout import parse_seeds

    seeds = parse_seeds(a.seeds)
    name = a.name or f"seeds_{Path(a.sequence).name}_{a.feature}"
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    prefix = str(out / name) if a.trajectories else None
    jobs = [(a.sequence, a.feature, tuple(a.set), s, a.max_frames, _fraction(a.r_l), a.intrinsics, prefix)
            for s in seeds]
    with ProcessPoolExecutor(max_workers=max(1, a.jobs)) as pool:
        rows = []
        for row in pool.map(_run, jobs):
            rows.append(row)
            vals = " ".join(f"{k} {row[k]:.4g}" for k in METRICS if row[k] is not None)
            print(f"seed {row['seed']}: {row['tracked']}/{row['total']} tracked, {row['keyframes']} kf, {vals}")
    with open(out / f"{name}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = [
        f"# {name}",
        "",
        f"`python benchmarks/seed_study.py {a.sequence} --seeds {a.seeds} --feature {a.feature}"
        + "".join(f" --set {s}" for s in a.set)
        + (f" --max-frames {a.max_frames}" if a.max_frames else "")
        + (f" --r-l {a.r_l}" if a.r_l else "")
        + "`",
        "",
        "| seed | tracked | keyframes | RPE rot | RPE trans-angle | ATE |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        vals = " | ".join("–" if r[k] is None else f"{r[k]:.4g}" for k in METRICS)
        lines.append(f"| {r['seed']} | {r['tracked']}/{r['total']} | {r['keyframes']} | {vals} |")
    first3 = rows[:3]
    lines += [
        "",
        f"median (range) over {len(rows)} seeds: RPE rot {_summary(rows, METRICS[0])}, trans-angle "
        f"{_summary(rows, METRICS[1])}, ATE {_summary(rows, METRICS[2])}",
        f"median (range) over seeds {', '.join(str(r['seed']) for r in first3)}: RPE rot "
        f"{_summary(first3, METRICS[0])}, trans-angle {_summary(first3, METRICS[1])}, "
        f"ATE {_summary(first3, METRICS[2])}",
        "",
    ]
    (out / f"{name}.md").write_text("\n".join(lines))
    print("\n".join(lines[-4:]))
    print(f"wrote {out / (name + '.md')}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
