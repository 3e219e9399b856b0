"""The pieces of a self-contained ``report.html``: escaped text, tables, embedded pictures and plotly figures.

A :class:`Page` collects headed sections, tables, pictures (``data:`` URIs) and interactive plotly figures and
renders them as one HTML file that needs nothing else: plotly.js is inlined once in the ``<head>``, the CSS is
a few inline lines, there are no fonts, no CDN links and no ``http(s)://`` address that a browser would fetch when
the file is opened.  All text is escaped with :func:`html.escape`.

plotly is imported inside the functions (:func:`require_plotly`), so importing this module costs nothing.
"""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack import __version__
from dmtrack.errors import InputError

#: Line colours by index (matplotlib's tab10, as the PNG figures of ``report.md``: feature i has colour ``C{i}``).
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
           "#17becf")  # fmt: skip
#: Options of every plotly figure: no plotly logo link, resize with the page.
PLOT_CONFIG = {"displaylogo": False, "responsive": True}
#: Margins of a figure with subplot titles (room for the figure's title above them).
SUBPLOT_MARGIN = {"l": 64, "r": 20, "t": 96, "b": 52}
#: Most points drawn per line of a figure (longer trajectories are thinned evenly; the file stays small).
MAX_LINE_POINTS = 3000

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;margin:0;color:#1d2330;
background:#fafbfc;line-height:1.45}
header,main,footer{max-width:1180px;margin:0 auto;padding:0 20px}
header{padding-top:18px}
h1{font-size:1.6em;margin:.3em 0}h2{font-size:1.3em;margin-top:1.6em;border-bottom:1px solid #d5dae1}
h3{font-size:1.08em;margin-top:1.3em}
nav{font-size:.92em}nav a{margin-right:1em}
table{border-collapse:collapse;margin:.6em 0;font-size:.9em;background:#fff}
th,td{border:1px solid #d5dae1;padding:3px 8px;vertical-align:top}th{background:#eef1f5;text-align:left}
td.r{text-align:right;font-variant-numeric:tabular-nums}td.c{text-align:center}
table.kv th{width:14em}
.caption,figcaption{font-size:.88em;color:#4a5261;font-style:italic;margin:.2em 0 1em}
figure{margin:.8em 0 1.4em;background:#fff;border:1px solid #e3e7ec;padding:6px}
.note{background:#fff8e1;border-left:4px solid #f2c037;padding:6px 10px;font-size:.92em}
.problem{background:#fdecea;border-left:4px solid #d93025;padding:6px 10px;font-size:.92em}
.pictures{display:flex;flex-wrap:wrap;gap:10px}.pictures figure{margin:0;flex:0 0 auto}
.pictures img{display:block;max-width:100%}
footer{font-size:.85em;color:#6b7280;padding:20px}
""".strip()


def esc(text: Any) -> str:
    """``text`` as HTML text (``&``, ``<``, ``>`` and quotes escaped)."""
    return html.escape(str(text), quote=True)


def colour(i: int) -> str:
    """The ``i``-th line colour (:data:`PALETTE`, cycled)."""
    return PALETTE[i % len(PALETTE)]


def require_plotly() -> Any:
    """The ``plotly`` package, or an :class:`~dmtrack.errors.InputError` saying how to install it."""
    try:
        import plotly
        import plotly.graph_objects  # noqa: F401
    except ImportError:
        raise InputError("report.html needs plotly, which is not installed: pip install plotly") from None
    return plotly


# ================================================================================================ tables
def table(headers: Sequence[str], rows: Sequence[Sequence[Any]], align: str | None = None, cls: str = "") -> str:
    """An HTML table; ``align`` has one letter per column (``l``, ``r``, ``c``; default: first left, others right)."""
    align = align or "l" + "r" * (len(headers) - 1)
    out = [f'<table class="{esc(cls)}">' if cls else "<table>", "<thead><tr>"]
    out += [f"<th>{esc(h)}</th>" for h in headers]
    out.append("</tr></thead><tbody>")
    for r in rows:
        cells = [f'<td class="{a}">{esc(c)}</td>' if a != "l" else f"<td>{esc(c)}</td>"
                 for c, a in zip(r, align, strict=False)]  # fmt: skip
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def key_value_table(items: Sequence[tuple[str, Any]]) -> str:
    """A two-column table of ``(name, value)`` rows."""
    rows = "".join(f"<tr><th>{esc(k)}</th><td>{esc(v)}</td></tr>" for k, v in items)
    return f'<table class="kv"><tbody>{rows}</tbody></table>'


_MD_SPLIT = re.compile(r"(?<!\\) \| ")
_MD_ALIGN = {":---": "l", "---:": "r", ":---:": "c"}


def md_table_html(md: str) -> str:
    """The HTML of a markdown table made by :func:`dmtrack.evaluation.tables.md_table` (same cells, same
    alignment), so that report.html shows exactly the numbers of report.md."""
    lines = [ln.strip() for ln in md.strip().splitlines() if ln.strip()]
    if len(lines) < 2:
        raise ValueError("not a markdown table: fewer than 2 lines")

    def cells(line: str) -> list[str]:
        if not (line.startswith("| ") and line.endswith(" |")):
            raise ValueError(f"not a markdown table row: {line[:60]!r}")
        return [c.replace("\\|", "|") for c in _MD_SPLIT.split(line[2:-2])]

    headers = cells(lines[0])
    align = "".join(_MD_ALIGN.get(m, "l") for m in cells(lines[1]))
    return table(headers, [cells(ln) for ln in lines[2:]], align)


# ============================================================================================ pictures
def png_data_uri(path: Path, max_width: int = 320) -> str:
    """An image file as a ``data:image/png;base64,…`` URI, scaled down (area averaging) to at most ``max_width``
    pixels wide; raises ``ValueError`` if the file cannot be read as an image."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"{path}: not a readable image")
    h, w = img.shape[:2]
    if w > max_width:
        img = cv2.resize(img, (max_width, max(1, round(h * max_width / w))), interpolation=cv2.INTER_AREA)
    ok, data = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise ValueError(f"{path}: OpenCV cannot encode it as PNG")
    return "data:image/png;base64," + base64.b64encode(data.tobytes()).decode("ascii")


# ============================================================================================ figures
def thin(points: np.ndarray, max_n: int = MAX_LINE_POINTS) -> np.ndarray:
    """At most ``max_n`` rows of ``points``, evenly spaced, first and last kept, as float32 (compact in the file)."""
    p = np.asarray(points)
    if len(p) > max_n:
        p = p[np.unique(np.linspace(0, len(p) - 1, max_n).round().astype(int))]
    return p.astype(np.float32)


def base_layout(title: str, height: int, **kw: Any) -> dict[str, Any]:
    """Layout settings shared by the figures (plain template: a few bytes instead of plotly's default theme)."""
    layout: dict[str, Any] = {
        "template": "none",
        "title": {"text": esc(title), "x": 0.01, "font": {"size": 15}},
        "height": height,
        "margin": {"l": 64, "r": 20, "t": 56, "b": 52},
        "legend": {"orientation": "h", "y": -0.18, "font": {"size": 11}},
        "hovermode": "closest",
        "font": {"family": "system-ui, sans-serif", "size": 12},
    }
    layout.update(kw)
    return layout


def axis_basis_text(basis: np.ndarray) -> str:
    """``"axis 1 = +0.98 x − 0.20 z; axis 2 = …"``: the world directions of a top view's two axes."""
    parts = []
    for k, row in enumerate(np.asarray(basis)):
        terms = [(c, n) for c, n in zip(row, "xyz", strict=True) if abs(c) >= 0.05]
        text = " ".join(f"{'−' if c < 0 else '+'}{abs(c):.2f} {n}" for c, n in terms) or "0"
        parts.append(f"axis {k + 1} = {text.lstrip('+')}")
    return "; ".join(parts)


@dataclass
class Page:
    """One HTML report being built: its sections (HTML snippets), table of contents, figures and problems."""

    title: str
    parts: list[str] = field(default_factory=list)
    toc: list[tuple[str, str]] = field(default_factory=list)
    figures: int = 0
    problems: list[str] = field(default_factory=list)
    log: Callable[[str], None] | None = None

    def add(self, snippet: str) -> None:
        """Append raw HTML (already escaped)."""
        self.parts.append(snippet)

    def heading(self, level: int, text: str, toc: bool = False) -> None:
        """``<hN>`` with an anchor; ``toc``: listed in the navigation bar."""
        anchor = f"s{len(self.parts)}-" + (re.sub(r"[^A-Za-z0-9]+", "-", text).strip("-").lower() or "x")
        self.parts.append(f'<h{level} id="{esc(anchor)}">{esc(text)}</h{level}>')
        if toc:
            self.toc.append((anchor, text))

    def text(self, text: str, cls: str = "") -> None:
        """A paragraph of plain text (escaped); ``cls``: ``"caption"``, ``"note"`` or ``"problem"``."""
        self.parts.append(f'<p class="{cls}">{esc(text)}</p>' if cls else f"<p>{esc(text)}</p>")

    def items(self, lines: Sequence[str]) -> None:
        """A bulleted list of plain-text lines."""
        self.parts.append("<ul>" + "".join(f"<li>{esc(x)}</li>" for x in lines) + "</ul>")

    def problem(self, what: str, exc: BaseException) -> None:
        """Record something that could not be shown (listed at the end of the page and given to ``log``)."""
        msg = f"{what}: {type(exc).__name__}: {exc}"
        self.problems.append(msg)
        if self.log is not None:
            self.log(f"report.html: {msg}")

    def figure(self, fig: Any, caption: str) -> None:
        """An interactive plotly figure (drawn by the plotly.js inlined once in the page) with a caption."""
        self.figures += 1
        height = fig.layout.height or 450
        div = fig.to_html(full_html=False, include_plotlyjs=False, div_id=f"figure-{self.figures}",
                          config=PLOT_CONFIG, default_width="100%", default_height=f"{int(height)}px")  # fmt: skip
        self.parts.append(f'<figure class="plot">{div}<figcaption>{esc(caption)}</figcaption></figure>')

    def try_figure(self, make: Callable[[], tuple[Any, str] | None], what: str) -> None:
        """``make()`` → ``(figure, caption)`` or ``None`` (nothing to draw); an exception is a :meth:`problem`,
        so one broken figure never loses the rest of the report."""
        try:
            made = make()
        except Exception as e:  # noqa: BLE001 — reported on the page instead of failing the report
            self.problem(what, e)
            return
        if made is not None:
            self.figure(*made)

    def render(self, subtitle: str = "") -> str:
        """The whole page: plotly.js inlined once when it has figures, then the sections and the problems."""
        head_js = ""
        if self.figures:
            from plotly.offline import get_plotlyjs

            js = get_plotlyjs().replace("</script", "<\\/script")
            head_js = f'<script type="text/javascript">{js}</script>'
        body = list(self.parts)
        if self.problems:
            body.append('<h2 id="problems">Problems while writing this report</h2>')
            body.append("<ul>" + "".join(f'<li class="problem">{esc(p)}</li>' for p in self.problems) + "</ul>")
        nav = ""
        if self.toc:
            nav = "<nav>" + "".join(f'<a href="#{esc(a)}">{esc(t)}</a>' for a, t in self.toc) + "</nav>"
        stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
        return (
            '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
            f'<title>{esc(self.title)}</title>\n<link rel="icon" href="data:,">\n<style>{CSS}</style>\n'
            f"{head_js}\n</head>\n<body>\n<header><h1>{esc(self.title)}</h1>"
            + (f'<p class="caption">{esc(subtitle)}</p>' if subtitle else "")
            + f"{nav}</header>\n<main>\n"
            + "\n".join(body)
            + f"\n</main>\n<footer>Written by dmtrack {esc(__version__)} on {esc(stamp)}. This file is "
            "self-contained: it loads nothing from the network; the figures are interactive (zoom, pan, hover; "
            "click a legend entry to hide a line).</footer>\n</body>\n</html>\n"
        )


__all__ = [
    "PALETTE",
    "SUBPLOT_MARGIN",
    "Page",
    "axis_basis_text",
    "base_layout",
    "colour",
    "esc",
    "key_value_table",
    "md_table_html",
    "png_data_uri",
    "require_plotly",
    "table",
    "thin",
]
