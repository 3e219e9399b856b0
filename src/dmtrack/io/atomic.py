"""Atomic file writes: every file dmtrack writes appears complete or not at all.

A writer gets a temporary file in the destination folder (``.NAME.XXXX.tmp``), writes it, and the temporary file
replaces the destination with :func:`os.replace` (atomic on POSIX and Windows) only when writing succeeded. On any
failure — an exception in the writer, a full disk, an interrupt — the temporary file is removed and the previous
version of the destination, if any, is left untouched. Operating-system failures are reported as
:class:`~dmtrack.errors.OutputError` naming the destination, so the CLI prints one line.

Only a ``kill -9`` can leave a ``.NAME.*.tmp`` behind (nothing runs after it); :func:`remove_stale_temporaries`
cleans a folder of them before a run writes there again.

>>> from dmtrack.io.atomic import write_text
>>> write_text("out/notes.txt", "hello\\n")  # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from dmtrack.errors import OutputError

TMP_SUFFIX = ".tmp"


def output_error(path: str | Path, exc: OSError) -> OutputError:
    """The :class:`OutputError` of an OS failure while writing ``path`` ("PATH: cannot write: REASON")."""
    reason = exc.strerror or str(exc) or type(exc).__name__
    return OutputError(f"cannot write: {reason}", path, exc.errno)


def prepare_folder(folder: str | Path) -> Path:
    """Create ``folder`` (and parents); a clear :class:`OutputError` when that is impossible."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputError("is a file, not a folder", folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError) as exc:  # a parent is a regular file
        raise OutputError("a parent of this folder is a file", folder, exc.errno) from None
    except OSError as exc:
        raise OutputError(f"cannot create the folder: {exc.strerror or exc}", folder, exc.errno) from None
    return folder


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; it replaces ``path`` when the block ends without an exception.

    For writers that want a file name (``plyfile``, ``numpy.savez``): write to the yielded path, not to ``path``.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputError("is a folder, not a file", path)
    prepare_folder(path.parent)
    try:
        fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=TMP_SUFFIX)
    except OSError as exc:
        raise output_error(path, exc) from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise output_error(path, exc) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", encoding: str | None = "utf-8") -> Iterator[IO[Any]]:
    """``open`` for writing (mode ``"w"`` or ``"wb"``) whose result appears at ``path`` only when complete."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open writes only ('w' or 'wb'), got mode {mode!r}")
    with atomic_path(path) as tmp:
        try:
            kwargs = {"encoding": encoding} if mode == "w" else {}
            with open(tmp, mode, **kwargs) as f:
                yield f
        except OSError as exc:
            raise output_error(Path(path), exc) from None


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_open(path, "w") as f:
        f.write(text)


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_open(path, "wb") as f:
        f.write(data)


def remove_stale_temporaries(folder: str | Path) -> list[Path]:
    """Remove the ``.NAME.*.tmp`` files a killed writer left in ``folder`` (not recursive); return them."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    stale = [p for p in folder.glob(f".*{TMP_SUFFIX}") if p.is_file()]
    for p in stale:
        p.unlink(missing_ok=True)
    return stale
