"""Merge the ``results.csv`` of several ``dmtrack bench`` folders into one accuracy table (markdown).

Usage::

    python benchmarks/studies/2026-11-21-accuracy/accuracy_table.py LABEL=BENCH_DIR_OR_CSV [LABEL=...]
        [--out FILE.md] [--csv FILE.csv]

Each argument names a bench folder (or its ``results.csv``) and the label its rows get (e.g. ``sum=out/acc-final``
``mean=out/acc-mean``). The table has one row per (feature, label) and, per sequence, the tracked frames and the
paper's RPE figures (rotation and translation-angle error per unit of path; §3.1) and the Sim(3) ATE. A run that
lost tracking is evaluated on the frames it tracked (marked with the frame it was lost at); over a short prefix of
the path the RPE is dominated by the start-up and is not comparable with a full run. ``--csv`` writes the merged
rows (with the label) as well.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path


def _read(spec: str) -> list[dict[str, str]]:
    label, sep, path = spec.partition("=")
    if not sep:
        raise SystemExit(f"accuracy_table.py: expected LABEL=PATH, got {spec!r}")
    p = Path(path)
    if p.is_dir():
        p = p / "results.csv"
    if not p.is_file():
        raise SystemExit(f"accuracy_table.py: {p}: no such results.csv")
    with p.open(newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        r["label"] = label
    return rows


def _num(s: str) -> float:
    try:
        return float(s)
    except (TypeError, ValueError):
        return math.nan


def _fmt(x: float, digits: int = 3) -> str:
    return "–" if math.isnan(x) else f"{x:.{digits}g}" if abs(x) >= 100 else f"{x:.{digits}f}"


def table(rows: list[dict[str, str]]) -> str:
    """Markdown table: one row per (feature, label), column groups per sequence (in first-seen order)."""
    seqs: list[tuple[str, str]] = []
    for r in rows:
        key = (r["sequence"], r.get("dataset", ""))
        if key not in seqs:
            seqs.append(key)
    keys: list[tuple[str, str]] = []
    for r in rows:
        k = (r["feature"], r["label"])
        if k not in keys:
            keys.append(k)
    by = {(r["feature"], r["label"], r["sequence"]): r for r in rows}
    head = "| feature | channel reduction |" + "".join(f" {s} tracked | rot | trans-angle | ATE |" for s, _ in seqs)
    sep = "|---|---|" + "---:|---:|---:|---:|" * len(seqs)
    lines = [head, sep]
    for feat, label in keys:
        cells = [feat, label]
        for s, _ in seqs:
            r = by.get((feat, label, s))
            if r is None:
                cells += ["not run", "", "", ""]
                continue
            tracked = f"{r['tracked_frames']}/{r['total_frames']}"
            if r.get("lost_at"):
                tracked += f" (lost at {r['lost_at']})"
            cells += [
                tracked,
                _fmt(_num(r["rpe_rot_deg_per_m"])),
                _fmt(_num(r["rpe_trans_angle_deg_per_m"])),
                _fmt(_num(r["ate_rmse"])),
            ]
        lines.append("| " + " | ".join(cells) + " |")
    units = "; ".join(
        f"{s}: RPE in °/{'cm' if ds == 'Tsukuba' else 'm'} of path, ATE in {'cm' if ds == 'Tsukuba' else 'm'}"
        for s, ds in seqs
    )
    return "\n".join(lines) + f"\n\nUnits — {units}.\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="+", help="LABEL=BENCH_DIR (or LABEL=results.csv)")
    ap.add_argument("--out", type=Path, default=None, help="write the markdown table here (default: stdout)")
    ap.add_argument("--csv", type=Path, default=None, help="also write the merged rows as CSV")
    args = ap.parse_args(argv)
    rows = [r for spec in args.inputs for r in _read(spec)]
    md = table(rows)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(md)
    else:
        sys.stdout.write(md)
    if args.csv:
        fields = ["label"] + [k for k in rows[0] if k != "label"]
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with args.csv.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
