"""The run that compiles the numba kernels and the runs that load them from numba's cache give the same bytes.

numba keeps a jitted helper as its own compiled function and as a copy inside each caller's cached machine code;
which copy runs depends on what the cache held when the process started. With fast-math sums the copies rounded
differently, so multichannel runs differed between the first run of a fresh cache and later ones, and — once — a
cache that held a kernel but not its helper made ``make test`` fail (issue 41). The sums now have an order fixed by
the source (:mod:`dmtrack.odometry._lanes`), so every copy gives the same bits. Subprocesses share a fresh
``NUMBA_CACHE_DIR``: the first compiles every kernel, the second loads them all, the third finds the kernels cached
but their helpers gone (the state that broke the fast-math design); all track the same short synthetic sequence with
a 3-channel and an 8-channel feature.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

SEQUENCE = "synthetic:n_frames=12,width=160,height=120"
FEATURES = ("rgb", "bitplanes")

# runs FEATURES into argv[1]/<feature> and prints numba's cache statistics of the tracker and depth kernels
_SCRIPT = f"""
import json, sys
from dmtrack.odometry._depth_update import _observe_rows
from dmtrack.odometry._tracker_residuals import eval_pass_parallel
from dmtrack.pipeline import run_to_directory
for feature in {FEATURES!r}:
    run_to_directory({SEQUENCE!r}, sys.argv[1] + "/" + feature, feature=feature, seed=1, depth_images=False,
                     pointcloud=False)
stats = [k.stats for k in (eval_pass_parallel, _observe_rows)]
print(json.dumps({{"hits": sum(sum(s.cache_hits.values()) for s in stats),
                  "misses": sum(sum(s.cache_misses.values()) for s in stats)}}))
"""


def _run(out: Path, cache: Path) -> dict[str, int]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}  # no disabled JIT, no other cache
    env["NUMBA_CACHE_DIR"] = str(cache)
    proc = subprocess.run([sys.executable, "-c", _SCRIPT, str(out)], capture_output=True, text=True, env=env,
                          timeout=900)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


#: helpers that the kernels call (not inline) and cache on their own: removed from the cache for the third run
HELPERS = ("_chunk_channel_sums", "_window_cost", "_combine_eval")


@pytest.mark.slow  # the first subprocess compiles every kernel: 60-90 s on two cores
def test_compiling_run_and_cached_run_give_the_same_bytes(tmp_path: Path, fault_log) -> None:
    cache = tmp_path / "numba-cache"
    compiled = _run(tmp_path / "compiled", cache)
    partial = tmp_path / "partial-cache"
    shutil.copytree(cache, partial)
    cached = _run(tmp_path / "cached", cache)
    assert compiled["misses"] > 0 and compiled["hits"] == 0, compiled  # really compiled here...
    assert cached["hits"] > 0 and cached["misses"] == 0, cached  # ...and really loaded from the cache there
    removed = [f for f in partial.rglob("*.nb[ic]") if f.name.split("-")[0].split(".")[-1] in HELPERS]
    assert {f.name.split("-")[0].split(".")[-1] for f in removed} == set(HELPERS)
    for f in removed:
        f.unlink()
    helpers_gone = _run(tmp_path / "partial", partial)
    assert helpers_gone["hits"] > 0, helpers_gone  # the kernels came from the cache, without their helpers
    for feature in FEATURES:
        for name in ("trajectory.txt", "keyframes.txt"):
            first = (tmp_path / "compiled" / feature / name).read_bytes()
            assert first.strip(), f"{feature}: empty {name}"
            assert (tmp_path / "cached" / feature / name).read_bytes() == first, f"{feature}: {name} differs"
            assert (tmp_path / "partial" / feature / name).read_bytes() == first, f"{feature}: {name} differs"
    fault_log.tried("determinism", "rgb, bitplanes: the run that compiles the kernels vs a run from numba's cache",
                    n=len(FEATURES))  # fmt: skip
    fault_log.tried("determinism", "rgb, bitplanes: kernels cached without their helpers", n=len(FEATURES))
