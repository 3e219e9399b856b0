"""The ``dmtrack`` command line.

Every subcommand exits 0 on success and otherwise prints one line ``dmtrack: error: …`` on stderr naming the
file or argument and the problem (exit status 1 for bad input, 2 for bad usage).  Heavy modules are
imported inside the subcommands so that ``dmtrack --help`` stays fast and headless use never imports a
plotting backend.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import warnings
from collections.abc import Iterator as _Iter
from collections.abc import Sequence as _Seq
from typing import Any

from dmtrack import __version__
from dmtrack.errors import DmtrackError, Interrupted
from dmtrack.io.argtypes import fraction


def _add_sequence_args(p: argparse.ArgumentParser, optional: bool = False) -> None:
    from dmtrack.datasets.registry import FORMATS

    p.add_argument("sequence", nargs="?" if optional else None,
                   help="sequence folder or video file, camera:N / rtsp://… / http(s)://… (live), or "
                   "synthetic[:key=value,...]")
    p.add_argument("--format", choices=FORMATS, help="force the dataset format instead of detecting it")
    p.add_argument(
        "--intrinsics",
        metavar="FX,FY,CX,CY|FILE",
        help="pinhole intrinsics (pixels of the stored images) replacing or supplying the dataset's, or a "
        "calibration file (fx fy cx cy, or the DSO file calibrate-camera writes: frames are undistorted with it)",
    )
    p.add_argument("--topic", metavar="TOPIC",
                   help="of a ROS bag (a ROS 1 .bag or a ROS 2 bag folder): the image topic (Image or CompressedImage; "
                        "not needed when the bag has one)")


def _sequence_summary(seq: Any) -> dict[str, Any]:
    import numpy as np

    from dmtrack.geometry.camera import PinholeCamera

    cam: PinholeCamera | None = seq.camera
    info: dict[str, Any] = {
        "name": seq.name,
        "format": seq.format,
        "path": str(getattr(seq, "root", seq.name)),
        "frames": len(seq),
        "width": seq.width,
        "height": seq.height,
        "fx": None if cam is None else cam.fx,
        "fy": None if cam is None else cam.fy,
        "cx": None if cam is None else cam.cx,
        "cy": None if cam is None else cam.cy,
        "has_groundtruth": bool(seq.has_groundtruth),
        "has_depth": bool(getattr(seq, "has_depth", False)),
    }
    ts = np.asarray(seq.timestamps)
    info["duration"] = float(ts[-1] - ts[0]) if len(ts) > 1 else 0.0
    info["rate_hz"] = float((len(ts) - 1) / info["duration"]) if info["duration"] > 0 else None
    gt = seq.groundtruth
    if gt is not None:
        info["groundtruth_frames"] = len(gt)
        info["groundtruth_path_length"] = gt.path_length()
    if cam is not None:
        cropped, box = cam.crop_to_multiple(16)
        info["crop16"] = {
            "width": cropped.width,
            "height": cropped.height,
            "left": box[0],
            "top": box[1],
            "fx": cropped.fx,
            "fy": cropped.fy,
            "cx": cropped.cx,
            "cy": cropped.cy,
        }
    info["details"] = dict(getattr(seq, "details", {}))
    return info


def _print_summary(info: dict[str, Any]) -> None:
    def fmt(v: Any) -> str:
        return f"{v:g}" if isinstance(v, float) else str(v)

    rows = [
        ("sequence", f"{info['name']}  ({info['format']})"),
        ("path", info["path"]),
        ("frames", f"{info['frames']}  ({fmt(round(info['duration'], 3))} s"
         + (f", {info['rate_hz']:.1f} Hz)" if info["rate_hz"] else ")")),
        ("image size", f"{info['width']}x{info['height']}"),
    ]
    if info["fx"] is None:
        rows.append(("intrinsics", "none — give --intrinsics FX,FY,CX,CY or put camera.txt in the folder"))
    else:
        rows.append(("intrinsics", "fx={} fy={} cx={} cy={}".format(*(fmt(info[k]) for k in ("fx", "fy", "cx", "cy")))))
        c = info["crop16"]
        if (c["width"], c["height"]) != (info["width"], info["height"]):
            rows.append(("tracked as", f"{c['width']}x{c['height']} (cropped to multiples of 16; "
                         f"left {c['left']}, top {c['top']}), cx={fmt(c['cx'])} cy={fmt(c['cy'])}"))
    if info["has_groundtruth"]:
        rows.append(("ground truth", f"{info['groundtruth_frames']} frames, path length "
                     f"{info['groundtruth_path_length']:.3f}"))
    else:
        rows.append(("ground truth", "none"))
    rows.append(("depth", "yes" if info["has_depth"] else "no"))
    for k, v in info["details"].items():
        rows.append((k.replace("_", " "), fmt(v)))
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")


def _open_sequence_args(args: argparse.Namespace) -> Any:
    """The sequence named on the command line, with ``--format``, ``--intrinsics`` and (of a ROS bag) ``--topic``."""
    from dmtrack.datasets import open_sequence
    from dmtrack.datasets.registry import detect_format
    from dmtrack.errors import InputError

    options = {}
    if args.topic is not None:
        if (args.format or detect_format(args.sequence)) != "rosbag":
            raise InputError(f"--topic {args.topic}: only a ROS bag has topics, {args.sequence} is not one")
        options["topic"] = args.topic
    return open_sequence(args.sequence, format=args.format, intrinsics=args.intrinsics, **options)


def _bag_topics(args: argparse.Namespace) -> list[dict[str, Any]] | None:
    """The image topics of a ROS bag (``dmtrack info BAG``), or None for another sequence."""
    from dmtrack.datasets.registry import detect_format

    if (args.format or detect_format(args.sequence)) != "rosbag":
        return None
    import dataclasses

    from dmtrack.datasets.rosbag import image_topics

    return [dataclasses.asdict(t) for t in image_topics(args.sequence)]


def cmd_info(args: argparse.Namespace) -> int:
    if args.sequence is None:  # the machine: versions and whether the network features can use a GPU
        return _print_environment(args.json)
    topics = _bag_topics(args)
    if topics is not None and args.topic is None and len(topics) != 1:  # a bag: its image topics, then choose one
        if args.json:
            print(json.dumps({"format": "rosbag", "path": str(args.sequence), "image_topics": topics}, indent=2))
        else:
            _print_topics(topics)
            print(f"choose one with --topic ({len(topics)} image topics)")
        return 0
    info = _sequence_summary(_open_sequence_args(args))
    if topics is not None:
        info["image_topics"] = topics
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        _print_summary(info)
        if topics is not None:
            _print_topics(topics)
    return 0


def _print_topics(topics: list[dict[str, Any]]) -> None:
    print("image topics:" if topics else "image topics: none")
    for t in topics:
        kind = "CompressedImage" if t["msgtype"].endswith("CompressedImage") else "Image"
        info = f", intrinsics from {t['camera_info']}" if t["camera_info"] else ", no camera_info"
        print(f"  {t['topic']}  ({kind}, {t['count']} messages{info})")


def _print_environment(as_json: bool) -> int:
    import platform

    import numba
    import numpy as np

    from dmtrack.features.device import gpu_line, gpu_status

    env = {"dmtrack": __version__, "python": platform.python_version(), "numpy": np.__version__,
           "numba": numba.__version__, "numba_threads": int(numba.config.NUMBA_NUM_THREADS), "gpu": gpu_status()}
    if as_json:
        print(json.dumps(env, indent=2))
        return 0
    print(f"dmtrack {env['dmtrack']}: python {env['python']}, numpy {env['numpy']}, numba {env['numba']} "
          f"({env['numba_threads']} threads)")
    print(gpu_line())
    return 0


def _device_spec(value: str) -> str:
    """argparse type of ``--device``."""
    from dmtrack.errors import InputError
    from dmtrack.features.device import check_device

    try:
        return str(check_device(value))
    except InputError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _add_device_arg(p: argparse.ArgumentParser, what: str = "the network features") -> None:
    p.add_argument("--device", type=_device_spec, metavar="auto|cpu|cuda[:N]",
                   help=f"where {what} run: auto (default: a CUDA GPU when PyTorch sees one, else the CPU), cpu, "
                        "cuda or cuda:N; the hand-crafted features always run on the CPU")


def _limit_threads(threads: int | None) -> None:
    """``--threads N``: the threads of the kernels and of the features (before numba is imported)."""
    if threads is None:
        return
    from dmtrack.errors import InputError
    from dmtrack.experiments.task import limit_threads

    if threads < 1:
        raise InputError(f"--threads must be ≥ 1, got {threads}")
    os.environ["DMTRACK_FEATURE_THREADS"] = str(threads)
    limit_threads(threads)


def _slam_line(m: dict) -> str:
    if m.get("slam_error"):
        return f"slam: the back end failed ({m['slam_error']}); trajectory.txt is the odometry's"
    line = (f"slam: {m['loop_closures']} loop closures ({m['loop_candidates_tested']} candidates tested), "
            f"{m['graph_edges']} graph edges, optimisation {m['optimisation_ms']:.0f} ms")
    if m.get("vo_ate_rmse") is not None:
        line += f"; odometry alone: ATE {m['vo_ate_rmse']:.4f}, RPE rotation {m['vo_rpe_rot_deg_per_m']:.3f} deg/unit"
    return line


def cmd_run(args: argparse.Namespace) -> int:
    from pathlib import Path

    _limit_threads(args.threads)
    if args.threads is None:  # OpenCV's idle workers spin (sched_yield) beside numba's: 0.35 s of CPU a 700-frame run
        import cv2

        cv2.setNumThreads(1)

    from dmtrack.api import run_to_directory
    from dmtrack.odometry.config import VOConfig

    config = VOConfig.from_yaml(args.config) if args.config else VOConfig()
    if args.set:
        config = config.with_overrides(*args.set)
    if args.continue_after_loss:
        config = config.with_overrides("stop_on_loss=false")
    if args.init:
        config = config.with_overrides(f"init={args.init}")
    if args.window is not None:
        config = config.with_overrides(f"window.size={args.window}")
    if args.refine_intrinsics:
        config = config.with_overrides("window.refine_intrinsics=true")
    out = Path(args.out) if args.out else Path("out") / f"{Path(str(args.sequence)).name}-{args.feature}"
    from dmtrack.features import get_feature

    feature = get_feature(args.feature, **_feature_options(args.feature_opt, args.device))
    if args.rosbag_out:
        from dmtrack.io.rosbag import rosbags_modules

        rosbags_modules("--rosbag-out")  # without rosbags: one line, before the run
    sequence, viewers = _run_viewers(args)
    try:
        result = run_to_directory(
            sequence,
            out,
            feature=feature,
            config=config,
            start=args.start,
            max_frames=args.max_frames,
            frames=args.frames,
            seed=args.seed,
            format=args.format,
            intrinsics=args.intrinsics,
            r_l=args.r_l,
            depth_images=not args.no_depth_images,
            pointcloud=not args.no_pointcloud,
            progress=None if args.progress is None else args.progress,
            extra_sinks=viewers,
            realtime=args.realtime,
            slam=args.slam or None,
        )
    except KeyboardInterrupt as e:  # Ctrl-C or SIGTERM: the finished frames and their metrics are saved
        print(f"dmtrack: {_interrupt_text(e)}: the trajectory and metrics of the finished frames are in {out}/",
              file=sys.stderr)
        return _interrupt_code(e)
    finally:
        for v in viewers:
            v.discard()  # only a run that failed before its odometry started has left it open
    m = result.metrics
    lost = "never lost" if m["lost_at"] is None else f"lost at frame {m['lost_at']} ({m['lost_reason']})"
    print(f"{m['sequence']} [{m['feature']}]: tracked {m['tracked_frames']}/{m['total_frames']} frames, {lost}; "
          f"{m['keyframes']} keyframes, {m.get('points', 0)} points")
    if m.get("init_accepted_frame") is not None:
        print(f"start: geometric, first map accepted at frame {m['init_accepted_frame']} ({m['init_s']:.2f} s)")
    elif m.get("init_fallback"):
        print(f"start: geometric refused, random map (seed {m['seed']}) instead")
    if m.get("realtime"):
        print(f"realtime: {m['dropped_frames']} frames dropped")
    if m.get("lost_frames") or m.get("relocalisations"):
        found = ", ".join(f"frame {r['frame']} on keyframe {r['keyframe']} (lost since {r['lost_since']})"
                          for r in m.get("relocalised", [])[:5])  # fmt: skip
        segments = len(m.get("segments", []))
        print(f"losses: {m['lost_frames']} frames without a pose, {m['relocalisations']} relocalisations"
              + (f": {found}" if found else "") + (f"; {segments} map segments" if segments > 1 else ""))
    where = f" on {m['device']} ({m['gpu']})" if m.get("gpu") else ""
    print(f"speed: {m['fps']:.1f} fps  (per frame: feature {m['feature_ms']:.1f} ms{where}, "
          f"tracking {m['tracking_ms']:.1f} ms, mapping {m['mapping_ms']:.1f} ms, reading {m['io_ms']:.1f} ms); "
          f"kernels compiled/loaded in {m['compile_s']:.1f} s before the first frame, not counted")
    if m.get("ate_rmse") is not None:
        print(f"accuracy: RPE rotation {m['rpe_rot_deg_per_m']:.3f} deg/unit, translation angle "
              f"{m['rpe_trans_angle_deg_per_m']:.3f} deg/unit (r_l = {m['r_l']:.4g}), ATE {m['ate_rmse']:.4f} "
              f"(Sim3), {m['matched_poses']} poses")
        from dmtrack.evaluation.metrics import rotation_gain_text

        for line in rotation_gain_text(m.get("rotation_gain")):
            print(line)
    elif "evaluation_error" in m:
        print(f"accuracy: not evaluated ({m['evaluation_error']})")
    if m.get("slam"):
        print(_slam_line(m))
    if args.rosbag_out:
        from dmtrack.io.rosbag import write_trajectory_bag

        traj = result.trajectory
        write_trajectory_bag(args.rosbag_out, traj.timestamps, traj.poses)
        print(f"ROS 2 bag: {args.rosbag_out}/ ({len(traj)} odometry and /tf messages, one path)")
    print(f"outputs: {out}/" + (f", recording: {args.rrd}" if args.rrd else ""))
    return 0


def _run_viewers(args: argparse.Namespace) -> tuple[Any, tuple[Any, ...]]:
    """The sequence to run and, for ``--viewer`` / ``--rrd``, a RerunSink with the sequence's ground truth (opened
    here once and handed to the run as a Sequence)."""
    if not (args.viewer or args.rrd):
        return (args.sequence if args.topic is None else _open_sequence_args(args)), ()
    from dmtrack.evaluation.alignment import umeyama
    from dmtrack.outputs.rerun_sink import RerunSink

    seq = _open_sequence_args(args)
    return seq, (RerunSink(spawn=args.viewer, rrd=args.rrd, groundtruth=seq.groundtruth, align=umeyama),)


def _kernel_counts() -> tuple[int, int, set[str]]:
    """numba's compilations and cache loads so far in dmtrack's kernels, and the cache folders they use."""
    from numba.core.dispatcher import Dispatcher

    kernels = {id(v): v for name, mod in list(sys.modules.items()) if name.startswith("dmtrack.") and mod is not None
               for v in vars(mod).values() if isinstance(v, Dispatcher)}  # fmt: skip
    stats = [k.stats for k in kernels.values()]
    compiled = sum(sum(st.cache_misses.values()) for st in stats)
    loaded = sum(sum(st.cache_hits.values()) for st in stats)
    return compiled, loaded, {st.cache_path for st in stats if st.cache_path}


def cmd_warmup(args: argparse.Namespace) -> int:
    _limit_threads(args.threads)

    from dmtrack.errors import InputError
    from dmtrack.features import feature_names, get_feature
    from dmtrack.pipeline import warm_up

    names = feature_names() if args.all else (args.feature or ["gray"])
    compiled, loaded, _ = _kernel_counts()
    for name in names:
        try:
            feature = get_feature(name)
            seconds = warm_up(feature, strict=True)
        except Exception as e:  # e.g. weights not downloaded, torch not installed
            if not args.all:
                raise
            print(f"{name:<14} skipped: {type(e).__name__}: {e}" if not isinstance(e, InputError) else
                  f"{name:<14} skipped: {e}")
            continue
        c, lo, _ = _kernel_counts()
        print(f"{name:<14} {seconds:6.1f} s  ({c - compiled} kernels compiled, {lo - loaded} loaded from the cache)")
        compiled, loaded = c, lo
    caches = _kernel_counts()[2]
    where = os.path.commonpath(sorted(caches)) if caches else "none (numba caching is off)"
    print(f"numba's cache: {where}")
    from dmtrack.io.machine import compile_bytecode

    written, failed = compile_bytecode(os.path.dirname(__file__))  # dmtrack's modules (pip compiles a wheel's)
    print(f"Python bytecode: {written} of dmtrack's modules compiled into __pycache__"
          + (f", {failed} could not be written (a read-only install: pip wrote them)" if failed else ""))
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    from dmtrack.evaluation.alignment import umeyama
    from dmtrack.outputs.rerun_view import log_run_folder

    spawn = args.spawn or not args.rrd
    info = log_run_folder(args.run_dir, spawn=spawn, rrd=args.rrd, align=umeyama)
    print(f"{args.run_dir}: {info['poses']} poses, {info['keyframes']} keyframes, {info['points']} points, "
          f"{info['depth_images']} depth pictures, ground truth {info['groundtruth']}"
          + (f"; recording: {args.rrd}" if args.rrd else ""))
    return 0


def cmd_features(args: argparse.Namespace) -> int:
    from dmtrack.features import list_features

    rows = list_features()
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'name':<16} {'N':>4}  {'scale':>8}  {'pyramid':<10} {'needs':<14} description")
    for r in rows:
        needs = ",".join(k for k in ("torch", "weights") if r.get(f"needs_{k}")) or "-"
        scale = "-" if r.get("scale") is None else f"{r['scale']:.4g}"
        print(f"{r['name']:<16} {r['channels']:>4}  {scale:>8}  {r.get('pyramid', ''):<10} {needs:<14} "
              f"{r.get('description', '')}")
    print(f"{'NAME-pcaK':<16} {'K':>4}  {'-':>8}  {'as NAME':<10} {'as NAME':<14} any name above reduced to its "
          "first K principal components: fit a basis with `dmtrack fit-pca --feature NAME --k K SEQUENCE...`, "
          "or pass --feature-opt pca=FILE.npz")
    from dmtrack.features.device import gpu_line

    print(gpu_line())
    return 0


def _sample_images(sequences: list[str], n: int, fmt: str | None, intrinsics: str | None) -> list:
    """``n`` frames spread evenly over each sequence (uint8 images)."""
    import numpy as np

    from dmtrack.datasets import open_sequence

    images = []
    for path in sequences:
        seq = open_sequence(path, format=fmt, intrinsics=intrinsics)
        idx = np.unique(np.linspace(0, len(seq) - 1, min(n, len(seq))).round().astype(int))
        images.extend(seq[int(i)].image for i in idx)
    return images


def cmd_calibrate_scale(args: argparse.Namespace) -> int:
    from dmtrack.features import get_feature
    from dmtrack.features.base import save_user_scale
    from dmtrack.features.scale import calibrate_scale_detailed

    with warnings.catch_warnings():  # "no calibration of its own" is what this command is about to measure
        warnings.simplefilter("ignore", UserWarning)
        feature = get_feature(args.feature, **_feature_options(args.feature_opt, args.device))
    images = _sample_images(args.sequences, args.frames, args.format, None)
    cal = calibrate_scale_detailed(feature, images, args.min_use_grad)
    result = {"feature": feature.name, "scale": cal.scale, "images": len(images), "min_use_grad": args.min_use_grad,
              **{k: v for k, v in vars(cal).items() if k != "scale" and isinstance(v, (int, float, str))}}
    if args.save:
        result["saved_to"] = str(save_user_scale(feature.name, cal.scale, feature.options, images=len(images),
                                                 sequences=[str(s) for s in args.sequences]))
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"default feature scale of {feature.name}: {cal.scale:.6g}  ({len(images)} images, "
              f"gradient threshold {args.min_use_grad:g})")
        if args.save:
            print(f"saved to {result['saved_to']}: used from now on when --feature {feature.name} has no scale")
    return 0


def cmd_fit_pca(args: argparse.Namespace) -> int:
    from pathlib import Path

    from dmtrack.features import get_feature
    from dmtrack.features.base import user_pca_path
    from dmtrack.features.pca import calibrate_reduced, fit_pca

    feature = get_feature(args.feature, **_feature_options(args.feature_opt, args.device))
    images = _sample_images(args.sequences, args.frames, args.format, None)
    basis = fit_pca(feature, images, k=args.k, n_samples=args.samples, seed=args.seed)
    # the reduced feature's own default scale and channel counts, stored with the basis
    basis = calibrate_reduced(feature, basis, args.k, images)
    default = user_pca_path(feature.name, args.k)
    out = Path(args.out) if args.out else default
    out.parent.mkdir(parents=True, exist_ok=True)
    out = basis.save(out)
    ratio = getattr(basis, "explained_variance_ratio", None)
    kept = f", {100 * float(sum(ratio)):.1f}% of the variance" if ratio is not None else ""
    cal = basis.calibration
    print(f"PCA basis of {feature.name}: {args.k} of {feature.channels} components{kept} -> {out}")
    print(f"calibrated {feature.name}-pca{args.k} on the same {len(images)} images: scale {cal.scale:.4g}, "
          f"N_E {cal.energy_channels:.3g}, kappa {cal.info_channels:.3g}, N_sigma {cal.noise_energy_channels:.3g}")
    where = "" if out.resolve() == default.resolve() else f" --feature-opt pca={out}"
    print(f"use it with --feature {feature.name}-pca{args.k}{where}")
    return 0


def _feature_options(items: list[str] | None, device: str | None = None) -> dict[str, Any]:
    """``key=value`` feature options; values parsed as YAML scalars (numbers, true/false, strings); ``--device``
    (when given) is the ``device`` option unless ``--feature-opt device=`` names one."""
    import yaml

    from dmtrack.errors import InputError

    options: dict[str, Any] = {}
    for item in items or []:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"--feature-opt {item!r}: expected key=value")
        options[key.strip()] = yaml.safe_load(raw)
    if device is not None:
        options.setdefault("device", device)
    return options


def cmd_eval(args: argparse.Namespace) -> int:
    from dmtrack.evaluation import evaluate, rotation_gain_text
    from dmtrack.io.trajectory import read_trajectory

    gt = read_trajectory(args.groundtruth, args.format, times=args.times)
    est = read_trajectory(args.estimate, args.format, times=args.times)
    result = evaluate(gt, est, max_diff=args.max_diff, r_l=args.r_l, align=args.align,
                      gt_name=args.groundtruth, est_name=args.estimate)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    unit = args.unit
    print(f"matched poses               {result['matched_poses']} (of {len(gt)} ground truth, {len(est)} estimated)")
    print(f"ATE RMSE ({args.align} aligned)     {result['ate_rmse']:.6f} {unit}   (scale {result['ate_scale']:.6g})")
    print(f"RPE rotation                {result['rpe_rot_deg_per_m']:.6f} deg/{unit}   (r_l = {args.r_l:g})")
    print(f"RPE translation angle       {result['rpe_trans_angle_deg_per_m']:.6f} deg/{unit}")
    for line in rotation_gain_text(result.get("rotation_gain"), result.get("rotation_gain_frames")):
        print(line)
    return 0


def _add_self_calibration_parser(subparsers: argparse._SubParsersAction) -> None:
    """``calibrate-from-video`` (its command: :mod:`dmtrack.pipeline.cli_self_calibration`, imported when it runs)."""
    p = subparsers.add_parser(
        "calibrate-from-video",
        help="estimate the camera's intrinsics from a sequence's own images, without a board (docs/window.md)")
    p.add_argument("sequence", metavar="SEQUENCE", help="video file, image folder or dataset")
    p.add_argument("--out", required=True, metavar="FILE", help="file to write (fx fy cx cy; f-k1: DSO RadTan)")
    p.add_argument("--intrinsics", metavar="FX,FY,CX,CY|FILE",
                   help="starting guess (default: the sequence's own, else fx = fy = 0.8 × width at the centre)")
    p.add_argument("--feature", default="gray", help="feature tracked with (default gray)")
    p.add_argument("--method", choices=("tracks", "groundtruth", "window"), default="tracks",
                   help="corner tracks on the odometry's poses (default), on the dataset's ground truth, or the window")
    p.add_argument("--model", choices=("f", "f-k1", "f-c", "fxfy-c"), default="f",
                   help="what is estimated: one focal length (default; the principal point kept, as COLMAP); "
                        "f-k1: also k1 (a RadTan file; not the window); f-c, fxfy-c (window): also cx, cy, or fx, fy")
    p.add_argument("--step", type=int, default=5, metavar="N", help="tracks, groundtruth: every N-th frame is used")
    p.add_argument("--start", type=int, default=0, metavar="N", help="first frame")
    p.add_argument("--max-frames", type=int, metavar="N", help="use at most N frames")
    p.add_argument("--iterations", type=int, default=6, metavar="N", help="window: at most N runs (default 6)")
    p.add_argument("--tolerance", type=float, default=0.002, metavar="T", help="window: stop at this change of f")
    p.add_argument("--window", type=int, default=5, metavar="K", help="window: keyframes in the window (default 5)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=_cmd_calibrate_from_video)


def _cmd_calibrate_from_video(args: argparse.Namespace) -> int:
    from dmtrack.pipeline.cli_self_calibration import cmd_calibrate_from_video

    return cmd_calibrate_from_video(args)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="dmtrack",
        description="Direct multichannel tracking: semi-dense monocular visual odometry on multichannel features.",
    )
    parser.add_argument("--version", action="version", version=f"dmtrack {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    p = sub.add_parser("info", help="describe a sequence (format, frames, size, intrinsics, ground truth); without "
                       "one, this machine (versions, whether a GPU is usable)")
    _add_sequence_args(p, optional=True)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("run", help="track a sequence and write trajectory, point cloud, depth images, metrics")
    _add_sequence_args(p)
    p.add_argument("--feature", default="gray", help="feature name (see `dmtrack features`; default gray)")
    p.add_argument("--feature-opt", action="append", metavar="KEY=VALUE",
                   help="feature option, e.g. scale=2 or pca=basis.npz (repeatable)")
    p.add_argument("--out", help="output folder (default out/SEQUENCE-FEATURE)")
    p.add_argument("--start", type=int, default=0, metavar="N", help="first frame (default 0)")
    p.add_argument("--max-frames", type=int, metavar="N", help="process at most N frames")
    p.add_argument("--frames", metavar="RANGES",
                   help="run on these frames of the sequence only, e.g. 0-349,500-699 (inclusive ranges, A:B half-open "
                        "ones, single frames; increasing); --start and --max-frames then count in them. Frames left "
                        "out make a camera that jumps (a kidnapped camera)")
    p.add_argument("--seed", type=int, metavar="S", help="seed of the random depth initialisation (default 0)")
    p.add_argument("--config", metavar="YAML", help="odometry parameters (sections tracker, depth, keyframe)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override one parameter, e.g. --set tracker.huber_d=2 (repeatable)")
    p.add_argument("--r-l", type=fraction, metavar="R",
                   help="RPE length ratio (default 1/20 for KITTI, 1/3 otherwise; the paper uses 1/20 for Tsukuba)")
    p.add_argument("--init", choices=("random", "geometric", "groundtruth"),
                   help="first keyframe's depth: seeded random (the paper's), geometric (from the first frames' own "
                        "motion: tracked corners, essential matrix, bundle adjustment, stereo) or the dataset's depth "
                        "image (docs/initialization.md)")
    _add_device_arg(p)
    p.add_argument("--slam", action="store_true",
                   help="SLAM: a keyframe graph with loop closures (Sim(3) alignment on the feature), optimised by "
                        "gtsam; trajectory.txt is the optimised one, the odometry's is trajectory_vo.txt "
                        "(pip install 'dmtrack[slam]'; docs/slam.md)")
    p.add_argument("--window", type=int, metavar="K",
                   help="optimise the newest K keyframes jointly (photometric bundle adjustment; 0: off, LSD-SLAM's "
                        "odometry; docs/window.md)")
    p.add_argument("--refine-intrinsics", action="store_true",
                   help="the window also estimates the focal length from the images (metrics.json: window.intrinsics; "
                        "a calibration from a video alone: dmtrack calibrate-from-video)")
    p.add_argument("--continue-after-loss", action="store_true",
                   help="keep going after a tracking loss: the lost frames get no pose until the camera is found "
                        "again on a keyframe of the run (relocalisation); without --slam a loss that lasts begins a "
                        "new map (default: stop at the first loss, as the paper counts tracked frames; a live camera "
                        "always goes on)")
    p.add_argument("--no-depth-images", action="store_true", help="do not write depth/*.png")
    p.add_argument("--no-pointcloud", action="store_true", help="do not write pointcloud.ply")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar (default: only on a terminal)")
    p.add_argument("--threads", type=int, metavar="N",
                   help="threads of the kernels and features (default: all cores; 1 is faster when other jobs "
                        "share the cores; results do not depend on it)")
    p.add_argument("--realtime", action="store_true",
                   help="track at the speed frames come (a camera as fast as it delivers, a video at its own speed); "
                        "frames the odometry has no time for are dropped (dropped_frames); not deterministic")
    p.add_argument("--viewer", action="store_true",
                   help="show the run live in the Rerun viewer (needs a display and pip install 'dmtrack[viewer]')")
    p.add_argument("--rrd", metavar="FILE", help="record the live view to a Rerun file (open it with `rerun FILE`)")
    p.add_argument("--rosbag-out", metavar="DIR",
                   help="also write the trajectory as a ROS 2 bag folder: nav_msgs/Odometry and /tf per frame, the "
                        "nav_msgs/Path at the end (for rviz, PlotJuggler; pip install 'dmtrack[ros]')")
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("warmup", help="compile the kernels of features into numba's cache (once after installing)",
                       description="Compile (or load from numba's cache) every kernel a run with the feature calls, "
                       "and print the time per feature; later runs then start at once. `dmtrack run` does the same "
                       "before its first frame (compile_s in metrics.json), so its fps never counts compilation. "
                       "Also writes the bytecode of dmtrack's modules where it is missing (an editable install under "
                       "PYTHONDONTWRITEBYTECODE=1 otherwise compiles them at every start: 0.1 s).")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--feature", action="append", metavar="NAME", help="feature (repeatable; default gray)")
    group.add_argument("--all", action="store_true", help="every feature of `dmtrack features` (those that cannot "
                       "be built here, e.g. without their weights, are skipped)")
    p.add_argument("--threads", type=int, metavar="N", help="for runs with --threads N (default: all cores; one "
                   "thread and several use different kernels)")
    p.set_defaults(func=cmd_warmup)

    p = sub.add_parser("view", help="show a finished run folder in the Rerun viewer, or write it to an .rrd file")
    p.add_argument("run_dir", metavar="RUN_DIR", help="a folder written by `dmtrack run`")
    p.add_argument("--rrd", metavar="FILE", help="write a Rerun file instead of opening the viewer")
    p.add_argument("--spawn", action="store_true", help="also open the viewer when writing --rrd")
    p.set_defaults(func=cmd_view)

    p = sub.add_parser("features", help="list the available features")
    p.add_argument("--json", action="store_true", help="print a JSON list")
    p.set_defaults(func=cmd_features)

    from dmtrack.datasets.cli_download import add_download_parser

    add_download_parser(sub)

    from dmtrack.datasets.cli_calibrate import add_calibrate_parser

    add_calibrate_parser(sub)

    _add_self_calibration_parser(sub)

    def sampling_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("--feature", required=True, help="feature name")
        p.add_argument("--feature-opt", action="append", metavar="KEY=VALUE", help="feature option (repeatable)")
        p.add_argument("sequences", nargs="+", metavar="SEQUENCE", help="sequences to sample frames from")
        p.add_argument("--frames", type=int, default=20, metavar="N", help="frames per sequence (default 20)")
        from dmtrack.datasets.registry import FORMATS

        p.add_argument("--format", choices=FORMATS, help="force the dataset format")
        _add_device_arg(p, "the feature's network")

    p = sub.add_parser(
        "calibrate-scale",
        help="find a feature's default scale (paper §2.4): as many pixels above minUseGrad as grey",
    )
    sampling_args(p)
    p.add_argument("--min-use-grad", type=float, default=5.0, help="gradient threshold (default 5, LSD-SLAM)")
    p.add_argument("--save", action="store_true", help="store it in the user's table, used automatically afterwards")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_calibrate_scale)

    p = sub.add_parser("fit-pca", help="fit a PCA basis reducing a feature to K channels (FEATURE-pcaK)")
    sampling_args(p)
    p.add_argument("--k", type=int, required=True, help="number of components")
    p.add_argument("--samples", type=int, default=200_000, help="pixels sampled in total (default 200000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the pixel sampling (default 0)")
    p.add_argument("--out", help="output .npz (default: the user's PCA folder, found automatically by FEATURE-pcaK)")
    p.set_defaults(func=cmd_fit_pca)

    p = sub.add_parser(
        "eval",
        help="compare an estimated trajectory with ground truth (ATE after Sim(3) alignment, the paper's RPE)",
        description="Metrics of the paper (§3.1): RPE rotation and translation-angle errors per unit of path "
        "length over 8 lengths up to r_l × the ground-truth path, and ATE RMSE after Umeyama alignment.",
    )
    p.add_argument("groundtruth", help="ground-truth trajectory file")
    p.add_argument("estimate", help="estimated trajectory file")
    p.add_argument("--format", choices=("tum", "kitti"), help="file format (default: guessed from the columns)")
    p.add_argument("--times", metavar="FILE",
                   help="timestamps (times.txt) for KITTI-format files, which have none (default: line index)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--r-l", type=fraction, default=1.0 / 3.0, metavar="R",
                   help="longest RPE length as a fraction of the path (default 1/3; the paper uses 1/20 for KITTI "
                   "and Tsukuba)")
    p.add_argument("--max-diff", type=float, default=0.01, metavar="S",
                   help="largest timestamp difference when associating poses (default 0.01)")
    p.add_argument("--align", choices=("sim3", "se3", "scale", "none"), default="sim3",
                   help="alignment before ATE (default sim3: monocular scale is unknown)")
    p.add_argument("--unit", default="m", help="length unit of the ground truth, for the printout (default m)")
    p.set_defaults(func=cmd_eval)

    from dmtrack.experiments.cli import add_bench_parser, add_report_parser

    add_bench_parser(sub)
    add_report_parser(sub)

    from dmtrack.training.cli import add_train_parser

    add_train_parser(sub)

    from dmtrack.ros.cli import add_ros2_parser

    add_ros2_parser(sub, _feature_options, _add_device_arg)
    return parser


def _showwarning(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
    print(f"dmtrack: warning: {message}", file=sys.stderr)


def _interrupt_text(e: KeyboardInterrupt) -> str:
    return str(e) if isinstance(e, Interrupted) else "interrupted by SIGINT"


def _interrupt_code(e: KeyboardInterrupt) -> int:
    return e.exit_code if isinstance(e, Interrupted) else 130


@contextlib.contextmanager
def _terminate_as_interrupt() -> _Iter[None]:
    """SIGTERM (``kill PID``, a job scheduler's stop) and SIGHUP stop a command like Ctrl-C does (main thread only);
    the handlers they had before come back when the command returns (``main`` called in a longer-lived process)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: object) -> None:
        raise Interrupted(signal.Signals(signum).name, signum)

    before = {}
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            before[name] = signal.signal(getattr(signal, name), handler)
    try:
        yield
    finally:
        for name, old in before.items():
            signal.signal(getattr(signal, name), old)


def main(argv: _Seq[str] | None = None) -> int:
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args = argv[argv.index("--ros-args"):] if "--ros-args" in argv else []  # ROS's own, for dmtrack ros2
    args = parser.parse_args(argv[: len(argv) - len(ros_args)])
    if ros_args:
        if args.command != "ros2":
            parser.error(f"--ros-args: only dmtrack ros2 takes ROS arguments, not dmtrack {args.command}")
        args.ros_args = ros_args
    showwarning = warnings.showwarning
    warnings.showwarning = _showwarning
    try:
        with _terminate_as_interrupt():
            return int(args.func(args) or 0)
    except DmtrackError as e:
        print(f"dmtrack: error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:
        print(f"dmtrack: {_interrupt_text(e)}", file=sys.stderr)
        return _interrupt_code(e)
    except BrokenPipeError:  # output piped into `head` and closed early
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    finally:
        warnings.showwarning = showwarning


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
