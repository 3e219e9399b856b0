"""Exceptions raised by dmtrack.

Every error caused by user input names the file (and line, where there is one) and the problem, so
that the CLI can print it as a single line.
"""

from __future__ import annotations

from pathlib import Path


class DmtrackError(Exception):
    """Base class of all dmtrack errors."""


class InputError(DmtrackError):
    """Bad user input: a missing or malformed file, a wrong argument.

    ``path`` and ``line`` (1-based) locate the problem when known.
    """

    def __init__(self, message: str, path: str | Path | None = None, line: int | None = None):
        self.path = None if path is None else Path(path)
        self.line = line
        self.reason = message
        where = ""
        if path is not None:
            where = f"{path}"
            if line is not None:
                where += f":{line}"
            where += ": "
        super().__init__(where + message)


class DatasetError(InputError):
    """A sequence could not be recognised or read."""


class TrackingLost(DmtrackError):
    """Tracking failed at ``frame`` for ``reason``."""

    def __init__(self, frame: int, reason: str):
        self.frame = frame
        self.reason = reason
        super().__init__(f"tracking lost at frame {frame}: {reason}")
