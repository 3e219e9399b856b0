"""KITTI 06 0-50: every tracknet weight file tracked from the true pose against grey's map (seeds 0, 1).

Run from the repository root: ``python benchmarks/studies/2026-11-27-tracknet-kitti-diagnostic/weights_at_truth.py``.
Keyframes 8, 13, ..., 43; grey's depth mapped from the 8 frames before each at ground-truth poses (start scale
1/10 m); frames k+1 ... k+4 tracked from their true pose; the median angle of R_gt^T R_est is printed per file.
"""

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # decoupled_tracking.py beside this file
import decoupled_tracking as dt  # noqa: E402

from dmtrack.features import get_feature  # noqa: E402
from dmtrack.features.tracknet import TrackNetFeature  # noqa: E402
from dmtrack.odometry.config import VOConfig  # noqa: E402
from dmtrack.odometry.tracker import Tracker, TrackingReference  # noqa: E402
from dmtrack.pipeline import _for_feature  # noqa: E402

WEIGHTS = {
    "tracknet-prelim (synthetic)": "src/dmtrack/weights/tracknet-prelim.npz",
    "7scenes-only, seed 0": "benchmarks/studies/2026-11-27-tracknet-real/7scenes-s0/tracknet.npz",
    "both, seed 0 (packaged default)": "src/dmtrack/weights/tracknet-7s-synth.npz",
}

seq = dt.Sequence(Path("../shared/data/kitti-odometry/sequences/06"), None, 51)
levels = VOConfig().pyramid_levels
grey = get_feature("gray")
gcfg = _for_feature(VOConfig(), grey)
gframes = seq.frames("gray", grey, levels)
maps = {(k, s): dt.map_keyframe(seq, gframes, gcfg, k, 8, s, 0.1) for k in range(8, 47, 5) for s in (0, 1)}
features = {"gray": grey, "bitplanes": get_feature("bitplanes")}
for label, path in WEIGHTS.items():
    meta = json.loads(str(np.load(path)["meta"]))
    features[label] = TrackNetFeature(scale=float(meta["scale"]), weights=path)
for label, feat in features.items():
    cfg = _for_feature(VOConfig(), feat)
    frames = seq.frames(label, feat, levels)
    tracker = Tracker(cfg.tracker, use_numba=True, parallel=False, channel_cost=cfg.channel_cost,
                      energy_channels=cfg.energy_channels, noise_energy_channels=cfg.noise_energy_channels)
    errs = []
    for (k, _), (d, v) in maps.items():
        ref = TrackingReference.from_keyframe(frames[k], d, v, tuple(cfg.tracker.levels), True)
        for g in range(1, 5):
            T = np.linalg.inv(seq.poses[k + g]) @ seq.poses[k]
            E = np.linalg.inv(T) @ tracker.track(ref, frames[k + g], T).T_fk
            errs.append(dt._rot_deg(E[:3, :3]))
    print(f"{label:34s} median {np.median(errs):.3f}°  mean {np.mean(errs):.3f}°  ({len(errs)} frames)", flush=True)
