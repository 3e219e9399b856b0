"""How far grey's own unrolled alignment moves when started *at* the ground-truth pose (README, table 1).

    python benchmarks/studies/2026-11-27-tracknet-real/ground_truth_consistency.py [SHARED_7SCENES]

Synthetic validation pairs (exact depth and pose), then 24 pairs of the shared 7-Scenes frames (every 50th frame a
keyframe, depth mapped by the odometry at the ground-truth poses) with the dataset's focal length and two others.
"""

import sys

import numpy as np

from dmtrack.odometry.config import TrackerConfig
from dmtrack.training.realdata import SequencePairs
from dmtrack.training.train import TrainOptions, ValidationSet, make_validation, reference_points, to_tensor, validate

path = sys.argv[1] if len(sys.argv) > 1 else "../shared/data/7scenes-0000-0699"
opts = TrainOptions()
tracker = TrackerConfig()


def grey(img):
    return to_tensor(img)[0]


val = make_validation(opts)
at_truth = [p.T_fk.copy() for p in val.pairs]
print("synthetic", validate(grey, ValidationSet(val.pairs, val.refs, at_truth), opts, tracker))
for intrinsics in (None, "525,525,320,240", "550,550,320,240"):
    sp = SequencePairs(path, 0, keyframe_every=50, intrinsics=intrinsics)
    rng = np.random.default_rng(5)
    pairs, refs = [], []
    for _ in range(24):
        p = sp.sample(rng, opts.crop, opts.max_gap)
        pairs.append(p)
        refs.append(reference_points(p.idepth, p.camera, opts.levels, rng, opts.point_fraction, opts.max_points, p.var))
    res = validate(grey, ValidationSet(pairs, refs, [p.T_fk.copy() for p in pairs]), opts, tracker)
    print(intrinsics or "dataset (585)", sp.summary, res, flush=True)
