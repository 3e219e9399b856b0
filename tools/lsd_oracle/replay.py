#!/usr/bin/env python3
"""Replay LSD-SLAM's depth-map updates through dmtrack's DepthMap and compare them pixel by pixel.

    python tools/lsd_oracle/replay.py SEQUENCE DUMP_DIR --keyframe K --frames A:B [--grey lsd|dmtrack]

DUMP_DIR is what ``lsd_oracle ... dump=DUMP_DIR dumpframes=A:B`` wrote: for each mapped frame n the map before
(``pre_n.bin``) and after (``post_n.bin``) LSD-SLAM's ``DepthMap::updateKeyframe``, the tracker's level-1
flags (``good_n.bin``) and the stereo pose and tracked residual (``stereo_n.txt``). For each frame this script
loads LSD-SLAM's *pre* state into a dmtrack :class:`DepthMap` on keyframe K, runs :meth:`DepthMap.update` with
LSD-SLAM's pose, flags and residual, and reports how dmtrack's result differs from LSD-SLAM's *post* state:
pixels whose validity differs, and among pixels valid in both the differences of inverse depth and variance.
Frames whose pre state is missing (keyframe changes) are skipped.

With identical inputs the two implementations should agree up to float rounding; what remains is a
behavioural difference to explain (docs/lsd-slam-fidelity.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from dmtrack.datasets import open_sequence
from dmtrack.geometry.camera import crop_image
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.depthmap import DepthMap
from dmtrack.odometry.frame import build_frame

FIELDS = ("valid", "blacklisted", "next_id", "validity", "idepth", "var", "idepth_s", "var_s")


def load_state(path: Path, h: int, w: int) -> np.ndarray:
    return np.fromfile(path, np.float32).reshape(h, w, 8)


def to_state(a: np.ndarray) -> tuple[np.ndarray, ...]:
    return (
        a[..., 0] > 0.5,
        a[..., 1].astype(np.int32),
        np.ceil(a[..., 2]).astype(np.int32),  # nextStereoFrameMinID (float in LSD-SLAM): first frame id ≥ it
        a[..., 3].astype(np.float32),
        a[..., 4].copy(),
        a[..., 5].copy(),
        a[..., 6].copy(),
        a[..., 7].copy(),
    )


def read_stereo(path: Path) -> tuple[np.ndarray, float]:
    """(T_fk, initialTrackedResidual) from lsd_oracle's stereo_n.txt (which holds frame→keyframe)."""
    lines = path.read_text().split("\n")
    M = np.array([[float(x) for x in lines[r].split()] for r in range(3)])
    T_kf = np.eye(4)
    T_kf[:3, :] = M
    itr = float(lines[4].split()[1])
    return np.linalg.inv(T_kf), itr


def compare(name: str, ours: tuple[np.ndarray, ...], lsd: tuple[np.ndarray, ...]) -> dict[str, float]:
    vo, vl = ours[0], lsd[0]
    both = vo & vl
    rel = np.abs(ours[4][both] - lsd[4][both]) / np.maximum(np.abs(lsd[4][both]), 1e-6)
    relv = np.abs(ours[5][both] - lsd[5][both]) / np.maximum(lsd[5][both], 1e-12)
    out = {
        "valid_lsd": int(vl.sum()),
        "valid_ours": int(vo.sum()),
        "only_lsd": int((vl & ~vo).sum()),
        "only_ours": int((vo & ~vl).sum()),
        "idepth_rel_p99": float(np.percentile(rel, 99)) if rel.size else 0.0,
        "idepth_rel_gt1e-3": int((rel > 1e-3).sum()),
        "var_rel_gt1e-3": int((relv > 1e-3).sum()),
        "blacklist_diff": int((ours[1] != lsd[1]).sum()),
        "validity_diff": int(((ours[3] != lsd[3]) & both).sum()),
    }
    print(name, " ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in out.items()))
    return out


def read_reference(path: Path, kf_frame, use_numba: bool = True):
    """A dmtrack TrackingReference holding LSD-SLAM's point clouds of levels 1..4 (lsd_oracle's track_n.bin)."""
    from dmtrack.odometry.tracker import ReferenceLevel, TrackingReference

    raw = path.read_bytes()
    ref = TrackingReference(kf_frame, [], use_numba)
    off = 0
    for lvl in range(1, 5):
        n = int(np.frombuffer(raw, np.int32, 1, off)[0])
        off += 4
        rec = np.frombuffer(raw, np.float32, n * 6, off).reshape(n, 6)
        off += n * 24
        kl = kf_frame.levels[lvl]
        ref._levels[lvl] = ReferenceLevel(
            lvl,
            np.ascontiguousarray(rec[:, :3]),
            np.ascontiguousarray(rec[:, 3:4]),
            np.ascontiguousarray(rec[:, 4]),
            np.ascontiguousarray(rec[:, 5].astype(np.int32)),
            kl.width,
            kl.height,
        )
    return ref


def replay_tracking(a, seq, camera, cfg, frame, dump: Path, frames) -> int:
    """Track each frame with dmtrack from LSD-SLAM's reference and initial pose; compare with LSD-SLAM's result."""
    import json

    from dmtrack.geometry.lie import rotation_angle
    from dmtrack.odometry.tracker import Tracker

    lsd = {}
    for line in open(a.track):
        r = json.loads(line)
        lsd[r["frame"]] = r
    tracker = Tracker(cfg.tracker)
    for n in frames:
        tpath = dump / f"track_{n:06d}.bin"
        if not tpath.exists() or n not in lsd:
            continue
        r = lsd[n]
        ref = read_reference(tpath, frame(r["parent"]))
        lines = (dump / f"trackinit_{n:06d}.txt").read_text().split("\n")
        T0 = np.eye(4)
        T0[:3, :] = np.array([[float(x) for x in lines[i].split()] for i in range(3)])
        res = tracker.track(ref, frame(n), T0)
        T_l = np.eye(4)
        T_l[:3, :] = np.array(r["T_fk"]).reshape(3, 4)
        dT = np.linalg.inv(T_l) @ res.T_fk
        step = np.linalg.norm((np.linalg.inv(T0) @ T_l)[:3, 3])
        print(
            f"frame {n} (kf {r['parent']}): rot diff {float(rotation_angle(dT[:3, :3])) * 180 / np.pi:.4f} deg, "
            f"trans diff {np.linalg.norm(dT[:3, 3]):.2e} (LSD step {step:.2e}); "
            f"residual {r['residual']:.4f}/{res.last_residual:.4f} good {r['good']:.0f}/{res.good_count} "
            f"bad {r['bad']:.0f}/{res.bad_count} usage {r['usage']:.4f}/{res.point_usage:.4f} its {res.iterations}"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence")
    ap.add_argument("dump")
    ap.add_argument("--keyframe", type=int, required=True, help="frame index of the keyframe being mapped")
    ap.add_argument("--frames", required=True, help="A:B")
    ap.add_argument("--grey", choices=("lsd", "dmtrack"), default="lsd")
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--save", default=None, help="folder: write ours_n.bin (our post state) for inspection")
    ap.add_argument(
        "--track", metavar="TRACE", default=None,
        help="replay tracking instead: track_n.bin + trackinit_n.txt through dmtrack's Tracker; TRACE is the "
        "lsd_oracle _trace.jsonl with LSD-SLAM's results",
    )
    ap.add_argument(
        "--create", action="store_true",
        help="replay keyframe creations instead: kfold_n.bin (old map, finalised) → kfnew_n.bin (dumpkf=1)",
    )
    a = ap.parse_args(argv)
    seq = open_sequence(a.sequence)
    camera, box = seq.camera.crop_to_multiple(16)
    h, w = camera.height, camera.width
    # LSD-SLAM's rule and its random start unless overridden
    cfg = VOConfig(init="random").with_overrides("depth.update_variance=smoothed", *a.set)
    dump = Path(a.dump)

    def frame(i: int):
        fr = seq[i]
        img = cv2.imread(str(fr.path), cv2.IMREAD_GRAYSCALE) if a.grey == "lsd" else fr.image
        if img.ndim == 3:
            img = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
        img = crop_image(img, box)
        return build_frame(i, float(i), img, img.astype(np.float32)[..., None], camera, cfg.pyramid_levels)

    lo, _, hi = a.frames.partition(":")
    if a.track:
        return replay_tracking(a, seq, camera, cfg, frame, dump, range(int(lo), int(hi or lo) + 1))
    if a.create:
        # n: the frame that becomes a keyframe; its parent is the previous keyframe (a.keyframe or older dumps)
        kf_ids = sorted(int(p.stem.split("_")[1]) for p in dump.glob("kfnew_*.bin"))
        parent = a.keyframe
        for n in kf_ids:
            if not int(lo) <= n <= int(hi or lo):
                parent = n
                continue
            dm = DepthMap(cfg.depth)
            dm.keyframe = frame(parent)
            dm._set_state(to_state(load_state(dump / f"kfold_{n:06d}.bin", h, w)))
            T_new_old, _ = read_stereo(dump / f"kfpose_{n:06d}.txt")
            gpath = dump / f"kfgood_{n:06d}.bin"
            good = np.fromfile(gpath, np.uint8).reshape(h >> 1, w >> 1).astype(bool) if gpath.exists() else None
            child = dm.create_keyframe(frame(n), T_new_old, good, finalize=False)
            lsd_new = to_state(load_state(dump / f"kfnew_{n:06d}.bin", h, w))
            compare(f"keyframe {n} (from {parent}):", child.state, lsd_new)
            print("    ours:", child.last_counts, "rho", round(child.scale_from_parent, 6))
            parent = n
        return 0
    kf = frame(a.keyframe)
    for n in range(int(lo), int(hi or lo) + 1):
        pre, post = dump / f"pre_{n:06d}.bin", dump / f"post_{n:06d}.bin"
        if not (pre.exists() and post.exists()):
            continue
        dm = DepthMap(cfg.depth)
        dm.keyframe = kf
        dm._set_state(to_state(load_state(pre, h, w)))
        dm.n_updates = n - a.keyframe - 1
        T_fk, itr = read_stereo(dump / f"stereo_{n:06d}.txt")
        good = np.fromfile(dump / f"good_{n:06d}.bin", np.uint8).reshape(h >> 1, w >> 1).astype(bool)
        counts = dm.update(frame(n), T_fk, good, itr)
        compare(f"frame {n}:", dm.state, to_state(load_state(post, h, w)))
        print("    ours:", {k: v for k, v in counts.items() if v})
        if a.save:
            Path(a.save).mkdir(parents=True, exist_ok=True)
            np.stack([np.asarray(x, np.float32) for x in dm.state], -1).tofile(Path(a.save) / f"ours_{n:06d}.bin")
    return 0


if __name__ == "__main__":
    sys.exit(main())
