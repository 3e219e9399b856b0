"""The per-run bound of ``results.json``: 1 − shared / √(own² + shared²) for dmtrack's translation direction and
rotation in each run, with its median and range (see README.md). Usage: ``bounds.py`` from the repository root."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).parent / "results.json"


def main() -> None:
    table = json.loads(RESULTS.read_text())
    for set_name in ("held", "chosen"):
        for cal in ("585", "v2"):
            for kind in ("gray", "bitplanes"):
                for what in ("trans", "rot"):
                    bounds = []
                    for run in table[set_name][cal][kind]["three_way_runs"]:
                        own = run[what]["own_rms_deg"]
                        total = float(np.hypot(own["dmtrack"], own["shared"]))
                        bounds.append(100.0 * (1.0 - own["shared"] / total) if total > 0 else 0.0)
                    print(f"{set_name} {cal} {kind} {what}: median {np.median(bounds):.0f} %, range "
                          f"{min(bounds):.0f}–{max(bounds):.0f} %, runs {[round(b) for b in bounds]}")


if __name__ == "__main__":
    main()
