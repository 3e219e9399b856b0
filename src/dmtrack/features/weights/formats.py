"""The table of weight formats and the one loader that reads any of them (no PyTorch, Caffe, protobuf or ONNX).

Every learned feature's weights are read the same way: pick the reader by the file's suffix, check that the
expected arrays are there with the expected shapes, convert them to what the feature uses. A
:class:`WeightFormat` holds the per-kind parts of that (readers, shapes, conversion, where the format comes
from); :data:`FORMATS` is the table; :func:`read_weights` reads a file in a named format and
:func:`load_weights` finds a catalogue entry's file (:func:`~dmtrack.features.weights.catalogue.find_weights`)
and reads it in the entry's format.

=================  ============================================  ============================================
format             suffixes                                      result
=================  ============================================  ============================================
``alexnet-conv1``  ``.caffemodel``, ``.onnx``, ``.pth``/``.pt``,  :class:`Conv1Weights`
                   ``.npz``
``siam``           ``.bin`` (the authors'), ``.npz``             ``{name: float32}`` (:data:`SIAM_SHAPES`)
``tfeat``          ``.npz``, any other: a torch state dict       ``{name: float32}`` (:data:`TFEAT_SHAPES`)
``disk``           a torch file                                  ``{"unet.*": float32}``
=================  ============================================  ============================================

A new learned feature adds a row (and a :class:`~dmtrack.features.weights.catalogue.WeightFile` naming it).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack.errors import InputError
from dmtrack.features.weights.catalogue import find_weights, weight_info
from dmtrack.features.weights.torchfile import load_state_dict, load_torch_file

#: A reader: an existing file → what it holds (a ``{name: array}`` dict for formats with ``shapes``).
Reader = Callable[[Path], Any]


@dataclass(frozen=True)
class WeightFormat:
    """One kind of weights: how its files are read, checked and converted.

    Attributes
    ----------
    name
        Key in :data:`FORMATS` (and :attr:`WeightFile.format <dmtrack.features.weights.catalogue.WeightFile>`).
    label
        Its name in error messages.
    provenance
        Whose network it is and where the file layout is defined.
    readers
        Lower-case file suffix → :data:`Reader`; ``"*"`` reads any other suffix.
    expected
        The accepted suffixes in words, for the error about an unknown one.
    shapes
        Arrays the reader's dict must hold, with their shapes; None when ``convert`` does its own checks.
    convert
        ``convert(read, path)`` → the loaded weights; default (None): the ``shapes`` arrays, in that order, as
        C-contiguous float32.
    """

    name: str
    label: str
    provenance: str
    readers: Mapping[str, Reader]
    expected: str = ""
    shapes: Mapping[str, tuple[int, ...]] | None = None
    convert: Callable[[Any, Path], Any] | None = field(default=None, repr=False)

    def read(self, path: str | os.PathLike[str]) -> Any:
        """Read, check and convert the existing file ``path``; :class:`InputError` naming it when it cannot."""
        p = Path(path)
        suffix = p.suffix.lower()
        reader = self.readers.get(suffix, self.readers.get("*"))
        if reader is None:
            raise InputError(f"unknown {self.label} weight format {suffix!r}: expected {self.expected}", path=p)
        raw = reader(p)
        if self.shapes is not None:
            _require(raw, self.shapes, p)
        if self.convert is not None:
            return self.convert(raw, p)
        assert self.shapes is not None
        return {k: np.ascontiguousarray(raw[k], dtype=np.float32) for k in self.shapes}


def _require(sd: dict[str, np.ndarray], shapes: Mapping[str, tuple[int, ...]], path: str | os.PathLike[str]) -> None:
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


# ------------------------------------------------------------------------------------------ AlexNet conv1
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


#: What the AlexNet readers return: weight, bias, channel order, input convention.
_Conv1 = tuple[np.ndarray, np.ndarray, str, str]


def _conv1_caffe(p: Path) -> _Conv1:
    """Layer ``conv1`` of a Caffe ``NetParameter`` (current or V1/V0 layer lists), BGR."""
    from dmtrack.features import _caffe

    layer = _caffe.read_caffe_layer(p, "conv1")
    if len(layer.blobs) < 1:
        raise InputError("Caffe layer 'conv1' has no weight blob", path=p)
    w = layer.blobs[0]
    b = layer.blobs[1] if len(layer.blobs) > 1 else np.zeros(w.shape[0], np.float32)
    return w, b, "BGR", "caffe"


def _conv1_onnx(p: Path) -> _Conv1:
    """The weight and bias inputs of the graph's first ``Conv`` node (BVLC AlexNet from the ONNX model zoo:
    ``conv1_w_0``/``conv1_b_0``), BGR as the Caffe original."""
    from dmtrack.features import _caffe

    nodes, inits = _caffe.read_onnx_graph(p)
    conv = next((n for n in nodes if n.op_type == "Conv" and len(n.inputs) >= 2), None)
    wname = "conv1_w_0" if conv is None else conv.inputs[1]
    bname = "conv1_b_0" if conv is None else (conv.inputs[2] if len(conv.inputs) > 2 else None)
    if wname not in inits:
        raise InputError(f"ONNX model has no initializer {wname!r} for the first convolution", path=p)
    w = _caffe.decode_onnx_tensor(inits[wname], p)
    b = _caffe.decode_onnx_tensor(inits[bname], p) if bname and bname in inits else np.zeros(w.shape[0])
    return w, b, "BGR", "caffe"


def _conv1_torchvision(p: Path) -> _Conv1:
    """A torchvision AlexNet state dict (``features.0.weight`` 64×3×11×11, RGB, torchvision normalisation)."""
    sd = load_state_dict(p)
    if "features.0.weight" not in sd:
        raise InputError(f"not a torchvision AlexNet state dict: no 'features.0.weight' (keys: {list(sd)[:8]})", path=p)
    w = sd["features.0.weight"]
    b = sd.get("features.0.bias", np.zeros(w.shape[0], np.float32))
    return w, b, "RGB", "torchvision"


def _conv1_npz(p: Path) -> _Conv1:
    """Arrays ``weight`` (out, 3, k, k) and ``bias``, BGR-ordered like Caffe's, unless an array ``channel_order``
    says ``"RGB"`` (then the torchvision convention applies)."""
    z = _load_npz(p)
    if "weight" not in z:
        raise InputError(f".npz AlexNet weights need arrays 'weight' and 'bias' (found: {list(z)})", path=p)
    order = str(z["channel_order"]) if "channel_order" in z else "BGR"
    if order not in ("BGR", "RGB"):
        raise InputError(f"channel_order must be 'BGR' or 'RGB', got {order!r}", path=p)
    convention = "caffe" if order == "BGR" else "torchvision"
    return z["weight"], z.get("bias", np.zeros(z["weight"].shape[0])), order, convention


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


def _to_conv1(read: _Conv1, p: Path) -> Conv1Weights:
    w, b, order, convention = read
    w, b = _check_conv1(w, b, p)
    return Conv1Weights(w, b, order, convention, str(p))


# ------------------------------------------------------------------------------------------ siam
SIAM_SHAPES: dict[str, tuple[int, ...]] = {
    "conv0.weight": (96, 1, 7, 7),
    "conv0.bias": (96,),
    "conv1.weight": (192, 96, 5, 5),
    "conv1.bias": (192,),
    "conv2.weight": (256, 192, 3, 3),
    "conv2.bias": (256,),
}


def _read_siam_bin(p: Path) -> dict[str, np.ndarray]:
    """The authors' binary format (cvpr15deepcompare ``loader.cpp``): int32 length + network type string
    (``"siam"`` or ``"siam_desc"``), then for each layer an int32 module index, int32 weight and bias element
    counts and the float32 weights (``(out, in, kh, kw)`` order) and biases; the three convolution records come
    first (identified by their sizes) and the decision layers of ``"siam"`` that follow are not read."""
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


def _disk_unet(obj: Any, p: Path) -> dict[str, np.ndarray]:
    """The ``unet.*`` arrays of ``{'extractor': state_dict}`` or of a bare state dict, as float32."""
    if isinstance(obj, dict) and "extractor" in obj:
        obj = obj["extractor"]
    if not isinstance(obj, dict) or not any(str(k).startswith("unet.") for k in obj):
        raise InputError("not a DISK weight file: no 'unet.*' parameters", path=p)
    return {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in obj.items() if k.startswith("unet.")}


# ------------------------------------------------------------------------------------------ the table
FORMATS: dict[str, WeightFormat] = {
    f.name: f
    for f in (
        WeightFormat(
            name="alexnet-conv1",
            label="AlexNet",
            provenance="AlexNet conv1: Caffe BVLC model zoo (BGR, ILSVRC mean), its ONNX model zoo export, or "
            "torchvision's AlexNet (RGB, ImageNet mean/std)",
            readers={
                ".caffemodel": _conv1_caffe,
                ".onnx": _conv1_onnx,
                ".pth": _conv1_torchvision,
                ".pt": _conv1_torchvision,
                ".npz": _conv1_npz,
            },
            expected=".caffemodel, .onnx, .pth/.pt (torchvision) or .npz",
            convert=_to_conv1,
        ),
        WeightFormat(
            name="siam",
            label="siam",
            provenance="Zagoruyko & Komodakis 'siam' descriptor branch (szagoruyko/cvpr15deepcompare: the .bin "
            "layout of loader.cpp; .npz arrays named as in the authors' PyTorch port)",
            readers={".bin": _read_siam_bin, ".npz": _load_npz},
            expected="the authors' .bin or .npz",
            shapes=SIAM_SHAPES,
        ),
        WeightFormat(
            name="tfeat",
            label="TFeat",
            provenance="TFeat (Balntas et al. 2016; vbalnt/tfeat tfeat_model.py state dict)",
            readers={".npz": _load_npz, "*": load_state_dict},
            shapes=TFEAT_SHAPES,
        ),
        WeightFormat(
            name="disk",
            label="DISK",
            provenance="DISK U-Net (Tyszkiewicz et al. 2020; cvlab-epfl/disk save files, {'extractor': state_dict})",
            readers={"*": load_torch_file},
            convert=_disk_unet,
        ),
    )
}


def weight_format(name: str) -> WeightFormat:
    """The table entry ``name``; :class:`InputError` listing the known formats otherwise."""
    try:
        return FORMATS[name]
    except KeyError:
        raise InputError(f"unknown weight format {name!r}; known: {', '.join(FORMATS)}") from None


def read_weights(format: str, path: str | os.PathLike[str]) -> Any:
    """Read the existing file ``path`` in the format ``format`` (a key of :data:`FORMATS`).

    Raises
    ------
    InputError
        Unknown format or suffix, unreadable file, missing arrays or wrong shapes.
    """
    return weight_format(format).read(path)


def load_weights(key: str, path: str | os.PathLike[str] | None = None) -> Any:
    """Find the weights of catalogue entry ``key`` (or check the explicit ``path``) and read them in its format.

    Raises
    ------
    InputError
        Unknown key, a file found nowhere (the message says where to get it), or an unreadable file.
    """
    info = weight_info(key)
    if not info.format:
        raise InputError(f"weight file {key!r} has no reader in dmtrack")
    return read_weights(info.format, find_weights(key, path))


# ------------------------------------------------------------------------------------------ by name
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
    return read_weights("alexnet-conv1", path)


def load_siamese(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Read the descriptor branch of the Zagoruyko–Komodakis "siam" network.

    Formats (by suffix): ``.bin`` – the authors' binary format (cvpr15deepcompare ``loader.cpp``, see
    :func:`_read_siam_bin`); ``.npz`` – arrays named as in the authors' PyTorch port (``conv0.weight``
    96×1×7×7, ``conv0.bias``, ``conv1.weight`` 192×96×5×5, ``conv1.bias``, ``conv2.weight`` 256×192×3×3,
    ``conv2.bias``).

    Returns
    -------
    dict
        ``name -> float32 array`` with the shapes of :data:`SIAM_SHAPES`.
    """
    return read_weights("siam", path)


def load_tfeat(path: str | os.PathLike[str] | None = None) -> dict[str, np.ndarray]:
    """TFeat state dict (``features.1``/``features.4`` convolutions, ``descr.0`` linear) as float32 arrays.

    ``path`` defaults to the shipped ``tfeat-liberty.params``; ``.npz`` files with the same array names are
    accepted too.
    """
    return load_weights("tfeat", path)


def load_disk(path: str | os.PathLike[str] | None = None) -> dict[str, np.ndarray]:
    """DISK U-Net state dict (keys ``unet.*``) from ``{'extractor': state_dict}`` or a bare state dict.

    ``path`` defaults to the shipped ``disk-depth-save.pth``.
    """
    return load_weights("disk", path)
