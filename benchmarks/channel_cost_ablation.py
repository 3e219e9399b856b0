"""Channel-cost ablation: every feature × channel rule × seed on the shared sequences, medians and ranges.

Usage::

    python benchmarks/channel_cost_ablation.py --out DIR [--features rgb,lab,bitplanes,dsift]
        [--sequences 7scenes,tsukuba,kitti] [--seeds 0-2] [--variant NAME=KEY=VALUE[;KEY=VALUE...] ...]
        [--max-frames N] [--jobs 2] [--data ../shared/data] [--table-only]

Default variants: the three values of ``channel_cost`` (``sum`` = the paper's literal squared L2 norm,
``mean``, ``balanced`` = the default rule, docs/multichannel-cost.md). One job per (sequence, feature) runs
:func:`dmtrack.api.track_many`: each frame is read and its feature computed once and given to one odometry per
(variant, seed) — the results are those of separate ``dmtrack run``s (the odometries share no state), at a
fraction of the cost for the expensive features. Jobs run ``--jobs`` at a time, one numba thread each; a finished
job's rows are kept in ``DIR/rows/`` and not recomputed when the command is run again (resume).

Writes ``DIR/ablation.csv`` (one row per run) and ``DIR/ablation.md`` (per sequence × feature × variant: tracked
frames, RPE rotation and translation angle and ATE as median and min–max over the seeds).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: name → (folder under the data directory, open_sequence options, r_l, unit of RPE and ATE)
SEQUENCES = {
    "7scenes": ("7scenes-0000-0699", {}, 1.0 / 3.0, "°/m, m"),
    "tsukuba": ("tsukuba-150", {"intrinsics": "615,615,320,240"}, 1.0 / 20.0, "°/cm, cm"),
    "kitti": ("kitti-odometry/sequences/06", {}, 1.0 / 20.0, "°/m, m"),
}
METRICS = ("rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "ate_rmse")
DEFAULT_VARIANTS = {"sum": ["channel_cost=sum"], "mean": ["channel_cost=mean"], "balanced": ["channel_cost=balanced"]}


def _job(job: tuple) -> list[dict]:
    seq_key, path, opts, r_l, feature, variants, seeds, max_frames, rows_file = job
    os.environ["NUMBA_NUM_THREADS"] = "1"
    import numba

    numba.set_num_threads(1)
    from dmtrack.api import track_many
    from dmtrack.odometry.config import VOConfig

    keys = [(v, s) for v in variants for s in seeds]
    configs = [VOConfig(init="random").with_overrides(*variants[v], f"seed={s}") for v, s in keys]
    t0 = time.perf_counter()
    results = track_many(path, feature, configs, max_frames=max_frames, r_l=r_l, **opts)
    wall = time.perf_counter() - t0
    rows = []
    for (v, s), res in zip(keys, results, strict=True):
        m = res.metrics
        rows.append(
            {
                "sequence": seq_key,
                "feature": feature,
                "variant": v,
                "overrides": ";".join(variants[v]),
                "seed": s,
                "tracked": m["tracked_frames"],
                "total": m["total_frames"],
                "lost_at": m["lost_at"],
                "lost_reason": m.get("lost_reason"),
                "keyframes": m["keyframes"],
                "info_channels": m.get("info_channels"),
                **{k: m.get(k) for k in METRICS},
                "job_wall_s": round(wall, 1),
            }
        )
    tmp = rows_file.with_suffix(".tmp")
    tmp.write_text(json.dumps(rows, indent=1))
    os.replace(tmp, rows_file)
    return rows


def _fmt(vals: list[float | None], digits: int = 3) -> str:
    v = [x for x in vals if x is not None]
    if not v:
        return "–"
    med = statistics.median(v)
    return f"{med:.{digits}g} ({min(v):.{digits}g}–{max(v):.{digits}g})" if len(v) > 1 else f"{med:.{digits}g}"


def write_tables(out: Path, rows: list[dict], seeds: list[int]) -> None:
    cols = list(dict.fromkeys(k for r in rows for k in r))  # rows from older runs may lack later columns
    with open(out / "ablation.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        w.writerows(rows)
    lines = [
        f"# Channel-cost ablation: median (min–max) over seeds {','.join(map(str, seeds))}",
        "",
        "A run that lost tracking has its RPE/ATE over the prefix it tracked (not comparable with a full run);",
        "`tracked` gives the median tracked frames and the worst seed.",
        "",
    ]
    for seq_key in dict.fromkeys(r["sequence"] for r in rows):
        unit = SEQUENCES[seq_key][3]
        lines += [
            f"## {seq_key} (RPE, ATE in {unit})",
            "",
            "| feature | variant | κ | tracked (median, worst) | RPE rot | RPE trans-angle | ATE |",
            "|---|---|---:|---|---|---|---|",
        ]
        for r0 in [r for r in rows if r["sequence"] == seq_key and r["seed"] == seeds[0]]:
            grp = [
                r
                for r in rows
                if r["sequence"] == seq_key and r["feature"] == r0["feature"] and r["variant"] == r0["variant"]
            ]
            tr = [r["tracked"] for r in grp]
            kappa = r0["info_channels"]
            lines.append(
                f"| {r0['feature']} | {r0['variant']} | {'' if kappa is None else f'{kappa:.3g}'} | "
                f"{statistics.median(tr):g}/{r0['total']} (worst {min(tr)}) | "
                + " | ".join(_fmt([r[k] for r in grp]) for k in METRICS)
                + " |"
            )
        lines.append("")
    (out / "ablation.md").write_text("\n".join(lines))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--features", default="rgb,lab,bitplanes,dsift")
    ap.add_argument("--sequences", default="7scenes,tsukuba,kitti")
    ap.add_argument("--seeds", default="0-2")
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=KEY=VALUE[;KEY=VALUE...]")
    ap.add_argument("--max-frames", type=int)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument(
        "--table-only",
        action="store_true",
        help="run nothing: write the tables from every finished (sequence, feature) in DIR/rows/ that has all the "
        "variants and seeds asked for (e.g. when some features were run on only some sequences)",
    )
    a = ap.parse_args(argv)
    from dmtrack.io.bench_layout import parse_seeds

    seeds = parse_seeds(a.seeds)
    variants = dict(DEFAULT_VARIANTS)
    if a.variant:
        variants = {}
        for spec in a.variant:
            name, _, ov = spec.partition("=")
            variants[name] = [x for x in ov.split(";") if x]
    out = a.out
    (out / "rows").mkdir(parents=True, exist_ok=True)
    jobs, rows = [], []
    for seq_key in a.sequences.split(","):
        folder, opts, r_l, _unit = SEQUENCES[seq_key]
        path = a.data / folder
        if not a.table_only and not path.exists():
            print(f"skipping {seq_key}: {path} not found", file=sys.stderr)
            continue
        for feature in a.features.split(","):
            rows_file = out / "rows" / f"{seq_key}__{feature}.json"
            if rows_file.exists():
                done = json.loads(rows_file.read_text())
                if {(r["variant"], r["seed"]) for r in done} >= {(v, s) for v in variants for s in seeds}:
                    rows += [r for r in done if r["variant"] in variants and r["seed"] in seeds]
                    continue
            if not a.table_only:
                jobs.append((seq_key, str(path), opts, r_l, feature, variants, seeds, a.max_frames, rows_file))
    # longest jobs first (7-Scenes has the most frames, dsift/tfeat/disk the most channels)
    cost = {"7scenes": 700, "tsukuba": 150, "kitti": 75}
    jobs.sort(key=lambda j: -cost.get(j[0], 100) * (128 if j[4] in ("dsift", "tfeat", "disk") else 8))
    with ProcessPoolExecutor(max_workers=max(1, a.jobs)) as pool:
        for job_rows in pool.map(_job, jobs):
            rows += job_rows
            r = job_rows[0]
            print(f"done {r['sequence']} {r['feature']} ({r['job_wall_s']} s)", flush=True)
    order = {k: i for i, k in enumerate(a.sequences.split(","))}
    forder = {k: i for i, k in enumerate(a.features.split(","))}
    vorder = {k: i for i, k in enumerate(variants)}
    def rank(r: dict) -> tuple:
        return (order.get(r["sequence"], 99), forder.get(r["feature"], 99), vorder.get(r["variant"], 99), r["seed"])

    rows.sort(key=rank)
    if rows:
        write_tables(out, rows, seeds)
        print((out / "ablation.md").read_text())
    return 0


def run_default_rule(out: Path, features: list[str], sequences: str, seeds: str, jobs: str, data: str) -> int:
    """:func:`main` for ``features`` (registered by the caller before the pool forks) with the default rule only."""
    return main(["--out", str(out), "--features", ",".join(features), "--sequences", sequences, "--seeds", seeds,
                 "--jobs", str(jobs), "--data", str(data), "--variant", "balanced=channel_cost=balanced"])  # fmt: skip


if __name__ == "__main__":
    sys.exit(main())
