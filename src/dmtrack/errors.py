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


class OutputError(DmtrackError):
    """An output file could not be written (disk full, read-only folder, a path that is a folder, …).

    ``path`` names the file; ``errno`` is the operating system's error number when there is one.
    """

    def __init__(self, message: str, path: str | Path, errno: int | None = None):
        self.path = Path(path)
        self.errno = errno
        self.reason = message
        super().__init__(f"{path}: {message}")


class Interrupted(KeyboardInterrupt):
    """A termination signal (SIGTERM, SIGHUP) turned into an interrupt, so runs stop as cleanly as on Ctrl-C.

    ``signal_name`` is e.g. ``"SIGTERM"``; ``exit_code`` is the shell convention 128 + signal number.
    """

    def __init__(self, signal_name: str, signal_number: int):
        self.signal_name = signal_name
        self.exit_code = 128 + int(signal_number)
        super().__init__(f"interrupted by {signal_name}")
