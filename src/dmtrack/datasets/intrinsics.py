"""Reading pinhole intrinsics from the small text files datasets ship, or from a command-line string."""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from dmtrack.errors import InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.files import read_text_file

#: Largest magnitude accepted for a camera parameter read from a file (focal lengths, principal point, distortion
#: coefficients): real cameras are far below it, and larger values only overflow later computations.
MAX_PARAMETER = 1e6

#: File names searched (in this order) for the intrinsics of an image folder.
INTRINSICS_FILES = ("camera.txt", "intrinsics.txt", "camera-intrinsics.txt", "K.txt", "calib.txt")


def _numbers(path: Path) -> list[float]:
    values: list[float] = []
    for lineno, raw in enumerate(read_text_file(path, "intrinsics file").splitlines(), start=1):
        line = raw.split("#", 1)[0].replace(",", " ").strip()
        for field in line.split():
            try:
                values.append(float(field))
            except ValueError:
                raise InputError(f"intrinsics: cannot read {field!r} as a number", path=path, line=lineno) from None
    return values


def check_range(values: Iterable[float], what: str, path: str | Path | None = None, line: int | None = None) -> None:
    """An :class:`InputError` if a value is not finite or beyond ±:data:`MAX_PARAMETER`."""
    for v in values:
        if not math.isfinite(v):
            raise InputError(f"{what}: {v} is not a finite number", path=path, line=line)
        if abs(v) > MAX_PARAMETER:
            raise InputError(f"{what}: {v:g} is out of range (at most {MAX_PARAMETER:g} in magnitude)", path=path,
                             line=line)


def read_intrinsics_file(path: str | Path, width: int, height: int) -> PinholeCamera:
    """Read pinhole intrinsics from ``path``.

    Accepted contents: four numbers ``fx fy cx cy`` (one line), or a 3×3 matrix K (9 numbers, e.g.
    7-Scenes' ``camera-intrinsics.txt``).  Intrinsics are in pixels of the stored images.
    """
    path = Path(path)
    v = _numbers(path)
    if len(v) == 4:
        fx, fy, cx, cy = v
    elif len(v) == 9:
        K = np.asarray(v).reshape(3, 3)
        if not np.isfinite(K).all():
            raise InputError("intrinsics: the 3×3 K has a value that is not a finite number", path=path)
        if not np.allclose(K[2], (0.0, 0.0, 1.0)) or K[1, 0] != 0.0:
            raise InputError("intrinsics: a 3×3 K must have the last row 0 0 1 and K[1,0] = 0", path=path)
        if K[0, 1] != 0.0:
            raise InputError("intrinsics: skewed K (K[0,1] ≠ 0) is not supported", path=path)
        fx, fy, cx, cy = (float(v) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
    else:
        raise InputError(
            f"intrinsics: expected 'fx fy cx cy' (4 numbers) or a 3×3 matrix (9 numbers), found {len(v)} numbers",
            path=path,
        )
    check_range((fx, fy, cx, cy), "intrinsics", path)
    try:
        return PinholeCamera(fx, fy, cx, cy, width, height)
    except ValueError as e:
        raise InputError(f"intrinsics: {e}", path=path) from None


def parse_intrinsics(text: str, width: int, height: int) -> PinholeCamera:
    """Intrinsics from a command-line string ``"fx,fy,cx,cy"`` (commas or spaces)."""
    fields = text.replace(",", " ").split()
    try:
        values = [float(f) for f in fields]
    except ValueError:
        raise InputError(f"--intrinsics {text!r}: expected four numbers 'fx,fy,cx,cy'") from None
    if len(values) != 4:
        raise InputError(f"--intrinsics {text!r}: expected four numbers 'fx,fy,cx,cy', got {len(values)}")
    check_range(values, f"--intrinsics {text!r}")
    try:
        return PinholeCamera(*values, width, height)
    except ValueError as e:
        raise InputError(f"--intrinsics {text!r}: {e}") from None


def find_intrinsics_file(folder: Path, names: tuple[str, ...] = INTRINSICS_FILES) -> Path | None:
    for name in names:
        if (folder / name).exists():  # a folder of that name is reported when it is read
            return folder / name
    return None
