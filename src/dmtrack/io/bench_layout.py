"""The bench folder: where ``dmtrack bench`` puts its files, their JSON, and the names found in them.

One definition, used both by the bench that writes the folder (:mod:`dmtrack.experiments`) and by the report
that reads it (:mod:`dmtrack.evaluation.records`, :mod:`dmtrack.evaluation.report`)::

    DIR/bench.json                      the grid of the last invocation (features, sequences, options, machine)
    DIR/runs/<sequence>/<feature>/      one run: the files of ``dmtrack run`` (trajectory.txt, keyframes.txt,
                                        pointcloud.ply, depth/, config.yaml, metrics.json) and
        spec.json                       what defines the run (compared on resume)
        evaluation.json                 dmtrack.evaluation.evaluate() of the run (per-length RPE, alignment)
        groundtruth.txt                 ground truth of the processed frames (TUM, T_wc) for the figures
        run_info.json                   where/when it ran: host, platform, CPUs, elapsed, status
        error.json                      only for a crashed run: exception, traceback, frames reached
    DIR/runs/<sequence>/<feature>/seed-<S>/   the same, for each seed of a bench with several seeds
    DIR/report.md, DIR/results.csv, DIR/tables/*.csv, DIR/figures/*.png   (dmtrack.evaluation.report)

Also here: seed lists as written on the command line and in the tables (``0-2,5``, :func:`parse_seeds`,
:func:`format_seeds`), the seed a run used (:func:`effective_seed`), and the dataset group and length unit of
a sequence when the sequences file gives none (:func:`dataset_label`, :func:`length_unit`).

Pure Python, importing nothing heavy: a bench's worker processes import it before they limit their threads.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from dmtrack.errors import InputError
from dmtrack.io.atomic import write_text

#: ``DIR/bench.json``: the grid of the last ``dmtrack bench`` on ``DIR``.
BENCH_JSON = "bench.json"
#: ``DIR/runs/``: one folder per sequence, one per feature inside it.
RUNS_DIR = "runs"
#: Files of a run folder written by the bench (next to those of ``dmtrack run``).
SPEC_JSON = "spec.json"
METRICS_JSON = "metrics.json"
ERROR_JSON = "error.json"
EVALUATION_JSON = "evaluation.json"
RUN_INFO_JSON = "run_info.json"
GROUNDTRUTH_TXT = "groundtruth.txt"
TRAJECTORY_TXT = "trajectory.txt"

_SAFE_NAME = re.compile(r"[^A-Za-z0-9._+-]+")


# ============================================================================================ names
def safe_name(text: str) -> str:
    """``text`` made safe as one folder name (letters, digits, ``. _ + -``; anything else → ``_``)."""
    s = _SAFE_NAME.sub("_", text).strip("._") or "sequence"
    return s[:120]


def seed_dir_name(seed: int) -> str:
    """Folder of one seed's run inside a feature folder with several seeds: ``seed-<S>``."""
    return f"seed-{int(seed)}"


#: A seed's run folder inside a feature folder (see :func:`seed_dir_name`).
SEED_DIR = re.compile(r"^seed-(\d+)$")


# ============================================================================================ JSON files
def read_json(path: Path) -> Any:
    """The JSON in ``path``, or ``None`` if it is missing or unreadable."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` as indented JSON (anything else as ``str``) to ``path``, atomically."""
    write_text(path, json.dumps(data, indent=2, default=str) + "\n")


# ============================================================================================ seeds
_SEED_ITEM = re.compile(r"^\s*(\d+)\s*(?:-\s*(\d+)\s*)?$")


def parse_seeds(text: str | int | Iterable[int]) -> list[int]:
    """Seeds from ``"0,1,2"``, ``"0-2"``, ``"0-2,5"`` (a comma list of seeds and inclusive ranges), an int or
    a list of ints, in the given order; seeds are integers ≥ 0 and each may appear once.

    >>> parse_seeds("0-2,5")
    [0, 1, 2, 5]
    """
    if isinstance(text, bool):
        raise InputError(f"seeds: not an integer: {text!r}")
    if isinstance(text, int):
        items: list[int] = [text]
    elif isinstance(text, str):
        items = []
        if not text.strip():
            raise InputError("seeds: empty list (expected e.g. 0,1,2 or 0-2 or 0-2,5)")
        for part in text.split(","):
            m = _SEED_ITEM.match(part)
            if not m:
                raise InputError(f"seeds: cannot read {part.strip()!r} in {text!r} (expected e.g. 0,1,2 or 0-2 or "
                                 "0-2,5; seeds are integers ≥ 0)")  # fmt: skip
            lo = int(m.group(1))
            hi = lo if m.group(2) is None else int(m.group(2))
            if hi < lo:
                raise InputError(f"seeds: empty range {part.strip()!r} in {text!r} (write LOW-HIGH, LOW ≤ HIGH)")
            items += range(lo, hi + 1)
    else:
        items = []
        for v in text:
            if isinstance(v, bool) or not isinstance(v, int):
                raise InputError(f"seeds: not an integer: {v!r}")
            items.append(int(v))
        if not items:
            raise InputError("seeds: empty list")
    for v in items:
        if v < 0:
            raise InputError(f"seeds must be ≥ 0, got {v}")
    dup = sorted({v for v in items if items.count(v) > 1})
    if dup:
        raise InputError(f"seeds: {', '.join(map(str, dup))} listed twice in {text!r}")
    return items


def format_seeds(seeds: Iterable[int]) -> str:
    """The inverse of :func:`parse_seeds` for sorted output: ``[0, 1, 2, 5]`` → ``"0-2,5"``."""
    xs = sorted(set(int(s) for s in seeds))
    parts: list[str] = []
    i = 0
    while i < len(xs):
        j = i
        while j + 1 < len(xs) and xs[j + 1] == xs[j] + 1:
            j += 1
        parts.append(str(xs[i]) if j == i else f"{xs[i]}-{xs[j]}" if j > i + 1 else f"{xs[i]},{xs[j]}")
        i = j + 1
    return ",".join(parts)


def effective_seed(spec: Any) -> Any:
    """The seed a run with this spec uses: its ``seed``, else its configuration's (``None`` if unknown)."""
    if not isinstance(spec, dict):
        return None
    if spec.get("seed") is not None:
        return spec["seed"]
    cfg = spec.get("config")
    return cfg.get("seed", 0) if isinstance(cfg, dict) else None


# ============================================================================================ datasets
def dataset_label(format: str | None, name: str | None) -> str:
    """The dataset a sequence belongs to, for the ranking tables (used when none is given).

    By format (``kitti`` → KITTI, ``7scenes`` → 7-Scenes, ``tsukuba`` → Tsukuba, ``icl-nuim`` → ICL-NUIM,
    ``tum-monovo`` → TUM monoVO, ``tum-rgbd`` → TUM RGB-D, ``euroc`` → EuRoC, ``lsd-slam`` → LSD-SLAM,
    ``synthetic``); for image folders and videos by name (``tsukuba``, ``icl``, ``monovo``/``mono``/``tum``,
    ``lsd``, ``kitti``, ``7scenes``, ``euroc`` in it), else the format itself.
    """
    fmt = (format or "").lower()
    low = (name or "").lower()
    fixed = {"kitti": "KITTI", "7scenes": "7-Scenes", "synthetic": "synthetic", "tum-rgbd": "TUM RGB-D",
             "tsukuba": "Tsukuba", "icl-nuim": "ICL-NUIM", "tum-monovo": "TUM monoVO", "euroc": "EuRoC",
             "lsd-slam": "LSD-SLAM"}  # fmt: skip
    if fmt in fixed:
        return fixed[fmt]
    for needle, label in (("tsukuba", "Tsukuba"), ("icl", "ICL-NUIM"), ("monovo", "TUM monoVO"),
                          ("mono", "TUM monoVO"), ("tum", "TUM monoVO"), ("lsd", "LSD-SLAM"),
                          ("kitti", "KITTI"), ("7scenes", "7-Scenes"), ("euroc", "EuRoC")):  # fmt: skip
        if needle in low:
            return label
    return fmt or "unknown"


def length_unit(format: str | None, name: str | None) -> str:
    """The ground truth's length unit when the sequences file gives none: ``"cm"`` for New Tsukuba read as
    an image folder (its ``groundtruth.txt`` keeps the dataset's centimetres; the ``tsukuba`` reader converts
    to metres), else ``"m"``."""
    fmt = (format or "").lower()
    if fmt in ("image-folder", "") and "tsukuba" in (name or "").lower():
        return "cm"
    return "m"


__all__ = [
    "BENCH_JSON",
    "ERROR_JSON",
    "EVALUATION_JSON",
    "GROUNDTRUTH_TXT",
    "METRICS_JSON",
    "RUNS_DIR",
    "RUN_INFO_JSON",
    "SEED_DIR",
    "SPEC_JSON",
    "TRAJECTORY_TXT",
    "dataset_label",
    "effective_seed",
    "format_seeds",
    "length_unit",
    "parse_seeds",
    "read_json",
    "safe_name",
    "seed_dir_name",
    "write_json",
]
