"""A broken environment around a run: --out is a file, the disk fills up, the output folder is read-only.

The promise (docs/reliability.md): one line naming the file; the trajectory and the metrics of every finished
frame stay on disk; no temporary file is left behind.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dmtrack.cli import main
from dmtrack.errors import OutputError
from dmtrack.pipeline import run_to_directory

SYNTH = "synthetic:n_frames=20,width=320,height=240,seed=3"
N = 20


def _trajectory_lines(out: Path) -> int:
    p = out / "trajectory.txt"
    if not p.exists():
        return 0
    return sum(1 for line in p.read_text().splitlines() if line and not line.startswith("#"))


def _one_error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def test_out_that_is_a_file_is_refused_before_any_frame(tmp_path: Path, capsys, fault_log) -> None:
    target = tmp_path / "results.txt"
    target.write_text("not a folder\n")
    # the sequence does not exist either: the --out check comes first, so nothing was read or tracked
    code = main(["run", str(tmp_path / "no-such-sequence"), "--out", str(target), "--no-progress"])
    line = _one_error_line(capsys.readouterr().err)
    assert code == 1
    assert str(target) in line and "is a file, not a folder" in line
    assert target.read_text() == "not a folder\n"
    fault_log.tried("dmtrack run --out", "names an existing file")


def test_out_below_a_file_is_refused(tmp_path: Path, capsys, fault_log) -> None:
    (tmp_path / "f").write_text("x")
    code = main(["run", SYNTH, "--out", str(tmp_path / "f" / "run"), "--no-progress"])
    line = _one_error_line(capsys.readouterr().err)
    assert code == 1 and "a parent of this folder is a file" in line
    fault_log.tried("dmtrack run --out", "a parent is a file")


def test_disk_full_while_writing_the_point_cloud(tmp_path: Path, capsys, full_disk, leftover_temporaries,
                                                 fault_log) -> None:
    out = tmp_path / "run"
    disk = full_disk(out, budget=0, match="pointcloud.ply")  # every other file still fits
    code = main(["run", SYNTH, "--out", str(out), "--no-progress", "--no-depth-images"])
    line = _one_error_line(capsys.readouterr().err)
    assert code == 1 and disk.failures >= 1
    assert "pointcloud.ply" in line and "No space left on device" in line
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["tracked_frames"] == _trajectory_lines(out) == N
    assert "pointcloud.ply" in metrics["output_error"]
    assert not (out / "pointcloud.ply").exists()
    assert leftover_temporaries(out) == []
    fault_log.tried("run outputs", "ENOSPC writing pointcloud.ply")
    fault_log.kept("run outputs", "ENOSPC writing pointcloud.ply", finished=N, kept=_trajectory_lines(out))


@pytest.mark.parametrize("lines", [3, 11])
@pytest.mark.parametrize("shared", [False, True], ids=["trajectory-only", "whole-disk"])
def test_disk_full_in_the_middle_of_the_trajectory(tmp_path: Path, full_disk, leftover_temporaries, fault_log,
                                                   lines: int, shared: bool) -> None:
    """The disk fills up after a few trajectory lines: those lines stay; the run stops with the file named.

    ``shared``: every file of the run draws on the same budget, so metrics.json cannot be written either; the error
    reported is still the first one (the trajectory).
    """
    out = tmp_path / "run"
    header, line = 62, 90  # bytes of the TUM header, and at least those of one pose line
    budget = header + lines * line
    if shared:  # config.yaml and the keyframes' header are written first
        run_to_directory(SYNTH, tmp_path / "dry", depth_images=False, pointcloud=False, max_frames=1)
        budget += (tmp_path / "dry" / "config.yaml").stat().st_size + header
    full_disk(out, budget=budget, match="" if shared else "trajectory.txt")
    with pytest.raises(OutputError) as info:
        run_to_directory(SYNTH, out, depth_images=False, pointcloud=False)
    assert info.value.path.name in ("trajectory.txt", "keyframes.txt")
    assert "No space left on device" in str(info.value)
    kept = _trajectory_lines(out)
    assert 0 < kept < N
    # each kept line is a complete pose (7 numbers after the timestamp): nothing half-written counts as kept
    for text in (out / "trajectory.txt").read_text().splitlines()[1:]:
        assert len(text.split()) == 8
    if not shared:  # the metrics describe exactly the frames on disk
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["output_error"] and "trajectory.txt" in metrics["output_error"]
        assert metrics["tracked_frames"] >= kept
    assert leftover_temporaries(out) == []
    fault = f"ENOSPC after {lines} trajectory lines" + (", whole disk" if shared else "")
    fault_log.tried("run outputs", fault)
    fault_log.kept("run outputs", fault, finished=kept, kept=kept)


def test_disk_full_keeps_the_earlier_point_cloud_intact(tmp_path: Path, full_disk, leftover_temporaries,
                                                        fault_log) -> None:
    """Atomic replacement: a failed rewrite leaves the previous complete file, never half of the new one."""
    out = tmp_path / "run"
    run_to_directory(SYNTH, out, depth_images=False, max_frames=8)
    before = (out / "pointcloud.ply").read_bytes()
    full_disk(out, budget=64, match="pointcloud.ply")
    with pytest.raises(OutputError, match="pointcloud.ply"):
        run_to_directory(SYNTH, out, depth_images=False)
    assert (out / "pointcloud.ply").read_bytes() == before
    assert json.loads((out / "metrics.json").read_text())["tracked_frames"] == N
    assert leftover_temporaries(out) == []
    fault_log.tried("io.atomic", "ENOSPC while replacing a file")


def test_disk_full_for_depth_images(tmp_path: Path, capsys, full_disk, leftover_temporaries, fault_log) -> None:
    out = tmp_path / "run"
    full_disk(out / "depth", budget=0)
    code = main(["run", SYNTH, "--out", str(out), "--no-progress"])
    line = _one_error_line(capsys.readouterr().err)
    assert code == 1 and "depth" in line and ".png" in line
    assert json.loads((out / "metrics.json").read_text())["tracked_frames"] == _trajectory_lines(out)
    assert leftover_temporaries(out) == []
    fault_log.tried("run outputs", "ENOSPC writing depth/*.png")


def test_read_only_output_folder(tmp_path: Path, capsys, read_only, leftover_temporaries, fault_log) -> None:
    out = tmp_path / "run"
    out.mkdir()
    read_only(out)
    code = main(["run", SYNTH, "--out", str(out), "--no-progress"])
    line = _one_error_line(capsys.readouterr().err)
    assert code == 1 and str(out) in line and "Read-only file system" in line
    assert leftover_temporaries(out) == []
    fault_log.tried("dmtrack run --out", "read-only folder")


_CACHE_SCRIPT = """
import os, sys
from pathlib import Path
import dmtrack  # its own call found a writable folder (or NUMBA_CACHE_DIR was cleared): nothing set yet
assert "NUMBA_CACHE_DIR" not in os.environ and "numba" not in sys.modules
dmtrack._numba_cache_fallback([Path(p) for p in sys.argv[1:]])
import numba
assert os.path.realpath(numba.config.CACHE_DIR) == os.path.realpath(os.environ["NUMBA_CACHE_DIR"])
@numba.njit(cache=True)
def f(x):
    return x + 1
assert f(1) == 2
print(os.environ["NUMBA_CACHE_DIR"])
"""


def test_numba_cache_falls_back_to_a_private_temporary_folder(tmp_path: Path, fault_log) -> None:
    """A read-only installation with a read-only home (no folder numba can cache in): importing dmtrack points
    numba at a private folder of the temporary directory, for the API as for the command line."""
    import os
    import stat
    import subprocess
    import sys
    import tempfile

    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder\n")
    unwritable = [blocker / "odometry" / "__pycache__", blocker / "home-cache" / "numba"]  # mkdir fails under a file
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env["TMPDIR"] = str(tmp_path / "tmp")
    (tmp_path / "tmp").mkdir()
    script = tmp_path / "script.py"  # a file: numba caches only functions whose source file it can locate
    script.write_text(_CACHE_SCRIPT)
    proc = subprocess.run([sys.executable, str(script), *map(str, unwritable)], capture_output=True, text=True,
                          env=env, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    folder = Path(proc.stdout.strip().splitlines()[-1])
    assert folder.parent == tmp_path / "tmp" and folder.name.startswith("dmtrack-numba-cache-")
    if hasattr(os, "getuid"):
        assert stat.S_IMODE(folder.stat().st_mode) == 0o700  # machine code: nobody else may write there
    assert any(folder.rglob("*.nbi")), "numba did not cache in the fallback folder"
    assert tempfile.gettempdir() != str(tmp_path / "tmp")  # the test's TMPDIR stayed in the subprocess
    fault_log.tried("environment", "no writable numba cache folder (read-only installation and home)")
