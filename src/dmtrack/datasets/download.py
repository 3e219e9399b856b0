"""Downloading the public datasets of the paper from their official servers.

``dmtrack download DATASET SEQUENCE DIR`` (or :func:`download`) streams the archive to ``DIR`` (resuming a
partial ``.part`` file with an HTTP ``Range`` request), checks its size against ``Content-Length`` and its
checksum where one is published, and unpacks it.  Nothing here runs without network access; on machines
without it the error says which URL could not be reached.

=============  ==========================================================================================
dataset        sequences / notes
=============  ==========================================================================================
tum-monovo     ``01`` … ``50`` (``sequence_NN.zip``; images stay zipped — the reader reads ``images.zip``)
tum-rgbd       ``freiburg1_xyz``, ``freiburg3_long_office_household``, … (``rgbd_dataset_*.tgz``)
kitti          ``00`` … ``21``: the odometry archives hold *all* sequences (grey images 22 GB, poses,
               calibration); only the asked sequence is unpacked.  KITTI asks users to register on
               cvlibs.net and accept the licence (CC BY-NC-SA 3.0) before downloading.
euroc          ``MH_01_easy`` … ``V2_03_difficult`` (ASL format zip)
icl-nuim       ``lr_kt0`` … ``lr_kt3`` (living room), ``of_kt0`` … ``of_kt3`` (office); TUM-compatible PNGs
7scenes        ``chess``, ``fire``, ``heads``, ``office``, ``pumpkin``, ``redkitchen``, ``stairs`` (one scene
               zip holding ``seq-NN.zip`` archives, which are unpacked too)
=============  ==========================================================================================

New Tsukuba and the LSD-SLAM sample sequences are distributed through web forms / servers without stable
direct links; get them from their pages (cvlab.cs.tsukuba.ac.jp, vision.in.tum.de/research/vslam/lsdslam).
"""

from __future__ import annotations

import hashlib
import sys
import tarfile
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from dmtrack.errors import InputError

__all__ = ["DATASETS", "Archive", "DownloadError", "download", "plan", "sequences"]

CHUNK = 1 << 20


class DownloadError(InputError):
    """A download failed (network, HTTP status, size or checksum)."""


@dataclass(frozen=True)
class Archive:
    """One file to fetch.

    Attributes
    ----------
    url : official download address.
    filename : name of the downloaded file in the target folder.
    sha256, md5 : published checksum (hex), when the provider publishes one.
    members : unpack only archive members whose path starts with one of these prefixes (``None``: all).
    """

    url: str
    filename: str
    sha256: str | None = None
    md5: str | None = None
    members: tuple[str, ...] | None = None


@dataclass(frozen=True)
class Dataset:
    name: str
    sequences: tuple[str, ...]
    archives: Callable[[str], list[Archive]]
    note: str = ""
    nested_zips: bool = field(default=False)


def _tum_monovo(seq: str) -> list[Archive]:
    return [Archive(f"https://vision.in.tum.de/mono/dataset/sequence_{seq}.zip", f"sequence_{seq}.zip")]


_TUM_RGBD = (
    "freiburg1_xyz", "freiburg1_rpy", "freiburg1_360", "freiburg1_floor", "freiburg1_desk", "freiburg1_desk2",
    "freiburg1_room", "freiburg1_plant", "freiburg1_teddy",
    "freiburg2_xyz", "freiburg2_rpy", "freiburg2_360_hemisphere", "freiburg2_360_kidnap", "freiburg2_desk",
    "freiburg2_large_no_loop", "freiburg2_large_with_loop", "freiburg2_pioneer_360", "freiburg2_pioneer_slam",
    "freiburg2_pioneer_slam2", "freiburg2_pioneer_slam3", "freiburg2_desk_with_person",
    "freiburg3_long_office_household", "freiburg3_nostructure_notexture_far",
    "freiburg3_nostructure_notexture_near_withloop",
    "freiburg3_nostructure_texture_far", "freiburg3_nostructure_texture_near_withloop",
    "freiburg3_structure_notexture_far", "freiburg3_structure_notexture_near", "freiburg3_structure_texture_far",
    "freiburg3_structure_texture_near", "freiburg3_sitting_static", "freiburg3_sitting_xyz",
    "freiburg3_sitting_halfsphere", "freiburg3_sitting_rpy", "freiburg3_walking_static", "freiburg3_walking_xyz",
    "freiburg3_walking_halfsphere", "freiburg3_walking_rpy",
)


def _tum_rgbd(seq: str) -> list[Archive]:
    fr = seq.split("_", 1)[0]
    name = f"rgbd_dataset_{seq}"
    return [Archive(f"https://vision.in.tum.de/rgbd/dataset/{fr}/{name}.tgz", f"{name}.tgz")]


def _kitti(seq: str) -> list[Archive]:
    base = "https://s3.eu-central-1.amazonaws.com/avg-kitti"
    out = [
        Archive(f"{base}/data_odometry_gray.zip", "data_odometry_gray.zip", members=(f"dataset/sequences/{seq}/",)),
        Archive(f"{base}/data_odometry_calib.zip", "data_odometry_calib.zip", members=(f"dataset/sequences/{seq}/",)),
    ]
    if int(seq) <= 10:
        out.append(Archive(f"{base}/data_odometry_poses.zip", "data_odometry_poses.zip",
                           members=(f"dataset/poses/{seq}.txt",)))
    return out


_EUROC = {
    "MH_01_easy": "machine_hall", "MH_02_easy": "machine_hall", "MH_03_medium": "machine_hall",
    "MH_04_difficult": "machine_hall", "MH_05_difficult": "machine_hall",
    "V1_01_easy": "vicon_room1", "V1_02_medium": "vicon_room1", "V1_03_difficult": "vicon_room1",
    "V2_01_easy": "vicon_room2", "V2_02_medium": "vicon_room2", "V2_03_difficult": "vicon_room2",
}


def _euroc(seq: str) -> list[Archive]:
    return [Archive(f"http://robotics.ethz.ch/~asl-datasets/ijrr_euroc_mav_dataset/{_EUROC[seq]}/{seq}/{seq}.zip",
                    f"{seq}.zip")]


def _icl(seq: str) -> list[Archive]:
    k = seq[-1]
    name = f"living_room_traj{k}_frei_png" if seq.startswith("lr") else f"traj{k}_frei_png"
    return [Archive(f"http://www.doc.ic.ac.uk/~ahanda/{name}.tar.gz", f"{name}.tar.gz")]


_SEVEN = ("chess", "fire", "heads", "office", "pumpkin", "redkitchen", "stairs")


def _seven(seq: str) -> list[Archive]:
    return [Archive(f"http://download.microsoft.com/download/2/8/5/28564B23-0828-408F-8631-23B1EFF1DAC8/{seq}.zip",
                    f"{seq}.zip")]


DATASETS: dict[str, Dataset] = {
    d.name: d
    for d in (
        Dataset("tum-monovo", tuple(f"{i:02d}" for i in range(1, 51)), _tum_monovo),
        Dataset("tum-rgbd", _TUM_RGBD, _tum_rgbd),
        Dataset("kitti", tuple(f"{i:02d}" for i in range(22)), _kitti,
                note="KITTI requires registration at cvlibs.net (odometry benchmark) and acceptance of its licence "
                     "(CC BY-NC-SA 3.0) before downloading; the archives hold all 22 sequences (about 23 GB)."),
        Dataset("euroc", tuple(_EUROC), _euroc),
        Dataset("icl-nuim", ("lr_kt0", "lr_kt1", "lr_kt2", "lr_kt3", "of_kt0", "of_kt1", "of_kt2", "of_kt3"), _icl),
        Dataset("7scenes", _SEVEN, _seven, nested_zips=True),
    )
}


def sequences(dataset: str) -> tuple[str, ...]:
    """The sequence names :func:`download` knows for ``dataset``."""
    if dataset not in DATASETS:
        raise InputError(f"unknown dataset {dataset!r}; known datasets: {', '.join(DATASETS)}")
    return DATASETS[dataset].sequences


def _normalise_sequence(dataset: str, sequence: str) -> str:
    seqs = sequences(dataset)
    s = sequence.strip()
    if dataset in ("tum-monovo", "kitti") and s.isdigit():
        s = f"{int(s):02d}"
    if dataset == "tum-monovo" and s.startswith("sequence_"):
        s = s[len("sequence_"):]
    if dataset == "tum-rgbd":
        s = s.removeprefix("rgbd_dataset_").replace("fr1", "freiburg1").replace("fr2", "freiburg2").replace(
            "fr3", "freiburg3").replace("/", "_")
    if s not in seqs:
        raise InputError(f"unknown {dataset} sequence {sequence!r}; known sequences: {', '.join(seqs)}")
    return s


def plan(dataset: str, sequence: str) -> list[Archive]:
    """The archives :func:`download` would fetch (no network)."""
    seq = _normalise_sequence(dataset, sequence)
    return DATASETS[dataset].archives(seq)


# -- transfer ------------------------------------------------------------------------------------------
def _fetch(archive: Archive, target: Path, progress: Callable[[int, int | None], None] | None) -> Path:
    """Stream ``archive.url`` to ``target`` (resuming ``target.part``); returns ``target``."""
    import urllib.error  # here, not at the top: `dmtrack run` builds the command line with this module (11 ms)
    import urllib.request

    if target.is_file():
        return target
    part = target.with_name(target.name + ".part")
    have = part.stat().st_size if part.is_file() else 0
    req = urllib.request.Request(archive.url, headers={"User-Agent": "dmtrack-download"})
    if have:
        req.add_header("Range", f"bytes={have}-")
    try:
        resp = urllib.request.urlopen(req, timeout=60)
    except urllib.error.HTTPError as e:
        if e.code == 416 and have:  # range not satisfiable: the part file is already complete
            part.replace(target)
            return target
        raise DownloadError(f"HTTP {e.code} {e.reason} for {archive.url}") from None
    except (urllib.error.URLError, OSError) as e:
        reason = getattr(e, "reason", e)
        raise DownloadError(f"cannot reach {archive.url} ({reason}); check the network connection or download "
                            f"the file by hand into {target.parent}") from None
    with resp:
        status = getattr(resp, "status", 200)
        mode = "ab" if (have and status == 206) else "wb"
        if mode == "wb":
            have = 0
        length = resp.headers.get("Content-Length")
        total = have + int(length) if length is not None else None
        done = have
        with open(part, mode) as f:
            while True:
                chunk = resp.read(CHUNK)
                if not chunk:
                    break
                f.write(chunk)
                done += len(chunk)
                if progress is not None:
                    progress(done, total)
    if total is not None and part.stat().st_size != total:
        raise DownloadError(f"incomplete download of {archive.url}: {part.stat().st_size} of {total} bytes "
                            f"(run the command again to resume)", path=part)
    _verify(archive, part)
    part.replace(target)
    return target


def _verify(archive: Archive, path: Path) -> None:
    for algo, expected in (("sha256", archive.sha256), ("md5", archive.md5)):
        if expected is None:
            continue
        h = hashlib.new(algo)
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(CHUNK), b""):
                h.update(chunk)
        if h.hexdigest().lower() != expected.lower():
            path.unlink(missing_ok=True)
            raise DownloadError(f"{algo} checksum mismatch for {archive.url} (got {h.hexdigest()}, expected "
                                f"{expected}); the partial file was removed", path=path)


def _safe_dest(base: Path, name: str) -> Path:
    dest = (base / name).resolve()
    if base.resolve() not in dest.parents and dest != base.resolve():
        raise DownloadError(f"archive member {name!r} would be written outside {base}")
    return dest


def _extract(path: Path, dest: Path, members: tuple[str, ...] | None) -> None:
    def wanted(name: str) -> bool:
        return members is None or any(name.startswith(m) for m in members)

    if zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as z:
            for info in z.infolist():
                if wanted(info.filename):
                    _safe_dest(dest, info.filename)
                    z.extract(info, dest)
    elif tarfile.is_tarfile(path):
        with tarfile.open(path) as t:
            chosen = [m for m in t.getmembers() if wanted(m.name)]
            for m in chosen:
                _safe_dest(dest, m.name)
            t.extractall(dest, members=chosen, filter="data")
    else:
        raise DownloadError("not a zip or tar archive", path=path)


def _default_progress(done: int, total: int | None) -> None:
    if total:
        sys.stderr.write(f"\r  {done / 1e6:8.1f} / {total / 1e6:.1f} MB ({100 * done / total:5.1f} %)")
    else:
        sys.stderr.write(f"\r  {done / 1e6:8.1f} MB")
    sys.stderr.flush()


def download(
    dataset: str,
    sequence: str,
    directory: str | Path,
    extract: bool = True,
    keep_archive: bool = True,
    progress: Callable[[int, int | None], None] | None = None,
) -> Path:
    """Download (and unpack) one sequence of ``dataset`` into ``directory``; returns ``directory``.

    Raises
    ------
    InputError
        Unknown dataset or sequence (the message lists the valid ones).
    DownloadError
        Network failure, HTTP error, incomplete file or checksum mismatch (the message names the URL).
    """
    archives = plan(dataset, sequence)
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    for a in archives:
        path = _fetch(a, out / a.filename, progress)
        if extract:
            _extract(path, out, a.members)
            if DATASETS[dataset].nested_zips:
                for inner in sorted(out.rglob("seq-*.zip")):
                    _extract(inner, inner.parent, None)
                    inner.unlink()
            if not keep_archive:
                path.unlink()
    return out
