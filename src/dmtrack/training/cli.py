"""``dmtrack train-feature --out DIR [--seed S] [--minutes M] [--steps N] [--channels K] [--data D --data-path P]``:
train the ``tracknet`` feature through the tracker's alignment (:mod:`dmtrack.training.train`).

Wire into the CLI with ``add_train_parser(sub)`` where ``sub`` is the subparsers object of
:func:`dmtrack.cli.build_parser`. PyTorch is imported only when the command runs.
"""

from __future__ import annotations

import argparse
import json
import sys

from dmtrack.io.argtypes import positive_float, positive_int


def cmd_train_feature(args: argparse.Namespace) -> int:
    try:
        import torch  # noqa: F401
    except ModuleNotFoundError:
        from dmtrack.errors import InputError

        msg = "train-feature needs PyTorch, which is not installed (pip install 'dmtrack[learned]')"
        raise InputError(msg) from None
    from dmtrack.training.train import TrainOptions, train

    opts = TrainOptions(
        seed=args.seed,
        minutes=args.minutes,
        steps=args.steps,
        channels=args.channels,
        data=args.data,
        data_path=args.data_path,
        intrinsics=args.intrinsics,
        keyframe_every=args.keyframe_every,
        mapping_frames=args.mapping_frames,
        threads=args.threads,
        lr_schedule=args.lr_schedule,
        device=args.device,
    )

    def say(msg: str) -> None:
        if not args.quiet:
            print(msg, file=sys.stderr, flush=True)

    res = train(args.out, opts, progress=say)
    if args.json:
        print(json.dumps({"out": str(res.out), "steps": res.steps, "seconds": round(res.seconds, 1),
                          "validation": res.validation, "files": res.files}, indent=2))  # fmt: skip
        return 0
    print(f"trained {res.steps} steps in {res.seconds / 60:.1f} min")
    for name in ("grey", "initial", "final"):
        v = res.validation.get(name)
        if v:
            print(f"validation ({name}): reprojection error {v['init_px']:.2f} px -> {v['final_px']:.2f} px "
                  f"(median {v['final_px_median']:.2f}), {100 * v['within_1px']:.0f}% of pairs within 1 px")
    print(f"written: {res.files['weights']} (use it: dmtrack run SEQUENCE --feature tracknet "
          f"--feature-opt weights={res.files['weights']})")
    return 0


def add_train_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``train-feature`` subcommand to ``subparsers``; returns its parser."""
    p = subparsers.add_parser(
        "train-feature",
        help="train the tracknet feature through the tracker's own alignment (needs PyTorch)",
        description="Train the small tracknet CNN by unrolling damped Gauss-Newton steps of the tracker's "
        "photometric objective on its feature maps and minimising the final pose error, on seeded synthetic "
        "pairs (exact depth and pose) and/or pairs of a real sequence with ground-truth poses. Writes tracknet.npz "
        "(use it with --feature tracknet --feature-opt weights=FILE), checkpoint.pt, train_log.csv/json and "
        "training_curve.png. Deterministic: the weights after "
        "N steps depend only on the seed and the options (--minutes stops after a machine-dependent number of "
        "steps; --steps N reproduces a run).",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument("--minutes", type=positive_float, default=10.0, metavar="M",
                   help="wall-clock budget of the training loop (default 10)")
    p.add_argument("--steps", type=positive_int, metavar="N", help="stop after N steps (whichever comes first)")
    p.add_argument("--channels", type=positive_int, default=8, metavar="K", help="output channels K (default 8)")
    p.add_argument("--data", choices=("synthetic", "7scenes", "both"), default="synthetic",
                   help="training data: synthetic renderer (default), a real sequence with ground-truth poses "
                   "(--data-path; depth from the odometry's own mapping at those poses), or both (half each)")
    p.add_argument("--data-path", metavar="DIR",
                   help="the real sequence of --data 7scenes/both, e.g. ../shared/data/7scenes-0000-0699 (never "
                   "a sequence you evaluate on)")
    p.add_argument("--intrinsics", metavar="FX,FY,CX,CY|FILE",
                   help="intrinsics replacing the real sequence's (as `dmtrack run --intrinsics`)")
    p.add_argument("--keyframe-every", type=positive_int, default=10, metavar="N",
                   help="real data: a training keyframe every N frames (default 10)")
    p.add_argument("--mapping-frames", type=positive_int, default=12, metavar="M",
                   help="real data: frames before a keyframe mapped into its depth (default 12)")
    p.add_argument("--lr-schedule", choices=("constant", "cosine"), default="constant",
                   help="learning rate: constant 1e-3 (default), or cosine from 1e-3 to 5e-5 over --steps")
    p.add_argument("--threads", type=positive_int, default=1, metavar="N",
                   help="torch and numba threads (default 1: faster than 2 when other jobs share the cores)")
    p.add_argument("--device", default="cpu", metavar="cpu|cuda[:N]|auto",
                   help="where the network and the unrolled alignment run (default cpu; a GPU run is deterministic "
                        "on its own, not equal to the CPU's)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=cmd_train_feature)
    return p
