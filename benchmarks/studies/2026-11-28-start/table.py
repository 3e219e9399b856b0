"""Prints the tables of README.md from before.json, forward_before.json and after.json (run in this folder)."""

import json
import re
import statistics
from pathlib import Path


def load(f: str) -> list[dict]:
    d = json.loads(Path(f).read_text())
    return d["rows"] if isinstance(d, dict) else d


def key(r: dict) -> tuple[str, int]:
    if "case" in r:  # forward_before.json: v{speed}-s{seed}
        v, seed = re.match(r"v(\d+)-s(\d+)", r["case"]).groups()
        return (f"forward {v} m/s, seed {seed}", r["start"])
    s = r["sequence"]
    if s.startswith("synthetic"):
        g = dict(kv.split("=") for kv in s.split(":", 1)[1].split(",") if "=" in kv)
        return (f"forward {g['speed']} m/s, seed {g['seed']}", r["start"])
    return ({"06": "KITTI 06"}.get(Path(s).name, Path(s).name), r["start"])


def accepted(x: dict | None) -> str:
    if x is None:
        return "—"
    if "error" in x:
        return "error"
    if x.get("init_accepted_frame") is None:
        return "refused → random"
    return f"+{x['init_accepted_frame'] - x['start']}"


def figures(xs: list[dict]) -> str:
    med = statistics.median
    return (f"{med(x['rpe_rot_deg_per_m'] for x in xs):.3f} / {med(x['rpe_trans_angle_deg_per_m'] for x in xs):.2f}, "
            f"{med(x['ate_rmse'] for x in xs):.3f}")  # fmt: skip


def main() -> None:
    before = [r for r in load("before.json") if "error" not in r] + load("forward_before.json")
    after = load("after.json")
    by_key = {key(r): r for r in before}
    print("| sequence | start | before: accepted | RPE rot / trans (°/m), ATE (m) | after: accepted "
          "| RPE rot / trans (°/m), ATE (m) |")  # fmt: skip
    print("|---|---:|---|---|---|---|")
    groups: dict[str, list[tuple[dict, dict]]] = {}
    for r in after:
        k = key(r)
        b = by_key.get(k)
        print(f"| {k[0]} | {k[1]} | {accepted(b)} | {'—' if b is None else figures([b])} | {accepted(r)} "
              f"| {figures([r])} |")  # fmt: skip
        groups.setdefault(k[0].split(",")[0], []).append((b, r))
    print()
    print("| case | starts | before: median RPE rot / trans, ATE | after: median RPE rot / trans, ATE "
          "| after better on rot |")  # fmt: skip
    print("|---|---:|---|---|---|")
    for g, pairs in groups.items():
        wins = sum(a["rpe_rot_deg_per_m"] < b["rpe_rot_deg_per_m"] for b, a in pairs)
        print(f"| {g} | {len(pairs)} | {figures([b for b, _ in pairs])} | {figures([a for _, a in pairs])} "
              f"| {wins}/{len(pairs)} |")  # fmt: skip


if __name__ == "__main__":
    main()
