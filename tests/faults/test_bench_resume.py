"""A bench killed (``kill -9``) at seeded random moments, then resumed: no finished cell lost or recomputed.

The grid is 2 features × 3 seeds of a short synthetic sequence, run with ``--jobs 1``. The bench is killed at
several moments drawn from a seeded generator (some before any cell finished, some between cells, some in the
middle of one), then resumed, until it finishes. After each kill, every cell that was complete (its
``metrics.json`` exists) must still be there, byte-identical and not rewritten (same mtime) after the next resume;
at the end every cell is complete, the tables count all of them, and no temporary folder is left.
"""

from __future__ import annotations

import hashlib
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")

SEQ = "synthetic:n_frames=30,width=320,height=240,seed=4"
FEATURES = "gray,rgb"
SEEDS = "0,1,2"
CELLS = 6


def _bench(out: Path) -> list[str]:
    return [sys.executable, "-m", "dmtrack.cli", "bench", "--sequences", SEQ, "--features", FEATURES,
            "--seeds", SEEDS, "--out", str(out), "--jobs", "1", "--no-progress"]


def _finished(out: Path) -> dict[str, tuple[str, int]]:
    """Complete cells: path → (sha256 of metrics.json, its mtime in ns). A cell is written in a temporary folder
    (``.NAME.tmp-…``) and renamed when complete: a metrics.json inside one belongs to a cell that was killed before
    its rename, which the resume throws away and computes again — not a finished cell."""
    return {
        str(p.parent.relative_to(out)): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
        for p in sorted((out / "runs").rglob("metrics.json"))
        if not any(".tmp-" in part or ".trash-" in part for part in p.relative_to(out).parts)
    } if (out / "runs").exists() else {}


def test_bench_killed_at_random_moments_loses_and_recomputes_nothing(tmp_path: Path, fault_log) -> None:
    out = tmp_path / "bench"
    # a first complete run tells how long one cell takes here, so the kill moments spread over the work
    rng = random.Random(17)
    subprocess.run(_bench(tmp_path / "warm-up"), check=True, capture_output=True, timeout=900)  # compiles kernels
    t0 = time.monotonic()
    subprocess.run(_bench(tmp_path / "timing"), check=True, capture_output=True, timeout=900)
    total = time.monotonic() - t0
    kills = 0
    before: dict[str, tuple[str, int]] = {}
    for attempt in range(7):  # killed attempts, then one left to finish
        proc = subprocess.Popen(_bench(out), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            proc.wait(timeout=None if attempt == 6 else rng.uniform(0.2, 0.6) * total)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=60)
            kills += 1
        now = _finished(out)
        lost = [cell for cell in before if cell not in now]
        rewritten = [cell for cell in before if cell in now and now[cell] != before[cell]]
        assert lost == [] and rewritten == [], (attempt, lost, rewritten)
        fault_log.kept("dmtrack bench", "kill -9 then resume", finished=len(before), kept=len(before) - len(lost))
        before = now
        if proc.returncode == 0:
            break
    assert proc.returncode == 0, proc.stderr.read() if proc.stderr else ""
    assert kills >= 2, f"only {kills} kill(s) landed before the bench finished"
    assert len(before) == CELLS
    assert [p for p in out.rglob("*") if ".tmp-" in p.name or ".trash-" in p.name] == []
    rows = (out / "results.csv").read_text().splitlines()
    assert len(rows) == 1 + CELLS
    fault_log.tried("dmtrack bench", "kill -9 at a random moment", n=kills)
