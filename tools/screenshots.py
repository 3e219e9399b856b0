"""Screenshots for the README: a run's report.html and its Rerun recording, rendered in headless Chromium.

Usage::

    python tools/screenshots.py RUN_DIR RECORDING.rrd [--out docs/img]

RUN_DIR is a folder of ``dmtrack run`` (``dmtrack report RUN_DIR`` is run first if it has no report.html);
RECORDING.rrd is what ``dmtrack run … --rrd`` wrote. The report is opened as a file; the recording is served by
``rerun RECORDING --web-viewer`` (the web viewer, WebGL on Chromium's software renderer) and photographed once it
has loaded. Needs playwright (dmtrack[dev]), Debian's chromium and rerun-sdk (dmtrack[viewer]).
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

ARGS = ["--headless=new", "--no-sandbox", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", "--no-first-run", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
        "--ignore-gpu-blocklist"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("rrd", type=Path)
    ap.add_argument("--out", type=Path, default=Path("docs/img"))
    ap.add_argument("--wait", type=float, default=25.0, help="seconds to let the web viewer load and draw")
    a = ap.parse_args(argv)
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        raise SystemExit("no chromium on PATH (Debian: apt-get install chromium)")
    from playwright.sync_api import sync_playwright

    a.out.mkdir(parents=True, exist_ok=True)
    report = a.run_dir / "report.html"
    if not report.exists():
        subprocess.run([sys.executable, "-m", "dmtrack.cli", "report", str(a.run_dir)], check=True)
    rerun = Path(sys.executable).with_name("rerun")
    viewer = subprocess.Popen([str(rerun), str(a.rrd), "--web-viewer", "--web-viewer-port", "9877", "--port", "9878",
                               "--renderer", "webgl"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, args=ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(report.resolve().as_uri() + "#s6-trajectory")  # the top view and the error along the path
            page.wait_for_timeout(3000)
            page.screenshot(path=str(a.out / "report.png"))
            time.sleep(3)
            page.goto("http://localhost:9877/?url=rerun%2Bhttp://localhost:9878/proxy")
            page.wait_for_timeout(int(a.wait * 1000))
            page.screenshot(path=str(a.out / "viewer.png"))
            browser.close()
    finally:  # the whole process group: rerun keeps serving (a core busy) if only its launcher is stopped
        os.killpg(viewer.pid, signal.SIGTERM)
        viewer.wait(timeout=10)
    print(f"written {a.out / 'report.png'} and {a.out / 'viewer.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
