"""Residuals of the tracker's good/bad test at the final pose of every frame, for choosing its constants.

Usage::

    python benchmarks/good_test_residuals.py SEQUENCE --feature F --out FILE.npz [--max-frames N] [--seed S]
        [--intrinsics fx,fy,cx,cy] [--set KEY=VALUE ...]

Runs :func:`dmtrack.track` with the given settings and, after every tracking call, recomputes at the returned pose
on the finest tracked level (with the float64 reference of the residual pass) each in-image point's residual
energy e = Σ_c r_c² and gradient energy G = Σ_c |∇F_c|² of the frame at the warped point, the two numbers the
good/bad test compares (good ⇔ e < K + ¼G). Nothing of the run is changed: the trajectory is the run's own.
Writes ``FILE.npz``: per call ``frame`` (index), ``n`` (in-image points), and up to 4000 (e, G) pairs per call
(random subsample, seed 0) in ``e``, ``g``, ``call`` (which call each pair belongs to); the run's metrics as
``metrics`` (JSON); the feature's N_E, N_σ.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def _energies(reference, frame, T, level):  # noqa: ANN001
    from dmtrack.odometry.frame import pack_numpy

    rl = reference.level(level)
    fl = frame.levels[level]
    cam = fl.camera
    packed = pack_numpy(fl.feat)
    h, w = fl.feat.shape[:2]
    P = rl.points.astype(np.float64)
    X = P @ T[:3, :3].T + T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        iz = 1.0 / X[:, 2]
        u = X[:, 0] * iz * cam.fx + cam.cx
        v = X[:, 1] * iz * cam.fy + cam.cy
        inside = (u > 1.0) & (v > 1.0) & (u < w - 2.0) & (v < h - 2.0)
    u, v = u[inside], v[inside]
    ix, iy = u.astype(np.int64), v.astype(np.int64)
    dx, dy = (u - ix)[:, None, None], (v - iy)[:, None, None]
    dxdy = dx * dy
    s = (dxdy * packed[iy + 1, ix + 1] + (dy - dxdy) * packed[iy + 1, ix] + (dx - dxdy) * packed[iy, ix + 1]
         + (1.0 - dx - dy + dxdy) * packed[iy, ix])
    r = rl.values[inside].astype(np.float64) - s[:, 0]
    e = np.sum(r * r, axis=1)
    g = np.sum(s[:, 1] ** 2 + s[:, 2] ** 2, axis=1)
    return e, g


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sequence")
    ap.add_argument("--feature", default="gray")
    ap.add_argument("--out", required=True)
    ap.add_argument("--max-frames", type=int)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--intrinsics")
    ap.add_argument("--r-l", type=float)
    ap.add_argument("--set", action="append", default=[])
    a = ap.parse_args(argv)

    from dmtrack.api import track
    from dmtrack.features import get_feature
    from dmtrack.odometry import tracker as tracker_mod
    from dmtrack.odometry.config import VOConfig

    rng = np.random.default_rng(0)
    rows: dict[str, list] = {"frame": [], "n": [], "e": [], "g": [], "call": []}
    original = tracker_mod.Tracker._track

    def instrumented(self, reference, frame, T_fk_init):  # noqa: ANN001
        res = original(self, reference, frame, T_fk_init)
        level = min(self.config.levels)
        e, g = _energies(reference, frame, np.asarray(res.T_fk, np.float64), level)
        k = len(rows["frame"])
        pick = rng.choice(len(e), size=min(4000, len(e)), replace=False) if len(e) else np.zeros(0, int)
        rows["frame"].append(getattr(frame, "index", k))
        rows["n"].append(len(e))
        rows["e"].append(e[pick])
        rows["g"].append(g[pick])
        rows["call"].append(np.full(len(pick), k))
        return res

    tracker_mod.Tracker._track = instrumented
    config = VOConfig(init="random").with_overrides(*a.set, f"seed={a.seed}")
    kw = {"intrinsics": a.intrinsics} if a.intrinsics else {}
    if a.r_l:
        kw["r_l"] = a.r_l
    result = track(a.sequence, a.feature, config, max_frames=a.max_frames, warmup=False, **kw)
    feat = get_feature(a.feature)
    np.savez_compressed(
        a.out,
        frame=np.asarray(rows["frame"]), n=np.asarray(rows["n"]),
        e=np.concatenate(rows["e"]) if rows["e"] else np.zeros(0),
        g=np.concatenate(rows["g"]) if rows["g"] else np.zeros(0),
        call=np.concatenate(rows["call"]) if rows["call"] else np.zeros(0, int),
        metrics=json.dumps(result.metrics), energy_channels=feat.energy_channels or 1.0,
        noise_energy_channels=feat.noise_energy_channels or 1.0,
    )
    print(f"{a.feature}: {result.tracked_frames}/{result.total_frames} tracked, {len(rows['frame'])} calls -> {a.out}",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
