"""Replay one dense-SIFT observe call with the stereo-projection patch applied (see README.md here).

Usage: ``PYTHONPATH=PATCHED/src python stereo_projection_micro.py K`` (K = 0: all channels, else the stereo basis's
first K axes). Prints the structure-tensor time (serial, threaded) and the observe time with it precomputed.
"""

import sys
import time

import dmtrack
from dmtrack.odometry import _depth_update as U
from dmtrack.odometry import depthmap as D
from dmtrack.odometry._epipolar_stereo import structure_tensor  # only in the patched tree
from dmtrack.odometry.config import VOConfig

found = {}
real = U.observe_numba


def spy(*a, **k):
    found["a"], found["k"], found["state"] = a, k, tuple(x.copy() for x in a[0])
    return real(*a, **k)


D.observe_numba = spy
k_channels = int(sys.argv[1])
dmtrack.track("../shared/data/7scenes-0000-0699", feature="dsift", config=VOConfig(stereo_channels=k_channels),
              max_frames=12)
args, kwargs = list(found["a"]), found["k"]
for parallel in (False, True):
    t0 = time.perf_counter()
    st = structure_tensor(args[1], args[4], 5.0, parallel)
    print("structure tensor ms", parallel, round(1e3 * (time.perf_counter() - t0), 1))
for parallel in (False, True):
    times = []
    for _ in range(5):
        args[0] = tuple(x.copy() for x in found["state"])
        t0 = time.perf_counter()
        counts = real(*args, parallel=parallel, search=kwargs.get("search"), kf_st=st)
        times.append(time.perf_counter() - t0)
    print("K", k_channels, "parallel", parallel, "observe ms", round(1e3 * min(times), 1), list(counts))
