"""The ``dmtrack bench`` and ``dmtrack report`` subcommands.

``dmtrack.cli.build_parser`` adds them with :func:`add_bench_parser` and :func:`add_report_parser`; each sets
``func`` to its command, which returns the exit status (errors are :class:`~dmtrack.errors.DmtrackError`,
printed by ``dmtrack.cli.main`` as one line).  Nothing heavy is imported until a command runs.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from typing import Any

from dmtrack.errors import InputError
from dmtrack.io.argtypes import non_negative_int, positive_int

__all__ = ["add_bench_parser", "add_report_parser", "cmd_bench", "cmd_report"]

_PCA_NAME = re.compile(r"^.+-pca[0-9]+$")


def _r_l(text: str) -> float:
    from dmtrack.experiments.grid import parse_r_l

    try:
        return parse_r_l(text)
    except InputError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _usable_cpus() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def add_bench_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``bench`` to an ``add_subparsers()`` object; returns its parser."""
    from dmtrack.datasets.registry import FORMATS

    p = subparsers.add_parser(
        "bench",
        help="run every sequence × feature (in parallel, resumable) and write a report with rankings and figures",
        description="Run the grid SEQUENCES × FEATURES into DIR/runs/<sequence>/<feature>/ (one `dmtrack run` "
        "each), skipping runs already finished with the same settings, then write DIR/report.md, "
        "DIR/results.csv, DIR/tables/*.csv and DIR/figures/*.png. A crashing run is recorded in its "
        "error.json and does not stop the grid. With --seeds (e.g. --seeds 0,1,2) every (sequence, feature) "
        "cell runs once per seed of the random depth initialisation, into .../<feature>/seed-<S>/, and the "
        "report gives per cell the median over the seeds and the min–max; rankings use the medians. "
        "Single-seed results on monocular sequences often differ by 2x between seeds.",
        epilog="example: dmtrack bench --sequences S1 S2 --features gray bitplanes --seeds 0-2 --out bench/",
    )
    p.add_argument(
        "--sequences",
        nargs="+",
        default=[],
        metavar="S",
        help="sequence folders or synthetic[:key=value,...] (options below apply to all)",
    )
    p.add_argument(
        "--sequences-file",
        metavar="YAML",
        help="YAML list of sequences with per-sequence path, name, format, intrinsics, r_l, start, "
        "max_frames, dataset (relative paths are relative to the file)",
    )
    p.add_argument(
        "--features",
        nargs="+",
        required=True,
        metavar="F",
        help="feature names (see `dmtrack features`; comma-separated also accepted)",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="bench folder (created; reused to resume)")
    p.add_argument(
        "--jobs",
        type=non_negative_int,
        metavar="N",
        help="runs at a time in worker processes (default: the usable CPUs; 0: serially in this process)",
    )
    p.add_argument(
        "--threads-per-job",
        type=positive_int,
        default=1,
        metavar="T",
        help="numba/OpenCV/BLAS threads per worker (default 1)",
    )
    p.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="run on this Dask distributed scheduler instead of local processes (needs dmtrack[cluster];"
        " DIR and the sequences must be on a filesystem shared by the workers)",
    )
    p.add_argument("--start", type=non_negative_int, default=0, metavar="N", help="first frame (default 0)")
    p.add_argument("--max-frames", type=positive_int, metavar="N", help="process at most N frames per sequence")
    p.add_argument("--seed", type=int, metavar="S", help="seed of the random depth initialisation (default 0)")
    p.add_argument(
        "--seeds",
        metavar="LIST",
        help="run every cell with each of these seeds: a comma list of seeds and ranges, e.g. 0,1,2 or 0-2 or "
        "0-2,5 (not with --seed; several seeds go to <feature>/seed-<S>/, one seed is the same as --seed S)",
    )
    p.add_argument(
        "--r-l", type=_r_l, metavar="R", help="RPE length ratio, e.g. 1/20 (default 1/20 for KITTI, 1/3 otherwise)"
    )
    p.add_argument(
        "--format",
        choices=FORMATS,
        help="force the dataset format (of --sequences; default for sequences-file entries without one)",
    )
    p.add_argument(
        "--intrinsics",
        metavar="FX,FY,CX,CY",
        help="pinhole intrinsics (of --sequences; default for sequences-file entries without them)",
    )
    p.add_argument(
        "--init",
        choices=("random", "geometric", "groundtruth"),
        help="how every run's first keyframe map is made (default: the configuration's; docs/initialization.md)",
    )
    p.add_argument(
        "--modes",
        default="vo",
        metavar="vo,slam,window",
        help="run every feature as the odometry alone (vo, the default), with the SLAM back end (slam; cells named "
        "FEATURE+slam; pip install 'dmtrack[slam]'), with the sliding window (window; cells FEATURE+window; "
        "docs/window.md) or several (vo,window), side by side in the tables",
    )
    p.add_argument(
        "--device",
        metavar="auto|cpu|cuda[:N]",
        help="where the network features run (default auto: a CUDA GPU when PyTorch sees one, else the CPU); "
        "recorded in every run's spec",
    )
    p.add_argument("--config", metavar="YAML", help="odometry parameters (sections tracker, depth, keyframe)")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override one odometry parameter, e.g. --set tracker.huber_d=2 (repeatable)",
    )
    p.add_argument(
        "--continue-after-loss",
        action="store_true",
        help="keep tracking after a loss (default: stop there, as the paper counts tracked frames)",
    )
    p.add_argument("--no-depth-images", action="store_true", help="do not write depth/*.png (and no Figure 4)")
    p.add_argument("--no-pointcloud", action="store_true", help="do not write pointcloud.ply")
    p.add_argument(
        "--skip-failed", action="store_true", help="do not run again runs that crashed before (default: run them again)"
    )
    p.add_argument("--no-report", action="store_true", help="only run; write the report later with `dmtrack report`")
    p.add_argument("--no-figures", action="store_true", help="report without figures")
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="progress bar (default: only on a terminal, not under CI)",
    )
    p.set_defaults(func=cmd_bench)
    return p


def add_report_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``report`` to an ``add_subparsers()`` object; returns its parser."""
    p = subparsers.add_parser(
        "report",
        help="write report.html of a run folder, or rebuild a bench folder's report.md, tables, figures and "
        "report.html",
        description="Write the reports of DIR. For a bench folder (written by `dmtrack bench`: runs/ inside): "
        "rebuild DIR/report.md, DIR/results.csv, DIR/tables/*.csv and DIR/figures/*.png from its finished runs, "
        "and write DIR/report.html. For a run folder (written by `dmtrack run --out DIR`: metrics.json inside): "
        "write DIR/report.html. report.html is one self-contained interactive page (tables, plotly figures, "
        "embedded pictures) that opens in any browser without a server or network access.",
        epilog="examples: dmtrack report bench/   ·   dmtrack report out/run1   ·   dmtrack report bench/ --html-only",
    )
    p.add_argument("bench_dir", metavar="DIR", help="a bench folder (`dmtrack bench`) or a run folder (`dmtrack run`)")
    p.add_argument("--no-figures", action="store_true", help="bench: report.md without figures/*.png")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--no-html", action="store_true", help="bench: do not write report.html")
    which.add_argument(
        "--html-only", action="store_true", help="bench: write only report.html (not report.md, CSVs, figures)"
    )
    p.set_defaults(func=cmd_report)
    return p


def _check_features(names: list[str]) -> None:
    from dmtrack.features.base import get_entry

    for name in names:
        if not _PCA_NAME.match(name.strip().lower()):
            get_entry(name)  # InputError listing the known names


def cmd_bench(args: argparse.Namespace) -> int:
    from dmtrack.experiments.bench import run_bench
    from dmtrack.experiments.grid import SequenceSpec, load_sequences_file
    from dmtrack.features.device import check_device
    from dmtrack.io.bench_layout import format_seeds, parse_seeds

    seeds: list[int] | None = None
    if args.seeds is not None:
        if args.seed is not None:
            raise InputError("--seed and --seeds exclude each other: give --seed S for one seed or --seeds LIST "
                             "(e.g. 0,1,2 or 0-2) for several")  # fmt: skip
        try:
            seeds = parse_seeds(args.seeds)
        except InputError as e:
            raise InputError(f"--seeds: {str(e).removeprefix('seeds: ')}") from None
    # SIGTERM (`kill PID`) arrives as dmtrack.errors.Interrupted, a KeyboardInterrupt (dmtrack.cli.main installs
    # it for every command): the bench stops its workers and leaves no half-written run, as on Ctrl-C

    features = [f.strip() for item in args.features for f in item.split(",") if f.strip()]
    _check_features(features)
    sequences: list[SequenceSpec] = []
    if args.sequences_file:
        sequences += load_sequences_file(args.sequences_file)
    sequences += [SequenceSpec(s) for s in args.sequences]
    if not sequences:
        raise InputError("no sequences: give --sequences S... and/or --sequences-file YAML")
    config = None
    if args.config:
        from dmtrack.odometry.config import VOConfig

        config = VOConfig.from_yaml(args.config)
    overrides = list(args.set)
    if args.init:
        overrides.append(f"init={args.init}")
    if args.continue_after_loss:
        overrides.append("stop_on_loss=false")
    if seeds and len(seeds) > 1:
        from dmtrack.odometry.config import VOConfig

        if (config or VOConfig()).with_overrides(*overrides).init == "geometric":
            print("dmtrack bench: with the geometric start (the default) the seed plays no part: every seed gives the "
                  "same run; add --init random to compare the random starts", file=sys.stderr)
    jobs = args.jobs if args.jobs is not None else max(1, _usable_cpus() // args.threads_per_job)
    n_seeds = len(seeds) if seeds else 1
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    jobs = min(jobs, len(sequences) * len(features) * len(modes) * n_seeds) if jobs > 0 else 0

    def log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    result = run_bench(
        sequences, features, args.out, jobs=jobs, scheduler=args.scheduler, start=args.start,
        max_frames=args.max_frames, seed=args.seed, seeds=seeds, r_l=args.r_l, format=args.format,
        intrinsics=args.intrinsics,
        config=config, overrides=overrides, depth_images=not args.no_depth_images,
        pointcloud=not args.no_pointcloud, threads_per_job=args.threads_per_job, skip_failed=args.skip_failed,
        report=not args.no_report, figures=not args.no_figures, progress=args.progress, log=log,
        device=None if args.device is None else check_device(args.device), modes=modes,
    )  # fmt: skip
    statuses = [o["status"] for o in result.outcomes.values()]
    n_cells = len(result.tasks) // n_seeds
    over = f" ({n_cells} cell{'s' if n_cells != 1 else ''} × seeds {format_seeds(seeds or [])})" if n_seeds > 1 else ""
    print(
        f"bench: {len(result.tasks)} runs{over} — {len(result.skipped)} finished before, "
        f"{len(result.executed)} run now "
        f"({statuses.count('ok')} ok, {statuses.count('lost')} lost tracking, {statuses.count('failed')} failed)"
    )
    if result.report is not None:
        print(f"report: {result.report}")
    if result.failed:
        print(f"dmtrack: warning: {len(result.failed)} run(s) failed: {', '.join(result.failed)} "
              "(see their error.json)", file=sys.stderr)  # fmt: skip
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from pathlib import Path

    from dmtrack.evaluation.html import folder_kind, write_html_report

    root = Path(args.bench_dir)
    if not root.is_dir():
        raise InputError("not a bench folder or a run folder: no such folder", path=root)
    try:
        kind = folder_kind(root)
    except InputError:
        raise InputError("not a bench folder (no runs/ inside; create one with `dmtrack bench`) nor a run folder (no "
                         "metrics.json; create one with `dmtrack run --out DIR`)", path=root) from None  # fmt: skip

    def log(line: str) -> None:
        print(f"dmtrack: warning: {line}", file=sys.stderr)

    if kind == "run":
        if args.no_html:
            raise InputError("--no-html: a run folder has only report.html, so there is nothing to write", path=root)
        out = write_html_report(root, log=log)
        print(f"report: {out} ({_size(out)})")
        return 0
    from dmtrack.evaluation.records import collect_runs
    from dmtrack.evaluation.report import write_report

    n = len(collect_runs(root))
    if n == 0:
        raise InputError("no finished runs in runs/ (nothing to report)", path=root)
    if not args.html_only:
        out = write_report(root, figures=not args.no_figures, log=log)
        print(f"report: {out} ({n} runs)")
    if not args.no_html:
        out = write_html_report(root, log=log)
        print(f"report: {out} ({n} runs, {_size(out)})")
    return 0


def _size(path: Any) -> str:
    return f"{path.stat().st_size / 1e6:.1f} MB"
