"""Ctrl-C and SIGTERM stop a run between frames (docs/reliability.md)."""

from __future__ import annotations

from typing import Any


class _StopBetweenFrames:
    """While tracking: Ctrl-C (SIGINT) and SIGTERM stop the run *between* frames, never in the middle of one.

    Only signals whose current handler raises (Python's Ctrl-C handler; the CLI's SIGTERM handler) are wrapped;
    default and ignored dispositions are left alone. The first signal is remembered and the loop stops after the
    frame in progress; :meth:`exception` is then what the original handler raises (KeyboardInterrupt,
    :class:`~dmtrack.errors.Interrupted`). A second signal acts at once through the original handler.
    """

    def __enter__(self) -> _StopBetweenFrames:
        import signal
        import threading

        self.pending: int | None = None
        self._old: dict[int, Any] = {}
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, getattr(signal, "SIGTERM", None)):
                if sig is not None and callable(old := signal.getsignal(sig)):
                    self._old[sig] = old
                    signal.signal(sig, self._handler)
        return self

    def _handler(self, signum: int, frame: Any) -> None:
        if self.pending is not None:
            self._old[signum](signum, frame)
        self.pending = signum

    def exception(self) -> BaseException | None:
        if self.pending is None:
            return None
        try:
            self._old[self.pending](self.pending, None)
        except BaseException as e:  # noqa: BLE001 - this is the exception the handler wants raised
            return e
        return None

    def __exit__(self, *exc: object) -> None:
        import signal

        for sig, old in self._old.items():
            signal.signal(sig, old)
