"""Time one depth-map observe (line stereo + filter update) of a real frame, replayed on a saved pre-state.

Usage::

    python benchmarks/studies/2026-11-27-dsift-stereo/profile_observe.py [SEQUENCE] [--feature dsift] [--frames 12]
        [--repeat 5] [--quantize STEP] [--json FILE]

The VO runs ``--frames`` frames of ``SEQUENCE`` (default: the shared 7-Scenes, else the demo sequence); the last
:func:`~dmtrack.odometry._depth_update.observe_numba` call is captured with its arguments and the depth map's state
before it. That call is then replayed ``--repeat`` times per setting, serially and with the row threads
(``parallel``), each time on a fresh copy of the pre-state, and the minimum time is reported with the counters
(created / updated), which must agree between the serial and the threaded replays (exit 1 otherwise).

``--quantize STEP`` adds a replay of the same call with the keyframe and reference maps stored as uint8
(``round(F / STEP)``, clipped to 0…255) and the residual factor multiplied by STEP², which keeps every threshold's
meaning: a measure of what 8-bit feature storage would save in the stereo (an experiment; the odometry stores
float32). It only makes sense for features with non-negative values below 255·STEP (dense SIFT at its default
scale: 0…172).

The question it answers (issue 14): what bounds the 128-channel stereo — the channel arithmetic or the memory
traffic of the (H, W, 128) float32 maps. Results: ``benchmarks/studies/2026-11-27-dsift-stereo/``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[3]
SHARED_7SCENES = REPO.parent / "shared" / "data" / "7scenes-0000-0699"
DEMO = REPO / "data" / "7scenes-redkitchen-0000-0299"


def capture(sequence: str, feature: str, frames: int) -> tuple[list[Any], tuple[np.ndarray, ...]]:
    """The arguments and pre-state of the last observe call of a ``frames``-frame run."""
    import dmtrack
    from dmtrack.odometry import _depth_update, depthmap

    found: dict[str, Any] = {}
    real = _depth_update.observe_numba

    def spy(*args: Any, **kwargs: Any) -> Any:
        found["args"] = list(args)
        found["state"] = tuple(a.copy() for a in args[0])
        return real(*args, **kwargs)

    depthmap.observe_numba = spy
    try:
        dmtrack.track(sequence, feature=feature, max_frames=frames)
    finally:
        depthmap.observe_numba = real
    if "args" not in found:
        raise SystemExit(f"no depth update in the first {frames} frames of {sequence}")
    return found["args"], found["state"]


def replay(args: list[Any], state: tuple[np.ndarray, ...], parallel: bool, repeat: int) -> tuple[float, list[int]]:
    from dmtrack.odometry._depth_update import observe_numba

    times = []
    counts: list[int] = []
    for _ in range(repeat):
        call = list(args)
        call[0] = tuple(a.copy() for a in state)
        t0 = time.perf_counter()
        c = observe_numba(*call, parallel=parallel)
        times.append(time.perf_counter() - t0)
        counts = [int(x) for x in c]
    return 1e3 * min(times), counts


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sequence", nargs="?", default=str(SHARED_7SCENES if SHARED_7SCENES.is_dir() else DEMO))
    ap.add_argument("--feature", default="dsift")
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--quantize", type=float, default=0.0, help="also replay with uint8 maps of this step")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    from dmtrack.odometry._depth_common import COUNT_NAMES

    args, state = capture(a.sequence, a.feature, a.frames)
    kf, ref = args[1], args[5]
    settings: dict[str, list[Any]] = {"float32": args}
    if a.quantize > 0:
        step = float(a.quantize)
        if float(kf.min()) < 0 or float(kf.max()) > 255 * step:
            print(f"warning: values {float(kf.min()):.1f}…{float(kf.max()):.1f} do not fit uint8 at step {step}")
        q = [np.clip(np.rint(m / step), 0, 255).astype(np.uint8) for m in (kf, ref)]
        quant = list(args)
        quant[1], quant[5], quant[9] = q[0], q[1], float(args[9]) * step * step
        settings[f"uint8 (step {step:g})"] = quant
    rows = []
    agree = True
    for name, call in settings.items():
        serial_counts = None
        for parallel in (False, True):
            ms, counts = replay(call, state, parallel, a.repeat)
            if serial_counts is None:
                serial_counts = counts
            elif counts != serial_counts:
                agree = False
                print(f"{name}: the threaded replay's counters differ from the serial one's", file=sys.stderr)
            named = dict(zip(COUNT_NAMES, counts, strict=True))
            rows.append({"maps": name, "parallel": parallel, "observe_ms": round(ms, 2), "counts": named})
            print(f"{name:<18} parallel={parallel!s:<5} observe {ms:7.1f} ms   created {named['created']:6d}  "
                  f"updated {named['updated']:6d}", flush=True)
    if a.json:
        meta = {"sequence": a.sequence, "feature": a.feature, "frames": a.frames, "repeat": a.repeat,
                "map_shape": list(kf.shape), "map_dtype": str(kf.dtype), "load_before": os.getloadavg()[0]}
        Path(a.json).write_text(json.dumps({"meta": meta, "rows": rows}, indent=1) + "\n", encoding="utf-8")
    return 0 if agree else 1


if __name__ == "__main__":
    sys.exit(main())
