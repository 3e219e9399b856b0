"""report.html of a real run folder and a real bench folder: its structure, and the page in a real headless Chromium.

One run of the shipped 7-Scenes sample (40 frames) and one small bench (two synthetic sequences × gray,
bitplanes × seeds 0-1, 10 frames) are made once per module through the ``dmtrack`` command line; the reports are
written by ``dmtrack report``.  The structure tests parse the HTML; the browser tests open the files in Debian's
Chromium driven by playwright (skipped, with the reason, when either is missing) and check that every figure is
drawn, nothing is fetched, no error is logged and the numbers of metrics.json / report.md are on screen.
"""

from __future__ import annotations

import base64
import json
import re
import shutil
import sys
import time
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from dmtrack.cli import main
from dmtrack.errors import InputError
from dmtrack.evaluation.html import REPORT_HTML, write_html_report
from dmtrack.evaluation.html.run import MAX_DEPTH_PICTURES
from dmtrack.evaluation.tables import fmt_value

SYN = ["synthetic:n_frames=25,width=320,height=240,seed=1,texel=0.02",
       "synthetic:n_frames=25,width=320,height=240,seed=2,texel=0.02"]  # fmt: skip
FEATURES = ["gray", "bitplanes"]
BROWSER_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", "--no-first-run"]  # fmt: skip
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


# =============================================================================================== fixtures
@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory, sample_dir: Path) -> Path:
    out = tmp_path_factory.mktemp("html-run") / "run"
    assert main(["run", str(sample_dir), "--max-frames", "40", "--out", str(out)]) == 0
    assert main(["report", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def bench_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("html-bench") / "bench"
    assert main(["bench", "--sequences", *SYN, "--features", *FEATURES, "--seeds", "0-1", "--max-frames", "10",
                 "--jobs", "0", "--no-pointcloud", "--no-report", "--out", str(out)]) == 0  # fmt: skip
    assert main(["report", str(out), "--no-figures"]) == 0
    return out


class _Parsed(HTMLParser):
    """Tags with their attributes, the text of <title>, and every table as rows of cell texts."""

    def __init__(self, text: str) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.title = ""
        self.tables: list[list[list[str]]] = []
        self._in: list[str] = []
        self._cell: list[str] | None = None
        self.feed(text)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))
        self._in.append(tag)
        if tag == "table":
            self.tables.append([])
        elif tag == "tr" and self.tables:
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._cell is not None and self.tables and self.tables[-1]:
            self.tables[-1][-1].append("".join(self._cell))
            self._cell = None
        if self._in and self._in[-1] == tag:
            self._in.pop()

    def handle_data(self, data: str) -> None:
        if self._in and self._in[-1] == "title":
            self.title += data
        if self._cell is not None:
            self._cell.append(data)


def parse(path: Path) -> tuple[str, _Parsed]:
    text = path.read_text(encoding="utf-8")
    return text, _Parsed(text)


def figure_count(text: str) -> int:
    return len(re.findall(r'class="plotly-graph-div"', text))


def assert_self_contained(text: str, doc: _Parsed) -> None:
    """plotly.js inlined exactly once and nothing a browser would fetch from elsewhere when opening the file."""
    from plotly.offline import get_plotlyjs

    js_head = get_plotlyjs()[:300]
    assert text.count(js_head) == 1
    scripts = [a for t, a in doc.tags if t == "script"]
    assert scripts and all("src" not in a for a in scripts)  # inline scripts only
    for tag, attrs in doc.tags:
        for key in ("src", "href", "srcset", "data", "poster", "action"):
            v = (attrs.get(key) or "").strip().lower()
            assert not v.startswith(("http:", "https:", "//", "ftp:")), (tag, key, v[:80])
        if tag == "link":
            assert (attrs.get("href") or "").startswith("data:"), attrs  # only the empty favicon
    style = text[text.index("<style>"): text.index("</style>")]
    assert "@import" not in style and "url(" not in style


def md_tables(md: str) -> list[list[list[str]]]:
    """The markdown tables of report.md as rows of cell texts (the alignment row left out)."""
    tables: list[list[list[str]]] = []
    previous = False
    for line in md.splitlines():
        if line.startswith("| ") and line.endswith(" |"):
            cells = [c.replace("\\|", "|") for c in re.split(r"(?<!\\) \| ", line[2:-2])]
            if not previous:
                tables.append([])
            if not all(re.fullmatch(r":?-+:?", c) for c in cells):
                tables[-1].append(cells)
            previous = True
        else:
            previous = False
    return tables


# ============================================================================================ run folder
def test_run_report_shows_the_metrics_and_is_self_contained(run_dir: Path):
    m = json.loads((run_dir / "metrics.json").read_text())
    text, doc = parse(run_dir / REPORT_HTML)
    assert_self_contained(text, doc)
    assert m["sequence"] in doc.title and m["feature"] in doc.title
    cells = {row[0]: row[1] for table in doc.tables for row in table if len(row) == 2}
    assert cells["ATE RMSE (m, Sim(3)-aligned)"] == fmt_value(m["ate_rmse"], 4)
    assert cells["RPE rotation (deg/m)"] == fmt_value(m["rpe_rot_deg_per_m"], 3)
    assert cells["RPE translation angle (deg/m)"] == fmt_value(m["rpe_trans_angle_deg_per_m"], 3)
    assert cells["fps (processed frames per wall-clock second)"] == fmt_value(m["fps"], 1)
    assert cells["Sim(3) scale of the alignment"] == fmt_value(m["ate_scale"], 3)
    gain = cells["Rotation gain x / y / z (estimate's turn over the ground truth's)"]
    assert gain == " / ".join(fmt_value(g, 2) for g in m["rotation_gain"]) and gain.count(" / ") == 2
    assert cells["Frames tracked / total"] == f"{m['tracked_frames']} / {m['total_frames']}"
    assert cells["Seed"] == str(m["seed"]) and cells["Matched poses"] == str(m["matched_poses"])
    total = m["io_ms"] + m["feature_ms"] + m["tracking_ms"] + m["mapping_ms"]
    assert cells["Total time per frame (ms)"] == fmt_value(total, 1)
    assert m["cpu"] in cells["Machine"]
    # time per frame, top view, position error over the path, RPE per length
    assert figure_count(text) == 4
    assert "Sim(3)-aligned to the ground truth" in text and "no ground truth" not in text
    # the keyframe depth pictures: embedded, scaled down to 320 pixels wide, one per keyframe up to 12
    n_kf = len(list((run_dir / "depth").glob("kf_*.png")))
    uris = [a["src"] for t, a in doc.tags if t == "img"]
    assert (run_dir / "depth" / "initial_map.png").is_file()  # the first map as the start made it, shown first
    assert len(uris) == 1 + min(n_kf, MAX_DEPTH_PICTURES) >= 2
    assert f"initial map ({m['init']}" in text
    for uri in uris:
        assert uri.startswith("data:image/png;base64,")
        img = cv2.imdecode(np.frombuffer(base64.b64decode(uri.split(",", 1)[1]), np.uint8), cv2.IMREAD_COLOR)
        assert img is not None and img.shape[1] == 320 and img.shape[0] == 240


def test_a_run_that_was_lost_and_found_again_shows_where(tmp_path: Path):
    """A kidnapped synthetic camera (frames 0–59, then 270–299 of seed 4's path, which revisits its start) with
    --continue-after-loss: the losses section lists each span without a pose and the keyframe it ended on, as
    metrics.json has them, draws their time line, and marks the relocalisations on the top view."""
    out = tmp_path / "kidnapped"
    assert main(["run", "synthetic:n_frames=330,width=320,height=240,seed=4", "--frames", "0-59,270-299",
                 "--continue-after-loss", "--no-depth-images", "--out", str(out)]) == 0  # fmt: skip
    m = json.loads((out / "metrics.json").read_text())
    assert m["relocalisations"] >= 1 and m["lost_spans"], m
    text, doc = parse(write_html_report(out))
    assert_self_contained(text, doc)
    assert "Losses and relocalisation" in text
    rows = next(t for t in doc.tables if t and t[0] == ["frames without a pose", "frames", "how it ended"])[1:]
    assert len(rows) == len(m["lost_spans"])
    first, last = m["lost_spans"][0]
    found = m["relocalised"][0]
    assert rows[0] == [f"{first}–{last}", str(last - first + 1),
                       f"relocalised at frame {found['frame']} on keyframe {found['keyframe']}"]  # fmt: skip
    assert figure_count(text) == 5  # the time line besides the four figures of a run
    assert f"relocalised ({m['relocalisations']})" in text  # the markers on the top view


def test_run_report_aligns_the_trajectory_with_the_evaluation_of_the_run(run_dir: Path):
    """The position errors drawn are those of the Sim(3) alignment behind metrics.json's ATE."""
    text, _ = parse(run_dir / REPORT_HTML)
    m = json.loads((run_dir / "metrics.json").read_text())
    caption = re.search(r"each of the (\d+) matched poses .*?\(RMSE ([0-9.]+) m, max ([0-9.]+) m\)", text)
    assert caption is not None
    assert int(caption.group(1)) == m["matched_poses"]
    assert caption.group(2) == fmt_value(m["ate_rmse"], 4)


def test_run_without_ground_truth_shows_the_trajectory_alone(run_dir: Path, tmp_path: Path):
    d = tmp_path / "nogt"
    shutil.copytree(run_dir, d)
    (d / "groundtruth.txt").unlink()
    (d / REPORT_HTML).unlink()
    out = write_html_report(d)
    text, doc = parse(out)
    assert_self_contained(text, doc)
    assert "no ground truth" in text and "Top view (no ground truth)" in text
    assert figure_count(text) == 2  # time per frame and the top view; no error plots
    assert "Error over the path" not in text


def test_run_text_is_escaped(run_dir: Path, tmp_path: Path):
    d = tmp_path / "odd"
    shutil.copytree(run_dir, d)
    m = json.loads((d / "metrics.json").read_text())
    m["sequence"] = 'kitchen <script>alert("x")</script> & co'
    m["feature"] = "gray<b>"
    (d / "metrics.json").write_text(json.dumps(m))
    text, doc = parse(write_html_report(d))
    assert "<script>alert" not in text and "gray<b>" not in text
    assert "kitchen &lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt; &amp; co" in text
    assert doc.title == 'dmtrack run: kitchen <script>alert("x")</script> & co · gray<b>'


def test_what_is_not_a_run_or_a_bench_is_one_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    with pytest.raises(InputError, match=r"neither a run folder \(no metrics.json\) nor a bench folder"):
        write_html_report(tmp_path)
    with pytest.raises(InputError, match="no such folder"):
        write_html_report(tmp_path / "missing")
    (tmp_path / "metrics.json").write_text("{not json")
    with pytest.raises(InputError, match=r"metrics\.json: cannot read the run's metrics"):
        write_html_report(tmp_path)
    assert not (tmp_path / REPORT_HTML).exists()
    assert main(["report", str(tmp_path / "missing")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "missing: not a bench folder or a run folder" in err


def test_without_plotly_the_error_says_what_to_install(run_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    d = tmp_path / "run"
    shutil.copytree(run_dir, d)
    (d / REPORT_HTML).unlink()
    for name in [n for n in sys.modules if n == "plotly" or n.startswith("plotly.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "plotly", None)  # what `import plotly` meets when it is not installed
    with pytest.raises(InputError, match="report.html needs plotly, which is not installed: pip install plotly"):
        write_html_report(d)
    assert not (d / REPORT_HTML).exists()


# ========================================================================================== bench folder
def test_bench_report_has_the_tables_of_report_md(bench_dir: Path):
    text, doc = parse(bench_dir / REPORT_HTML)
    assert_self_contained(text, doc)
    html_rows = {tuple(r) for t in doc.tables for r in t}
    html_headers = {tuple(t[0]) for t in doc.tables if t}
    md = (bench_dir / "report.md").read_text()
    compared = 0
    for t in md_tables(md):
        if tuple(t[0]) not in html_headers:
            continue  # report.md's table of the sequences is not in report.html
        for row in t[1:]:
            assert tuple(row) in html_rows, row
            compared += 1
    # Table 1 (rankings), 2 (averages, 7 rows), 3 (timings) per feature and the 4 per-sequence cells
    assert compared == 2 + 7 + 2 + 4
    assert re.search(r"\d+\.\d+ \(\d+\.\d+–\d+\.\d+\)", text)  # medians with their min–max over the seeds
    # per dataset: grouped bars and accuracy vs time; per sequence: RPE per length and the top view
    assert figure_count(text) == 2 + 2 * len(SYN)
    assert "seeds 0,1" in text or "seeds 0-1" in text


def test_bench_report_switches(bench_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    d = tmp_path / "b"
    shutil.copytree(bench_dir, d)
    (d / "report.md").unlink()
    (d / REPORT_HTML).unlink()
    assert main(["report", str(d), "--html-only"]) == 0
    assert (d / REPORT_HTML).is_file() and not (d / "report.md").exists()
    (d / REPORT_HTML).unlink()
    assert main(["report", str(d), "--no-html", "--no-figures"]) == 0
    assert (d / "report.md").is_file() and not (d / REPORT_HTML).exists()
    out = capsys.readouterr().out
    assert f"report: {d / REPORT_HTML} (8 runs, " in out and f"report: {d / 'report.md'} (8 runs)" in out
    with pytest.raises(SystemExit):
        main(["report", str(d), "--no-html", "--html-only"])


# ================================================================================= in a headless browser
@pytest.fixture(scope="module")
def browser() -> Any:
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed: pip install playwright")
    if CHROMIUM is None:
        pytest.skip("no Chromium binary on PATH (chromium or chromium-browser): apt-get install chromium")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS)
        yield b
        b.close()


def open_report(browser: Any, path: Path) -> tuple[Any, dict[str, Any]]:
    """Open ``path`` in a new page, wait until every plotly figure is drawn; returns the page and what it logged
    and fetched."""
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    seen: dict[str, Any] = {"errors": [], "requests": []}
    page.on("console", lambda msg: seen["errors"].append(f"console: {msg.text}") if msg.type == "error" else None)
    page.on("pageerror", lambda exc: seen["errors"].append(f"page error: {exc}"))
    page.on("request", lambda req: seen["requests"].append(req.url))
    t = time.perf_counter()
    page.goto(path.resolve().as_uri(), wait_until="load")
    n = figure_count(path.read_text(encoding="utf-8"))
    page.wait_for_function(
        f"[...document.querySelectorAll('.js-plotly-plot')].filter(d => d.querySelector('.main-svg')).length == {n}",
        timeout=20000,
    )
    seen["seconds"] = time.perf_counter() - t
    seen["figures"] = n
    return page, seen


def assert_drawn(page: Any, seen: dict[str, Any], path: Path) -> None:
    assert seen["errors"] == []
    assert [u for u in seen["requests"] if not u.startswith("data:")] == [path.resolve().as_uri()]
    # every figure drawn, each with its lines or bars
    plots = page.evaluate("[...document.querySelectorAll('.js-plotly-plot')].map(d => [d.id, "
                          "d.querySelectorAll('.main-svg').length, d.querySelectorAll('g.trace').length])")  # fmt: skip
    assert len(plots) == seen["figures"] >= 2
    assert all(svgs >= 1 and traces >= 1 for _, svgs, traces in plots), plots


def test_run_report_in_chromium(browser: Any, run_dir: Path):
    path = run_dir / REPORT_HTML
    page, seen = open_report(browser, path)
    try:
        assert_drawn(page, seen, path)
        m = json.loads((run_dir / "metrics.json").read_text())
        body = page.inner_text("body")
        for value in (fmt_value(m["ate_rmse"], 4), fmt_value(m["fps"], 1), fmt_value(m["rpe_rot_deg_per_m"], 3)):
            assert value in body
            assert page.get_by_text(value, exact=True).first.is_visible()
        images = page.evaluate("[...document.images].map(i => [i.complete, i.naturalWidth])")
        assert images and all(ok and w == 320 for ok, w in images)
        # the legend of the top view names the ground truth, the estimate and the keyframes
        legend = page.locator("#figure-2 .legendtext").all_text_contents()
        assert legend[0] == "ground truth" and legend[1].startswith("gray [") and legend[2].startswith("keyframes")
    finally:
        page.close()


def test_bench_report_in_chromium(browser: Any, bench_dir: Path):
    path = bench_dir / REPORT_HTML
    page, seen = open_report(browser, path)
    try:
        assert_drawn(page, seen, path)
        body = page.inner_text("body")
        cells = list(csv_rows(bench_dir / "tables" / "cells.csv"))
        assert len(cells) == len(SYN) * len(FEATURES)
        for c in cells:  # each cell's median ATE with its min–max over the seeds, as in report.md
            med, lo, hi = (fmt_value(float(c[f"ate_rmse_{k}"]), 4) for k in ("median", "min", "max"))
            assert f"{med} ({lo}–{hi})" in body
        bars = page.locator("#figure-1 .legendtext").all_text_contents()
        assert bars == FEATURES
    finally:
        page.close()


def csv_rows(path: Path) -> list[dict[str, str]]:
    import csv

    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))
