"""The cost of a PCA-reduced feature against its base, whole runs, interleaved (issue 32).

    python benchmarks/pca_cost.py [--features dsift,dsift-pca8] [--frames 100] [--repeat 3] [--json OUT]

Runs ``dmtrack run`` on the repository's sample sequence (7-Scenes redkitchen, 640×480) for each feature in turn,
``--repeat`` rounds (A, B, A, B, …; default numba threads), and reports the median of metrics.json's ``feature_ms``
(generation: the feature map, and for a reduced feature its projection, per frame), ``tracking_ms``,
``mapping_ms`` and ``fps``. A ``BASE-pcaK`` feature needs its basis in the user's PCA folder
(``dmtrack fit-pca --feature BASE --k K SEQUENCE``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "data" / "7scenes-redkitchen-0000-0299"
KEYS = ("feature_ms", "tracking_ms", "mapping_ms", "fps")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--features", default="dsift,dsift-pca8")
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args(argv)
    features = a.features.split(",")
    runs: dict[str, list[dict]] = {f: [] for f in features}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(a.repeat):
            for f in features:
                out = Path(tmp) / f
                subprocess.run([sys.executable, "-m", "dmtrack.cli", "run", str(SAMPLE), "--feature", f,
                                "--max-frames", str(a.frames), "--no-depth-images", "--no-pointcloud", "--out",
                                str(out)], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                m = json.loads((out / "metrics.json").read_text())
                runs[f].append({k: m[k] for k in (*KEYS, "channels", "feature_scale", "energy_channels")})
    median = {f: {k: statistics.median(r[k] for r in rs) for k in KEYS} for f, rs in runs.items()}
    for f, m in median.items():
        print(f"{f:14s} " + "  ".join(f"{k} {v:8.1f}" for k, v in m.items()))
    if a.json:
        a.json.write_text(json.dumps({"frames": a.frames, "runs": runs, "median": median}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
