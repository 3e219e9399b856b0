"""Accuracy of a start (random or geometric) over start frames and seeds: one row per (start frame, seed).

Usage::

    python benchmarks/start_study.py SEQUENCE [--init geometric] [--feature gray] [--starts 0,350]
        [--seeds 0-9] [--max-frames N] [--set section.key=value ...] [--jobs 2] [--r-l 1/3]
        [--intrinsics FX,FY,CX,CY] [--out DIR] [--name NAME] [--trajectories]

A random start depends on its seed; a geometric start does not (``--seeds`` is then one seed), but on the frames it
starts from: ``--starts`` runs the same configuration from several frames of a sequence (each run to ``--max-frames``
frames or the end), e.g. to check a choice made on frames 0–349 on frames 350–699. Every run is a separate process
with one numba thread (``--jobs`` at a time; results do not depend on it). Writes ``NAME.csv`` and ``NAME.md`` (the
rows, then per start frame and over all the median and range of each metric, and where the start accepted) into
``--out`` (default ``out/benchmarks``); ``--trajectories`` also writes each run's trajectory
(``NAME_start{F}_seed{S}.txt``) and the ground truth over its frames (``NAME_start{F}_groundtruth.txt``).
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from seed_study import METRICS, REPO, _fraction, _summary  # noqa: E402  (the same parsing and summaries)


def _ints(text: str) -> list[int]:
    from dmtrack.io.bench_layout import parse_seeds

    return parse_seeds(text)  # comma lists and ranges: 0,350 or 0-9


def _run(job: tuple) -> dict:
    sequence, feature, overrides, start, seed, max_frames, r_l, intrinsics, traj_prefix = job
    os.environ["NUMBA_NUM_THREADS"] = "1"
    import warnings

    import dmtrack
    from dmtrack.odometry.config import VOConfig

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a refusal is in the row
        res = dmtrack.track(
            sequence, feature=feature, config=VOConfig().with_overrides(*overrides), seed=seed, start=start,
            max_frames=max_frames, r_l=r_l, intrinsics=intrinsics,
        )  # fmt: skip
    if traj_prefix is not None:
        from dmtrack.io.trajectory import write_tum

        write_tum(f"{traj_prefix}_start{start}_seed{seed}.txt", res.trajectory)
        if res.groundtruth is not None:
            write_tum(f"{traj_prefix}_start{start}_groundtruth.txt", res.groundtruth)
    m = res.metrics
    row = {"start": start, "seed": seed, "tracked": m["tracked_frames"], "total": m["total_frames"],
           "keyframes": m["keyframes"], "init": m.get("init"), "accepted_at": m.get("init_accepted_frame"),
           "refused": m.get("init_refused")}
    row.update({k: m.get(k) for k in METRICS})
    row["fps"] = round(m["fps"], 2) if m.get("fps") else None
    row["init_s"] = m.get("init_s")
    row["wall_s"] = round(time.perf_counter() - t0, 1)
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence")
    ap.add_argument("--init", default="geometric", choices=("random", "geometric"))
    ap.add_argument("--feature", default="gray")
    ap.add_argument("--starts", default="0", help="start frames, e.g. 0,350 (default 0)")
    ap.add_argument("--seeds", default=None, help="seeds, e.g. 0-9 (default: 0-9 random, 0 geometric)")
    ap.add_argument("--max-frames", type=int, default=None)
    ap.add_argument("--set", action="append", default=[], help="config override section.key=value (repeatable)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--r-l", default=None, help="RPE length ratio, e.g. 1/20 (default: per dataset)")
    ap.add_argument("--intrinsics", default=None)
    ap.add_argument("--out", default=str(REPO / "out" / "benchmarks"))
    ap.add_argument("--name", default=None)
    ap.add_argument("--trajectories", action="store_true", help="also write each run's trajectory and the truth")
    a = ap.parse_args(argv)
    starts = _ints(a.starts)
    seeds = _ints(a.seeds or ("0-9" if a.init == "random" else "0"))
    overrides = (f"init={a.init}", *a.set)
    name = a.name or f"start_{Path(a.sequence).name}_{a.feature}_{a.init}"
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    prefix = str(out / name) if a.trajectories else None
    jobs = [(a.sequence, a.feature, overrides, st, s, a.max_frames, _fraction(a.r_l), a.intrinsics, prefix)
            for st in starts for s in seeds]
    rows = []
    with ProcessPoolExecutor(max_workers=max(1, a.jobs)) as pool:
        for row in pool.map(_run, jobs):
            rows.append(row)
            vals = " ".join(f"{k} {row[k]:.4g}" for k in METRICS if row[k] is not None)
            acc = "" if row["init"] != "geometric" else (
                f", refused ({row['refused']})" if row["refused"] else f", accepted at {row['accepted_at']}")
            print(f"start {row['start']} seed {row['seed']}: {row['tracked']}/{row['total']} tracked{acc}, {vals}",
                  flush=True)
    with open(out / f"{name}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    cmd = (f"`python benchmarks/start_study.py {a.sequence} --init {a.init} --feature {a.feature} --starts {a.starts}"
           + (f" --seeds {a.seeds}" if a.seeds else "") + (f" --max-frames {a.max_frames}" if a.max_frames else "")
           + "".join(f" --set {s}" for s in a.set) + (f" --r-l {a.r_l}" if a.r_l else "")
           + (f" --intrinsics {a.intrinsics}" if a.intrinsics else "") + "`")
    lines = [f"# {name}", "", cmd, "",
             "| start | seed | tracked | keyframes | start accepted at | RPE rot | RPE trans-angle | ATE | fps |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        vals = " | ".join("–" if r[k] is None else f"{r[k]:.4g}" for k in METRICS)
        acc = "refused" if r["refused"] else ("–" if r["accepted_at"] is None else str(r["accepted_at"]))
        lines.append(f"| {r['start']} | {r['seed']} | {r['tracked']}/{r['total']} | {r['keyframes']} | {acc} | "
                     f"{vals} | {r['fps'] or '–'} |")
    lines.append("")
    groups = [(f"start {st}", [r for r in rows if r["start"] == st]) for st in starts] if len(starts) > 1 else []
    for label, rs in [*groups, ("all", rows)]:
        lines.append(f"median (range), {label} ({len(rs)} runs): RPE rot {_summary(rs, METRICS[0])}, trans-angle "
                     f"{_summary(rs, METRICS[1])}, ATE {_summary(rs, METRICS[2])}")
    refusals = [r for r in rows if r["refused"]]
    for r in refusals:
        lines.append(f"\nstart {r['start']}: the geometric start refused: {r['refused']}")
    lines.append("")
    (out / f"{name}.md").write_text("\n".join(lines))
    print("\n".join(lines[-len(groups) - 2 - len(refusals):]))
    print(f"wrote {out / (name + '.md')}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
