"""``dmtrack calibrate-from-video``: the window's focal length repeated to a fixed point, written as the intrinsics file
``run`` reads."""

from __future__ import annotations

import json

import pytest

from dmtrack.cli import main
from dmtrack.datasets.intrinsics import read_intrinsics_file

SYN = "synthetic:n_frames=45,width=320,height=240,seed=1"


def test_calibrate_from_video_writes_the_file_run_reads(tmp_path, capsys) -> None:
    out = tmp_path / "cam.txt"
    rc = main(["calibrate-from-video", SYN, "--method", "window", "--intrinsics", "262.5,262.5,159.5,119.5",
               "--iterations", "2", "--out", str(out), "--json", "--quiet"])  # fmt: skip
    result = json.loads(capsys.readouterr().out)
    assert rc in (0, 3) and (rc == 0) == result["converged"]
    assert 1 <= len(result["history"]) <= 2 and result["history"][0]["start"][0] == 262.5
    cam = read_intrinsics_file(out, 320, 240)
    assert cam.fx == pytest.approx(result["fx"], abs=1e-3) and cam.cx == pytest.approx(159.5)
    assert abs(cam.fx / 262.5 - 1) < 0.05  # started at the truth: it stays near it
    assert main(["run", SYN, "--intrinsics", str(out), "--out", str(tmp_path / "run"), "--no-progress",
                 "--no-pointcloud", "--no-depth-images"]) == 0  # fmt: skip


def test_calibrate_from_video_says_when_nothing_can_be_estimated(tmp_path, capsys) -> None:
    rc = main(["calibrate-from-video", "synthetic:n_frames=8,width=320,height=240,seed=1", "--method", "window",
               "--out", str(tmp_path / "cam.txt")])  # fmt: skip
    assert rc != 0
    err = capsys.readouterr().err
    assert "no keyframe change to estimate the intrinsics from" in err
    assert not (tmp_path / "cam.txt").exists()
