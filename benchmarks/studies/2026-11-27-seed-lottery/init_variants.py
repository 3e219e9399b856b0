"""The initialisation experiments of README.md here (monkeypatched, not in the package).

Usage: ``python init_variants.py FEATURE SEEDS KIND VALUE`` with SEEDS comma-separated, on the shared 7-Scenes 0–699:

* ``amp A``: random inverse depth 1 + A·(U − 0.5) instead of LSD-SLAM's 0.5 + U (A = 0: a flat map);
* ``hold M``: the first keyframe must be mapped more than M times before a new keyframe (instead of 5);
* ``boot K``: a two-pass start. Pass 1 runs frames 0…K from the random map; pass 2 starts again at frame 0 with the
  first keyframe's map as pass 1 left it (update count reset) and runs the whole sequence.
"""

import dataclasses
import sys

import numpy as np

from dmtrack.odometry import depthmap, vo
from dmtrack.odometry.config import VOConfig
from dmtrack.pipeline import track_many

feature, seeds, kind, value = sys.argv[1], [int(s) for s in sys.argv[2].split(",")], sys.argv[3], float(sys.argv[4])
if kind == "amp":
    real_init = depthmap.DepthMap.initialize_random

    def initialize_random(self, keyframe, seed):
        real_init(self, keyframe, seed)
        m = self.valid
        d = (1.0 + value * (self.idepth[m].astype(np.float64) - 1.0)).astype(np.float32)
        self.idepth[m] = d
        self.idepth_smoothed[m] = d

    depthmap.DepthMap.initialize_random = initialize_random
elif kind == "boot":
    saved = {}
    real_process = vo.VisualOdometry._process

    def _process_saving(self, *args, **kwargs):
        result = real_process(self, *args, **kwargs)
        if self._n_frames == int(value) + 1 and self._kf_id == 0:
            saved[self.config.seed] = tuple(a.copy() for a in self._dm.state)
        return result

    vo.VisualOdometry._process = _process_saving
    track_many("../shared/data/7scenes-0000-0699", feature, [VOConfig(seed=s) for s in seeds],
               max_frames=int(value) + 1)
    vo.VisualOdometry._process = real_process
    real_init = depthmap.DepthMap.initialize_random

    def initialize_random(self, keyframe, seed):
        real_init(self, keyframe, seed)
        if seed in saved:
            self._set_state(tuple(a.copy() for a in saved[seed]))

    depthmap.DepthMap.initialize_random = initialize_random
elif kind == "hold":
    real_process = vo.VisualOdometry._process

    def _process(self, *args, **kwargs):
        base = self.__dict__.setdefault("_base_config", self.config)
        mapped = int(value) if self._kf_id <= 0 else base.keyframe.min_mapped
        self.config = dataclasses.replace(base, keyframe=dataclasses.replace(base.keyframe, min_mapped=mapped))
        return real_process(self, *args, **kwargs)

    vo.VisualOdometry._process = _process
else:
    raise SystemExit("kind must be amp, hold or boot")
results = track_many("../shared/data/7scenes-0000-0699", feature, [VOConfig(seed=s) for s in seeds])
for seed, r in zip(seeds, results, strict=True):
    m = r.metrics
    print(feature, kind, value, "seed", seed, "tracked", r.tracked_frames, "RPE rot", round(m["rpe_rot_deg_per_m"], 3),
          "trans-angle", round(m["rpe_trans_angle_deg_per_m"], 2), "ATE", round(m["ate_rmse"], 3), flush=True)
