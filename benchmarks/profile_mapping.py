"""Per-stage profile of the depth-map (mapping) kernels, replayed deterministically (1 and 2 numba threads).

Usage::

    python benchmarks/profile_mapping.py [SEQUENCE] [--frames 150] [--threads 1,2] [--repeat 3]
                                         [--feature gray] [--json FILE]

``SEQUENCE`` defaults to the demo sequence ``data/7scenes-redkitchen-0000-0299``; the shared 7-Scenes
(``../shared/data/7scenes-0000-0699``) works the same way.

What it measures
----------------
First a *recording* run: the VO (:class:`~dmtrack.odometry.vo.VisualOdometry`, one thread, mapping on the
calling thread) processes the first ``--frames`` frames (images decoded once beforehand) while the depth-map
calls it makes — the random initialisation, every :meth:`~dmtrack.odometry.depthmap.DepthMap.update`, every
:meth:`~dmtrack.odometry.depthmap.DepthMap.create_keyframe` and the final
:meth:`~dmtrack.odometry.depthmap.DepthMap.finalize` — are recorded with their inputs (frame index, pose, the
tracker's ``ref_pixel_was_good`` flags and residual). No kernel is timed there.

Then *replays*: the recorded calls are applied to a fresh :class:`DepthMap` in the same order (frames rebuilt
from the decoded images, untimed), with ``--threads`` numba threads (``parallel`` as the VO sets it: on for more
than one thread). The replay does exactly the mapping work of the real run and nothing else — tracking does not
run beside it — and the stage times come from :attr:`DepthMap.timings_ms` (``time.perf_counter`` around each
stage, which :class:`DepthMap` always records):

* per update: ``observe`` (observeDepth: line stereo + EKF), ``fill_holes``, ``regularize`` and ``update`` (their
  sum with the Python around them); ``snapshot`` — the tracking snapshot the VO takes after every update;
* per keyframe: ``kf.finalize`` (fill holes + regularize of the old map), ``kf.propagate``,
  ``kf.regularize_fill`` (regularize(true) → fill holes → regularize(false) of the new map), ``kf.scale`` and
  ``keyframe`` (their sum); ``final`` — the last keyframe's finalize at the end of the run.

The same call does the same work in every replay: per call the minimum over ``--repeat`` replays is taken (most
of a shared machine's noise goes), then min / median / mean over the calls and the total per tracked frame
(``ms/frame``) are reported. Replays alternate between the thread counts. After every replay the final map is
hashed (all eight per-pixel arrays): every replay must give the recording run's hash — the benchmark exits 1
otherwise. The load average before and after is recorded: on a shared machine compare interleaved A/B runs
(e.g. two checkouts through ``PYTHONPATH``), never single absolute figures.
"""

from __future__ import annotations

import argparse
import hashlib
import inspect
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_SEQUENCE = REPO / "data" / "7scenes-redkitchen-0000-0299"

#: Table rows, in order: (row, source), source = (event kind, key of DepthMap.timings_ms).
ROWS = (
    ("observe", ("update", "observe")),
    ("fill_holes", ("update", "fill_holes")),
    ("regularize", ("update", "regularize")),
    ("update", ("update", "total")),
    ("snapshot", ("update", "snapshot")),
    ("kf.finalize", ("keyframe", "finalize")),
    ("kf.propagate", ("keyframe", "propagate")),
    ("kf.regularize_fill", ("keyframe", "regularize_fill")),
    ("kf.scale", ("keyframe", "scale")),
    ("keyframe", ("keyframe", "total")),
    ("final", ("finalize", "total")),
)


def _load() -> list[float]:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:  # pragma: no cover - platform without getloadavg
        return []


def load_images(sequence: str, frames: int) -> tuple[Any, list[tuple[float, np.ndarray]]]:
    """(cropped camera, [(timestamp, cropped image)]) of the first ``frames`` frames, decoded once."""
    from dmtrack.datasets import open_sequence
    from dmtrack.geometry.camera import crop_image

    seq = open_sequence(sequence)
    camera, box = seq.camera.crop_to_multiple(16)
    out = []
    for i in range(min(frames, len(seq))):
        fr = seq[i]
        out.append((float(fr.timestamp), crop_image(fr.image, box)))
    return camera, out


def state_digest(dm: Any) -> str:
    """sha256 (16 hex) of the eight per-pixel arrays of a depth map."""
    h = hashlib.sha256()
    for a in dm.state:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def _config(feat: Any) -> Any:
    """The configuration ``dmtrack run`` uses for ``feat``: the defaults completed by the pipeline (Gray-A's affine
    brightness, the feature's measured energy/information channel counts of the multichannel cost rule)."""
    from dmtrack.odometry.config import VOConfig

    config = VOConfig(init="random")  # the odometry alone
    try:
        from dmtrack.pipeline import _for_feature
    except ImportError:  # an older tree
        if getattr(feat, "affine_brightness", False):
            config = config.with_overrides("tracker.affine=true")
        return config
    return _for_feature(config, feat)


class Frames:
    """Builds the VO's :class:`Frame` of image ``i`` on demand (the same arithmetic as ``VisualOdometry``)."""

    def __init__(self, camera: Any, images: list[tuple[float, np.ndarray]], feat: Any, config: Any):
        self.camera, self.images, self.feat, self.config = camera, images, feat, config
        self.recompute = getattr(feat, "pyramid", "downsample") == "recompute"

    def fmap(self, i: int) -> np.ndarray:
        image = self.images[i][1]
        levels = self.config.pyramid_levels
        return self.feat.compute_pyramid(image, levels) if self.recompute else self.feat.compute(image)

    def __call__(self, i: int) -> Any:
        from dmtrack.odometry.frame import build_frame

        ts, image = self.images[i]
        return build_frame(i, ts, image, self.fmap(i), self.camera, self.config.pyramid_levels, True)


def record(frames: Frames) -> tuple[list[tuple], str, int]:
    """Run the VO over the frames on one thread; return (depth-map calls, final map hash, tracked frames)."""
    from dmtrack.odometry.depthmap import DepthMap
    from dmtrack.odometry.vo import VisualOdometry

    events: list[tuple] = []
    depth = [0]  # nesting: calls made by a recorded call (create_keyframe → finalize) are not recorded
    orig = {name: getattr(DepthMap, name) for name in ("initialize_random", "update", "create_keyframe", "finalize")}

    def wrap(name: str) -> Any:
        fn = orig[name]

        def recorded(self: Any, *args: Any, **kwargs: Any) -> Any:
            if depth[0] == 0:
                bound = inspect.signature(fn).bind(self, *args, **kwargs)
                bound.apply_defaults()
                a = dict(bound.arguments)
                a.pop("self")
                for key in ("keyframe", "frame", "new_keyframe"):
                    if key in a:
                        a[key] = int(a[key].index)
                a = {k: (np.array(v, copy=True) if isinstance(v, np.ndarray) else v) for k, v in a.items()}
                events.append((name, a))
            depth[0] += 1
            try:
                return fn(self, *args, **kwargs)
            finally:
                depth[0] -= 1

        return recorded

    kwargs: dict[str, Any] = {"threads": 1}
    if "overlap" in inspect.signature(VisualOdometry).parameters:
        kwargs["overlap"] = False
    vo = VisualOdometry(frames.camera, frames.config, **kwargs)
    for name in orig:
        setattr(DepthMap, name, wrap(name))
    try:
        for i, (ts, image) in enumerate(frames.images):
            vo.process(i, ts, image, frames.fmap(i))
            if vo.stopped:
                raise SystemExit(f"tracking lost at frame {i}")
        out = vo.finish()
    finally:
        for name, fn in orig.items():
            setattr(DepthMap, name, fn)
    return events, state_digest(vo.depth_map), int(out.tracked_frames)


def replay(events: list[tuple], frames: Frames, threads: int) -> tuple[dict[str, list[float]], str]:
    """Apply the recorded calls to a fresh map with ``threads`` numba threads; (row → ms per call, final hash).

    Row ``searches`` holds the line-stereo searches of every update (created + updated attempts), not times."""
    import numba

    from dmtrack.odometry.depthmap import DepthMap

    cfg = frames.config
    rows: dict[str, list[float]] = {name: [] for name, _ in ROWS}
    prev = numba.get_num_threads()
    numba.set_num_threads(threads)
    perf = time.perf_counter
    try:
        dm = DepthMap(
            cfg.depth,
            parallel=threads > 1,
            channel_cost=cfg.channel_cost,
            info_channels=cfg.info_channels,
            energy_channels=cfg.energy_channels,
        )
        for name, a in events:
            if name == "initialize_random":
                dm.initialize_random(frames(a["keyframe"]), a["seed"])
            elif name == "update":
                dm.update(frames(a["frame"]), a["T_fk"], a["ref_pixel_was_good"], a["initial_tracked_residual"])
                t0 = perf()
                dm.tracking_snapshot()
                tm = {**dm.timings_ms, "snapshot": 1e3 * (perf() - t0)}
                for row, (kind, key) in ROWS:
                    if kind == "update":
                        rows[row].append(tm[key])
                c = dm.last_counts
                rows.setdefault("searches", []).append(c["create_attempted"] + c["update_attempted"])
            elif name == "create_keyframe":
                dm = dm.create_keyframe(
                    frames(a["new_keyframe"]), a["T_new_old"], a["ref_pixel_was_good"], a["finalize"]
                )
                for row, (kind, key) in ROWS:
                    if kind == "keyframe":
                        rows[row].append(dm.timings_ms[key])
            elif name == "finalize":
                t0 = perf()
                dm.finalize()
                rows["final"].append(1e3 * (perf() - t0))
    finally:
        numba.set_num_threads(prev)
    return rows, state_digest(dm)


def summarise(rows: dict[str, np.ndarray], tracked: int) -> dict[str, dict[str, float]]:
    """Per row: calls, min / median / mean ms per call and ms per tracked frame."""
    table = {}
    for name, _ in ROWS:
        a = rows[name]
        if len(a) == 0:
            continue
        table[name] = {
            "calls": len(a),
            "min": float(a.min()),
            "median": float(np.median(a)),
            "mean": float(a.mean()),
            "ms_per_frame": float(a.sum() / max(tracked, 1)),
        }
    return table


def print_table(threads: int, table: dict[str, dict[str, float]], tracked: int) -> None:
    print(f"\n{threads} thread(s), {tracked} tracked frames — ms per call (min over repeats)")
    print(f"{'stage':<20}{'calls':>6}{'min':>9}{'median':>9}{'mean':>9}{'ms/frame':>10}")
    for name, e in table.items():
        print(f"{name:<20}{e['calls']:>6}{e['min']:9.3f}{e['median']:9.3f}{e['mean']:9.3f}{e['ms_per_frame']:10.3f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence", nargs="?", default=str(DEFAULT_SEQUENCE))
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--threads", default="1,2", help="comma-separated numba thread counts (default 1,2)")
    ap.add_argument("--repeat", type=int, default=3, help="replays per thread count; min per call over them")
    ap.add_argument("--feature", default="gray")
    ap.add_argument("--json", default=None, help="write the results to this JSON file")
    args = ap.parse_args(argv)

    import numba

    import dmtrack
    from dmtrack.features import get_feature

    thread_counts = [int(t) for t in args.threads.split(",")]
    load_before = _load()
    t0 = time.perf_counter()
    camera, images = load_images(args.sequence, args.frames)
    feat = get_feature(args.feature)
    frames = Frames(camera, images, feat, _config(feat))
    print(f"dmtrack {Path(dmtrack.__file__).parent}; {len(images)} frames decoded in {time.perf_counter() - t0:.1f} s")
    t0 = time.perf_counter()
    events, want, tracked = record(frames)
    kinds = {k: sum(1 for n, _ in events if n == k) for k in ("update", "create_keyframe")}
    print(f"recorded in {time.perf_counter() - t0:.1f} s: {kinds['update']} updates, "
          f"{kinds['create_keyframe']} keyframes; final map {want}")  # fmt: skip
    # warm-up (compiles / loads the parallel builds): the calls up to the first keyframe, untimed
    first_kf = next((i for i, (n, _) in enumerate(events) if n == "create_keyframe"), len(events) - 1)
    t0 = time.perf_counter()
    for t in thread_counts:
        replay(events[: first_kf + 1], frames, t)
    print(f"warm-up: {time.perf_counter() - t0:.1f} s")

    best: dict[int, dict[str, np.ndarray]] = {}
    hashes: dict[int, list[str]] = {t: [] for t in thread_counts}
    for r in range(args.repeat):
        for t in thread_counts:  # interleaved, so load changes hit every thread count alike
            rows, digest = replay(events, frames, t)
            hashes[t].append(digest)
            arr = {k: np.asarray(v, np.float64) for k, v in rows.items()}
            best[t] = arr if t not in best else {k: np.minimum(best[t][k], arr[k]) for k in arr}
            total = arr["update"].sum() + arr["keyframe"].sum() + arr["final"].sum()
            print(f"replay {r + 1}/{args.repeat}, {t} thread(s): mapping {total / 1e3:.2f} s, final map {digest}")
    load_after = _load()

    results: dict[str, Any] = {}
    for t in thread_counts:
        table = summarise(best[t], tracked)
        print_table(t, table, tracked)
        results[str(t)] = table
    if kinds["update"]:
        searches = best[thread_counts[0]]["searches"]
        print(f"\nline-stereo searches per update: mean {searches.mean():.0f}, median {np.median(searches):.0f}")
    ok = all(h == want for hs in hashes.values() for h in hs)
    print(f"\nfinal map of every replay equals the recording run's ({want}): {ok}")
    print(f"load average before {load_before}, after {load_after}")

    if args.json:
        from dmtrack.io.atomic import write_text

        doc = {
            "sequence": str(args.sequence),
            "feature": args.feature,
            "frames": len(images),
            "tracked_frames": tracked,
            "repeat": args.repeat,
            "updates": kinds["update"],
            "searches_per_update": float(np.mean(best[thread_counts[0]]["searches"])) if kinds["update"] else 0.0,
            "keyframes": kinds["create_keyframe"],
            "threads": results,
            "final_map_hash": want,
            "replay_hashes": {str(t): h for t, h in hashes.items()},
            "deterministic": ok,
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
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
