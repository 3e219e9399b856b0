"""The odometry with the sliding window (dmtrack.window.SlidingWindow through VisualOdometry(window=…)): keyframes
held until they leave and emitted once with their final poses, the trajectory placed by the final keyframe poses,
the same bytes for any thread count, and the window's figures in metrics.json."""

from __future__ import annotations

import dataclasses
import importlib.util
import json

import numpy as np
import pytest

from dmtrack.datasets.synthetic import SyntheticConfig, SyntheticSequence
from dmtrack.errors import InputError
from dmtrack.odometry.config import VOConfig, WindowConfig
from dmtrack.odometry.records import _inv_se3, _se3_part, _sim3
from dmtrack.odometry.vo import VisualOdometry
from dmtrack.outputs.memory import MemorySink
from dmtrack.window import SlidingWindow

N_FRAMES = 40
CAMERA = SyntheticConfig(width=320, height=240).camera()
CONFIG = VOConfig(init="groundtruth", window=WindowConfig(size=4, points=300))


@pytest.fixture(scope="module")
def frames() -> list:
    seq = SyntheticSequence(SyntheticConfig(width=320, height=240, n_frames=N_FRAMES, seed=0))
    return [seq[i] for i in range(N_FRAMES)]


def _grey(image: np.ndarray) -> np.ndarray:
    return image.astype(np.float32)


def _run(frames, config=CONFIG, threads=None, window=True, n=None, feature=_grey):
    sink = MemorySink()
    vo = VisualOdometry(CAMERA, config, sink, threads=threads,
                        window=SlidingWindow(config, CAMERA) if window else None)  # fmt: skip
    for i, fr in enumerate(frames[:n]):
        vo.process(fr.index, fr.timestamp, fr.image, feature(fr.image), fr.depth if i == 0 else None)
    return vo, vo.finish(), sink


@pytest.fixture(scope="module")
def windowed(frames):
    return _run(frames)


def test_every_keyframe_is_emitted_once_in_order_with_its_final_pose(windowed) -> None:
    vo, res, sink = windowed
    assert len(res.keyframes) >= 5  # more keyframes than the window holds: some left it during the run
    assert [k.keyframe_id for k in sink.keyframes] == list(range(len(res.keyframes)))
    for rec, snap in zip(res.keyframes, sink.keyframes, strict=True):
        np.testing.assert_array_equal(rec.T_wc, snap.T_wc)
        assert rec.scale == snap.scale
    assert res.window is not None and res.window["optimisations"] == len(res.keyframes) - 1
    assert res.window["left"] == len(res.keyframes) - 4  # size 4: the last four left at the end
    assert 0 < res.window["median_cost_ratio"] < 1  # each optimisation lowers the cost


def test_trajectory_is_placed_by_the_final_keyframe_poses(windowed) -> None:
    vo, res, sink = windowed
    live = np.array([T for _, _, T in sink.frames])
    assert res.poses.shape == live.shape
    assert not np.array_equal(res.poses, live)  # the window moved keyframes after their frames were told
    kf_frames = {k.frame_index: k for k in res.keyframes}
    for idx, T in zip(res.indices, res.poses, strict=True):
        if idx in kf_frames:  # a keyframe's own frame is where its keyframe is
            np.testing.assert_allclose(T, kf_frames[idx].T_wc, atol=1e-12)
    # every frame = its keyframe's Sim(3) pose composed with its tracked pose on it
    for (kf_id, T_fk), T in zip(vo._pose_refs, res.poses, strict=True):
        rec = res.keyframes[kf_id]
        np.testing.assert_allclose(T, _se3_part(_sim3(rec.T_wc, rec.scale) @ _inv_se3(T_fk), rec.scale), atol=1e-12)


def test_window_improves_or_keeps_the_synthetic_trajectory(frames, windowed) -> None:
    from dmtrack.evaluation import evaluate
    from dmtrack.io.trajectory import Trajectory

    seq = SyntheticSequence(SyntheticConfig(width=320, height=240, n_frames=N_FRAMES, seed=0))
    gt = seq.groundtruth
    _, off, _ = _run(frames, window=False)
    _, on, _ = windowed
    e_off = evaluate(gt, Trajectory(off.timestamps, off.poses), align="sim3")["ate_rmse"]
    e_on = evaluate(gt, Trajectory(on.timestamps, on.poses), align="sim3")["ate_rmse"]
    assert on.tracked_frames == off.tracked_frames == N_FRAMES
    assert e_on < 1.5 * e_off + 1e-3  # exact depth, no noise: little to gain, nothing to lose


def test_same_bytes_at_one_and_two_threads(frames) -> None:
    runs = [_run(frames, threads=t, n=25)[1] for t in (1, 2)]
    assert runs[0].poses.tobytes() == runs[1].poses.tobytes()
    assert [k.T_wc.tobytes() for k in runs[0].keyframes] == [k.T_wc.tobytes() for k in runs[1].keyframes]


def test_window_off_is_the_odometry_alone(frames) -> None:
    """``window.size = 0`` builds no window: the same bytes as an odometry given none."""
    cfg = dataclasses.replace(CONFIG, window=WindowConfig(size=0))
    a = _run(frames, cfg, window=False, n=20)[1]
    from dmtrack.pipeline.run import _window

    assert _window(cfg, CAMERA) is None
    b = _run(frames, VOConfig(init="groundtruth"), window=False, n=20)[1]
    assert a.poses.tobytes() == b.poses.tobytes()


def test_run_writes_the_window_figures_and_the_refined_trajectory(tmp_path) -> None:
    from dmtrack.io.trajectory import read_tum
    from dmtrack.pipeline import run_to_directory

    out = tmp_path / "run"
    cfg = VOConfig(init="groundtruth", window=WindowConfig(size=4, points=300, refine_intrinsics=True))
    result = run_to_directory("synthetic:n_frames=30,width=320,height=240", out, "gray", config=cfg,
                              pointcloud=False, depth_images=False)  # fmt: skip
    m = json.loads((out / "metrics.json").read_text())
    assert m["window"]["optimisations"] >= 1 and m["window"]["intrinsics"]["fx"] > 0
    assert m["window"]["intrinsics_sigma"]["fx"] > 0
    written = read_tum(out / "trajectory.txt")
    np.testing.assert_allclose(written.poses, result.trajectory.poses, atol=1e-6)
    pytest.importorskip("plotly", reason="report.html needs plotly")
    from dmtrack.evaluation.html import write_html_report

    html = write_html_report(out).read_text()
    assert "Sliding window" in html and "Estimated fx (px)" in html


def test_marginalising_window_runs_through(frames) -> None:
    cfg = dataclasses.replace(CONFIG, window=WindowConfig(size=3, points=300, leave="marginalise"))
    vo, res, sink = _run(frames, cfg)
    assert res.tracked_frames == N_FRAMES and len(res.keyframes) >= 5
    assert [k.keyframe_id for k in sink.keyframes] == list(range(len(res.keyframes)))
    assert res.window["leave"] == "marginalise" and res.window["left"] == len(res.keyframes) - 3
    for rec, snap in zip(res.keyframes, sink.keyframes, strict=True):
        np.testing.assert_array_equal(rec.T_wc, snap.T_wc)


@pytest.mark.skipif(importlib.util.find_spec("gtsam") is None,
                    reason="gtsam not installed (pip install 'dmtrack[slam]')")
def test_slam_takes_the_window_keyframes(tmp_path) -> None:
    """``--slam --window``: the back end gets each keyframe when it leaves the window, with its final pose, and places
    the frames on the optimised graph from their poses on their keyframes (a keyframe's own frame is where the graph
    put the keyframe)."""
    from dmtrack.io.trajectory import read_tum
    from dmtrack.pipeline import run_to_directory

    out = tmp_path / "run"
    cfg = VOConfig(init="groundtruth", window=WindowConfig(size=3, points=300))
    result = run_to_directory("synthetic:n_frames=40,width=320,height=240", out, "gray", config=cfg, slam=True,
                              pointcloud=False, depth_images=False)  # fmt: skip
    assert result.metrics["window"]["optimisations"] >= 3
    traj, kfs = read_tum(out / "trajectory.txt"), read_tum(out / "keyframes.txt")
    assert len(traj) == result.tracked_frames and len(kfs) == result.metrics["keyframes"]
    for t, T in zip(kfs.timestamps, kfs.poses, strict=True):
        np.testing.assert_allclose(traj.poses[int(np.argmin(np.abs(traj.timestamps - t)))], T, atol=1e-6)


def test_a_rejected_optimisation_leaves_the_odometry_alone(frames) -> None:
    """An optimisation whose residuals are mostly outliers is dropped and the window begins anew: with a threshold no
    optimisation can meet, every one is rejected, and the run is the odometry alone, byte for byte."""
    strict = dataclasses.replace(CONFIG, window=WindowConfig(size=4, points=300, max_outliers=1e-9))
    _, res, sink = _run(frames, strict, n=30)
    _, alone, _ = _run(frames, VOConfig(init="groundtruth"), window=False, n=30)
    assert res.window["optimisations"] >= 2 and res.window["rejected"] == res.window["optimisations"]
    assert res.poses.tobytes() == alone.poses.tobytes()
    assert [k.T_wc.tobytes() for k in res.keyframes] == [k.T_wc.tobytes() for k in alone.keyframes]
    assert [k.keyframe_id for k in sink.keyframes] == list(range(len(res.keyframes)))
    moved = dataclasses.replace(CONFIG, window=WindowConfig(size=4, points=300, max_move=1e-9))
    assert _run(frames, moved, n=30)[1].window["rejected"] >= 1  # the new keyframe moved at all


def test_held_keyframes_keep_only_what_their_emission_reads(frames) -> None:
    """A finished keyframe waits in the window without its depth map's working state or its full-resolution
    gradients (45 MB of a grey 640×480 run); what it emits when it leaves is what it held."""
    from dmtrack.odometry.windowing import FinishedMap

    sink = MemorySink()
    vo = VisualOdometry(CAMERA, CONFIG, sink, window=SlidingWindow(CONFIG, CAMERA))
    for i, fr in enumerate(frames[:30]):
        vo.process(fr.index, fr.timestamp, fr.image, fr.image.astype(np.float32), fr.depth if i == 0 else None)
    held = dict(vo._held)
    assert held, "the window holds finished keyframes"
    for kf, finished in held.values():
        assert isinstance(finished, FinishedMap)
        assert kf.levels[0]._gx is None and kf.levels[0]._max_grad is None and kf.levels[0]._packed is None
        assert kf.levels[1].packed is not None  # the window's levels are there
    vo.finish()
    emitted = {s.keyframe_id: s for s in sink.keyframes}
    for kf_id, (_, finished) in held.items():
        idepth, var = finished.tracking_depth()
        np.testing.assert_array_equal(emitted[kf_id].idepth, idepth)
        np.testing.assert_array_equal(emitted[kf_id].idepth_var, var)


def _three_channels(image: np.ndarray) -> np.ndarray:
    g = image.astype(np.float32)
    return np.ascontiguousarray(np.dstack([g, 255.0 - g, np.float32(0.5) * g]))


def test_grey_residuals_whatever_the_feature(frames) -> None:
    """``window.channels = "grey"``: the window compares the keyframes' grey images. For a grey feature that is its
    own channel (the same bytes); for a three-channel one the window holds one-channel pyramids of the same images
    while the odometry tracks all three, and its optimisations differ from those on the three channels."""
    grey = dataclasses.replace(CONFIG, window=dataclasses.replace(CONFIG.window, channels="grey"))
    assert _run(frames, grey, n=20)[1].poses.tobytes() == _run(frames, CONFIG, n=20)[1].poses.tobytes()
    vo = VisualOdometry(CAMERA, grey, MemorySink(), window=SlidingWindow(grey, CAMERA))
    for i, fr in enumerate(frames[:25]):
        vo.process(fr.index, fr.timestamp, fr.image, _three_channels(fr.image), fr.depth if i == 0 else None)
    assert vo._kf.n_channels == 3
    assert len(vo._window.keyframes) > 1 and all(kf.frame.n_channels == 1 for kf in vo._window.keyframes)
    assert vo._window.stats.optimisations > 0
    on_grey = vo.finish()
    on_feature = _run(frames, CONFIG, n=25, feature=_three_channels)[1]
    assert on_grey.poses.tobytes() != on_feature.poses.tobytes()
    with pytest.raises(InputError, match="window.channels"):
        WindowConfig(size=5, channels="gray")
    blind = VisualOdometry(CAMERA, grey, MemorySink(), window=SlidingWindow(grey, CAMERA))
    with pytest.raises(InputError, match="no image"):  # feature maps without their images: a clear error
        for i, fr in enumerate(frames[:25]):
            blind.process(fr.index, fr.timestamp, None, _three_channels(fr.image), fr.depth if i == 0 else None)
