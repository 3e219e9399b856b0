#!/usr/bin/env python3
"""Run dmtrack's grey VO frame by frame and write the same trace as the LSD-SLAM oracle driver.

    python tools/lsd_oracle/dmtrack_trace.py SEQUENCE --out PREFIX [--end N] [--seed S] [--initdepth F]
        [--grey lsd|dmtrack] [--dump DIR --dump-frames A:B] [--set section.key=value ...]

Writes PREFIX.txt (TUM, camera-to-world, timestamp = frame index, like lsd_oracle), PREFIX_kf.txt and
PREFIX_trace.jsonl: one JSON object per frame with the keys of lsd_oracle's trace (see README.md): the tracking
result (``parent``, ``keyframe``, ``residual``, ``itr``, ``usage``, ``good``, ``bad``, ``T_fk``), what the
keyframe decision saw (``parent_mapped``, ``parent_mean_idepth``) and the depth-map summaries after mapping
(``update``, or ``finalized`` and ``created`` for a new keyframe).

``--initdepth F`` starts from an inverse-depth image (H·W float32, ≤ 0 or NaN = no hypothesis; e.g. one written
by ``lsd_oracle dumpinit=F``) with the random initialisation's variance and validity, so both systems start
from the identical map. ``--grey lsd`` reads images as LSD-SLAM does (OpenCV's greyscale decoder);
``--grey dmtrack`` (default) as ``dmtrack run`` (RGB, then OpenCV's RGB→grey).

A developer tool (never imported by the package).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from dmtrack.datasets import open_sequence
from dmtrack.features import get_feature
from dmtrack.geometry.camera import crop_image
from dmtrack.io.trajectory import Trajectory, write_tum
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.depthmap import DepthMap
from dmtrack.odometry.vo import VisualOdometry


def depth_stats(dm: DepthMap, min_blacklist: int) -> dict:
    """The summary lsd_oracle writes: valid, tracking pixels, their mean idepth, blacklisted, log10 var histogram."""
    m = dm.valid & (dm.idepth_smoothed >= -0.05)
    lv = np.log10(np.maximum(dm.idepth_var_smoothed[m].astype(np.float64), 1e-30))
    b = np.where(lv < -6, 0, np.where(lv >= 0, 7, np.floor(lv).astype(np.int64) + 7))
    return {
        "valid": int(dm.valid.sum()),
        "tracking": int(m.sum()),
        "blacklisted": int((dm.blacklisted < min_blacklist).sum()),
        "mean_idepth": float(dm.idepth_smoothed[m].astype(np.float64).mean()) if m.any() else 0.0,
        "var_hist": np.bincount(b, minlength=8).tolist(),
    }


def dump_state(dm: DepthMap, path: Path) -> None:
    """H·W·8 float32 in lsd_oracle's layout."""
    arr = np.stack(
        [
            dm.valid.astype(np.float32),
            dm.blacklisted.astype(np.float32),
            dm.next_stereo_frame_min_id.astype(np.float32),
            dm.validity_counter.astype(np.float32),
            dm.idepth,
            dm.idepth_var,
            dm.idepth_smoothed,
            dm.idepth_var_smoothed,
        ],
        axis=-1,
    ).astype(np.float32)
    arr.tofile(path)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence")
    ap.add_argument("--out", required=True)
    ap.add_argument("--end", type=int, default=None, help="frames to process (default all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--initdepth", default=None)
    ap.add_argument("--grey", choices=("lsd", "dmtrack"), default="dmtrack")
    ap.add_argument("--dump", default=None)
    ap.add_argument("--dump-frames", default=None, help="A:B — dump the depth map before/after mapping A..B")
    ap.add_argument("--set", action="append", default=[], help="config override section.key=value")
    ap.add_argument("--intrinsics", default=None)
    a = ap.parse_args(argv)

    seq = open_sequence(a.sequence, intrinsics=a.intrinsics)
    camera, box = seq.camera.crop_to_multiple(16)
    cfg = VOConfig(init="random").with_overrides(f"seed={a.seed}", *a.set)
    vo = VisualOdometry(camera, cfg, threads=1)
    feat = get_feature("gray")
    n = len(seq) if a.end is None else min(a.end, len(seq))
    dump = Path(a.dump) if a.dump else None
    lo, hi = (1, 0)
    if a.dump_frames:
        lo_s, _, hi_s = a.dump_frames.partition(":")
        lo, hi = int(lo_s), int(hi_s or lo_s)
    if dump:
        dump.mkdir(parents=True, exist_ok=True)
    mb = cfg.depth.min_blacklist
    out = Path(a.out)
    trace = open(f"{out}_trace.jsonl", "w")
    kf_frames: list[int] = []
    for i in range(n):
        fr = seq[i]
        if a.grey == "lsd":
            img = cv2.imread(str(fr.path), cv2.IMREAD_GRAYSCALE)
        else:
            img = fr.image
        img = crop_image(img, box)
        fmap = feat.compute(img)
        rec: dict = {"frame": i}
        dm_before = vo.depth_map
        if i > 0:
            rec["parent_mapped"] = vo.depth_map.n_updates
            rec["parent_mean_idepth"] = vo.depth_map.mean_idepth
            if dump and lo <= i <= hi:
                dump_state(vo.depth_map, dump / f"pre_{i:06d}.bin")
        res = vo.process(i, float(i), img, fmap)
        if i == 0:
            if a.initdepth:
                d = np.fromfile(a.initdepth, np.float32).reshape(camera.height, camera.width)
                d = np.where(np.isfinite(d) & (d > 0), d, np.nan)
                vo.depth_map.initialize_from_depth(
                    vo.keyframe, d, var=cfg.depth.var_random_init_initial, validity=cfg.depth.random_init_validity
                )
                vo._snaps.clear()  # the map the first frames are tracked against: this one
                vo._take_snapshot(0)
            rec.update(keyframe=True, init=depth_stats(vo.depth_map, mb))
        else:
            tr = res.track
            if not res.tracked:
                rec.update(lost=True, reason=res.lost_reason)
                trace.write(json.dumps(rec) + "\n")
                break
            rec.update(
                parent=kf_frames[-1],
                keyframe=bool(res.is_keyframe),
                lost=False,
                diverged=bool(tr.diverged),
                tracking_good=bool(tr.good),
                residual=tr.last_residual,
                itr=tr.initial_tracked_residual,
                usage=tr.point_usage,
                good=tr.good_count,
                bad=tr.bad_count,
                T_fk=[float(x) for x in tr.T_fk[:3, :4].ravel()],
            )
            if res.is_keyframe:
                rec["created"] = depth_stats(vo.depth_map, mb)
                rec["rescale"] = vo.depth_map.scale_from_parent
                rec["finalized"] = depth_stats(dm_before, mb)
            else:
                rec["update"] = depth_stats(vo.depth_map, mb)
                if dump and lo <= i <= hi:
                    dump_state(vo.depth_map, dump / f"post_{i:06d}.bin")
                    np.asarray(tr.ref_pixel_was_good, np.uint8).tofile(dump / f"good_{i:06d}.bin")
        trace.write(json.dumps(rec) + "\n")
        if res.is_keyframe:
            kf_frames.append(i)
    trace.close()
    r = vo.finish()
    # timestamps = frame indices, as lsd_oracle writes them
    write_tum(f"{out}.txt", Trajectory(r.indices.astype(np.float64), r.poses))
    kf_poses = np.array([k.T_wc for k in r.keyframes]).reshape(-1, 4, 4)
    write_tum(f"{out}_kf.txt", Trajectory(np.array([k.frame_index for k in r.keyframes], np.float64), kf_poses))
    print(f"dmtrack_trace: {n} frames, {vo.n_keyframes} keyframes, wrote {out}.txt", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
