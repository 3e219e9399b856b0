"""The fault suite's bookkeeping: every test records what it tried, so docs/reliability.md is generated, not written.

``fault_log`` (session scope, usable inside hypothesis ``@given`` tests) has

* ``tried(target, fault, n=1)`` — ``n`` malformed inputs / injected faults of kind ``fault`` against ``target``
  (a parser, a reader, a writer, a command) that were handled as promised (a test fails otherwise, so a recorded
  case is a passed case);
* ``kept(target, fault, finished, kept)`` — a fault that interrupted work: ``finished`` results existed before it,
  ``kept`` of them are on disk afterwards (the tests assert ``kept == finished``).

With ``DMTRACK_FAULT_LOG=FILE`` every record is appended to FILE as a JSON line; ``tools/reliability_report.py``
runs this suite that way and writes docs/reliability.md. Fuzzers run ``DMTRACK_FUZZ_EXAMPLES`` examples per parser
(default 200 in the test suite; the report runs 1,000).
"""

from __future__ import annotations

import builtins
import errno
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

FUZZ_EXAMPLES = int(os.environ.get("DMTRACK_FUZZ_EXAMPLES", "200"))


class FaultLog:
    def __init__(self, path: str | None) -> None:
        self.path = Path(path) if path else None
        self.records: list[dict[str, Any]] = []

    def _add(self, record: dict[str, Any]) -> None:
        self.records.append(record)
        if self.path is not None:
            with open(self.path, "a", encoding="utf-8") as f:
                f.write(json.dumps(record) + "\n")

    def tried(self, target: str, fault: str, n: int = 1) -> None:
        self._add({"kind": "tried", "target": target, "fault": fault, "n": int(n)})

    def kept(self, target: str, fault: str, finished: int, kept: int) -> None:
        self._add({"kind": "kept", "target": target, "fault": fault, "finished": int(finished), "kept": int(kept)})


@pytest.fixture(scope="session")
def fault_log() -> FaultLog:
    return FaultLog(os.environ.get("DMTRACK_FAULT_LOG"))


class FullDisk:
    """A disk that fills up: writes of files whose name matches ``match`` fail with ENOSPC after ``budget`` bytes.

    Installed over :func:`builtins.open`, so every writer (the PLY library, the line-by-line trajectory, the
    atomic helpers) meets it the way it would meet a full disk: ``write`` raises ``OSError(ENOSPC)``.
    """

    def __init__(self, folder: Path, budget: int, match: str = "") -> None:
        self.folder = Path(folder).resolve()
        self.budget = budget
        self.match = match
        self.written = 0
        self.failures = 0

    def applies(self, file: Any, mode: str) -> bool:
        if not isinstance(file, (str, os.PathLike)) or not any(c in mode for c in "wax+"):
            return False
        p = Path(file).resolve()
        return p.is_relative_to(self.folder) and self.match in p.name


class _Metered:
    def __init__(self, f: Any, disk: FullDisk) -> None:
        self._f = f
        self._disk = disk

    def write(self, data: Any) -> int:
        size = len(data.encode("utf-8") if isinstance(data, str) else bytes(data))
        if self._disk.written + size > self._disk.budget:
            self._disk.failures += 1
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self._disk.written += size
        return self._f.write(data)

    def __enter__(self) -> _Metered:
        return self

    def __exit__(self, *exc: object) -> None:
        self._f.close()

    def __iter__(self) -> Iterator[Any]:
        return iter(self._f)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._f, name)


@pytest.fixture
def full_disk(monkeypatch: pytest.MonkeyPatch):  # noqa: ANN201
    """``full_disk(folder, budget, match="")`` installs a :class:`FullDisk` for the rest of the test."""
    real_open = builtins.open

    def install(folder: Path, budget: int, match: str = "") -> FullDisk:
        disk = FullDisk(folder, budget, match)

        def fake_open(file: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
            f = real_open(file, mode, *args, **kwargs)
            return _Metered(f, disk) if disk.applies(file, mode) else f

        monkeypatch.setattr(builtins, "open", fake_open)
        return disk

    return install


@pytest.fixture
def read_only(monkeypatch: pytest.MonkeyPatch):  # noqa: ANN201
    """``read_only(folder)``: opening a file under ``folder`` for writing fails with EROFS from then on.

    Tests run as root in CI, where a chmod-ed folder is still writable; this makes the failure real for the code
    under test (its ``open`` fails exactly as on a read-only mount).
    """
    real_open = builtins.open

    def install(folder: Path) -> None:
        disk = FullDisk(folder, 0)

        def fake_open(file: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
            if disk.applies(file, mode):
                raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(file))
            return real_open(file, mode, *args, **kwargs)

        monkeypatch.setattr(builtins, "open", fake_open)

    return install


def temporaries(folder: Path) -> list[Path]:
    """Every ``*.tmp`` / ``*.part`` left anywhere under ``folder``."""
    return sorted(p for p in Path(folder).rglob("*") if p.name.endswith((".tmp", ".part")))


@pytest.fixture
def leftover_temporaries():  # noqa: ANN201
    return temporaries
