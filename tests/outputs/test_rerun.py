"""The Rerun viewer: ``dmtrack run --rrd`` (RerunSink), ``dmtrack view RUN_DIR --rrd``, read back with rerun's own
RRD reader (``rerun.chunk.RrdReader``)."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
import warnings
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np
import pytest

pytest.importorskip("rerun")

from rerun.chunk import RrdReader  # noqa: E402

from dmtrack.api import run_to_directory  # noqa: E402
from dmtrack.cli import main  # noqa: E402
from dmtrack.errors import InputError  # noqa: E402
from dmtrack.evaluation.alignment import umeyama  # noqa: E402
from dmtrack.io.ply import read_ply  # noqa: E402
from dmtrack.io.trajectory import Trajectory, read_tum  # noqa: E402
from dmtrack.odometry.sink import FrameInfo  # noqa: E402
from dmtrack.outputs.memory import MemorySink  # noqa: E402
from dmtrack.outputs.rerun_sink import RerunSink, aligned_groundtruth  # noqa: E402

N_FRAMES = 40


def load(rrd: Path) -> tuple[object, dict[str, list]]:
    """The recording's store entry and its record batches by entity path."""
    reader = RrdReader(rrd)
    (recording,) = reader.recordings()
    batches: dict[str, list] = defaultdict(list)
    for chunk in reader.stream().to_chunks():
        batches[chunk.entity_path].append(chunk.to_record_batch())
    return recording, batches


def rows(batches: list, component: str) -> list[tuple[int | None, object]]:
    """(frame, value) of every row that has ``component``, by frame (static rows: frame None, first)."""
    out = []
    for b in batches:
        if component in b.schema.names:
            values = b.column(component).to_pylist()
            frames = b.column("frame").to_pylist() if "frame" in b.schema.names else [None] * len(values)
            out += [(f, v) for f, v in zip(frames, values, strict=True) if v is not None]
    return sorted(out, key=lambda fv: -1 if fv[0] is None else fv[0])


def points(batches: list, component: str = "Points3D:positions") -> np.ndarray:
    """All (N, 3) positions of ``component`` (float32, as stored)."""
    parts = [np.asarray(b.column(component).flatten().flatten()) for b in batches if component in b.schema.names]
    return np.concatenate(parts).reshape(-1, 3)


@pytest.fixture(scope="module")
def recorded(sample_dir: Path, tmp_path_factory: pytest.TempPathFactory, restored_state) -> tuple[Path, Path, Path]:  # noqa: ANN001
    """``dmtrack run`` of the sample, once with --rrd (in the run folder, which the run cleans of temporary files
    before its first frame) and once without."""
    tmp = tmp_path_factory.mktemp("rerun")
    args = ["run", str(sample_dir), "--max-frames", str(N_FRAMES), "--threads", "2"]
    with restored_state():  # --threads sets the thread variables of its process
        assert main([*args, "--out", str(tmp / "with"), "--rrd", str(tmp / "with" / "run.rrd")]) == 0
        assert main([*args, "--out", str(tmp / "without")]) == 0
    return tmp / "with", tmp / "without", tmp / "with" / "run.rrd"


def test_run_rrd_is_a_recording_of_the_run(recorded: tuple[Path, Path, Path]) -> None:
    run, _, rrd = recorded
    assert [p.name for p in rrd.parent.iterdir() if p.name.endswith(".tmp")] == []
    recording, ent = load(rrd)
    assert recording.application_id == "dmtrack" and len(RrdReader(rrd).blueprints()) == 1
    metrics = json.loads((run / "metrics.json").read_text())
    n_kf = metrics["keyframes"]
    assert metrics["tracked_frames"] == N_FRAMES and n_kf >= 2
    expected = {
        "/world", "/world/camera", "/world/camera/image", "/world/trajectory/estimate/0000",
        "/world/trajectory/groundtruth", "/keyframe/depth", "/stats/residual", "/stats/points",
        "/stats/point_usage", "/stats/keyframe_id", "/timing", "/log",
        *(f"/world/points/{k:04d}" for k in range(n_kf)), *(f"/world/keyframes/{k:04d}" for k in range(n_kf)),
    }  # fmt: skip
    assert expected <= ent.keys()
    assert not any(e.startswith("/world/points/") for e in ent.keys() - expected)
    # the camera: one pose per tracked frame on the frame timeline, equal to trajectory.txt
    camera = rows(ent["/world/camera"], "Transform3D:translation")
    assert [f for f, _ in camera] == list(range(N_FRAMES))
    traj = read_tum(run / "trajectory.txt")
    np.testing.assert_allclose(np.array([v[0] for _, v in camera]), traj.positions, atol=1e-6)
    # the frame images (JPEG, half size) and the depth overlay, one per frame
    images = rows(ent["/world/camera/image"], "EncodedImage:blob")
    assert [f for f, _ in images] == list(range(N_FRAMES))
    first = cv2.imdecode(np.frombuffer(bytes(images[0][1][0]), np.uint8), cv2.IMREAD_COLOR)
    assert first.shape == (240, 320, 3)
    assert [f for f, _ in rows(ent["/keyframe/depth"], "EncodedImage:blob")] == list(range(N_FRAMES))
    # statistics: keyframe id per frame ends at the last keyframe; the tracker's numbers from frame 1 on
    kf_ids = rows(ent["/stats/keyframe_id"], "Scalars:scalars")
    assert len(kf_ids) == N_FRAMES and kf_ids[-1][1] == [n_kf - 1]
    good_bad = rows(ent["/stats/points"], "Scalars:scalars")
    assert [f for f, _ in good_bad] == list(range(1, N_FRAMES)) and all(v[0] > 1000 for _, v in good_bad)
    assert all(len(v) == 5 for _, v in rows(ent["/timing"], "Scalars:scalars")[1:])
    # keyframe point clouds: exactly the points of pointcloud.ply, keyframe by keyframe (metrics' "points")
    clouds = [points(ent[f"/world/points/{k:04d}"]) for k in range(n_kf)]
    assert sum(len(c) for c in clouds) == metrics["points"]
    ply, _ = read_ply(run / "pointcloud.ply")
    assert np.array_equal(np.concatenate(clouds), ply)
    # the ground truth, Sim(3)-aligned to the estimate: close to the estimated camera path (ATE 6 mm here)
    gt_strip = rows(ent["/world/trajectory/groundtruth"], "LineStrips3D:strips")[-1][1][0]
    assert len(gt_strip) == N_FRAMES
    assert np.sqrt(np.mean(np.sum((np.array(gt_strip) - traj.positions) ** 2, axis=1))) < 0.05


def test_rrd_does_not_change_the_run(recorded: tuple[Path, Path, Path]) -> None:
    with_rrd, without, _ = recorded
    for name in ("trajectory.txt", "keyframes.txt", "pointcloud.ply", "groundtruth.txt"):
        assert (with_rrd / name).read_bytes() == (without / name).read_bytes(), name


def test_view_run_folder(recorded: tuple[Path, Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    run = recorded[1]
    rrd = run.parent / "view.rrd"
    assert main(["view", str(run), "--rrd", str(rrd)]) == 0
    assert "ground truth aligned" in capsys.readouterr().out
    _, ent = load(rrd)
    metrics = json.loads((run / "metrics.json").read_text())
    traj = read_tum(run / "trajectory.txt")
    camera = rows(ent["/world/camera"], "Transform3D:translation")
    assert [f for f, _ in camera] == list(range(len(traj))) and len(traj) == N_FRAMES
    np.testing.assert_allclose(np.array([v[0] for _, v in camera]), traj.positions, atol=1e-6)
    assert len(points(ent["/world/points"])) == metrics["points"]
    assert len(points(ent["/world/keyframes"])) == metrics["keyframes"]
    depth = sorted((run / "depth").glob("kf_*.png"))
    assert [f for f, _ in rows(ent["/keyframe/depth"], "EncodedImage:blob")] == [int(p.stem[-6:]) for p in depth]
    assert len(rows(ent["/world/trajectory/groundtruth"], "LineStrips3D:strips")[0][1][0]) == N_FRAMES
    text = rows(ent["/run/metrics"], "TextDocument:text")[0][1][0]
    assert f"| tracked_frames | {N_FRAMES} |" in text


def test_bad_run_folder_and_no_display(
    tmp_path: Path, sample_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    for bad, reason in ((tmp_path / "nope", "no such folder"), (tmp_path, "not a run folder")):
        assert main(["view", str(bad), "--rrd", str(tmp_path / "x.rrd")]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(bad) in err[0] and reason in err[0]
    # a run that fails before its first frame leaves neither the recording nor its temporary file
    assert main(["run", str(sample_dir), "--start", "999", "--rrd", str(tmp_path / "x.rrd")]) == 1
    assert "start frame 999" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    if sys.platform.startswith("linux"):
        monkeypatch.delenv("DISPLAY", raising=False)
        monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
        assert main(["run", str(sample_dir), "--viewer", "--out", str(tmp_path / "out")]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "needs a display" in err[0]
        assert not (tmp_path / "out").exists()


class _InterruptAt(MemorySink):
    """Sends this process SIGINT while frame ``at`` is processed, like Ctrl-C."""

    def __init__(self, at: int) -> None:
        super().__init__()
        self.at = at

    def on_frame_info(self, info: FrameInfo) -> None:
        if info.frame_index == self.at:
            signal.raise_signal(signal.SIGINT)


def test_interrupted_run_still_writes_a_valid_recording(sample_dir: Path, tmp_path: Path) -> None:
    rrd = tmp_path / "cut.rrd"
    sink = RerunSink(rrd=rrd, recording_id="cut")
    with pytest.raises(KeyboardInterrupt):
        run_to_directory(sample_dir, tmp_path / "run", max_frames=N_FRAMES, extra_sinks=(sink, _InterruptAt(6)))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cut.rrd", "run"]
    recording, ent = load(rrd)
    assert recording.recording_id == "cut"
    assert [f for f, _ in rows(ent["/world/camera"], "Transform3D:translation")] == list(range(7))
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["interrupted"] == "SIGINT" and metrics["keyframes"] == 1
    assert len(points(ent["/world/points/0000"])) == metrics["points"]  # the last keyframe, emitted at the stop


def test_aligned_groundtruth_undoes_a_similarity() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(50) * 0.1
    gt_pos = np.cumsum(rng.normal(size=(50, 3)), axis=0)
    gt = Trajectory.from_positions(t, gt_pos)
    angle = 0.7
    R = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    est_pos = 0.3 * gt_pos[10:40] @ R.T + [1.0, -2.0, 0.5]  # the estimate covers 3 s of the 5 s
    aligned = aligned_groundtruth(t[10:40] + 0.002, est_pos, gt, umeyama)
    np.testing.assert_allclose(aligned, est_pos, atol=1e-9)
    assert aligned_groundtruth(t[10:12], est_pos[:2], gt, umeyama) is None  # too few poses
    assert aligned_groundtruth(t[10:40] + 0.05, est_pos, gt, umeyama) is None  # no timestamps match
    with pytest.raises(InputError, match="align="):
        RerunSink(rrd="unused.rrd", groundtruth=gt)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_for(check, seconds: float) -> bool:  # noqa: ANN001
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if check():
            return True
        time.sleep(0.1)
    return False


def test_spawn_streams_to_a_listening_viewer(
    sample_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``spawn=True`` with a viewer already on the port: the run streams to it over gRPC. The viewer here is rerun's
    own receiver without a window (``rerun --save FILE``), which writes what it receives to a file."""
    rerun_cli = pytest.importorskip("rerun_cli")
    binary = Path(rerun_cli.__file__).parent / "rerun"
    if not binary.is_file():
        pytest.skip(f"no rerun executable at {binary}")
    port, received = _free_port(), tmp_path / "received.rrd"
    server = subprocess.Popen(
        [str(binary), "--save", str(received), "--port", str(port)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        def listening() -> bool:
            with socket.socket() as s:
                return s.connect_ex(("127.0.0.1", port)) == 0

        assert _wait_for(listening, 20), "rerun --save did not start listening"
        monkeypatch.setenv("DISPLAY", ":0")  # passes the display check; the listening receiver is used
        sink = RerunSink(spawn=True, port=port, recording_id="live")
        run_to_directory(sample_dir, tmp_path / "run", max_frames=8, extra_sinks=(sink,))

        def arrived() -> bool:
            if not received.is_file():
                return False
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # the receiver's file has no footer yet
                    _, ent = load(received)
            except (RuntimeError, ValueError):  # read while the first message or a later one is half written
                return False
            return len(rows(ent.get("/world/camera", []), "Transform3D:translation")) == 8

        assert _wait_for(arrived, 20)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            recording, ent = load(received)
        assert recording.recording_id == "live"
        assert [f for f, _ in rows(ent["/world/camera/image"], "EncodedImage:blob")] == list(range(8))
    finally:
        server.terminate()
        server.wait(timeout=20)


def test_sink_with_the_four_methods_only_and_unix_times(tmp_path: Path) -> None:
    """A caller that never calls on_frame_info still gets the poses and the log; Unix timestamps become dates."""
    sink = RerunSink(rrd=tmp_path / "u.rrd")
    for i in range(3):
        T = np.eye(4)
        T[:3, 3] = (0.1 * i, 0.0, 0.0)
        sink.on_frame(i, 1.3e9 + i / 30, T)
    sink.on_lost(3, "diverged")
    sink.close()
    sink.close()  # idempotent
    _, ent = load(tmp_path / "u.rrd")
    camera = rows(ent["/world/camera"], "Transform3D:translation")
    assert [f for f, _ in camera] == [0, 1, 2] and camera[2][1][0] == pytest.approx([0.2, 0.0, 0.0])
    (batch,) = [b for b in ent["/world/camera"] if "time" in b.schema.names]
    assert str(batch.schema.field("time").type).startswith("timestamp")
    assert rows(ent["/log"], "TextLog:text") == [(3, ["tracking lost at frame 3: diverged"])]
    empty = RerunSink(rrd=tmp_path / "empty.rrd")
    empty.close()  # no call at all: still a valid recording
    assert load(tmp_path / "empty.rrd")[0].application_id == "dmtrack"


def test_a_relocalisation_is_drawn_live_and_from_the_run_folder(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """A kidnapped synthetic camera (seed 4: frames 0–59, then 270–299, which revisit the start) with
    --continue-after-loss: the live recording and ``dmtrack view`` of the folder both put a magenta point where the
    camera was found again, at the relocalised frame's position."""
    out = tmp_path / "run"
    assert main(["run", "synthetic:n_frames=330,width=320,height=240,seed=4", "--frames", "0-59,270-299",
                 "--continue-after-loss", "--no-depth-images", "--out", str(out),
                 "--rrd", str(tmp_path / "live.rrd")]) == 0  # fmt: skip
    metrics = json.loads((out / "metrics.json").read_text())
    (found,) = metrics["relocalised"]
    traj = read_tum(out / "trajectory.txt")
    where = traj.positions[int(np.argmin(np.abs(traj.timestamps - found["timestamp"])))]
    _, live = load(tmp_path / "live.rrd")
    (frame, _), *_ = rows(live["/world/relocalisations"], "Points3D:positions")
    assert frame == found["frame"]
    np.testing.assert_allclose(points(live["/world/relocalisations"]), [where], atol=1e-5)
    text = [v[0] for _, v in rows(live["/log"], "TextLog:text")]
    assert f"relocalised at frame {found['frame']} on keyframe {found['keyframe']}, lost since frame " + str(
        found["lost_since"]) in text
    assert main(["view", str(out), "--rrd", str(tmp_path / "view.rrd")]) == 0
    capsys.readouterr()
    _, view = load(tmp_path / "view.rrd")
    np.testing.assert_allclose(points(view["/world/relocalisations"]), [where], atol=1e-5)


def test_the_window_is_drawn_after_each_optimisation(tmp_path: Path) -> None:
    """``--window``: the viewer gets the window's keyframes after every optimisation, at the keyframes' positions then
    (the last drawing is where the run left them)."""
    out = tmp_path / "run"
    assert main(["run", "synthetic:n_frames=45,width=320,height=240,seed=1", "--window", "4", "--no-depth-images",
                 "--no-pointcloud", "--out", str(out), "--rrd", str(tmp_path / "w.rrd")]) == 0  # fmt: skip
    metrics = json.loads((out / "metrics.json").read_text())
    _, ent = load(tmp_path / "w.rrd")
    drawn = rows(ent["/world/window/keyframes"], "Points3D:positions")
    assert len(drawn) == metrics["window"]["optimisations"] >= 1
    last = points(ent["/world/window/keyframes"])[-min(4, metrics["keyframes"]):]  # the window after the last one
    kfs = read_tum(out / "keyframes.txt")
    np.testing.assert_allclose(last, kfs.positions[-len(last):], atol=1e-5)
