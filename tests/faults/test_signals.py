"""Ctrl-C (SIGINT), ``kill`` (SIGTERM) and ``kill -9`` in the middle of ``dmtrack run``.

SIGINT / SIGTERM: one line on stderr, exit status 130 / 143, and on disk every finished frame's pose, the
metrics of those frames (``interrupted`` names the signal), the point cloud of the finished keyframes, and no
temporary file. ``kill -9`` gives the process no chance to do anything: the trajectory still holds every frame
whose line was written (one flush per frame) and nothing is half-written.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "data" / "7scenes-redkitchen-0000-0299"
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


def _lines(out: Path) -> list[str]:
    p = out / "trajectory.txt"
    if not p.exists():
        return []
    return [line for line in p.read_text().splitlines() if line and not line.startswith("#")]


def _start_and_signal(out: Path, sig: int, after_frames: int = 25) -> tuple[subprocess.CompletedProcess, int]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "dmtrack.cli", "run", str(SAMPLE), "--out", str(out), "--no-progress",
         "--threads", "1"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )
    deadline = time.monotonic() + 600  # the first run of a fresh checkout compiles the kernels
    try:
        while len(_lines(out)) < after_frames:
            if proc.poll() is not None:
                pytest.fail(f"the run ended before it was signalled: {proc.stderr.read()}")
            if time.monotonic() > deadline:
                pytest.fail("the run did not reach the frame to signal it at")
            time.sleep(0.05)
        seen = len(_lines(out))
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr), seen


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["SIGINT", "SIGTERM"])
def test_interrupt_keeps_every_finished_frame(tmp_path: Path, leftover_temporaries, fault_log, sig: int,
                                              code: int) -> None:
    out = tmp_path / "run"
    done, seen = _start_and_signal(out, sig)
    name = signal.Signals(sig).name
    assert done.returncode == code, done.stderr
    err = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(err) == 1 and "Traceback" not in done.stderr, done.stderr
    assert f"interrupted by {name}" in err[0] and str(out) in err[0]
    metrics = json.loads((out / "metrics.json").read_text())
    lines = _lines(out)
    assert metrics["interrupted"] == name
    assert metrics["tracked_frames"] == len(lines) >= seen  # no finished frame lost
    assert metrics["processed_frames"] < metrics["total_frames"] == 300
    assert all(len(line.split()) == 8 for line in lines)
    assert (out / "pointcloud.ply").stat().st_size > 0
    assert leftover_temporaries(out) == []
    fault_log.tried("dmtrack run", name)
    fault_log.kept("dmtrack run", name, finished=metrics["tracked_frames"], kept=len(lines))


def test_kill_9_keeps_every_written_frame(tmp_path: Path, fault_log) -> None:
    out = tmp_path / "run"
    done, seen = _start_and_signal(out, signal.SIGKILL)
    assert done.returncode == -signal.SIGKILL
    lines = _lines(out)
    assert len(lines) >= seen and all(len(line.split()) == 8 for line in lines)
    assert not (out / "metrics.json").exists()  # nothing ran after the kill: no metrics claim a finished run
    # the next run into the same folder cleans up and starts afresh
    from dmtrack.pipeline import run_to_directory

    run_to_directory(SAMPLE, out, max_frames=3, depth_images=False)
    assert len(_lines(out)) == 3
    assert [p for p in out.rglob("*") if p.name.endswith(".tmp")] == []
    fault_log.tried("dmtrack run", "SIGKILL")
    fault_log.kept("dmtrack run", "SIGKILL", finished=seen, kept=min(len(lines), seen))


def test_signal_handlers_are_restored_after_a_run(tmp_path: Path) -> None:
    """The between-frames stop wraps SIGINT only while tracking; the caller's handler is back afterwards."""
    from dmtrack.outputs import MemorySink
    from dmtrack.pipeline import track

    class Failing(MemorySink):
        def on_frame(self, frame_index, timestamp, T_wc):  # noqa: ANN001, ANN202
            if frame_index == 2:
                raise RuntimeError("a sink that breaks at frame 2")
            super().on_frame(frame_index, timestamp, T_wc)

        def close(self) -> None:  # and again while the odometry finishes
            raise RuntimeError("a sink that breaks at frame 2 and on close")

    before = signal.getsignal(signal.SIGINT)
    track("synthetic:n_frames=4,width=160,height=128", max_frames=4)
    assert signal.getsignal(signal.SIGINT) is before
    with pytest.raises(RuntimeError, match="breaks at frame 2"):  # an error in the middle of the loop
        track("synthetic:n_frames=4,width=160,height=128", sink=Failing())
    assert signal.getsignal(signal.SIGINT) is before
