#!/usr/bin/env python3
"""Run upstream DSO (``_build/dso_dataset``, see build.sh) on frames of a dmtrack sequence and evaluate it as dmtrack
evaluates its own runs.

    python tools/dso_oracle/run_dso.py SEQUENCE --start N --frames K --out DIR \
        [--intrinsics FX,FY,CX,CY|FILE] [--format F] [--r-l R] [--keep-images]

What it does:

1. opens SEQUENCE with dmtrack (``dmtrack.datasets.open_sequence``) and writes frames ``N … N+K−1`` as grey PNGs
   (dmtrack's grey conversion, ``initialization.tracks.grey_u8``: OpenCV's RGB→grey rounded to uint8; grey
   datasets unchanged) into a temporary folder ``images/`` — or, with ``--images original``, links the dataset's
   own files there, which DSO reads with ``cv::imread(…, IMREAD_GRAYSCALE)`` (for a JPEG, libjpeg's grey decoding:
   grey values differ from dmtrack's by about one level) — with ``times.txt`` next to it: line ``j  N+j`` (DSO's
   ``ImageFolderReader`` reads it from the folder's parent: id, timestamp; no exposure column), so that every pose
   DSO writes carries its frame's index in the sequence;
2. writes DSO's calibration ``camera.txt``: from dmtrack's camera (``Pinhole fx fy cx cy 0`` / ``W H`` / ``none`` /
   ``W H``; dmtrack and DSO both put pixel centres at integer coordinates, so the pixel values are passed as they
   are — DSO subtracts 0.5 only from *relative* calibrations, cx < 1 and cy < 1), or, when ``--intrinsics`` names a
   4-line DSO calibration file (RadTan, FOV, Pinhole…; dmtrack's rule: 4 or more non-empty lines), that file as
   it is (lines stripped) with the *raw* frames, DSO undistorting them itself;
3. runs ``[stdbuf -oL] [setarch ARCH -R] dso_dataset files=./images calib=./camera.txt preset=0 mode=1 nogui=1
   nolog=1 nomt=1 quiet=1 kfposes=0 sampleoutput=0`` in the temporary folder (``kfposes=0``: the build's switch
   that makes ``result.txt`` list every frame with a valid pose instead of marginalised keyframes only; relative
   paths and no address-space randomisation make the heap layout, on which DSO's result depends, the same in every
   run — ``--aslr`` to leave it random). Where DSO would warn of too few pyramid levels (it segfaults below 3, e.g.
   KITTI's 1226×370) the frames are first centre-cropped to multiples of 16 (``--crop``); ``--rectify dmtrack``
   replaces a DSO calibration file's output camera by the one dmtrack's undistorter chooses for it;
4. converts ``result.txt`` (TUM, camera-to-world) to ``DIR/trajectory.txt`` with the sequence's own timestamps
   of those frames (the timestamps dmtrack's ``trajectory.txt`` has for them), writes the ground truth of the
   frames ``DIR/groundtruth.txt`` (as ``dmtrack run`` does: the poses timed within the frames' span), runs
   ``dmtrack eval GT EST --json --r-l R`` (R: ``--r-l``, default dmtrack's ``R_L_BY_FORMAT`` of the format, 1/3
   otherwise) and writes ``DIR/metrics.json``; ``DIR/dso.log`` is DSO's output.

Exit status 0 also when DSO never initialises (metrics.json says so); non-zero when DSO could not be run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
DEFAULT_DSO = HERE / "_build" / "dso_dataset"
DSO_SOURCE = HERE / "_build" / "dso"
DSO_ARGS = ("preset=0", "mode=1", "nogui=1", "nolog=1", "nomt=1", "quiet=1", "kfposes=0", "sampleoutput=0")


def parse_fraction(text: str) -> float:
    """``1/3``, ``0.05`` …"""
    return float(Fraction(text))


def dso_commit() -> str | None:
    try:
        out = subprocess.run(["git", "-C", str(DSO_SOURCE), "rev-parse", "HEAD"], capture_output=True, text=True,
                             check=True)
        return out.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def is_calibration_file(value: str) -> bool:
    """A 4-line DSO calibration (dmtrack's rule in ``apply_intrinsics``: a file with ≥ 4 non-empty lines)."""
    p = Path(value).expanduser()
    if not p.is_file():
        return False
    return len([ln for ln in p.read_text().splitlines() if ln.strip()]) >= 4


def open_sequence_for(args: argparse.Namespace):  # noqa: ANN201
    """(sequence, calibration text, calibration source)."""
    from dmtrack.datasets import open_sequence

    if args.intrinsics and is_calibration_file(args.intrinsics):
        from dmtrack.datasets.undistort import read_calibration_file

        path = Path(args.intrinsics).expanduser()
        read_calibration_file(path, flavour="dso")  # a clear error for a malformed file
        lines = [ln.strip() for ln in path.read_text().splitlines() if ln.strip()][:4]
        seq = open_sequence(args.sequence, format=args.format)  # raw frames: DSO undistorts them itself
        in_w, in_h = (int(v) for v in lines[1].split())
        if (in_w, in_h) != (seq.width, seq.height):
            sys.exit(f"run_dso.py: {path}: input size {in_w}x{in_h}, the images are {seq.width}x{seq.height}")
        source = str(path)
        if args.rectify == "dmtrack":
            # DSO's own undistortion, into the pinhole camera dmtrack's undistorter chooses for this file (line 3 as
            # an explicit relative output camera: DSO computes c = rel * size - 0.5, so rel = (c + 0.5) / size)
            cam = open_sequence(args.sequence, format=args.format, intrinsics=str(path)).camera
            lines[2] = (f"{cam.fx / cam.width!r} {cam.fy / cam.height!r} {(cam.cx + 0.5) / cam.width!r} "
                        f"{(cam.cy + 0.5) / cam.height!r} 0")
            lines[3] = f"{cam.width} {cam.height}"
            source += " (output camera: dmtrack's)"
        return seq, "\n".join(lines) + "\n", source, None
    seq = open_sequence(args.sequence, format=args.format, intrinsics=args.intrinsics)
    cam = seq.camera
    if cam is None:
        sys.exit(f"run_dso.py: {args.sequence}: no intrinsics; give --intrinsics FX,FY,CX,CY or a file")
    box = None
    if args.crop == "16" or (args.crop == "auto" and dso_warns(cam.width, cam.height)):
        cropped, box = cam.crop_to_multiple(16)  # dmtrack's centred crop: c' = c - offset
        if box == (0, 0, cam.width, cam.height):
            box = None
        else:
            cam = cropped
    if cam.cx < 1 and cam.cy < 1:
        sys.exit("run_dso.py: cx, cy < 1 would be read by DSO as a relative calibration")
    text = (f"Pinhole {cam.fx!r} {cam.fy!r} {cam.cx!r} {cam.cy!r} 0\n"
            f"{cam.width} {cam.height}\nnone\n{cam.width} {cam.height}\n")
    source = args.intrinsics or "the sequence's"
    return seq, text, source, box


def dso_pyramid(width: int, height: int) -> tuple[int, int, int]:
    """(levels, coarsest width, coarsest height) as DSO's ``setGlobalCalib`` chooses them (PYR_LEVELS 6)."""
    levels, w, h = 1, width, height
    while w % 2 == 0 and h % 2 == 0 and w * h > 5000 and levels < 6:
        w, h, levels = w // 2, h // 2, levels + 1
    return levels, w, h


def dso_warns(width: int, height: int) -> bool:
    """Whether DSO warns about this size ("using not enough pyramid levels" / "I will probably segfault")."""
    levels, w, h = dso_pyramid(width, height)
    return levels < 3 or (w > 100 and h > 100)


def grey_u8(image: np.ndarray) -> np.ndarray:
    try:
        from dmtrack.initialization.tracks import grey_u8 as dm_grey
    except ImportError:  # older dmtrack: the same conversion
        a = np.asarray(image)
        if a.ndim == 3:
            a = cv2.cvtColor(np.ascontiguousarray(a[..., :3]), cv2.COLOR_RGB2GRAY)
        return np.ascontiguousarray(a.astype(np.uint8))
    return dm_grey(image)


def groundtruth_span(seq, indices: list[int]):  # noqa: ANN001, ANN201
    """The ground-truth poses timed within the frames' span (± 1 µs), as ``dmtrack run`` writes them."""
    gt = seq.groundtruth
    if gt is None or len(gt) == 0:
        return None
    times = np.asarray([seq.timestamps[i] for i in indices], dtype=np.float64)
    keep = (gt.timestamps >= times.min() - 1e-6) & (gt.timestamps <= times.max() + 1e-6)
    return gt[np.nonzero(keep)[0]] if keep.any() else None


def dmtrack_bin() -> str:
    cand = Path(sys.executable).with_name("dmtrack")
    return str(cand) if cand.exists() else (shutil.which("dmtrack") or "dmtrack")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sequence")
    ap.add_argument("--start", type=int, default=0, help="first frame (default 0)")
    ap.add_argument("--frames", type=int, default=None, help="number of frames (default: to the end)")
    ap.add_argument("--out", required=True, type=Path, help="output folder")
    ap.add_argument("--intrinsics", help="FX,FY,CX,CY, a dmtrack intrinsics file (fx fy cx cy / 3x3 K), or a 4-line "
                    "DSO calibration file (passed to DSO as it is, with the raw frames)")
    ap.add_argument("--format", help="dmtrack dataset format (default: detected)")
    ap.add_argument("--r-l", type=parse_fraction, default=None,
                    help="RPE length ratio for dmtrack eval (default: dmtrack run's for the format)")
    ap.add_argument("--dso", type=Path, default=DEFAULT_DSO, help="dso_dataset binary (default _build/dso_dataset)")
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds before DSO is stopped")
    ap.add_argument("--images", choices=("dmtrack", "original"), default="dmtrack",
                    help="dmtrack: the frames as dmtrack reads them, converted to grey PNGs (default); original: "
                    "links to the dataset's files, read by DSO itself")
    ap.add_argument("--rectify", choices=("file", "dmtrack"), default="file",
                    help="with a DSO calibration file: its own lines 3-4 (default; DSO's crop / full search), or "
                    "dmtrack's output camera for it as an explicit line 3 (DSO still undistorts)")
    ap.add_argument("--crop", choices=("auto", "16", "none"), default="auto",
                    help="centre-crop the frames to multiples of 16 (dmtrack's crop_to_multiple; cx, cy shifted): "
                    "auto (default) only where DSO would warn of too few pyramid levels (it segfaults below 3, "
                    "e.g. KITTI's 1226x370)")
    ap.add_argument("--aslr", action="store_true",
                    help="leave address-space randomisation on (default: off via setarch -R, for repeatable runs)")
    ap.add_argument("--keep-images", action="store_true", help="keep the temporary folder (images, camera.txt)")
    args = ap.parse_args(argv)

    if not args.dso.exists():
        sys.exit(f"run_dso.py: {args.dso} not found; build it with tools/dso_oracle/build.sh")
    seq, calib_text, calib_source, box = open_sequence_for(args)
    n = len(seq)
    if not 0 <= args.start < n:
        sys.exit(f"run_dso.py: --start {args.start} outside the sequence's {n} frames")
    stop = n if args.frames is None else min(n, args.start + args.frames)
    indices = list(range(args.start, stop))
    if args.r_l is None:
        from dmtrack.pipeline.result import DEFAULT_R_L, R_L_BY_FORMAT

        r_l = R_L_BY_FORMAT.get(seq.format, DEFAULT_R_L)
    else:
        r_l = args.r_l
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    for stale in ("trajectory.txt", "groundtruth.txt", "metrics.json", "dso.log", "camera.txt"):
        (out / stale).unlink(missing_ok=True)

    work = Path(tempfile.mkdtemp(prefix="dso_oracle_"))
    try:
        images = work / "images"
        images.mkdir()
        times = []
        paths = getattr(seq, "image_paths", None) if args.images == "original" else None
        if args.images == "original":
            from dmtrack.datasets.undistort import UndistortedSequence

            if not paths or isinstance(seq, UndistortedSequence):
                sys.exit("run_dso.py: --images original needs a sequence of image files that dmtrack does not "
                         "undistort (a DSO calibration file is fine: DSO undistorts)")
            first = cv2.imread(str(paths[indices[0]]), cv2.IMREAD_GRAYSCALE)
            if box is not None:
                sys.exit("run_dso.py: --images original cannot be cropped (use --crop none or the default images)")
            if first is None or first.shape != (seq.height, seq.width):
                sys.exit(f"run_dso.py: {paths[indices[0]]}: not an image of {seq.width}x{seq.height} that OpenCV reads")
        for j, i in enumerate(indices):
            if paths is not None:
                src = Path(paths[i]).resolve()
                (images / f"{j:06d}{src.suffix}").symlink_to(src)
            else:
                grey = grey_u8(seq[i].image)
                if box is not None:
                    from dmtrack.geometry.camera import crop_image

                    grey = crop_image(grey, box)
                if not cv2.imwrite(str(images / f"{j:06d}.png"), grey):
                    sys.exit(f"run_dso.py: cannot write {images / f'{j:06d}.png'}")
            times.append(f"{j} {i}")
        (work / "times.txt").write_text("\n".join(times) + "\n")
        (work / "camera.txt").write_text(calib_text)
        (out / "camera.txt").write_text(calib_text)

        # Relative paths (the same strings wherever the temporary folder is) and, unless --aslr, no address-space
        # randomisation: DSO reads uninitialised and freed memory (valgrind), so its result depends on the heap
        # layout; with both fixed a run is repeatable to the byte (README, "Repeatability").
        cmd = [str(args.dso.resolve()), "files=./images", "calib=./camera.txt", *DSO_ARGS]
        stdbuf = shutil.which("stdbuf")  # line-buffered output: the log survives a crash
        if stdbuf:
            cmd = [stdbuf, "-oL", *cmd]
        setarch = shutil.which("setarch")
        if not args.aslr and setarch:
            cmd = [setarch, platform.machine(), "-R", *cmd]
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, cwd=work, capture_output=True, text=True, errors="replace",
                                  timeout=args.timeout)
            rc, log = proc.returncode, proc.stdout + proc.stderr
        except subprocess.TimeoutExpired as e:
            rc = None
            log = (e.stdout or b"").decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or "")
        wall = time.perf_counter() - t0
        (out / "dso.log").write_text(" ".join(cmd) + "\n\n" + log)

        # result.txt: "timestamp tx ty tz qx qy qz qw", our timestamps = frame indices of the sequence
        posed: dict[int, list[float]] = {}
        result = work / "result.txt"
        if result.exists():
            for line in result.read_text().splitlines():
                f = line.split()
                if len(f) != 8:
                    continue
                idx = int(round(float(f[0])))
                vals = [float(v) for v in f[1:]]
                if all(math.isfinite(v) for v in vals):
                    posed[idx] = vals
        if args.keep_images:
            print(f"kept {work}")
    finally:
        if not args.keep_images:
            shutil.rmtree(work, ignore_errors=True)

    from dmtrack.io.trajectory import tum_row_text, write_tum

    frames_posed = sorted(posed)
    (out / "trajectory.txt").write_text(
        "".join(tum_row_text(seq.timestamps[i], posed[i]) + "\n" for i in frames_posed))
    gt = groundtruth_span(seq, indices)
    if gt is not None:
        write_tum(out / "groundtruth.txt", gt,
                  header="ground truth of the run's frames (camera-to-world, TUM format, the dataset's units)")

    metrics: dict = {
        "system": "DSO",
        "dso_commit": dso_commit(),
        "dso_args": list(DSO_ARGS),
        "sequence": str(args.sequence),
        "sequence_name": getattr(seq, "name", None),
        "format": seq.format,
        "start": args.start,
        "frames_given": len(indices),
        "frames_posed": len(frames_posed),
        "first_posed_frame": frames_posed[0] if frames_posed else None,
        "last_posed_frame": frames_posed[-1] if frames_posed else None,
        "initialised": len(frames_posed) > 1,
        "resets": log.count("RESETTING!"),
        "segfault_warning": "I will probably segfault" in log,
        "lost": ("LOST!!" in log) or ("Initial Tracking failed" in log),
        "images": args.images,
        "crop": list(box) if box is not None else None,
        "aslr": bool(args.aslr or not shutil.which("setarch")),
        "calibration": calib_text.strip().splitlines(),
        "calibration_source": calib_source,
        "r_l": r_l,
        "wall_s": round(wall, 3),
        "dso_exit_code": rc,
    }
    for k in ("ate_rmse", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "matched_poses"):
        metrics[k] = None
    if rc is None:
        metrics["note"] = f"DSO stopped after the {args.timeout:g} s timeout"
    elif not metrics["initialised"]:
        if rc != 0:
            metrics["note"] = f"DSO failed (exit status {rc})"
        elif metrics["resets"]:
            metrics["note"] = ("DSO never initialised (its initialisation failed and was reset "
                               f"{metrics['resets']} times)")
        else:
            metrics["note"] = "DSO never initialised (no tracked frame)"
    elif gt is None:
        metrics["note"] = "no ground truth"
    else:
        ev = subprocess.run([dmtrack_bin(), "eval", str(out / "groundtruth.txt"), str(out / "trajectory.txt"),
                             "--json", "--r-l", repr(r_l)], capture_output=True, text=True)
        if ev.returncode == 0:
            res = json.loads(ev.stdout)
            for k in ("ate_rmse", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "matched_poses"):
                metrics[k] = res.get(k)
        else:
            metrics["note"] = "dmtrack eval failed: " + (ev.stderr.strip().splitlines() or ["?"])[-1]
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    summary = {k: metrics[k] for k in ("frames_given", "frames_posed", "first_posed_frame", "ate_rmse",
                                       "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "wall_s")}
    print(json.dumps(summary) + (f"  ({metrics['note']})" if "note" in metrics else ""))
    return 0 if rc is not None and (rc == 0 or metrics["initialised"]) else 1


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    sys.exit(main())
