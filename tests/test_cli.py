"""The command line: `dmtrack info` output contract and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dmtrack.cli import main

CONTRACT_KEYS = {"format", "frames", "width", "height", "fx", "fy", "cx", "cy", "has_groundtruth"}


def info_json(capsys: pytest.CaptureFixture[str], *args: str) -> dict:
    assert main(["info", *args, "--json"]) == 0
    out = capsys.readouterr().out
    return json.loads(out)


def test_info_sample(capsys: pytest.CaptureFixture[str], sample_dir: Path) -> None:
    info = info_json(capsys, str(sample_dir))
    assert CONTRACT_KEYS <= info.keys()
    assert info["format"] == "7scenes" and info["frames"] == 300
    assert (info["width"], info["height"]) == (640, 480)
    assert (info["fx"], info["fy"], info["cx"], info["cy"]) == (585.0, 585.0, 320.0, 240.0)
    assert info["has_groundtruth"] is True


def test_info_shared(capsys: pytest.CaptureFixture[str], shared_dir: Path) -> None:
    data = shared_dir / "data"
    info = info_json(capsys, str(data / "7scenes-0000-0699"))
    assert (info["frames"], info["width"], info["height"], info["has_groundtruth"]) == (700, 640, 480, True)
    info = info_json(capsys, str(data / "kitti-odometry" / "sequences" / "06"))
    assert (info["format"], info["frames"], info["width"], info["height"]) == ("kitti", 51, 1226, 370)
    assert (info["crop16"]["width"], info["crop16"]["height"]) == (1216, 368)
    assert info["has_groundtruth"] is True
    info = info_json(capsys, str(data / "tsukuba-150"))
    assert (info["frames"], info["has_groundtruth"], info["fx"]) == (150, True, None)
    info = info_json(capsys, str(data / "tsukuba-150"), "--intrinsics", "615,615,320,240")
    assert (info["fx"], info["cx"]) == (615.0, 320.0)


def test_info_human_readable(capsys: pytest.CaptureFixture[str], sample_dir: Path) -> None:
    assert main(["info", str(sample_dir)]) == 0
    out = capsys.readouterr().out
    assert "300" in out and "640x480" in out and "fx=585" in out


def test_errors_are_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert main(["info", str(tmp_path / "nope")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope" in err[0] and "no such file or folder" in err[0]
    assert main(["info", str(tmp_path), "--intrinsics", "1,2,3"]) == 1
    assert "cannot recognise" in capsys.readouterr().err


def test_console_script_runs(sample_dir: Path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "dmtrack.cli", "info", str(sample_dir), "--json"],
        capture_output=True, text=True, check=True,
    )
    assert json.loads(out.stdout)["frames"] == 300
    bad = subprocess.run([sys.executable, "-m", "dmtrack.cli", "run"], capture_output=True, text=True)
    assert bad.returncode == 2 and "sequence" in bad.stderr
    # without a sequence, info describes this machine: versions and whether a GPU is usable (and why not)
    env = subprocess.run([sys.executable, "-m", "dmtrack", "info", "--json"], capture_output=True, text=True,
                         check=True)  # fmt: skip
    gpu = json.loads(env.stdout)["gpu"]
    assert isinstance(gpu["usable"], bool) and (gpu["usable"] or gpu["reason"])


def test_eval_matches_evo_reference(capsys: pytest.CaptureFixture[str], shared_dir: Path) -> None:
    tdir = shared_dir / "data" / "trajectories"
    assert main(["eval", str(tdir / "KITTI_00_gt.txt"), str(tdir / "KITTI_00_ORB.txt"), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert {"ate_rmse", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "matched_poses"} <= result.keys()
    assert result["ate_rmse"] == pytest.approx(0.937709074, abs=1e-6)  # evo's figure for these files
    assert result["matched_poses"] == 4541
    gt, est = tdir / "freiburg1_xyz-groundtruth.txt", tdir / "freiburg1_xyz-rgbdslam.txt"
    assert main(["eval", str(gt), str(est), "--format", "tum", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ate_rmse"] == pytest.approx(0.013389385, abs=1e-6)


def test_eval_errors(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    (tmp_path / "gt.txt").write_text("0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n2 2 0 0 0 0 0 1\n3 3 1 0 0 0 0 1\n")
    (tmp_path / "est.txt").write_text("0 0 0 0 0 0 0 1\nbroken line\n")
    assert main(["eval", str(tmp_path / "gt.txt"), str(tmp_path / "est.txt")]) == 1
    assert "est.txt:2" in capsys.readouterr().err


def test_features_listing(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["features", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    by_name = {r["name"]: r for r in rows}
    for name, n in (("gray", 1), ("gray-affine", 1), ("rgb", 3), ("lab", 3), ("bitplanes", 8), ("dsift", 128)):
        assert by_name[name]["channels"] == n
        assert by_name[name]["needs_torch"] is False
    assert main(["features"]) == 0
    assert "bitplanes" in capsys.readouterr().out


def test_calibrate_scale_save_and_fit_pca(capsys: pytest.CaptureFixture[str], sample_dir: Path, tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    from dmtrack.features import get_feature

    monkeypatch.setenv("DMTRACK_HOME", str(tmp_path))  # the saved scale and basis are this test's, not the session's

    assert main(["calibrate-scale", "--feature", "rgb", str(sample_dir), "--frames", "2", "--save", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert 0.5 < result["scale"] < 2.0 and Path(result["saved_to"]).is_file()
    assert get_feature("rgb").scale == pytest.approx(result["scale"])  # used automatically afterwards
    assert main(["fit-pca", "--feature", "rgb", "--k", "2", str(sample_dir), "--frames", "2", "--samples", "5000"]) == 0
    assert "rgb-pca2" in capsys.readouterr().out
    # every selectable name is listed: the fitted variant with its channels, and the BASE-pcaK pattern
    assert main(["features", "--json"]) == 0
    listed = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert listed["rgb-pca2"]["channels"] == 2 and listed["rgb-pca2"]["pca_of"] == "rgb"
    assert main(["features"]) == 0
    table = capsys.readouterr().out
    assert any(line.split()[:2] == ["rgb-pca2", "2"] for line in table.splitlines())
    assert "NAME-pcaK" in table and "dmtrack fit-pca" in table
    reduced = get_feature("rgb-pca2")  # found in the user's PCA folder
    assert reduced.channels == 2


def test_calibrate_scale_with_options_is_kept_for_those_options(
    capsys: pytest.CaptureFixture[str], sample_dir: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A scale calibrated with --feature-opt is stored with its options: it serves that variant, not the defaults,
    and calibrating does not warn that the variant is uncalibrated."""
    import warnings

    from dmtrack.features import get_feature
    from dmtrack.features.base import default_scales_table

    monkeypatch.setenv("DMTRACK_HOME", str(tmp_path))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["calibrate-scale", "--feature", "lab", "--feature-opt", "chroma_sigma=0.5", str(sample_dir),
                     "--frames", "2", "--save", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    saved = json.loads(Path(result["saved_to"]).read_text())["scales"]["lab"]
    assert saved["options"] == {"chroma_sigma": 0.5} and saved["scale"] == result["scale"]
    assert get_feature("lab", chroma_sigma=0.5).scale == pytest.approx(result["scale"])
    assert get_feature("lab").scale == default_scales_table()["scales"]["lab"]["scale"]


def test_eval_kitti_groundtruth_against_tum_estimate(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """KITTI ground truth has no timestamps: --times gives them, so a TUM estimate can be associated."""
    from dmtrack.io.trajectory import Trajectory, write_kitti, write_tum

    n = 10
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 2, 3] = np.arange(n) * 1.2
    poses[:, 0, 3] = 0.1 * np.arange(n) ** 2
    times = np.arange(n) * 0.1
    write_kitti(tmp_path / "gt.txt", Trajectory(np.arange(n), poses))
    np.savetxt(tmp_path / "times.txt", times)
    est = poses.copy()
    est[:, :3, 3] *= 0.5  # monocular: scale is unknown
    write_tum(tmp_path / "est.txt", Trajectory(times, est))
    assert main(["eval", str(tmp_path / "gt.txt"), str(tmp_path / "est.txt"), "--times", str(tmp_path / "times.txt"),
                 "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["matched_poses"] == n
    assert result["ate_rmse"] == pytest.approx(0.0, abs=1e-9)
    assert result["rpe_trans_angle_deg_per_m"] == pytest.approx(0.0, abs=1e-6)


def test_run_realtime_on_a_video_reports_dropped_frames(tmp_path: Path, sample_dir: Path, capsys) -> None:
    import cv2

    video = tmp_path / "walk.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 300.0, (640, 480))
    for i in range(30):
        writer.write(cv2.imread(str(sample_dir / f"frame-{i:06d}.color.jpg")))
    writer.release()
    out = tmp_path / "run"
    args = ["run", str(video), "--intrinsics", "585,585,320,240", "--out", str(out), "--no-depth-images"]
    assert main([*args, "--realtime"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["realtime"] is True
    assert m["dropped_frames"] > 0  # 300 fps: the odometry cannot take every frame
    assert m["processed_frames"] + m["dropped_frames"] == m["total_frames"] == 30
    assert f"realtime: {m['dropped_frames']} frames dropped" in capsys.readouterr().out
    assert main(args) == 0  # without --realtime every frame is tracked
    m = json.loads((out / "metrics.json").read_text())
    assert (m["realtime"], m["dropped_frames"], m["processed_frames"]) == (False, 0, 30)


def test_calibrate_camera_is_a_command_with_one_line_errors(tmp_path: Path, capsys) -> None:
    import cv2

    (tmp_path / "blank").mkdir()
    for i in range(3):
        cv2.imwrite(str(tmp_path / "blank" / f"{i}.png"), np.full((120, 160), 128, np.uint8))
    code = main(["calibrate-camera", str(tmp_path / "blank"), "--board", "9x6", "--square", "0.025",
                 "--out", str(tmp_path / "camera.txt"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 1 and len(err.splitlines()) == 1 and "blank" in err
    assert not (tmp_path / "camera.txt").exists()


def test_run_prints_the_compile_time_apart_from_the_speed(tmp_path: Path, sample_dir: Path, capsys) -> None:
    args = ["run", str(sample_dir), "--max-frames", "5", "--out", str(tmp_path), "--no-depth-images", "--no-pointcloud"]
    assert main(args) == 0
    m = json.loads((tmp_path / "metrics.json").read_text())
    speed = [line for line in capsys.readouterr().out.splitlines() if line.startswith("speed: ")]
    assert len(speed) == 1 and speed[0].startswith(f"speed: {m['fps']:.1f} fps  (per frame: ")
    compiled = f"kernels compiled/loaded in {m['compile_s']:.1f} s before the first frame, not counted"
    assert speed[0].endswith(f"); {compiled}")


def test_run_imports_no_module_it_does_not_use():
    """``import dmtrack`` and what ``dmtrack run`` imports before its first frame (the API, the features, the run's
    modules) leave out scipy's optimisation and transform modules, matplotlib, torch and rerun: they cost start-up
    time and memory (scipy.spatial alone 0.2 s and 40 MB) and are imported where a command uses them."""
    setup = ("import dmtrack, dmtrack.api, dmtrack.cli, dmtrack.pipeline.run, dmtrack.initialization.initializer\n"
             "from dmtrack.features import get_feature\n"
             "get_feature('gray')\n")
    heavy = ("scipy.spatial", "scipy.optimize", "scipy.sparse", "matplotlib", "torch", "rerun")
    assert _modules_after(setup, heavy) == "[]"


def test_run_starts_before_numba_is_imported():
    """What ``dmtrack run`` imports before its run begins (the API, the run's modules, the start's, the feature, the
    run folder's writer) leaves out numba and the kernels' modules: the run imports them while its geometric start
    already reads and tracks the first frames (0.15 s of the time to the first frame)."""
    setup = ("import dmtrack.api, dmtrack.cli, dmtrack.pipeline.run, dmtrack.initialization.run_start\n"
             "import dmtrack.outputs.run_directory, dmtrack.odometry.config\n"
             "from dmtrack.features import get_feature\n"
             "get_feature('gray'), get_feature('bitplanes'), get_feature('rgb')\n")
    heavy = ("numba", "llvmlite", "dmtrack.odometry.vo", "dmtrack.odometry.depthmap", "dmtrack.odometry.tracker")
    assert _modules_after(setup, heavy) == "[]"


def test_help_loads_no_heavy_module():
    """``dmtrack --help`` builds every subcommand's parser without importing numba, scipy, torch, matplotlib, the
    odometry or the pipeline (about 0.3 s; with the pipeline 1.0 s): a subcommand's parser lives where importing it
    costs little, its command is imported when it runs. (numpy and cv2 still come with the dataset readers' parsers.)"""
    setup = "from dmtrack.cli import build_parser\nbuild_parser().format_help()\n"
    heavy = ("numba", "scipy", "torch", "matplotlib", "dmtrack.pipeline", "dmtrack.odometry")
    assert _modules_after(setup, heavy) == "[]"


def _modules_after(setup: str, heavy: tuple[str, ...]) -> str:
    """The modules starting with one of ``heavy`` that a fresh interpreter holds after running ``setup``."""
    import subprocess
    import sys

    code = f"import sys\n{setup}print(sorted(m for m in sys.modules if m.startswith({heavy!r})))\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.strip()
