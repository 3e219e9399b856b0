"""Time per keyframe of the loop-candidate search against the keyframes already in the run: matching every older
keyframe (the search before the index, ``CandidateSearch(shortlist=None)``) against the ORB index's shortlist
(``CandidateSearch()``), on a long synthetic run.

Usage::

    python benchmarks/candidate_search_speed.py [--rooms 16] [--per-room 125] [--sizes 125,250,500,1000,1995]
        [--queries 5] [--threads 1] [--out out/benchmarks/candidates]

The run is ``--rooms`` synthetic rooms (``synthetic:seed=r,fps=3,…``, 320 × 240), ``--per-room`` frames each, one
after the other: every frame stands in for a keyframe (its image; its exact inverse depth, rendered again when a
keyframe's view is asked for, outside the timings), the ground truth's poses stand in for the graph's. A keyframe's
time is what the back end spends before its reciprocal tests: :meth:`CandidateSearch.candidates` (its ORB features,
the index look-up and insertion, the pairwise matches, the distance search) and :meth:`CandidateSearch.
initial_estimate` of each appearance candidate, among the keyframes at least 4 before it.

The index's search runs over the whole run in order, as in a run, and every keyframe is timed; the exhaustive
search, whose keyframe costs grow with the run, is timed at ``--sizes`` only, on the ``--queries`` keyframes from
each size on (the older keyframes' ORB features computed beforehand, as a run would have). Both give the medians of
the same keyframes, and whether their appearance candidates are the same. Results: ``candidate_search_speed.json``
and ``.md`` in ``--out``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from datetime import date
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from dmtrack.datasets.registry import open_sequence
from dmtrack.geometry.lie import SO3, Sim3
from dmtrack.io.machine import cpu_model
from dmtrack.slam.candidates import CandidateSearch

REPO = Path(__file__).resolve().parents[1]
MIN_GAP = 4  # SlamConfig.min_gap


@dataclass
class _View:
    """What the candidate search reads of a keyframe's view: the camera and the full-resolution inverse depth."""

    frame: Any
    idepth_pyramid: list[tuple[np.ndarray, np.ndarray]]


@dataclass
class StandIn:
    """A frame of the run standing in for a keyframe (the attributes ``CandidateSearch`` reads)."""

    kf_id: int
    image: np.ndarray
    mean_idepth: float
    seq: Any = field(repr=False)
    index: int
    views: OrderedDict = field(repr=False)

    @property
    def view(self) -> _View:
        """Its exact inverse depth (rendered again, the latest 16 kept: the run's would not fit in memory)."""
        if self.kf_id not in self.views:
            idepth = self.seq.inverse_depth(self.index)
            frame = SimpleNamespace(camera=self.seq.camera)
            self.views[self.kf_id] = _View(frame, [(idepth, np.full_like(idepth, 1e-4))])
            while len(self.views) > 16:
                self.views.popitem(last=False)
        self.views.move_to_end(self.kf_id)
        return self.views[self.kf_id]


def make_run(rooms: int, per_room: int) -> tuple[list[StandIn], dict[int, Sim3]]:
    keyframes, poses, views = [], {}, OrderedDict()
    for r in range(rooms):
        seq = open_sequence(f"synthetic:n_frames={per_room},width=320,height=240,seed={r},fps=3,texel=0.02")
        for i in range(per_room):
            frame = seq[i]
            k = len(keyframes)
            keyframes.append(StandIn(k, frame.image, float(np.mean(1.0 / frame.depth)), seq, i, views))
            T = frame.pose
            # rooms side by side, 10 m apart: the graph's poses of different rooms are far from each other
            poses[k] = Sim3(SO3.from_matrix(T[:3, :3], orthonormalize=True), T[:3, 3] + [10.0 * r, 0, 0], 1.0)
    return keyframes, poses


def time_keyframe(search: CandidateSearch, kf: StandIn, older: list[StandIn], poses: dict[int, Sim3]) -> dict:
    """One keyframe's candidates and initial estimates: seconds (the views' rendering excluded), candidates."""
    t0 = time.perf_counter()
    cands = search.candidates(kf, older, poses)
    seconds = time.perf_counter() - t0
    appearance = [c for _, c in search._by_appearance(kf, older)]  # cached: no matching
    for c in (kf, *appearance):
        _ = c.view  # rendered, outside the timing
    t0 = time.perf_counter()
    for c in appearance:
        search.initial_estimate(kf, c)
    seconds += time.perf_counter() - t0
    t0 = time.perf_counter()
    search._by_distance(kf, older, poses)
    distance = time.perf_counter() - t0
    return {"s": seconds, "distance_s": distance, "appearance": [c.kf_id for c in appearance],
            "candidates": [c.kf_id for c in cands]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rooms", type=int, default=16)
    ap.add_argument("--per-room", type=int, default=125)
    ap.add_argument("--sizes", default="125,250,500,1000,1995")
    ap.add_argument("--queries", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1, help="OpenCV's threads (cv2.setNumThreads)")
    ap.add_argument("--out", type=Path, default=REPO / "out" / "benchmarks" / "candidates")
    a = ap.parse_args(argv)
    import cv2

    cv2.setNumThreads(a.threads)
    t0 = time.perf_counter()
    keyframes, poses = make_run(a.rooms, a.per_room)
    n = len(keyframes)
    print(f"{n} keyframes rendered in {time.perf_counter() - t0:.0f} s", flush=True)
    sizes = [s for s in (int(x) for x in a.sizes.split(",")) if s + a.queries <= n]

    indexed = CandidateSearch()
    new: dict[int, dict] = {}
    t0 = time.perf_counter()
    for kf in keyframes:
        older = keyframes[: max(kf.kf_id - MIN_GAP + 1, 0)]
        before = indexed.pairs_matched
        new[kf.kf_id] = time_keyframe(indexed, kf, older, poses)
        new[kf.kf_id]["pairs"] = indexed.pairs_matched - before
    print(f"index: the whole run in {time.perf_counter() - t0:.0f} s", flush=True)

    exhaustive = CandidateSearch(shortlist=None)
    for kf in keyframes:
        exhaustive._orb_of(kf)  # the older keyframes' ORB features, as a run would have computed them
    rows = []
    for size in sizes:
        old, same = [], 0
        for kf in keyframes[size : size + a.queries]:
            exhaustive._orb.pop(kf.kf_id)  # the new keyframe's own features are part of its time
            older = keyframes[: kf.kf_id - MIN_GAP + 1]
            before = exhaustive.pairs_matched
            res = time_keyframe(exhaustive, kf, older, poses)
            res["pairs"] = exhaustive.pairs_matched - before
            old.append(res)
            same += res["appearance"] == new[kf.kf_id]["appearance"]
        ids = range(size, size + a.queries)
        row = {
            "keyframes_before": size,
            "exhaustive_ms": round(1e3 * statistics.median(r["s"] for r in old), 2),
            "index_ms": round(1e3 * statistics.median(new[k]["s"] for k in ids), 2),
            "exhaustive_pairs": statistics.median(r["pairs"] for r in old),
            "index_pairs": statistics.median(new[k]["pairs"] for k in ids),
            "distance_search_ms": round(1e3 * statistics.median(new[k]["distance_s"] for k in ids), 2),
            "same_appearance_candidates": f"{same}/{a.queries}",
        }
        rows.append(row)
        print(row, flush=True)

    # the index's time per keyframe over the whole run, in blocks
    block = max(n // 10, 1)
    blocks = [{"keyframes_before": f"{s}-{min(s + block, n) - 1}",
               "index_ms_median": round(1e3 * statistics.median(new[k]["s"] for k in range(s, min(s + block, n))), 2)}
              for s in range(0, n, block)]
    total_index = sum(r["s"] for r in new.values())
    found = sum(1 for r in new.values() if r["appearance"])
    result = {
        "date": str(date.today()), "cpu": cpu_model(),
        "opencv_threads": a.threads,
        "run": {"rooms": a.rooms, "per_room": a.per_room, "keyframes": n, "image": "320x240",
                "synthetic": "seed=room, fps=3, texel=0.02", "queries_per_size": a.queries},
        "search": {"n_orb": indexed.n_orb, "shortlist": indexed.shortlist, "min_matches": indexed.min_matches,
                   "max_appearance": indexed.max_appearance, "n_tables": indexed.index.n_tables,
                   "bits_at_the_end": indexed.index.bits, "max_distance": indexed.index.max_distance,
                   "max_bucket": indexed.index.max_bucket, "rows_per_key": indexed.index.rows_per_key},
        "sizes": rows, "index_over_the_run": blocks,
        "index_total_s": round(total_index, 1),
        "keyframes_with_appearance_candidates": found,
    }
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "candidate_search_speed.json").write_text(json.dumps(result, indent=2) + "\n")
    lines = [
        "# Loop-candidate search: time per keyframe against the keyframes before it", "",
        f"{date.today()}, {cpu_model()}; `python benchmarks/candidate_search_speed.py --rooms {a.rooms} "
        f"--per-room {a.per_room}` ({n} synthetic 320 × 240 frames as keyframes). A keyframe's time: "
        "`candidates` (ORB, index, pairwise matches, distance search) and `initial_estimate` of each appearance "
        f"candidate; median of {a.queries} keyframes from each size on.", "",
        "| keyframes before | matching every one (ms) | index shortlist (ms) | pairs matched: every / index "
        "| distance search (ms) | same appearance candidates |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['keyframes_before']} | {r['exhaustive_ms']} | {r['index_ms']} | "
                     f"{r['exhaustive_pairs']:g} / {r['index_pairs']:g} | {r['distance_search_ms']} | "
                     f"{r['same_appearance_candidates']} |")
    lines += ["", "The index's search over the whole run (median time per keyframe, by blocks of keyframes):", "",
              "| keyframes before | ms |", "|---|---|"]
    lines += [f"| {b['keyframes_before']} | {b['index_ms_median']} |" for b in blocks]
    lines += ["", f"Whole run with the index: {total_index:.1f} s; {found} of {n} keyframes had appearance "
              "candidates."]
    (a.out / "candidate_search_speed.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
