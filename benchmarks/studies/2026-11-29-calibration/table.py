"""The held-back medians of this study's runs (``held_*.json``, written by ``benchmarks/window_ab.py``).

Usage: ``python benchmarks/studies/2026-11-29-calibration/table.py`` (from the repository root).
"""

from __future__ import annotations

import json
import statistics
from pathlib import Path

HERE = Path(__file__).resolve().parent
HELD = ["7s-350-699"] + [f"scan-{s}" for s in range(50, 501, 50)]
DISJOINT = ["7s-350-699"] + [f"scan-{s}" for s in range(350, 501, 50)]  # no frame before 350
NAMES = {"off": "documented 585, pinhole", "w5": "585, window 5", "crop": "525, k1 −0.08 (crop)",
         "full": "525, k1 −0.08 (full)", "c555": "555, k1 −0.04", "c555w5": "555, k1 −0.04, window 5",
         "tracks": "tracks on 0–349: 509.8, k1 −0.048", "tracksw5": "tracks on 0–349, window 5",
         "affine": "tracks (affine) on 0–349: 517.7, k1 −0.036", "affinew5": "tracks (affine) on 0–349, window 5"}


def main() -> None:
    rows = []
    for name in ("held_calibrations.json", "held_c555.json", "held_c555_window.json", "held_tracks.json",
                 "held_tracks_window.json", "held_tracks_affine.json"):
        rows += json.loads((HERE / name).read_text())["rows"]
    seen = set()
    rows = [r for r in rows if (k := (r["run"], r["feature"], r["variant"])) not in seen and not seen.add(k)]
    print("| feature | calibration | 11 held runs: rot / trans-angle °/m | change | 5 disjoint runs | change |")
    print("|---|---|---|---|---|---|")
    for feat in ("gray", "bitplanes"):
        base = {}
        for var in NAMES:
            cells = []
            for set_name, runs in (("held", HELD), ("disjoint", DISJOINT)):
                sel = [r for r in rows if r["feature"] == feat and r["variant"] == var and r["run"] in runs
                       and r.get("rpe_rot_deg_per_m") is not None]
                if len(sel) != len(runs):
                    cells += ["–", ""]
                    continue
                rot = statistics.median(r["rpe_rot_deg_per_m"] for r in sel)
                tra = statistics.median(r["rpe_trans_angle_deg_per_m"] for r in sel)
                if var == "off":
                    base[set_name] = (rot, tra)
                    change = ""
                else:
                    b = base[set_name]
                    change = f"{100 * (rot / b[0] - 1):+.0f} % / {100 * (tra / b[1] - 1):+.0f} %"
                cells += [f"{rot:.2f} / {tra:.1f}", change]
            print(f"| {feat} | {NAMES[var]} | " + " | ".join(cells) + " |")
    thirteen(rows)


def thirteen(rows: list[dict]) -> None:
    """The issue's 13 held-back runs: the 11 of 7-Scenes with the calibration from corner tracks and the window, and
    KITTI 06 and Tsukuba (their calibrations are known) with the window alone; against the odometry with the
    documented calibrations."""
    other = json.loads((HERE / "held_window_kitti_tsukuba.json").read_text())["rows"]
    print("\n| feature | 13 held runs: today (585) | calibration + window 5 | change |\n|---|---|---|---|")
    for feat in ("gray", "bitplanes"):
        def med(var7: str, var_other: str, feat: str = feat) -> tuple[float, float]:
            sel = [r for r in rows if r["feature"] == feat and r["variant"] == var7 and r["run"] in HELD]
            sel += [r for r in other if r["feature"] == feat and r["variant"] == var_other]
            assert len(sel) == 13, len(sel)
            return (statistics.median(r["rpe_rot_deg_per_m"] for r in sel),
                    statistics.median(r["rpe_trans_angle_deg_per_m"] for r in sel))  # fmt: skip

        b = med("off", "off")
        for var in ("tracksw5", "affinew5"):
            v = med(var, "w5")
            print(f"| {feat} | {b[0]:.2f} / {b[1]:.1f} | {NAMES[var]}: {v[0]:.2f} / {v[1]:.1f} | "
                  f"{100 * (v[0] / b[0] - 1):+.0f} % / {100 * (v[1] / b[1] - 1):+.0f} % |")


if __name__ == "__main__":
    main()
