"""Where runs execute: a worker process that dies, a bench killed while its workers run."""

from __future__ import annotations

import json
import os
import sys
import textwrap
from pathlib import Path

import pytest

from dmtrack.experiments.backends import run_tasks_processes
from dmtrack.experiments.grid import plan_grid

MISSING = "/nonexistent/dmtrack-test-sequence"


def test_a_dying_worker_is_retried_alone_then_recorded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    helper = tmp_path / "helpers"
    helper.mkdir()
    (helper / "dmtrack_test_crash_helper.py").write_text(
        textwrap.dedent("""
        import os

        def run(task):
            if task.feature == "boom":
                os._exit(3)  # the worker process dies
            return {"key": task.key, "status": "ok", "tracked_frames": 1, "total_frames": 1, "lost_at": None,
                    "message": None, "elapsed_s": 0.0, "run_dir": str(task.run_dir)}
    """)
    )
    monkeypatch.syspath_prepend(str(helper))  # spawned workers get the parent's sys.path
    import dmtrack_test_crash_helper as h

    tasks, _ = plan_grid([MISSING], ["gray", "boom", "gray-affine", "rgb"], tmp_path / "b")
    done: dict[str, str] = {}
    run_tasks_processes(tasks, 2, lambda t, o: done.__setitem__(t.key, o["status"]), fn=h.run)
    assert done == {"dmtrack-test-sequence/gray": "ok", "dmtrack-test-sequence/boom": "failed",
                    "dmtrack-test-sequence/gray-affine": "ok", "dmtrack-test-sequence/rgb": "ok"}  # fmt: skip
    err = json.loads((tmp_path / "b" / "runs" / "dmtrack-test-sequence" / "boom" / "error.json").read_text())
    assert err["type"] == "WorkerError" and "died twice" in err["message"]


def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (from /proc; Linux)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _alive(pid: int) -> bool:
    stat = Path(f"/proc/{pid}/stat")
    try:
        return stat.read_text().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc to find the worker processes")
@pytest.mark.parametrize("signame", ["SIGTERM", "SIGKILL"])
def test_killing_a_bench_stops_its_workers(tmp_path: Path, signame: str) -> None:
    """`kill` (SIGTERM) or `kill -9` of a running bench: no worker goes on computing into DIR; resuming works."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "dmtrack.cli", "bench", "--sequences", "synthetic:n_frames=400,width=320,height=240",
           "--features", "gray", "--out", str(out), "--jobs", "2", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not list((out / "runs").glob("*/.*tmp-*")):  # a worker has started its run
            assert proc.poll() is None and time.monotonic() < deadline, "the bench did not start a run"
            time.sleep(0.2)
        workers = [p for p in _children(proc.pid) if p != proc.pid]
        assert workers, "no worker process found"
        proc.send_signal(getattr(signal, signame))
        proc.wait(timeout=30)
        deadline = time.monotonic() + 15
        while any(_alive(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not any(_alive(w) for w in workers), "a worker outlived the bench"
    finally:
        if proc.poll() is None:
            proc.kill()
    assert not list((out / "runs").glob("*/*/metrics.json"))  # nothing finished, nothing half-written


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_an_orphaned_worker_dies_at_once_even_while_holding_the_gil(tmp_path: Path) -> None:
    """kill -9 of the bench while its worker is inside a long call that holds the GIL (numba code without
    ``nogil``, a C loop): the worker must die at once, not when its polling thread next gets the GIL — else it
    can recreate a temporary folder after the resuming bench cleaned the stale ones (a CI failure of
    tests/faults/test_bench_resume.py)."""
    import signal
    import subprocess
    import time

    script = tmp_path / "parent.py"
    pid_file = tmp_path / "worker.pid"
    script.write_text(textwrap.dedent(f"""
        import ctypes, os, time
        from concurrent.futures import ProcessPoolExecutor
        import multiprocessing
        from dmtrack.experiments.backends import _init_worker

        def hold_the_gil():
            open({str(pid_file)!r}, "w").write(str(os.getpid()))
            ctypes.PyDLL(None).sleep(60)  # PyDLL: the call keeps the GIL, so no Python thread runs meanwhile

        if __name__ == "__main__":
            ctx = multiprocessing.get_context("spawn")
            with ProcessPoolExecutor(1, mp_context=ctx, initializer=_init_worker, initargs=(1, os.getpid())) as p:
                p.submit(hold_the_gil).result()
    """))
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while not (pid_file.exists() and pid_file.read_text()):
            assert proc.poll() is None and time.monotonic() < deadline, "the worker did not start"
            time.sleep(0.05)
        worker = int(pid_file.read_text())
        time.sleep(0.3)  # the worker is now inside the GIL-holding call
        assert _alive(worker)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
        t0 = time.monotonic()
        while _alive(worker) and time.monotonic() - t0 < 10:
            time.sleep(0.02)
        assert not _alive(worker), "the orphaned worker outlived its bench by 10 s"
        assert time.monotonic() - t0 < 2.0, f"the orphaned worker lived {time.monotonic() - t0:.1f} s on"
    finally:
        if proc.poll() is None:
            proc.kill()
        if pid_file.exists() and pid_file.read_text() and _alive(int(pid_file.read_text())):
            os.kill(int(pid_file.read_text()), signal.SIGKILL)
