"""``dmtrack download DATASET SEQUENCE DIR``: fetch a public dataset sequence (see :mod:`dmtrack.datasets.download`).

Wire into the CLI with ``add_download_parser(sub)`` where ``sub`` is the subparsers object of
:func:`dmtrack.cli.build_parser`.
"""

from __future__ import annotations

import argparse
import sys


def cmd_download(args: argparse.Namespace) -> int:
    from dmtrack.datasets.download import DATASETS, _default_progress, download, plan

    if args.list:
        if args.dataset is None:
            for name, d in DATASETS.items():
                print(f"{name:<12} {len(d.sequences):>3} sequences" + (f"  ({d.note})" if d.note else ""))
        else:
            from dmtrack.datasets.download import sequences

            print("\n".join(sequences(args.dataset)))
        return 0
    if args.dataset is None or args.sequence is None or args.dir is None:
        raise SystemExit("dmtrack download: error: DATASET, SEQUENCE and DIR are required (or use --list)")
    archives = plan(args.dataset, args.sequence)
    note = DATASETS[args.dataset].note
    if note:
        print(f"note: {note}", file=sys.stderr)
    for a in archives:
        print(f"{a.url} -> {args.dir}/{a.filename}", file=sys.stderr)
    if args.dry_run:
        return 0
    out = download(args.dataset, args.sequence, args.dir, extract=not args.no_extract,
                   keep_archive=not args.delete_archive,
                   progress=None if args.quiet else _default_progress)
    if not args.quiet:
        print(file=sys.stderr)
    print(out)
    return 0


def add_download_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``download`` subcommand to ``subparsers``; returns its parser."""
    from dmtrack.datasets.download import DATASETS

    p = subparsers.add_parser(
        "download",
        help="download a sequence of a public dataset (TUM monoVO, TUM RGB-D, KITTI, EuRoC, ICL-NUIM, 7-Scenes)",
        description="Stream an official dataset archive into DIR (resuming partial downloads) and unpack it.",
    )
    p.add_argument("dataset", nargs="?", metavar="DATASET", help=f"one of {', '.join(DATASETS)}")
    p.add_argument("sequence", nargs="?", metavar="SEQUENCE", help="sequence name (see --list)")
    p.add_argument("dir", nargs="?", metavar="DIR", help="target folder")
    p.add_argument("--list", action="store_true", help="list datasets, or the sequences of DATASET")
    p.add_argument("--dry-run", action="store_true", help="print the URLs only")
    p.add_argument("--no-extract", action="store_true", help="keep the archive packed")
    p.add_argument("--delete-archive", action="store_true", help="delete the archive after unpacking")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=cmd_download)
    return p
