"""The study's tables from its run folders (``run.sh``): per calibration, the median RPE of each method over the
held-back and the chosen-on runs, and three_way.py's shared and own errors of each dmtrack variant against DSO.

Usage: table.py RUNS_DIR OUT.json — RUNS_DIR holds KIND-CAL-START-FRAMES/ folders (KIND: dso, gray, bitplanes,
grayw5, bitplanesw5; CAL: 585, v2, self) with metrics.json (dmtrack's, or run_dso.py's).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from three_way import compare  # noqa: E402

HELD = [(s, 160) for s in range(50, 501, 50)] + [(350, 350)]
CHOSEN = [(0, 350)] + [(s, 160) for s in range(25, 476, 50)]
KINDS = ("dso", "gray", "bitplanes", "grayw5", "bitplanesw5", "grayw5m", "grayw7", "grayw7m", "grayw7mk07",
         "grayw7mk10", "grayk10", "grayw7mL0", "grayw7mP2", "grayw7mDP01", "grayw7mI12", "grayl0")


def _metrics(folder: Path) -> dict | None:
    f = folder / "metrics.json"
    if not (folder / "done").exists() or not f.exists():
        return None
    m = json.loads(f.read_text())
    if m.get("rpe_rot_deg_per_m") is None:
        return None
    return m


def _rounded(x):  # noqa: ANN001, ANN202 - 4 significant digits keep the file small and are all the figures carry
    if isinstance(x, float):
        return float(f"{x:.4g}")
    if isinstance(x, dict):
        return {k: _rounded(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_rounded(v) for v in x]
    return x


def main(runs: Path, out: Path) -> None:
    result: dict = {}
    for set_name, runs_of_set in (("held", HELD), ("chosen", CHOSEN)):
        for cal in ("585", "v2", "self"):
            for kind in KINDS:
                rows = []
                for s, n in runs_of_set:
                    m = _metrics(runs / f"{kind}-{cal}-{s}-{n}")
                    if m is not None:
                        rows.append({"run": f"{s}+{n}", "rot": m["rpe_rot_deg_per_m"],
                                     "trans": m["rpe_trans_angle_deg_per_m"], "ate": m.get("ate_rmse")})  # fmt: skip
                if not rows:
                    continue
                entry = {"runs": rows, "n": len(rows),
                         "median_rot": float(np.median([r["rot"] for r in rows])),
                         "median_trans": float(np.median([r["trans"] for r in rows]))}  # fmt: skip
                if kind != "dso":
                    three = []
                    for s, n in runs_of_set:
                        a, b = runs / f"{kind}-{cal}-{s}-{n}", runs / f"dso-{cal}-{s}-{n}"
                        if _metrics(a) is not None and _metrics(b) is not None:
                            three.append(compare(f"{s}+{n}", str(a), str(b)))
                    if three:
                        entry["three_way"] = {
                            what: {
                                "median_deg_per_m": {k: float(np.median([t[what]["deg_per_m"][k] for t in three]))
                                                     for k in three[0][what]["deg_per_m"]},
                                "median_own_rms_deg": {k: float(np.median([t[what]["own_rms_deg"][k] for t in three]))
                                                       for k in three[0][what]["own_rms_deg"]},
                            }
                            for what in ("trans", "rot")
                        }  # fmt: skip
                        entry["three_way_runs"] = three
                result.setdefault(set_name, {}).setdefault(cal, {})[kind] = entry
    out.write_text(json.dumps(_rounded(result), separators=(",", ":")) + "\n")
    for set_name, by_cal in result.items():
        print(f"## {set_name}")
        for cal, by_kind in by_cal.items():
            for kind, e in by_kind.items():
                line = f"{cal:5s} {kind:12s} n={e['n']:2d} median {e['median_rot']:6.2f} / {e['median_trans']:6.1f}"
                if "three_way" in e:
                    t = e["three_way"]["trans"]
                    own = t["median_own_rms_deg"]
                    line += (f" | vs DSO on the same pairs: {t['median_deg_per_m']['dmtrack_dso']:5.1f} °/m;"
                             f" own rms ° dmtrack {own['dmtrack']:4.1f} DSO {own['dso']:4.1f}"
                             f" shared {own['shared']:4.1f}")
                print(line)


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
