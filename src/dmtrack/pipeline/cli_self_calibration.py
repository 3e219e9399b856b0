"""``dmtrack calibrate-from-video``: intrinsics from a sequence's own images."""

from __future__ import annotations

import argparse
import json
import sys

from dmtrack.errors import InputError


def cmd_calibrate_from_video(args: argparse.Namespace) -> int:
    from dmtrack.pipeline.self_calibration import calibrate_from_video, write_intrinsics

    method = getattr(args, "method", "window")
    adjusts = method in ("tracks", "groundtruth")  # the corner tracks' bundle adjustment
    if adjusts and args.model not in ("f", "f-k1"):
        raise InputError(f"--model {args.model}: the {method} method estimates f or f-k1 (--method window for the "
                         "rest)")  # fmt: skip
    if method == "window" and args.model == "f-k1":
        raise InputError("--model f-k1: only the tracks and groundtruth methods estimate k1")

    def show(rec: dict) -> None:
        if args.quiet:
            return
        if adjusts:
            print(f"pass {rec['pass']}: f={rec['f']:.2f}" + (f" k1={rec['k1']:+.4f}" if args.model == "f-k1" else "")
                  + f", median error {rec['median_error_px']:.3f} px over {rec['observations']} observations of "
                  f"{rec['points']} corners in {rec['keyframes']} keyframes", file=sys.stderr)  # fmt: skip
            return
        s, e = rec["start"], rec["estimate"]
        print(f"run {rec['iteration']}: from fx={s[0]:.2f} fy={s[1]:.2f} cx={s[2]:.2f} cy={s[3]:.2f} → "
              f"fx={e[0]:.2f} fy={e[1]:.2f} cx={e[2]:.2f} cy={e[3]:.2f} ({100 * rec['change']:.2f} %; tracked "
              f"{rec['tracked_frames']}/{rec['total_frames']} frames)", file=sys.stderr)  # fmt: skip

    calib = calibrate_from_video(args.sequence, args.feature, args.intrinsics, model=args.model, method=method,
                                 step=getattr(args, "step", 5), start=args.start, max_frames=args.max_frames,
                                 iterations=args.iterations, tolerance=args.tolerance, window=args.window,
                                 on_iteration=show)  # fmt: skip
    path = write_intrinsics(calib, args.out, str(args.sequence))
    if args.json:
        print(json.dumps({**calib.to_dict(), "intrinsics_file": str(path)}, indent=2))
        return 0 if calib.converged else 3
    if adjusts:
        state = "converged" if calib.converged else "NOT converged"
        print(f"fx=fy={calib.fx:.2f} (σ {calib.sigma['fx']:.2f} px, from independent pixel errors: a lower bound)"
              + (f" k1={calib.k1:+.5f} (σ {calib.sigma['k1']:.5f})" if calib.model == "f-k1" else "")
              + f" cx={calib.cx:.2f} cy={calib.cy:.2f} (kept); {state} after {len(calib.history)} passes"
              + ("; the poses: the ground truth's" if method == "groundtruth" else ""))
    else:
        state = "converged" if calib.converged else f"not converged after {len(calib.history)} runs"
        sig = calib.sigma.get("fx")
        print(f"fx={calib.fx:.2f} fy={calib.fy:.2f} cx={calib.cx:.2f} cy={calib.cy:.2f} ({state}"
              + (f"; σ(fx) {sig:.2f} px from the last run, optimistic)" if sig else ")"))
    print(f"written: {path}")
    print(f"use it:  dmtrack run {args.sequence} --intrinsics {path}")
    return 0 if calib.converged else 3
