"""Reading ``torch.save`` files without PyTorch: tensors come back as numpy arrays, nothing else is rebuilt.

Both the zip container (PyTorch ≥ 1.6 default) and the legacy pickle stream (TFeat's ``.params``, torchvision's
``alexnet-owt-7be5be79.pth``) are read through a restricted unpickler that only rebuilds tensors, dicts and lists,
so loading cannot execute code.
"""

from __future__ import annotations

import collections
import io
import os
import pickle
import struct
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from dmtrack.errors import InputError

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
