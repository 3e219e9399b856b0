"""Where features' calibrations are kept: the packaged ``default_scales.json``, the user's folder and table, and how
a calibration's recorded options are matched to a feature's (:mod:`dmtrack.features.base` builds on it).

``default_scales.json`` entries record the options they were measured with (the feature's defaults) and may hold
``variants`` measured with other options; the user's ``scales.json`` (``dmtrack calibrate-scale --save``) records the
options that differ from the defaults. :func:`options_match` decides whether a calibration applies.
"""

from __future__ import annotations

import json
import os
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack.errors import InputError

__all__ = [
    "changed_options",
    "default_scales_table",
    "options_match",
    "same_value",
    "user_dir",
    "user_pca_path",
    "user_scales",
    "user_scales_path",
]


@lru_cache(maxsize=1)
def default_scales_table() -> dict[str, Any]:
    """The packaged ``default_scales.json`` (``{"scales": {name: {"scale": float, ...}}, ...}``)."""
    text = resources.files("dmtrack.features").joinpath("default_scales.json").read_text(encoding="utf-8")
    table = json.loads(text)
    if not isinstance(table, dict) or not isinstance(table.get("scales"), dict):
        raise RuntimeError("dmtrack/features/default_scales.json is malformed (no 'scales' object)")
    return table


def user_dir() -> Path:
    """Where dmtrack keeps what users calibrate and fit: ``$DMTRACK_HOME``, else ``~/.config/dmtrack``."""
    env = os.environ.get("DMTRACK_HOME")
    return Path(env) if env else Path.home() / ".config" / "dmtrack"


def user_scales_path() -> Path:
    """The user's table of calibrated feature scales (written by ``dmtrack calibrate-scale --save``)."""
    return user_dir() / "scales.json"


def user_scales() -> dict[str, Any]:
    """``{name: {"scale": float, ...}}`` from :func:`user_scales_path` (empty when there is none)."""
    path = user_scales_path()
    if not path.is_file():
        return {}
    try:
        table = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read the calibrated scales ({exc})", path=path) from None
    scales = table.get("scales") if isinstance(table, dict) else None
    if not isinstance(scales, dict):
        raise InputError("malformed scales file (expected {\"scales\": {name: {\"scale\": ...}}})", path=path)
    return scales


def user_pca_path(base: str, k: int | None = None) -> Path:
    """Where ``dmtrack fit-pca`` stores a basis: ``pca/BASE-pcaK.npz`` (or ``pca/BASE.npz`` for all components)."""
    return user_dir() / "pca" / (f"{base}-pca{k}.npz" if k is not None else f"{base}.npz")


def same_value(a: Any, b: Any) -> bool:
    a, b = (os.fspath(x) if isinstance(x, os.PathLike) else x for x in (a, b))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool | np.bool_) \
            and not isinstance(b, bool | np.bool_):
        return float(a) == float(b)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same_value(x, y) for x, y in zip(a, b, strict=True))
    return bool(a == b)


#: Options that choose where or how the same function is computed (``device``: CPU or GPU; ``backend``: which CPU
#: kernels), not what: a calibration applies whatever their values.
RUNTIME_OPTIONS = frozenset({"device", "backend"})


def _calibrated(options: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in options.items() if k not in RUNTIME_OPTIONS}


def options_match(recorded: dict[str, Any] | None, options: dict[str, Any] | None, defaults: dict[str, Any]) -> bool:
    """Whether a calibration measured with ``recorded`` options applies to a feature built with ``options``; both
    are completed with ``defaults`` (an entry recorded without options, or a feature built without any, means the
    defaults), numbers compare by value (2 == 2.0); :data:`RUNTIME_OPTIONS` do not count."""
    a = _calibrated({**defaults, **(recorded or {})})
    b = _calibrated({**defaults, **(options or {})})
    return a.keys() == b.keys() and all(same_value(a[k], b[k]) for k in a)


def changed_options(options: dict[str, Any] | None, defaults: dict[str, Any]) -> dict[str, Any]:
    """The items of ``options`` whose value differs from ``defaults``' (by :func:`same_value`; an option without a
    default counts as changed), :data:`RUNTIME_OPTIONS` left out."""
    missing = object()
    return {k: v for k, v in _calibrated(options or {}).items() if not same_value(v, defaults.get(k, missing))}
