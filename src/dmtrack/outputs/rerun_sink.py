"""A live 3D view of a run in the `Rerun <https://rerun.io>`_ viewer, as an :class:`~dmtrack.odometry.sink.OutputSink`.

rerun-sdk is optional (``pip install 'dmtrack[viewer]'``) and imported only when a :class:`RerunSink` is made.
The sink logs to the native viewer it spawns (``spawn=True``), to an ``.rrd`` file (``rrd=PATH``, written to a
temporary file in the same folder and renamed when the sink closes — also after an interrupt — so it is complete
or absent; open it with ``rerun FILE``), or to both.

=================================  ============================================================================
``world``                          the first camera's frame, x right, y down, z forward (ViewCoordinates RDF)
``world/camera``                   the current camera pose T_wc (Transform3D), per frame
``world/camera/image``             its Pinhole and the frame's image (JPEG, downscaled by ``image_downscale``)
``world/trajectory/estimate/N``    the estimated camera path (LineStrips3D), growing, in pieces of 100 frames
``world/trajectory/groundtruth``   the ground truth, Sim(3)-aligned to the estimate so far; re-aligned at every
                                   keyframe and when the sink closes
``world/keyframes/N``              keyframe N's pose and frustum
``world/points/N``                 keyframe N's semi-dense points (world frame, coloured by its image), logged
                                   when its depth map is final
``world/slam/keyframes``           SLAM (``--slam``), after each optimisation of the graph: the keyframes at
                                   their optimised poses (points), at the newest keyframe's frame
``world/slam/trajectory``          the optimised keyframes joined in order (LineStrips3D)
``world/slam/edges/odometry``,     the graph's accepted edges as segments between the optimised keyframes: the
``world/slam/edges/loop``          odometry's (grey) and the loop closures (magenta)
``keyframe/depth``                 the current keyframe's inverse depth over its image, coloured as
                                   :func:`dmtrack.viz.depth.inverse_depth_image` (per frame, downscaled)
``world/initial_map``, ``keyframe/initial_map``  the first keyframe's map as the start made it (random, geometric,
                                   ground truth): its points, and its inverse depth over the image (optional
                                   sink method ``on_initial_map``)
``stats/…``                        per frame: the tracker's ``residual``, ``points`` (good, bad),
                                   ``point_usage``, and ``keyframe_id``
``timing``                         per frame, ms: pyramid, tracking, mapping, odometry (their sum) and frame
                                   (wall time since the previous frame: reading, features and this sink included)
``log``                            keyframes and tracking losses (TextLog)
=================================  ============================================================================

Timelines: ``frame`` (the frame index) and ``time`` (the dataset's timestamp: a date for Unix times, otherwise a
duration in seconds). The images, depth overlay and statistics need the optional sink method ``on_frame_info``
(:class:`~dmtrack.odometry.sink.FrameInfo`); the poses, trajectory and points come through the four standard ones.
The ``world/slam`` entities come from the SLAM back end, which calls the sink's ``on_graph_optimised``
(:class:`~dmtrack.slam.listener.GraphListener`) from its own thread; the odometry's entities stay where the
odometry put them.

The ground truth is given in the dataset's frame; the sink maps it into the estimate's frame with a similarity
found by ``align`` — :func:`dmtrack.evaluation.alignment.umeyama`, passed in by the caller because the evaluation
is a layer above the outputs.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from dmtrack.errors import InputError
from dmtrack.io.association import associate
from dmtrack.io.atomic import atomic_path
from dmtrack.io.trajectory import Trajectory
from dmtrack.odometry.sink import FrameInfo, KeyframeSnapshot
from dmtrack.slam.listener import OptimisedGraph
from dmtrack.viz.depth import inverse_depth_image

#: Application id of every recording dmtrack makes.
APPLICATION_ID = "dmtrack"
#: ``align(src, dst) → (s, R, t)`` with dst ≈ s·R·src + t (the signature of ``evaluation.alignment.umeyama``).
Aligner = Callable[[np.ndarray, np.ndarray], tuple[float, np.ndarray, np.ndarray]]
#: Port of the spawned viewer (rerun's default).
VIEWER_PORT = 9876
#: Frames per piece of the estimated trajectory (a piece is re-logged whole while it grows).
TRAJECTORY_PIECE = 100
#: The series of the ``timing`` entity (milliseconds per frame).
TIMING_SERIES = ("pyramid", "tracking", "mapping", "odometry", "frame")
#: Largest time difference (seconds) when matching ground-truth and estimated poses, as the run's metrics.
GROUNDTRUTH_MAX_DIFF = 0.01
_UNIX_TIME = 1e8  # timestamps above this (1973) are Unix times
#: Colours of the SLAM layer: the optimised keyframes and their path, odometry edges, loop edges.
SLAM_COLOUR = (250, 200, 40)
EDGE_COLOURS = {"odometry": (150, 150, 150), "loop": (230, 40, 200)}


def import_rerun() -> Any:
    """The ``rerun`` module, or an :class:`InputError` saying how to install it."""
    try:
        import rerun
    except ImportError:
        raise InputError("the viewer needs rerun-sdk: pip install 'dmtrack[viewer]'") from None
    return rerun


def blueprint(rr: Any, live: bool = True) -> Any:
    """The viewer layout: the 3D world beside the keyframe depth and — live — the frame, the statistics and the log,
    or — for a finished run folder — its metrics and configuration."""
    import rerun.blueprint as rrb

    if live:
        side = [
            rrb.Spatial2DView(origin="world/camera/image", name="frame"),
            rrb.Tabs(
                rrb.Spatial2DView(origin="keyframe/depth", name="keyframe inverse depth"),
                rrb.Spatial2DView(origin="keyframe/initial_map", name="initial map"),
            ),
            rrb.Tabs(
                rrb.TimeSeriesView(origin="stats/residual", name="residual"),
                rrb.TimeSeriesView(origin="stats/points", name="points"),
                rrb.TimeSeriesView(origin="stats/point_usage", name="usage"),
                rrb.TimeSeriesView(origin="stats/keyframe_id", name="keyframe"),
                rrb.TimeSeriesView(origin="timing", name="ms"),
            ),
            rrb.TextLogView(origin="log", name="log"),
        ]
    else:
        side = [
            rrb.Tabs(
                rrb.Spatial2DView(origin="keyframe/depth", name="keyframe inverse depth"),
                rrb.Spatial2DView(origin="keyframe/initial_map", name="initial map"),
            ),
            rrb.Tabs(
                rrb.TextDocumentView(origin="run/metrics", name="metrics"),
                rrb.TextDocumentView(origin="run/config", name="config"),
            ),
        ]
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Spatial3DView(origin="world", name="3D"), rrb.Vertical(*side), column_shares=[3, 2]),
        collapse_panels=True,
    )


def _check_display() -> None:
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise InputError(
            "the viewer needs a display (neither DISPLAY nor WAYLAND_DISPLAY is set): record with --rrd FILE and "
            "open it with `rerun FILE` where there is one"
        )


class Recording:
    """A rerun :class:`RecordingStream` of its own (not the global one) to a spawned viewer and/or an .rrd file.

    The viewer (listening on ``port``; one already listening there is used instead) is spawned at once; the stream
    and the .rrd's temporary file (next to ``rrd``, renamed into place by :meth:`close`) are made on the first use of
    :attr:`stream` — for a run, after the run folder has been cleaned of stale temporary files, which may be the
    .rrd's folder too. ``live`` picks the layout (:func:`blueprint`) of a running odometry, or of a finished run
    folder.

    Raises
    ------
    InputError
        rerun-sdk is missing; neither ``spawn`` nor ``rrd``; ``spawn`` without a display (Linux).
    """

    def __init__(
        self,
        *,
        spawn: bool = False,
        rrd: str | Path | None = None,
        recording_id: str | None = None,
        live: bool = True,
        port: int = VIEWER_PORT,
    ) -> None:
        rr = import_rerun()
        if not spawn and rrd is None:
            raise InputError("a rerun recording needs spawn=True or an .rrd path")
        if spawn:
            _check_display()
        self.rr = rr
        self.rrd = None if rrd is None else Path(rrd)
        self.spawn = bool(spawn)
        self.port = int(port)
        self._blueprint = blueprint(rr, live)
        with contextlib.suppress(ImportError):  # rerun's first blueprint conversion imports pandas (≈ 0.2 s):
            importlib.import_module("pandas")  # now, rather than during the first frame
        self._stream = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)  # its sinks come in .stream
        if spawn:
            rr.spawn(port=self.port, connect=False, recording=self._stream)  # starts while the run gets ready
        self._open = False
        self._files = contextlib.ExitStack()
        self._closed = False

    @property
    def is_open(self) -> bool:
        """Whether :attr:`stream` has been used (its sinks are set up)."""
        return self._open

    @property
    def stream(self) -> Any:
        """The ``rr.RecordingStream``; its sinks (and the .rrd's temporary file) are set up on first use.

        Raises
        ------
        OutputError
            The .rrd's folder cannot be written.
        """
        if not self._open:
            if self._closed:
                raise RuntimeError("the recording is closed")
            rr, stream = self.rr, self._stream
            try:
                sinks = []
                if self.rrd is not None:
                    tmp = self._files.enter_context(atomic_path(self.rrd))
                    sinks.append(rr.FileSink(str(tmp)))
                if self.spawn:
                    sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{self.port}/proxy"))
                stream.set_sinks(*sinks, default_blueprint=self._blueprint)
            except BaseException:
                self._files.__exit__(*sys.exc_info())  # removes the temporary file
                raise
            self._open = True
        return self._stream

    def close(self) -> None:
        """Flush and disconnect, then move the .rrd into place (idempotent; a recording never used is written
        empty)."""
        if self._closed:
            return
        stream = self.stream
        self._closed = True
        try:
            try:
                stream.flush()
            except RuntimeError as e:  # the viewer went away: the file sink still has everything
                warnings.warn(f"viewer: {e}", stacklevel=2)
            stream.disconnect()  # writes the file's footer
        except BaseException:
            self._files.__exit__(*sys.exc_info())  # removes the temporary file
            raise
        self._files.close()  # renames it into place

    def discard(self) -> None:
        """Disconnect and remove the unfinished .rrd (nothing is renamed into place); no-op after :meth:`close`."""
        if self._closed:
            return
        self._closed = True
        try:
            self._stream.disconnect()
        finally:
            self._files.__exit__(InputError, InputError("recording discarded"), None)  # removes the temporary file


def aligned_groundtruth(
    est_times: np.ndarray, est_positions: np.ndarray, gt: Trajectory, align: Aligner
) -> np.ndarray | None:
    """The ground-truth positions within the estimate's time span, in the estimate's frame.

    The similarity comes from ``align`` on the positions of the poses whose timestamps match within
    :data:`GROUNDTRUTH_MAX_DIFF`; ``None`` when fewer than 3 match or they are degenerate (all in one place).
    """
    if len(est_times) < 3 or len(gt) < 3:
        return None
    i_est, i_gt = associate(est_times, gt.timestamps, GROUNDTRUTH_MAX_DIFF)
    if len(i_est) < 3:
        return None
    try:
        s, R, t = align(gt.positions[i_gt], np.asarray(est_positions, dtype=np.float64)[i_est])
    except ValueError:  # all points in one place: the similarity is undetermined
        return None
    lo, hi = float(np.min(est_times)), float(np.max(est_times))
    span = (gt.timestamps >= lo - GROUNDTRUTH_MAX_DIFF) & (gt.timestamps <= hi + GROUNDTRUTH_MAX_DIFF)
    order = np.argsort(gt.timestamps[span], kind="stable")
    return s * gt.positions[span][order] @ np.asarray(R).T + np.asarray(t)


def pinhole(rr: Any, camera: Any, downscale: int = 1, **kwargs: Any) -> Any:
    """A ``rr.Pinhole`` of ``camera`` for its image downscaled by an integer factor (pixel centres kept)."""
    k = float(downscale)
    return rr.Pinhole(
        focal_length=[camera.fx / k, camera.fy / k],
        principal_point=[(camera.cx + 0.5) / k - 0.5, (camera.cy + 0.5) / k - 0.5],
        resolution=[camera.width // downscale, camera.height // downscale],
        **kwargs,
    )


def jpeg(rr: Any, image: np.ndarray, quality: int) -> Any:
    """An ``rr.EncodedImage`` of an RGB or grey uint8 image."""
    bgr = cv2.cvtColor(image, cv2.COLOR_RGB2BGR) if image.ndim == 3 else image
    ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError(f"OpenCV cannot encode this image as JPEG ({image.shape}, {image.dtype})")
    return rr.EncodedImage(contents=data.tobytes(), media_type="image/jpeg")


def log_graph(
    rr: Any, stream: Any, positions: np.ndarray, segments: dict[str, np.ndarray], static: bool = False
) -> None:
    """The ``world/slam`` entities: keyframe centres ``(n, 3)`` (in keyframe order) and, by edge kind
    (``odometry``, ``loop``), the edges' end points ``(m, 2, 3)``; every kind of :data:`EDGE_COLOURS` is logged
    (empty when it has no edge), so that a later graph replaces an earlier one."""
    pos = np.asarray(positions, dtype=np.float32).reshape(-1, 3)
    stream.log("world/slam/keyframes", rr.Points3D(pos, colors=[SLAM_COLOUR], radii=[-4.0]), static=static)
    stream.log("world/slam/trajectory", rr.LineStrips3D([pos], colors=[SLAM_COLOUR], radii=[-1.5]), static=static)
    for kind, colour in EDGE_COLOURS.items():
        seg = np.asarray(segments.get(kind, np.zeros((0, 2, 3))), dtype=np.float32).reshape(-1, 2, 3)
        stream.log(f"world/slam/edges/{kind}", rr.LineStrips3D(list(seg), colors=[colour], radii=[-1.0]),
                   static=static)  # fmt: skip


class RerunSink:
    """Logs a run to the Rerun viewer and/or an .rrd file (see the module docstring for what is logged).

    Parameters
    ----------
    spawn : launch the native viewer and stream to it (needs a display).
    port : the viewer's port; a viewer already listening there is used, none is launched.
    rrd : write the recording to this .rrd file (atomically, when the sink closes).
    recording_id : the recording's id (default: a random one); the application id is ``"dmtrack"``.
    groundtruth : the sequence's ground truth (T_wc, dataset frame), drawn aligned to the estimate.
    align : the similarity fit for the ground truth (``dmtrack.evaluation.alignment.umeyama``); required with
        ``groundtruth``.
    image_downscale : integer factor by which the frame image and the depth overlay are shrunk (2: 320×240 for
        640×480), to keep the per-frame cost and the file small.
    jpeg_quality : JPEG quality of the frame and overlay images.
    max_point_var : keep only points whose inverse-depth variance is at most this (keyframe units), as
        :class:`~dmtrack.outputs.run_directory.RunDirectorySink`; ``None`` keeps every hypothesis.
    frustum_size : distance of the drawn image planes from the camera centres (world units; the first keyframe
        has mean inverse depth 1).

    Raises
    ------
    InputError
        rerun-sdk is not installed; neither ``spawn`` nor ``rrd``; ``spawn`` without a display; ``groundtruth``
        without ``align``.
    """

    def __init__(
        self,
        *,
        spawn: bool = False,
        rrd: str | Path | None = None,
        recording_id: str | None = None,
        groundtruth: Trajectory | None = None,
        align: Aligner | None = None,
        image_downscale: int = 2,
        jpeg_quality: int = 75,
        max_point_var: float | None = None,
        frustum_size: float = 0.1,
        port: int = VIEWER_PORT,
    ) -> None:
        if groundtruth is not None and align is None:
            raise InputError("RerunSink: a ground truth needs align= (dmtrack.evaluation.alignment.umeyama)")
        if int(image_downscale) < 1:
            raise InputError(f"RerunSink: image_downscale must be ≥ 1, got {image_downscale}")
        self.recording = Recording(spawn=spawn, rrd=rrd, recording_id=recording_id, port=port)
        self.rr = self.recording.rr
        self.groundtruth = groundtruth if groundtruth is not None and len(groundtruth) else None
        self.align = align
        self.image_downscale = int(image_downscale)
        self.jpeg_quality = int(jpeg_quality)
        self.max_point_var = max_point_var
        self.frustum_size = float(frustum_size)
        self._kf_image: tuple[int, np.ndarray] | None = None  # (keyframe frame index, its downscaled image)
        self._times: list[float] = []
        self._positions: list[np.ndarray] = []
        self._relocalisations: list[np.ndarray] = []  # positions where a lost run was found again
        self._time_kind: str | None = None
        self._camera_logged = False
        self._last_wall: float | None = None
        self.n_frames = 0
        self.n_keyframes = 0
        self.n_points = 0
        self.n_graph_updates = 0
        self._closed = False

    # ------------------------------------------------------------------ helpers
    @property
    def stream(self) -> Any:
        """The recording stream, made (with the static entities) on the first call of the odometry."""
        if not self.recording.is_open:
            rr, stream = self.rr, self.recording.stream
            stream.log("world", rr.ViewCoordinates.RDF, static=True)
            stream.log("stats/points", rr.SeriesLines(names=["good", "bad"]), static=True)
            stream.log("timing", rr.SeriesLines(names=list(TIMING_SERIES)), static=True)
        return self.recording.stream

    def _at(self, frame_index: int, timestamp: float) -> None:
        if self._time_kind is None:
            self._time_kind = "timestamp" if timestamp > _UNIX_TIME else "duration"
        self.stream.set_time("frame", sequence=int(frame_index))
        self.stream.set_time("time", **{self._time_kind: float(timestamp)})

    def _log_camera(self, camera: Any) -> None:
        if self._camera_logged or camera is None:
            return
        self._camera_logged = True
        self.stream.log(
            "world/camera/image",
            pinhole(self.rr, camera, self.image_downscale, image_plane_distance=self.frustum_size),
            static=True,
        )

    def _log_groundtruth(self) -> None:
        if self.groundtruth is None or self.align is None:
            return
        pos = aligned_groundtruth(np.array(self._times), np.array(self._positions), self.groundtruth, self.align)
        if pos is not None:
            self.stream.log(
                "world/trajectory/groundtruth", self.rr.LineStrips3D([pos], colors=[[60, 200, 60]], radii=[-1.5])
            )

    # ------------------------------------------------------------------ sink protocol
    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        rr = self.rr
        self._at(frame_index, timestamp)
        T = np.asarray(T_wc, dtype=np.float64)
        self.stream.log("world/camera", rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]))
        self._times.append(float(timestamp))
        self._positions.append(T[:3, 3].copy())
        # piece p joins poses p·P … (p+1)·P (it shares its last pose with the next piece)
        j = len(self._positions) - 1
        piece = max(j - 1, 0) // TRAJECTORY_PIECE
        strip = np.array(self._positions[piece * TRAJECTORY_PIECE : j + 1])
        self.stream.log(
            f"world/trajectory/estimate/{piece:04d}", rr.LineStrips3D([strip], colors=[[230, 80, 40]], radii=[-1.5])
        )
        self.n_frames += 1

    def on_keyframe(
        self,
        keyframe_id: int,
        frame_index: int,
        timestamp: float,
        T_wc: np.ndarray,
        depthmap_snapshot: KeyframeSnapshot,
    ) -> None:
        rr = self.rr
        snap = depthmap_snapshot
        T = np.asarray(T_wc, dtype=np.float64)
        self._log_camera(snap.camera)
        pts, cols = snap.points_world(self.max_point_var)
        kf = f"{keyframe_id:04d}"
        self.stream.log(f"world/keyframes/{kf}", rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]))
        self.stream.log(
            f"world/keyframes/{kf}/frustum",
            pinhole(rr, snap.camera, 1, image_plane_distance=0.5 * self.frustum_size, color=[80, 140, 255]),
        )
        self.stream.log(f"world/points/{kf}", rr.Points3D(pts.astype(np.float32), colors=cols))
        self.stream.log(
            "log", rr.TextLog(f"keyframe {keyframe_id} (frame {frame_index}): {len(pts)} points, "
                              f"{snap.n_updates} frames mapped", level=rr.TextLogLevel.INFO),
        )  # fmt: skip
        self.n_keyframes += 1
        self.n_points += len(pts)
        self._log_groundtruth()

    def on_initial_map(self, snapshot: KeyframeSnapshot) -> None:
        """The first keyframe's map as the start made it: its points and its inverse depth over the image."""
        rr = self.rr
        self._at(snapshot.frame_index, snapshot.timestamp)
        pts, cols = snapshot.points_world(self.max_point_var)
        self.stream.log("world/initial_map", rr.Points3D(pts.astype(np.float32), colors=cols))
        if snapshot.image is not None:
            k = self.image_downscale
            overlay = inverse_depth_image(snapshot.idepth[::k, ::k], snapshot.valid[::k, ::k], snapshot.image[::k, ::k])
            self.stream.log("keyframe/initial_map", jpeg(rr, overlay, self.jpeg_quality))
        self.stream.log("log", rr.TextLog(f"initial map (frame {snapshot.frame_index}): {len(pts)} points",
                                          level=rr.TextLogLevel.INFO))

    def on_lost(self, frame_index: int, reason: str) -> None:
        self.stream.set_time("frame", sequence=int(frame_index))
        self.stream.log(
            "log", self.rr.TextLog(f"tracking lost at frame {frame_index}: {reason}", level=self.rr.TextLogLevel.WARN)
        )
        self.stream.log("stats/lost", self.rr.Scalars(1.0))  # the lost span on the time line

    def on_relocalised(self, frame_index: int, timestamp: float, keyframe_id: int, lost_since: int,
                       T_wc: np.ndarray) -> None:  # fmt: skip
        """Where a run that was lost found the camera again: a magenta point in the world, and a log line."""
        rr = self.rr
        self._at(frame_index, timestamp)
        self._relocalisations.append(np.asarray(T_wc, dtype=np.float64)[:3, 3].copy())
        self.stream.log("world/relocalisations", rr.Points3D(np.array(self._relocalisations, np.float32),
                                                             colors=[[255, 0, 255]], radii=[-6.0]))  # fmt: skip
        self.stream.log("stats/lost", rr.Scalars(0.0))
        self.stream.log("log", rr.TextLog(f"relocalised at frame {frame_index} on keyframe {keyframe_id}, lost since "
                                          f"frame {lost_since}", level=rr.TextLogLevel.INFO))  # fmt: skip

    def on_window(self, frame_index: int, timestamp: float, poses: dict[int, np.ndarray]) -> None:
        """The sliding window after an optimisation: its keyframes' positions, joined in order, in orange."""
        rr = self.rr
        self._at(frame_index, timestamp)
        pts = np.array([np.asarray(poses[k], np.float64)[:3, 3] for k in sorted(poses)], np.float32)
        self.stream.log("world/window", rr.LineStrips3D([pts], colors=[[255, 140, 0]], radii=[-2.0]))
        self.stream.log("world/window/keyframes", rr.Points3D(pts, colors=[[255, 140, 0]], radii=[-5.0]))

    def on_frame_info(self, info: FrameInfo) -> None:
        """The frame's image, the keyframe's inverse depth and the tracker's numbers."""
        rr, k = self.rr, self.image_downscale
        self._at(info.frame_index, info.timestamp)
        self._log_camera(info.camera)
        if info.image is not None:
            image = info.image
            if k > 1:
                image = cv2.resize(image, (image.shape[1] // k, image.shape[0] // k), interpolation=cv2.INTER_AREA)
            self.stream.log("world/camera/image", jpeg(rr, image, self.jpeg_quality))
        if info.keyframe_image is not None:
            if self._kf_image is None or self._kf_image[0] != info.keyframe_frame_index:
                self._kf_image = (info.keyframe_frame_index, np.ascontiguousarray(info.keyframe_image[::k, ::k]))
            idepth = info.keyframe_idepth[::k, ::k]
            overlay = inverse_depth_image(idepth, info.keyframe_idepth_var[::k, ::k] > 0, self._kf_image[1])
            self.stream.log("keyframe/depth", jpeg(rr, overlay, self.jpeg_quality))
        if np.isfinite(info.point_usage):  # the frame was tracked (not the first one)
            self.stream.log("stats/residual", rr.Scalars(info.residual))
            self.stream.log("stats/points", rr.Scalars([info.good_count, info.bad_count]))
            self.stream.log("stats/point_usage", rr.Scalars(info.point_usage))
        self.stream.log("stats/keyframe_id", rr.Scalars(info.keyframe_id))
        now = time.perf_counter()
        ms = [info.pyramid_ms, info.tracking_ms, info.mapping_ms, info.pyramid_ms + info.tracking_ms + info.mapping_ms]
        if self._last_wall is not None:
            ms.append(1e3 * (now - self._last_wall))
        self._last_wall = now
        self.stream.log("timing", rr.Scalars(ms))

    def on_graph_optimised(self, graph: OptimisedGraph) -> None:
        """The SLAM graph after an optimisation (:class:`~dmtrack.slam.listener.GraphListener`; called from the
        back end's thread): the keyframes at their optimised poses and the accepted edges, at the newest keyframe's
        frame. Ignored once the sink is closed."""
        if self._closed or len(graph.keyframe_ids) == 0:
            return
        self._at(int(graph.frame_indices[-1]), float(graph.timestamps[-1]))  # this thread's time
        log_graph(self.rr, self.stream, graph.positions, {k: graph.segments(k) for k in EDGE_COLOURS})
        loops = sum(1 for e in graph.edges if e[2] == "loop")
        self.stream.log("log", self.rr.TextLog(
            f"graph optimised ({graph.optimisation}{', final' if graph.final else ''}): "
            f"{len(graph.keyframe_ids)} keyframes, {loops} loop closures", level=self.rr.TextLogLevel.INFO,
        ))  # fmt: skip
        self.n_graph_updates += 1

    def close(self) -> None:
        """Log the final ground-truth alignment, then close the recording (the .rrd moves into place)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._log_groundtruth()
        finally:
            self.recording.close()

    def discard(self) -> None:
        """Drop the recording without writing the .rrd, unless :meth:`close` already wrote it (for a run that failed
        before its odometry started, and so never closed this sink)."""
        self._closed = True
        self.recording.discard()
