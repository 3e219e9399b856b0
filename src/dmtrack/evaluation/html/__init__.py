"""``report.html``: one self-contained, interactive HTML report of a run folder or a bench folder.

:func:`write_html_report` decides what the folder is — a run folder (``dmtrack run … --out DIR``: a
``metrics.json`` at its top) or a bench folder (``dmtrack bench``: a ``runs/`` folder) — and writes
``DIR/report.html`` atomically.  The file opens in any browser without a server or network access: plotly.js
is inlined once, pictures are ``data:`` URIs, the CSS is inline.  The run page is :mod:`.run`, the bench page
:mod:`.bench`; both are built from :mod:`.page` and :mod:`.figures`.  plotly is imported only when a report is
written; without it the error says what to install.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Literal

from dmtrack.errors import InputError
from dmtrack.io.bench_layout import METRICS_JSON, RUNS_DIR

#: The file written into the run or bench folder.
REPORT_HTML = "report.html"


def folder_kind(folder: str | Path) -> Literal["run", "bench"]:
    """``"run"`` for a folder with ``metrics.json`` at its top, ``"bench"`` for one with ``runs/``; otherwise an
    :class:`~dmtrack.errors.InputError` naming the folder."""
    root = Path(folder)
    if not root.is_dir():
        raise InputError("no such folder (expected a run folder or a bench folder)", path=root)
    if (root / METRICS_JSON).is_file():
        return "run"
    if (root / RUNS_DIR).is_dir():
        return "bench"
    raise InputError(f"neither a run folder (no {METRICS_JSON}) nor a bench folder (no {RUNS_DIR}/ inside): "
                     "nothing to report", path=root)  # fmt: skip


def write_html_report(folder: str | Path, *, log: Callable[[str], None] | None = None) -> Path:
    """Write ``report.html`` into a run folder or a bench folder; returns its path.

    Parameters
    ----------
    folder : a run folder (``metrics.json`` at its top) or a bench folder (``runs/`` inside).
    log : called with one line per part of the report that could not be drawn (the page lists them too).

    Raises
    ------
    InputError
        The folder is neither, its ``metrics.json`` is unreadable, a bench has no finished run, or plotly is
        not installed.
    OutputError
        ``report.html`` cannot be written.
    """
    from dmtrack.evaluation.html.page import Page, require_plotly
    from dmtrack.io.atomic import write_text

    root = Path(folder)
    kind = folder_kind(root)
    require_plotly()
    page = Page(title="dmtrack report", log=log)
    if kind == "run":
        from dmtrack.evaluation.html.run import run_page

        subtitle = run_page(root, page)
    else:
        from dmtrack.evaluation.html.bench import bench_page

        subtitle = bench_page(root, page)
    out = root / REPORT_HTML
    write_text(out, page.render(subtitle))
    return out


__all__ = ["REPORT_HTML", "folder_kind", "write_html_report"]
