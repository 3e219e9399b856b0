"""``dmtrack calibrate-from-video``: intrinsics from a sequence's own images."""

from __future__ import annotations

import argparse
import json
import sys


def cmd_calibrate_from_video(args: argparse.Namespace) -> int:
    from dmtrack.pipeline.self_calibration import calibrate_from_video, write_intrinsics

    def show(rec: dict) -> None:
        if not args.quiet:
            s, e = rec["start"], rec["estimate"]
            print(f"run {rec['iteration']}: from fx={s[0]:.2f} fy={s[1]:.2f} cx={s[2]:.2f} cy={s[3]:.2f} → "
                  f"fx={e[0]:.2f} fy={e[1]:.2f} cx={e[2]:.2f} cy={e[3]:.2f} ({100 * rec['change']:.2f} %; tracked "
                  f"{rec['tracked_frames']}/{rec['total_frames']} frames)", file=sys.stderr)  # fmt: skip

    calib = calibrate_from_video(args.sequence, args.feature, args.intrinsics, model=args.model, start=args.start,
                                 max_frames=args.max_frames, iterations=args.iterations, tolerance=args.tolerance,
                                 window=args.window, on_iteration=show)  # fmt: skip
    path = write_intrinsics(calib, args.out, str(args.sequence))
    if args.json:
        print(json.dumps({**calib.to_dict(), "intrinsics_file": str(path)}, indent=2))
        return 0
    state = "converged" if calib.converged else f"not converged after {len(calib.history)} runs"
    sig = calib.sigma.get("fx")
    print(f"fx={calib.fx:.2f} fy={calib.fy:.2f} cx={calib.cx:.2f} cy={calib.cy:.2f} ({state}"
          + (f"; σ(fx) {sig:.2f} px from the last run, optimistic)" if sig else ")"))
    print(f"written: {path}")
    print(f"use it:  dmtrack run {args.sequence} --intrinsics {path}")
    return 0 if calib.converged else 3
