"""End to end: `dmtrack run` / `dmtrack.api` on the synthetic renderer and on the shipped real sample."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from dmtrack.api import run_to_directory, track
from dmtrack.cli import main
from dmtrack.errors import InputError
from dmtrack.io.ply import read_ply
from dmtrack.io.trajectory import read_tum

SYNTH = "synthetic:n_frames=24,width=320,height=240,seed=2"
CONTRACT = {
    "feature", "sequence", "total_frames", "tracked_frames", "lost_at", "fps", "feature_ms", "tracking_ms",
    "mapping_ms", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "ate_rmse", "matched_poses",
}


@pytest.fixture(scope="module")
def synth_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    out = tmp_path_factory.mktemp("run")
    result = run_to_directory(SYNTH, out, feature="gray", seed=0)
    return out, result


def test_run_writes_every_output(synth_run: tuple[Path, object]) -> None:
    out, result = synth_run
    metrics = json.loads((out / "metrics.json").read_text())
    assert CONTRACT <= metrics.keys()
    assert metrics["total_frames"] == 24 and metrics["tracked_frames"] == 24 and metrics["lost_at"] is None
    assert metrics["matched_poses"] == 24 and metrics["feature"] == "gray"
    traj = read_tum(out / "trajectory.txt")
    assert len(traj) == metrics["tracked_frames"]
    np.testing.assert_allclose(traj.timestamps, np.arange(24) / 30.0, atol=1e-6)  # the dataset's timestamps
    kfs = read_tum(out / "keyframes.txt")
    assert len(kfs) == metrics["keyframes"] >= 1
    assert len(list((out / "depth").glob("kf_*.png"))) == metrics["keyframes"]
    pts, cols = read_ply(out / "pointcloud.ply")
    assert pts.shape[0] == metrics["points"] > 1000 and cols is not None
    assert np.isfinite(pts).all()
    assert (out / "config.yaml").is_file()


def test_synthetic_accuracy(tmp_path: Path) -> None:
    """Exact synthetic data, first keyframe's depth from the ground truth: tracking + mapping must be accurate."""
    from dmtrack.datasets import open_sequence
    from dmtrack.odometry.config import VOConfig

    result = run_to_directory(SYNTH, tmp_path, config=VOConfig(init="groundtruth"), pointcloud=False,
                              depth_images=False)
    m = result.metrics
    gt_len = open_sequence(SYNTH).groundtruth.path_length()
    assert gt_len > 0.1
    assert m["tracked_frames"] == 24
    assert m["ate_rmse"] < 0.01 * gt_len  # metres, after Sim(3) alignment
    assert m["rpe_rot_deg_per_m"] < 2.0
    assert m["ate_scale"] == pytest.approx(1.0, abs=0.05)  # metric depth at the start: metric trajectory


def test_groundtruth_init_refuses_unregistered_depth(shared_dir: Path) -> None:
    from dmtrack.odometry.config import VOConfig

    with pytest.raises(InputError, match="not registered"):
        track(shared_dir / "data" / "7scenes-0000-0699", config=VOConfig(init="groundtruth"), max_frames=2)


def test_same_seed_same_bytes(synth_run: tuple[Path, object], tmp_path: Path) -> None:
    out, _ = synth_run
    run_to_directory(SYNTH, tmp_path, feature="gray", seed=0, depth_images=False, pointcloud=False)
    assert (tmp_path / "trajectory.txt").read_bytes() == (out / "trajectory.txt").read_bytes()
    assert (tmp_path / "keyframes.txt").read_bytes() == (out / "keyframes.txt").read_bytes()


def test_cli_threads_option_gives_the_same_trajectory(synth_run: tuple[Path, object], tmp_path: Path) -> None:
    """`dmtrack run --threads 1` runs the kernels serially: byte-identical to the default (all cores) run."""
    import os

    import numba

    from dmtrack.experiments.task import THREAD_ENV_VARS

    # main() sets these for its process: put back exactly what was there (monkeypatch.delenv of a variable that is
    # not set records nothing, so it would not remove one that main() then set: a leak into later tests, issue 41)
    saved = {var: os.environ.get(var) for var in (*THREAD_ENV_VARS, "DMTRACK_FEATURE_THREADS")}
    prev = numba.get_num_threads()
    try:
        rc = main(["run", SYNTH, "--threads", "1", "--out", str(tmp_path), "--no-progress", "--no-pointcloud",
                   "--no-depth-images"])
        assert rc == 0 and numba.get_num_threads() == 1
    finally:
        numba.set_num_threads(prev)
        for var, value in saved.items():
            if value is None:
                os.environ.pop(var, None)
            else:
                os.environ[var] = value
    out, _ = synth_run
    assert (tmp_path / "trajectory.txt").read_bytes() == (out / "trajectory.txt").read_bytes()
    assert main(["run", SYNTH, "--threads", "0", "--out", str(tmp_path / "x")]) == 1


def test_cli_run_on_shipped_sample(tmp_path: Path, sample_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["run", str(sample_dir), "--max-frames", "12", "--start", "5", "--out", str(tmp_path), "--no-progress"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "tracked 12/12 frames" in out
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert (m["total_frames"], m["tracked_frames"], m["start"], m["width"], m["height"]) == (12, 12, 5, 640, 480)
    traj = read_tum(tmp_path / "trajectory.txt")
    np.testing.assert_allclose(traj.timestamps[0], 5 / 30.0, atol=1e-6)


def _loss_sequence(sample_dir: Path, root: Path, n_good: int) -> Path:
    """An image folder: n_good real frames, then black frames nothing can be tracked against."""
    (root / "images").mkdir(parents=True)
    for i in range(n_good):
        shutil.copy(sample_dir / f"frame-{i:06d}.color.jpg", root / "images" / f"{i:04d}.jpg")
    for i in range(n_good, n_good + 3):
        cv2.imwrite(str(root / "images" / f"{i:04d}.png"), np.zeros((480, 640), np.uint8))
    (root / "camera.txt").write_text("585 585 320 240\n")
    return root


def test_tracking_loss_is_recorded(tmp_path: Path, sample_dir: Path) -> None:
    seq = _loss_sequence(sample_dir, tmp_path / "seq", n_good=8)
    from dmtrack.odometry.config import VOConfig

    config = VOConfig().with_overrides("keyframe.loss_not_good_after=0")
    result = run_to_directory(seq, tmp_path / "out", config=config, pointcloud=False, depth_images=False)
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert m["lost_at"] == 8 and m["tracked_frames"] == 8 and m["lost_reason"]
    assert result.lost_at == 8
    # everything finished before the loss is on disk
    assert len(read_tum(tmp_path / "out" / "trajectory.txt")) == 8


def test_missing_intrinsics_is_a_clear_error(tmp_path: Path, sample_dir: Path, capsys) -> None:  # noqa: ANN001
    seq = _loss_sequence(sample_dir, tmp_path / "seq", n_good=2)
    (seq / "camera.txt").unlink()
    with pytest.raises(InputError, match="no intrinsics"):
        track(seq, max_frames=2)
    assert main(["run", str(seq), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert "no intrinsics" in err and "--intrinsics" in err


def test_bad_arguments(sample_dir: Path) -> None:
    with pytest.raises(InputError, match="start frame 400"):
        track(sample_dir, start=400)
    with pytest.raises(InputError, match="max_frames"):
        track(sample_dir, max_frames=0)
    with pytest.raises(InputError, match="unknown"):
        track(sample_dir, feature="no-such-feature", max_frames=2)


def test_track_many_equals_separate_runs(sample_dir: Path) -> None:
    """Lockstep runs (one feature computation, several odometries) give the separate runs' bytes."""
    from dmtrack.api import track_many
    from dmtrack.features import get_feature
    from dmtrack.odometry.config import VOConfig

    configs = [VOConfig(seed=1), VOConfig(seed=2, channel_cost="sum")]
    many = track_many(sample_dir, "bitplanes", configs, max_frames=20)
    bp = get_feature("bitplanes")
    for cfg, got in zip(configs, many, strict=True):
        one = track(sample_dir, "bitplanes", cfg, max_frames=20)
        assert got.trajectory.poses.tobytes() == one.trajectory.poses.tobytes()
        assert got.tracked_frames == one.tracked_frames == 20
        assert got.metrics["seed"] == cfg.seed and got.metrics["channel_cost"] == cfg.channel_cost
        # the feature's measured channel counts are filled in and recorded
        assert got.metrics["energy_channels"] == bp.energy_channels
        assert got.metrics["info_channels"] == bp.info_channels
        assert got.metrics["noise_energy_channels"] == bp.noise_energy_channels
    assert many[0].trajectory.poses.tobytes() != many[1].trajectory.poses.tobytes()
    with pytest.raises(InputError):
        track_many(sample_dir, "gray", [])


def test_run_folder_has_the_groundtruth_of_its_frames(tmp_path, sample_dir):
    run_to_directory(sample_dir, tmp_path / "run", start=10, max_frames=6, depth_images=False, pointcloud=False)
    gt = read_tum(tmp_path / "run" / "groundtruth.txt")
    est = read_tum(tmp_path / "run" / "trajectory.txt")
    np.testing.assert_array_equal(gt.timestamps, est.timestamps)  # 7-Scenes: a pose for every frame
    assert len(gt) == 6
    # a later run on a sequence without ground truth (the same images as a plain image folder) leaves no stale file
    folder = tmp_path / "images"
    folder.mkdir()
    for i in range(4):
        shutil.copy(sample_dir / f"frame-{i:06d}.color.jpg", folder / f"{i:06d}.jpg")
    run_to_directory(folder, tmp_path / "run", intrinsics="585,585,320,240", depth_images=False, pointcloud=False)
    assert (tmp_path / "run" / "metrics.json").is_file()
    assert not (tmp_path / "run" / "groundtruth.txt").exists()


class _CountingFrames:
    """A sequence whose decoded frames are counted while they are alive (weak references)."""

    def __init__(self, seq: object) -> None:
        self._seq = seq
        self.alive = self.peak = self.reads = 0

    def __getattr__(self, name: str) -> object:
        return getattr(self._seq, name)

    def __len__(self) -> int:
        return len(self._seq)

    def _count(self, frame: object) -> object:
        import weakref

        self.reads += 1
        self.alive += 1
        self.peak = max(self.peak, self.alive)
        weakref.finalize(frame.image, self._gone)
        return frame

    def _gone(self) -> None:
        self.alive -= 1

    def __getitem__(self, i: int) -> object:
        return self._count(self._seq[i])

    def read_frame(self, i: int, depth: bool = False) -> object:
        return self._count(self._seq.read_frame(i, depth=depth))


def test_odometry_failing_to_build_stops_the_start_it_ran_beside(sample_dir: Path, monkeypatch) -> None:
    """The run builds its odometry (importing numba's kernels) while the geometric start reads the first frames. When
    building fails, that error is raised, and the start stops at its next frame instead of reading on to its end."""
    import threading
    import time

    from dmtrack.datasets import open_sequence
    from dmtrack.odometry import vo

    def fails(self, *args, **kwargs) -> None:
        time.sleep(0.05)  # the start has begun reading
        raise RuntimeError("the odometry could not be built")

    monkeypatch.setattr(vo.VisualOdometry, "__init__", fails)
    seq = _CountingFrames(open_sequence(sample_dir))
    with pytest.raises(RuntimeError, match="could not be built"):
        track(seq, max_frames=60)
    assert seq.reads < 30  # the start accepts at frame 33 of this sequence when it runs to its end
    assert not any(t.name.startswith("dmtrack-start") for t in threading.enumerate())


_SLOW_RUN = r"""
import sys, time
import numpy as np
from dmtrack.api import run_to_directory
from dmtrack.datasets import open_sequence

class Slow:
    # the sample's frames; those in `slow` take 0.3 s to read, the first time each is read
    def __init__(self, seq, slow):
        self._seq, self._slow = seq, set(slow)
    def __getattr__(self, name):
        return getattr(self._seq, name)
    def __len__(self):
        return len(self._seq)
    def _wait(self, i):
        if i in self._slow:
            self._slow.discard(i)
            time.sleep(0.3)
    def __getitem__(self, i):
        self._wait(i)
        return self._seq[i]
    def read_frame(self, i, depth=False):
        self._wait(i)
        return self._seq.read_frame(i, depth=depth)

sample, out, first = sys.argv[1], sys.argv[2], int(sys.argv[3])
r = run_to_directory(Slow(open_sequence(sample), range(first, first + 4)), out, max_frames=50, depth_images=False,
                     pointcloud=False)
np.save(out + "/poses.npy", r.trajectory.poses)
"""


def test_frames_read_ahead_of_the_start_are_handed_on_without_a_hang(tmp_path: Path, sample_dir: Path) -> None:
    """When the start accepts, the frames its reader has read ahead go to the odometry. Reads still queued then
    (a slow disk) must finish first: a queued read that found its own future handed on waited on itself and the run
    hung (seen once in CI). The slow run is a child process, so that a hang fails here instead of holding the
    suite."""
    import subprocess
    import sys

    plain = run_to_directory(sample_dir, tmp_path / "a", max_frames=50, depth_images=False, pointcloud=False)
    accepted = json.loads((tmp_path / "a" / "metrics.json").read_text())["init_accepted_frame"]
    assert accepted is not None and accepted + 8 < 50
    out = tmp_path / "b"
    try:
        subprocess.run([sys.executable, "-c", _SLOW_RUN, str(sample_dir), str(out), str(accepted + 1)], check=True,
                       capture_output=True, timeout=120)  # fmt: skip
    except subprocess.TimeoutExpired:
        pytest.fail("the run hung after the start accepted")
    np.testing.assert_array_equal(np.load(out / "poses.npy"), plain.trajectory.poses)


def test_the_start_holds_few_frames_and_startup_is_measured(tmp_path: Path, sample_dir: Path) -> None:
    """The geometric start reads tens of frames before it accepts; frames of image files are read again when the
    odometry comes to them instead of being held (they were the run's peak of memory), with the same trajectory;
    a video's are kept (seeking back in a video may not land on the same picture). metrics.json says where the time
    before the first frame went."""
    from dmtrack.datasets import open_sequence

    seq = _CountingFrames(open_sequence(sample_dir))
    r = run_to_directory(seq, tmp_path / "a", max_frames=60, depth_images=False, pointcloud=False)
    m = json.loads((tmp_path / "a" / "metrics.json").read_text())
    assert m["init"] == "geometric" and m["init_accepted_frame"] is not None
    assert m["init_accepted_frame"] > 10  # the start read that many frames first
    assert seq.peak <= 8, f"{seq.peak} decoded frames alive at once"
    assert seq.reads > 60  # the start's frames were read twice
    plain = run_to_directory(sample_dir, tmp_path / "b", max_frames=60, depth_images=False, pointcloud=False)
    np.testing.assert_array_equal(r.trajectory.poses, plain.trajectory.poses)
    video = tmp_path / "sample.avi"  # the same frames as a video: each decoded once
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480))
    for i in range(60):
        writer.write(cv2.imread(str(sample_dir / f"frame-{i:06d}.color.jpg")))
    writer.release()
    vseq = _CountingFrames(open_sequence(video, intrinsics="585,585,320,240"))
    run_to_directory(vseq, tmp_path / "c", max_frames=60, depth_images=False, pointcloud=False)
    assert vseq.reads == 60
    s = m["startup"]
    assert set(s) == {"import_s", "run_s", "odometry_import_s", "warmup_s", "start_s", "first_frame_s"}
    if s["run_s"] is not None:  # Linux: ages of the process
        assert 0 < s["import_s"] <= s["run_s"] < s["first_frame_s"]
        assert s["warmup_s"] >= 0 and s["start_s"] >= 0 and s["odometry_import_s"] >= 0
