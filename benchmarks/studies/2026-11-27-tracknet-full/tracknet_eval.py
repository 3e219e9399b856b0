"""Evaluate tracknet weight files on the shared sequences, seeds 0–2 (issue 15's table).

Usage::

    python benchmarks/studies/2026-11-27-tracknet-full/tracknet_eval.py --out DIR --weights LABEL=FILE
        [--weights LABEL=FILE ...] [--sequences tsukuba,kitti,7scenes] [--seeds 0-2] [--jobs 2] [--data ../shared/data]

Each ``FILE`` must have been calibrated (:func:`dmtrack.training.train.calibrate_weights`: ``meta`` holds its
default ``scale``, N_E and κ). It is registered as the feature ``tracknet-LABEL`` at that scale and run through
``channel_cost_ablation.py`` with the default rule, so the rows and tables are the same as the other features'
(``DIR/ablation.md``) and finished (sequence, weights) jobs are not run again.
"""

from __future__ import annotations

import argparse
import json
import sys
from functools import partial
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(REPO / "benchmarks"))  # channel_cost_ablation


def _make(path: str, scale: float = 1.0):
    from dmtrack.features.tracknet import TrackNetFeature

    return TrackNetFeature(scale=scale, weights=path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--weights", action="append", required=True, metavar="LABEL=FILE")
    ap.add_argument("--sequences", default="tsukuba,kitti,7scenes")
    ap.add_argument("--seeds", default="0-2")
    ap.add_argument("--jobs", default="2")
    ap.add_argument("--data", default=str(REPO.parent / "shared" / "data"))
    a = ap.parse_args(argv)
    import numpy as np

    from dmtrack.features.base import register

    names = []
    for spec in a.weights:
        label, sep, file = spec.partition("=")
        if not sep or not label or not Path(file).is_file():
            ap.error(f"--weights {spec!r}: expected LABEL=FILE with an existing file")
        with np.load(file) as z:
            meta = json.loads(str(z["meta"]))
        if "scale" not in meta:
            ap.error(f"{file}: not calibrated (no meta['scale']); run dmtrack.training.train.calibrate_weights first")
        name = f"tracknet-{label}"
        register(name, partial(_make, str(Path(file).resolve())), channels=8, scale=float(meta["scale"]),
                 description=f"tracknet weights {file}", replace=True)  # fmt: skip
        names.append(name)
    import channel_cost_ablation

    return channel_cost_ablation.run_default_rule(a.out, names, a.sequences, a.seeds, a.jobs, a.data)


if __name__ == "__main__":
    sys.exit(main())
