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


def add_self_calibration_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """The ``calibrate-from-video`` subcommand."""
    p = subparsers.add_parser(
        "calibrate-from-video",
        help="estimate the camera's intrinsics from a sequence's own images, without a board (sliding-window "
             "photometric bundle adjustment, repeated to a fixed point; docs/window.md)",
    )  # fmt: skip
    p.add_argument("sequence", metavar="SEQUENCE", help="video file, image folder or dataset")
    p.add_argument("--out", required=True, metavar="FILE", help="intrinsics file to write (fx fy cx cy)")
    p.add_argument("--intrinsics", metavar="FX,FY,CX,CY|FILE",
                   help="starting guess (default: the sequence's own, else fx = fy = 0.8 × width at the centre)")
    p.add_argument("--feature", default="gray", help="feature tracked with (default gray)")
    p.add_argument("--model", choices=("f", "f-c", "fxfy-c"), default="f",
                   help="what is estimated: one focal length (default; the principal point kept, as COLMAP), also "
                        "the principal point, or fx, fy, cx, cy")
    p.add_argument("--start", type=int, default=0, metavar="N", help="first frame")
    p.add_argument("--max-frames", type=int, metavar="N", help="use at most N frames")
    p.add_argument("--iterations", type=int, default=6, metavar="N", help="at most N runs (default 6)")
    p.add_argument("--tolerance", type=float, default=0.002, metavar="T",
                   help="stop when the focal length changes by less than this fraction (default 0.002)")
    p.add_argument("--window", type=int, default=5, metavar="K", help="keyframes in the window (default 5)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=cmd_calibrate_from_video)
    return p
