"""Reading input files with errors that name them: one place for "missing", "a folder", "unreadable", "not text".

Every reader of dmtrack (trajectories, calibrations, timestamps, images) opens its files through these, so each of
those failures is one :class:`~dmtrack.errors.InputError` line naming the file, never a traceback.
"""

from __future__ import annotations

from pathlib import Path

from dmtrack.errors import InputError


def check_file(path: str | Path, what: str) -> Path:
    """``path`` if it is an existing file; else an :class:`InputError` saying that the ``what`` is missing or is a
    folder."""
    path = Path(path)
    try:
        is_dir, exists = path.is_dir(), path.exists()
    except OSError as e:  # e.g. a parent folder that may not be searched
        raise InputError(f"cannot read the {what} ({e.strerror or e})", path=path) from None
    if is_dir:
        raise InputError(f"{what} expected, but this is a folder", path=path)
    if not exists:
        raise InputError(f"{what} not found", path=path)
    return path


def read_bytes(path: str | Path, what: str) -> bytes:
    """The bytes of ``path``, or an :class:`InputError` naming the file (missing, a folder, unreadable)."""
    path = check_file(path, what)
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError as e:
        raise InputError(f"cannot read the {what} ({e.strerror or e})", path=path) from None


def read_text_file(path: str | Path, what: str) -> str:
    """The text of ``path`` (UTF-8, a byte-order mark is skipped), or an :class:`InputError` naming the file.

    ``what`` names the kind of file in the messages (``"TUM trajectory"``, ``"calibration file"``, …).  A missing
    file, a folder, an unreadable file (permissions, I/O error) and a file that is not UTF-8 text (binary data, a
    NUL byte, another encoding such as UTF-16) each give one clear line instead of a traceback.
    """
    data = read_bytes(path, what)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(
            f"not a text {what} ({e.reason} at byte {e.start}: not a text file, or not UTF-8)", path=path
        ) from None
    nul = text.find("\x00")
    if nul >= 0:
        raise InputError(f"not a text {what} (NUL character at position {nul}: not a text file)", path=path)
    return text
