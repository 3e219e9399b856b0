"""``python -m dmtrack.features.weights {list,download NAME [--dest DIR]}``: list and fetch weight files."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from dmtrack.errors import DmtrackError, InputError
from dmtrack.features.weights.catalogue import CATALOGUE, find_weights
from dmtrack.features.weights.download import download

_DESCRIPTION = "Pretrained weights of the learned features: where they live, how to read them, how to fetch them."


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m dmtrack.features.weights {list,download NAME [--dest DIR]}``."""
    parser = argparse.ArgumentParser(prog="python -m dmtrack.features.weights", description=_DESCRIPTION)
    sub = parser.add_subparsers(dest="cmd", required=True)
    sub.add_parser("list", help="known weight files and where they are found")
    d = sub.add_parser("download", help="download and verify an official weight file")
    d.add_argument("name", choices=sorted(CATALOGUE))
    d.add_argument("--dest", default=None, help="directory (default: $DMTRACK_WEIGHTS or ~/.cache/dmtrack/weights)")
    args = parser.parse_args(argv)
    if args.cmd == "list":
        for info in CATALOGUE.values():
            try:
                found = str(find_weights(info.key))
            except InputError:
                found = "missing"
            print(f"{info.key:18s} {info.filename:28s} {found}\n{'':18s} {info.url}")
        return 0
    try:
        path = download(args.name, args.dest)
    except DmtrackError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(path)
    return 0
