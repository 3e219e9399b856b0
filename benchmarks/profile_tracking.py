"""Per-stage and per-level profile of the tracker and the frame pyramid (any feature, 1 and 2 numba threads).

Usage::

    python benchmarks/profile_tracking.py [SEQUENCE] [--frames 150] [--threads 1,2] [--repeat 3]
                                          [--feature gray] [--plain] [--json FILE]

``SEQUENCE`` defaults to the demo sequence ``data/7scenes-redkitchen-0000-0299``; the shared 7-Scenes
(``../shared/data/7scenes-0000-0699``) works the same way.

What it measures
----------------
The VO runs frame by frame (:class:`~dmtrack.odometry.vo.VisualOdometry`, mapping on the calling thread), on
images decoded once beforehand. Python timers wrap the kernel entry points the tracker and the pyramid call
(whichever of them the installed ``dmtrack`` has), and attribute every call to its pyramid level:

* ``pyramid`` — :func:`~dmtrack.odometry.frame.build_frame` (``FrameResult.pyramid_ms``); ``downsample`` its 2×2
  means (level of the output); ``pack`` the tracker's (F, ∂F) layout, built lazily during tracking;
* ``reference`` — rebuilding the tracking reference after a map update (``FrameResult.reference_ms``), with
  ``idepth_downsample`` (inverse-depth pyramid) and ``make_points`` (point clouds) inside it;
* ``track`` — :meth:`Tracker.track` (``tracking_ms − reference_ms``), with ``residual`` (residual passes),
  ``normal_eq`` (6×6 normal equations), ``lm_step`` (damped solve + SE(3) exp) and ``python`` (the rest:
  the LM loop in Python, argument packing, calls; formed per run, before the minimum over repeats);
* ``iterations`` / ``evaluations`` — LM normal-equation builds and residual evaluations (counts, not ms).

Runs are deterministic, so the same frame does the same work in every repeat: per frame, stage and level the
minimum over repeats is taken (most of a shared machine's noise goes), then min / median / mean over frames
are reported. Repeats alternate between the thread counts. The timers cost about a microsecond per kernel call
(≈ 0.05 ms per frame); ``--plain`` runs without them (totals only). Every run's trajectory is hashed: the hashes
must agree across repeats and thread counts. The load average before and after is recorded: on a shared machine
compare interleaved A/B runs, never single absolute figures.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from profile_mapping import _config, _load, load_images  # noqa: E402  (the same frames and load figures as the mapping profile)

REPO = Path(__file__).resolve().parents[1]
DEFAULT_SEQUENCE = REPO / "data" / "7scenes-redkitchen-0000-0299"

#: (module, attribute, stage, level rule) of the kernel entry points to time; names a version lacks are skipped.
#: Level rules: ``("shape", k)`` — level of the (h, …) array argument k; ``("down", k)`` — one below it;
#: ``"current"`` — the level of the last residual pass (the normal equations and the step follow it).
WRAPS: tuple[tuple[str, str, str, Any], ...] = (
    ("dmtrack.odometry.frame", "downsample", "downsample", ("down", 0)),
    ("dmtrack.odometry.frame", "pack", "pack", ("shape", 0)),
    ("dmtrack.odometry.tracker", "idepth_downsample", "idepth_downsample", ("down", 0)),
    ("dmtrack.odometry.tracker", "make_points", "make_points", ("shape", 0)),
    ("dmtrack.odometry.tracker", "eval_pass", "residual", ("shape", 4)),  # before the per-N kernels
    ("dmtrack.odometry.tracker", "eval_pass_parallel", "residual", ("shape", 4)),
    ("dmtrack.odometry._tracker_residuals", "_eval_grey", "residual", ("shape", 4)),
    ("dmtrack.odometry._tracker_residuals", "_eval_grey_parallel", "residual", ("shape", 4)),
    ("dmtrack.odometry._tracker_residuals", "_eval_multi", "residual", ("shape", 4)),
    ("dmtrack.odometry._tracker_residuals", "eval_pass_parallel", "residual", ("shape", 4)),
    ("dmtrack.odometry._tracker_multi", "eval_multi", "residual", ("shape", 4)),  # 1 < N <= 32
    ("dmtrack.odometry._tracker_multi", "eval_multi_threaded", "residual", ("shape", 4)),
    ("dmtrack.odometry.tracker", "warp_update", "normal_eq", "current"),
    ("dmtrack.odometry.tracker", "warp_update_parallel", "normal_eq", "current"),
    ("dmtrack.odometry.tracker", "solve_damped", "lm_step", "current"),
    ("dmtrack.odometry.tracker", "se3_exp", "lm_step", "current"),
)
#: Stages inside Tracker.track (the rest of its time is ``python``).
TRACK_PARTS = ("pack", "make_points", "residual", "normal_eq", "lm_step")
#: Table rows, in order: (row, is a count).
ROWS = (
    ("pyramid", False),
    ("downsample", False),
    ("reference", False),
    ("idepth_downsample", False),
    ("make_points", False),
    ("track", False),
    ("pack", False),
    ("residual", False),
    ("normal_eq", False),
    ("lm_step", False),
    ("python", False),
    ("evaluations", True),
    ("iterations", True),
)


class Profiler:
    """Wraps the kernel entry points with timers; ``frame`` holds the current frame's (stage, level) → ms."""

    def __init__(self, height0: int):
        self.height0 = height0
        self.frame: dict[tuple[str, int], float] = defaultdict(float)
        self.level = -1
        self._depth = 0
        self._orig: list[tuple[Any, str, Any]] = []

    def _level_of(self, h: int) -> int:
        return int(round(math.log2(self.height0 / h)))

    def _wrap(self, fn: Any, stage: str, rule: Any) -> Any:
        frame = self.frame
        perf = time.perf_counter

        def timed(*args: Any, **kwargs: Any) -> Any:
            if self._depth:  # called from a timed function (e.g. a serial wrapper of a parallel kernel)
                return fn(*args, **kwargs)
            if rule == "current":
                lvl = self.level
            else:
                lvl = self._level_of(args[rule[1]].shape[0]) + (1 if rule[0] == "down" else 0)
                if stage == "residual":
                    self.level = lvl
            self._depth += 1
            t0 = perf()
            try:
                return fn(*args, **kwargs)
            finally:
                frame[(stage, lvl)] += 1e3 * (perf() - t0)
                self._depth -= 1

        return timed

    def install(self) -> list[str]:
        """Wrap what the installed dmtrack has; returns the wrapped names."""
        import importlib

        done = []
        for mod_name, attr, stage, rule in WRAPS:
            try:
                mod = importlib.import_module(mod_name)
            except ModuleNotFoundError:  # a version without that module
                continue
            fn = getattr(mod, attr, None)
            if fn is None:
                continue
            self._orig.append((mod, attr, fn))
            setattr(mod, attr, self._wrap(fn, stage, rule))
            done.append(f"{mod_name.rsplit('.', 1)[-1]}.{attr}")
        return done

    def uninstall(self) -> None:
        for mod, attr, fn in reversed(self._orig):
            setattr(mod, attr, fn)
        self._orig.clear()


def one_run(
    camera: Any, images: list[tuple[float, np.ndarray]], feature_name: str, threads: int, prof: Profiler | None
) -> tuple[dict[tuple[str, int], np.ndarray], str]:
    """One VO run: (stage, level) → (n,) ms per frame (level −1: whole frame), trajectory hash."""
    import inspect

    import numba

    from dmtrack.features import get_feature
    from dmtrack.odometry.vo import VisualOdometry

    feat = get_feature(feature_name)
    config = _config(feat)  # as `dmtrack run` completes it for the feature
    kwargs: dict[str, Any] = {"threads": threads}
    if "overlap" in inspect.signature(VisualOdometry).parameters:
        kwargs["overlap"] = False  # mapping on the calling thread: stage timers see tracking alone
    vo = VisualOdometry(camera, config, **kwargs)
    recompute = getattr(feat, "pyramid", "downsample") == "recompute"
    n = len(images)
    rows: dict[tuple[str, int], np.ndarray] = defaultdict(lambda: np.zeros(n))
    prev = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        for i, (ts, image) in enumerate(images):
            fmap = feat.compute_pyramid(image, config.pyramid_levels) if recompute else feat.compute(image)
            if prof is not None:
                prof.frame.clear()
            res = vo.process(i, ts, image, fmap)
            ref_ms = getattr(res, "reference_ms", 0.0)
            rows[("pyramid", -1)][i] = res.pyramid_ms
            rows[("reference", -1)][i] = ref_ms
            rows[("track", -1)][i] = res.tracking_ms - ref_ms
            if res.track is not None:
                for lvl, k in res.track.iterations.items():
                    rows[("iterations", lvl)][i] = k
                for lvl, k in res.track.evaluations.items():
                    rows[("evaluations", lvl)][i] = k
            if prof is not None:
                for key, ms in prof.frame.items():
                    rows[key][i] = ms
                inside = sum(ms for (stage, _), ms in prof.frame.items() if stage in TRACK_PARTS)
                rows[("python", -1)][i] = max(rows[("track", -1)][i] - inside, 0.0)
            if vo.stopped:
                raise SystemExit(f"tracking lost at frame {i}: {res.lost_reason}")
        out = vo.finish()
    finally:
        numba.set_num_threads(prev)
    digest = hashlib.sha256(np.ascontiguousarray(out.poses, dtype=np.float64).tobytes()).hexdigest()[:16]
    return dict(rows), digest


def summarise(rows: dict[tuple[str, int], np.ndarray], n_tracked: np.ndarray) -> dict[str, dict[str, Any]]:
    """Per table row: whole-frame and per-level min / median / mean over the tracked frames."""
    levels = sorted({lvl for (_, lvl) in rows if lvl >= 0})
    table: dict[str, dict[str, Any]] = {}
    for name, _ in ROWS:
        per_level = {lvl: rows[(name, lvl)][n_tracked] for lvl in levels if (name, lvl) in rows}
        whole = rows.get((name, -1))
        whole = whole[n_tracked] if whole is not None else sum(per_level.values()) if per_level else None
        if whole is None:
            continue
        entry: dict[str, Any] = {"min": float(whole.min()), "median": float(np.median(whole)),
                                 "mean": float(whole.mean())}  # fmt: skip
        entry["levels"] = {
            str(lvl): {"min": float(a.min()), "median": float(np.median(a)), "mean": float(a.mean())}
            for lvl, a in per_level.items()
        }
        table[name] = entry
    return table


def print_table(threads: int, table: dict[str, dict[str, Any]], n: int) -> None:
    levels = sorted({int(k) for e in table.values() for k in e["levels"]}, reverse=True)
    head = "".join(f"  L{lvl} med/mean" for lvl in levels)
    print(f"\n{threads} thread(s), {n} tracked frames — ms per frame (counts for the last two rows)")
    print(f"{'stage':<18}{'min':>7}{'median':>8}{'mean':>8}{head}")
    for name, is_count in ROWS:
        e = table.get(name)
        if e is None:
            continue
        fmt = "{:7.0f}" if is_count else "{:7.3f}"
        cells = ""
        for lvl in levels:
            cell = e["levels"].get(str(lvl))
            cells += "  " + (fmt.format(cell["median"]) + "/" + fmt.format(cell["mean"]) if cell else " " * 15)
        f2 = "{:7.1f}" if is_count else "{:7.3f}"
        print(f"{name:<18}{f2.format(e['min'])} {f2.format(e['median'])} {f2.format(e['mean'])}{cells}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence", nargs="?", default=str(DEFAULT_SEQUENCE))
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--threads", default="1,2", help="comma-separated numba thread counts (default 1,2)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per thread count; min per frame over them")
    ap.add_argument("--feature", default="gray")
    ap.add_argument("--warmup-frames", type=int, default=30, help="untimed run first (numba compile / cache load)")
    ap.add_argument("--plain", action="store_true", help="no kernel timers (stage totals only)")
    ap.add_argument("--json", default=None, help="write the results to this JSON file")
    args = ap.parse_args(argv)

    import numba

    import dmtrack

    thread_counts = [int(t) for t in args.threads.split(",")]
    load_before = _load()
    t0 = time.perf_counter()
    camera, images = load_images(args.sequence, args.frames)
    print(f"dmtrack {Path(dmtrack.__file__).parent}; {len(images)} frames decoded in {time.perf_counter() - t0:.1f} s")
    prof = None if args.plain else Profiler(int(images[0][1].shape[0]))
    wrapped = prof.install() if prof is not None else []
    t0 = time.perf_counter()
    for t in thread_counts:
        one_run(camera, images[: args.warmup_frames], args.feature, t, None)
    print(f"warm-up: {time.perf_counter() - t0:.1f} s; timed: {', '.join(wrapped) or 'totals only'}")

    best: dict[int, dict[tuple[str, int], np.ndarray]] = {}
    hashes: dict[int, list[str]] = {t: [] for t in thread_counts}
    for r in range(args.repeat):
        for t in thread_counts:  # interleaved, so load changes hit every thread count alike
            rows, digest = one_run(camera, images, args.feature, t, prof)
            hashes[t].append(digest)
            if t not in best:
                best[t] = rows
            else:
                keys = set(best[t]) | set(rows)
                n = len(images)
                best[t] = {k: np.minimum(best[t].get(k, np.zeros(n)), rows.get(k, np.zeros(n))) for k in keys}
            total = rows[("pyramid", -1)] + rows[("reference", -1)] + rows[("track", -1)]
            print(f"run {r + 1}/{args.repeat}, {t} thread(s): pyramid+reference+track {total.sum() / 1e3:.2f} s, "
                  f"hash {digest}")  # fmt: skip
    if prof is not None:
        prof.uninstall()
    load_after = _load()

    results: dict[str, Any] = {}
    for t in thread_counts:
        rows = best[t]
        tracked = rows[("track", -1)] > 0  # the first frame (and keyframe-only frames) is not tracked
        table = summarise(rows, tracked)
        print_table(t, table, int(tracked.sum()))
        results[str(t)] = {"tracked_frames": int(tracked.sum()), "stages": table}
    all_hashes = {h for hs in hashes.values() for h in hs}
    deterministic = len(all_hashes) == 1
    print(f"\ntrajectory hash {sorted(all_hashes)}; identical across repeats and thread counts: {deterministic}")
    print(f"load average before {load_before}, after {load_after}")

    if args.json:
        from dmtrack.io.atomic import write_text

        doc = {
            "sequence": str(args.sequence),
            "feature": args.feature,
            "frames": len(images),
            "repeat": args.repeat,
            "instrumented": prof is not None,
            "timed": wrapped,
            "threads": results,
            "trajectory_hashes": {str(t): h for t, h in hashes.items()},
            "deterministic": deterministic,
            "load_before": load_before,
            "load_after": load_after,
            "cpu_count": os.cpu_count(),
            "numba": numba.__version__,
            "numba_threading_layer": numba.config.THREADING_LAYER,
            "python": sys.version.split()[0],
            "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
        }
        write_text(args.json, json.dumps(doc, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0 if deterministic else 1


if __name__ == "__main__":
    sys.exit(main())
