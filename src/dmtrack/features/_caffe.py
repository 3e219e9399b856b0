"""Minimal protocol-buffers wire-format reader, enough to pull weights out of ``.caffemodel`` and ``.onnx`` files.

Neither Caffe nor the ``protobuf``/``onnx`` packages are needed: a protobuf message is a flat sequence of
``(field number, wire type, payload)`` records, and the few fields that hold convolution weights are read by
their field numbers, taken from ``caffe.proto`` (BVLC/caffe, ``src/caffe/proto/caffe.proto``) and ``onnx.proto``.

Caffe field numbers used here::

    NetParameter      name = 1, layers = 2 (V1LayerParameter, deprecated), layer = 100 (LayerParameter)
    LayerParameter    name = 1, type = 2 (string), blobs = 7
    V1LayerParameter  layer = 1 (V0LayerParameter), name = 4, type = 5 (enum), blobs = 6
    V0LayerParameter  name = 1, type = 2 (string), blobs = 50
    BlobProto         num = 1, channels = 2, height = 3, width = 4 (legacy 4-D shape),
                      data = 5 (packed float), shape = 7 (BlobShape), double_data = 8 (packed double)
    BlobShape         dim = 1 (packed int64)

Every parser works on a ``memoryview`` of the file, so the 230 MB BVLC AlexNet model is read once and only the
requested layer is decoded.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dmtrack.errors import InputError

# wire types
VARINT = 0
FIXED64 = 1
LENGTH = 2
FIXED32 = 5


class ProtobufError(ValueError):
    """The bytes are not a well-formed protocol-buffers message."""


def read_varint(buf: memoryview, pos: int) -> tuple[int, int]:
    """Decode one base-128 varint at ``pos``; return ``(value, new_pos)`` (value as unsigned 64-bit)."""
    result = 0
    shift = 0
    n = len(buf)
    while True:
        if pos >= n:
            raise ProtobufError("truncated varint")
        b = buf[pos]
        pos += 1
        result |= (b & 0x7F) << shift
        if not b & 0x80:
            return result, pos
        shift += 7
        if shift > 63:
            raise ProtobufError("varint longer than 10 bytes")


def iter_fields(buf: bytes | memoryview) -> Iterator[tuple[int, int, int | memoryview]]:
    """Iterate over the top-level fields of one serialised message.

    Parameters
    ----------
    buf
        The message bytes.

    Yields
    ------
    (field_number, wire_type, value)
        ``value`` is an ``int`` for varints, a ``memoryview`` (no copy) for length-delimited fields and the raw
        4 or 8 bytes (``memoryview``) for fixed32/fixed64 fields.
    """
    mv = memoryview(buf)
    pos = 0
    n = len(mv)
    while pos < n:
        key, pos = read_varint(mv, pos)
        field, wire = key >> 3, key & 7
        if field == 0:
            raise ProtobufError("field number 0")
        if wire == VARINT:
            value, pos = read_varint(mv, pos)
            yield field, wire, value
        elif wire == LENGTH:
            length, pos = read_varint(mv, pos)
            if pos + length > n:
                raise ProtobufError("length-delimited field runs past the end of the message")
            yield field, wire, mv[pos : pos + length]
            pos += length
        elif wire == FIXED32:
            if pos + 4 > n:
                raise ProtobufError("truncated fixed32")
            yield field, wire, mv[pos : pos + 4]
            pos += 4
        elif wire == FIXED64:
            if pos + 8 > n:
                raise ProtobufError("truncated fixed64")
            yield field, wire, mv[pos : pos + 8]
            pos += 8
        else:  # groups (3, 4) are not used by caffe.proto or onnx.proto
            raise ProtobufError(f"unsupported wire type {wire}")


def packed_varints(value: int | memoryview) -> list[int]:
    """Values of a repeated integer field occurrence, packed (length-delimited) or not (a single varint)."""
    if isinstance(value, int):
        return [value]
    out = []
    pos = 0
    while pos < len(value):
        v, pos = read_varint(value, pos)
        out.append(v)
    return out


def to_signed64(v: int) -> int:
    """Reinterpret an unsigned 64-bit varint as a signed int64."""
    return v - (1 << 64) if v >= 1 << 63 else v


def decode_string(value: int | memoryview) -> str:
    """Decode a length-delimited string field."""
    if isinstance(value, int):
        raise ProtobufError("expected a string, found a varint")
    return bytes(value).decode("utf-8", errors="replace")


@dataclass(frozen=True)
class CaffeLayer:
    """One layer of a Caffe ``NetParameter`` with its parameter blobs.

    Attributes
    ----------
    name
        Layer name (e.g. ``"conv1"``).
    type
        Layer type as a string (``"Convolution"``) for the current format, the V1 enum number as a string
        (``"4"`` is CONVOLUTION) for ``layers`` (V1) entries, or the V0 type string.
    blobs
        Parameter blobs in file order (for convolutions: weight ``(out, in, kh, kw)`` then bias ``(out,)``),
        float32.
    """

    name: str
    type: str
    blobs: tuple[np.ndarray, ...]


def _parse_blob(buf: memoryview) -> np.ndarray:
    """Decode a ``BlobProto`` into a float32 array of its shape."""
    chunks: list[np.ndarray] = []
    dchunks: list[np.ndarray] = []
    shape: list[int] | None = None
    legacy = {1: 0, 2: 0, 3: 0, 4: 0}
    for field, wire, value in iter_fields(buf):
        if field == 5:  # data, packed float (or unpacked fixed32 entries)
            chunks.append(np.frombuffer(value, dtype="<f4"))
        elif field == 8:  # double_data
            dchunks.append(np.frombuffer(value, dtype="<f8"))
        elif field == 7 and wire == LENGTH:
            dims: list[int] = []
            for f2, _w2, v2 in iter_fields(value):
                if f2 == 1:
                    dims.extend(to_signed64(d) for d in packed_varints(v2))
            shape = dims
        elif field in legacy and wire == VARINT:
            legacy[field] = to_signed64(value)
    if chunks:
        data = np.concatenate(chunks).astype(np.float32)
    elif dchunks:
        data = np.concatenate(dchunks).astype(np.float32)
    else:
        data = np.zeros(0, np.float32)
    if shape is None:
        dims4 = [legacy[1], legacy[2], legacy[3], legacy[4]]
        # Legacy blobs store 4-D shapes; biases were stored as (1, 1, 1, n).
        shape = [d for d in dims4 if d > 0] if any(dims4) else [data.size]
        if int(np.prod(shape)) != data.size:
            shape = [data.size]
    if int(np.prod(shape)) != data.size:
        raise ProtobufError(f"blob shape {shape} does not match its {data.size} values")
    return data.reshape(shape)


def _parse_layer(buf: memoryview, kind: str) -> tuple[str, str, memoryview]:
    """Return ``(name, type, buf)`` of a layer message without decoding its blobs."""
    name = ""
    ltype = ""
    for field, wire, value in iter_fields(buf):
        if kind == "layer":
            if field == 1 and wire == LENGTH:
                name = decode_string(value)
            elif field == 2 and wire == LENGTH:
                ltype = decode_string(value)
        elif kind == "v1":
            if field == 4 and wire == LENGTH:
                name = decode_string(value)
            elif field == 5 and wire == VARINT:
                ltype = str(value)
            elif field == 1 and wire == LENGTH and not name:  # V0 layer nested in a V1 entry
                n0, t0, _ = _parse_layer(value, "v0")
                name, ltype = n0, ltype or t0
        else:  # v0
            if field == 1 and wire == LENGTH:
                name = decode_string(value)
            elif field == 2 and wire == LENGTH:
                ltype = decode_string(value)
    return name, ltype, buf


def _layer_blobs(buf: memoryview, kind: str) -> tuple[np.ndarray, ...]:
    blob_field = {"layer": 7, "v1": 6, "v0": 50}[kind]
    blobs = []
    for field, wire, value in iter_fields(buf):
        if field == blob_field and wire == LENGTH:
            blobs.append(_parse_blob(value))
        elif kind == "v1" and field == 1 and wire == LENGTH:
            blobs.extend(_layer_blobs(value, "v0"))
    return tuple(blobs)


def caffe_layer_names(data: bytes | memoryview) -> list[str]:
    """Names of all layers of a serialised ``NetParameter`` (both the current and the deprecated V1 lists)."""
    names = []
    for field, wire, value in iter_fields(data):
        if wire != LENGTH:
            continue
        if field == 100:
            names.append(_parse_layer(value, "layer")[0])
        elif field == 2:
            names.append(_parse_layer(value, "v1")[0])
    return names


def read_caffe_layer(path: str | Path, layer_name: str) -> CaffeLayer:
    """Read the parameter blobs of one layer from a binary ``.caffemodel``.

    Parameters
    ----------
    path
        The ``.caffemodel`` file (a serialised ``caffe.NetParameter``).
    layer_name
        Name of the layer, e.g. ``"conv1"``.

    Returns
    -------
    CaffeLayer

    Raises
    ------
    InputError
        The file cannot be read, is not a protobuf message, or has no layer of that name (the message lists the
        layers it has).
    """
    path = Path(path)
    try:
        data = memoryview(path.read_bytes())
    except OSError as exc:
        raise InputError(f"cannot read Caffe model: {exc.strerror or exc}", path=path) from exc
    try:
        names = []
        for field, wire, value in iter_fields(data):
            if wire != LENGTH or field not in (2, 100):
                continue
            kind = "layer" if field == 100 else "v1"
            name, ltype, buf = _parse_layer(value, kind)
            names.append(name)
            if name == layer_name:
                return CaffeLayer(name=name, type=ltype, blobs=_layer_blobs(buf, kind))
    except ProtobufError as exc:
        raise InputError(f"not a valid Caffe model (protobuf NetParameter): {exc}", path=path) from exc
    listed = ", ".join(names[:20]) if names else "none"
    raise InputError(f"Caffe model has no layer named {layer_name!r} (layers: {listed})", path=path)


# --------------------------------------------------------------------------------------------------------------
# ONNX (onnx.proto): ModelProto.graph = 7; GraphProto.node = 1, initializer = 5;
# NodeProto.input = 1, output = 2, name = 3, op_type = 4;
# TensorProto.dims = 1, data_type = 2, float_data = 4, name = 8, raw_data = 9, double_data = 10,
#             external_data = 13, data_location = 14.  data_type: 1 FLOAT, 10 FLOAT16, 11 DOUBLE.

_ONNX_DTYPES = {1: "<f4", 10: "<f2", 11: "<f8"}


@dataclass(frozen=True)
class OnnxNode:
    """An ONNX graph node: operator type, name, input and output value names."""

    op_type: str
    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]


def _parse_onnx_tensor(buf: memoryview) -> tuple[str, np.ndarray | None, str]:
    """Decode a ``TensorProto``: ``(name, array or None, problem)``."""
    name = ""
    dims: list[int] = []
    dtype = 0
    raw: memoryview | None = None
    floats: list[np.ndarray] = []
    doubles: list[np.ndarray] = []
    external = False
    for field, wire, value in iter_fields(buf):
        if field == 1:
            dims.extend(to_signed64(d) for d in packed_varints(value))
        elif field == 2 and wire == VARINT:
            dtype = value
        elif field == 4:  # packed, or one fixed32 per entry
            floats.append(np.frombuffer(value, dtype="<f4"))
        elif field == 10:
            doubles.append(np.frombuffer(value, dtype="<f8"))
        elif field == 8 and wire == LENGTH:
            name = decode_string(value)
        elif field == 9 and wire == LENGTH:
            raw = value
        elif field == 14 and wire == VARINT and value == 1:
            external = True
    if external:
        return name, None, "stored as ONNX external data (a separate file); not supported"
    if raw is not None:
        if dtype not in _ONNX_DTYPES:
            return name, None, f"unsupported ONNX data type {dtype}"
        arr = np.frombuffer(raw, dtype=_ONNX_DTYPES[dtype]).astype(np.float32)
    elif floats:
        arr = np.concatenate(floats).astype(np.float32)
    elif doubles:
        arr = np.concatenate(doubles).astype(np.float32)
    else:
        arr = np.zeros(0, np.float32)
    shape = dims if dims else [arr.size]
    if int(np.prod(shape)) != arr.size:
        return name, None, f"tensor shape {dims} does not match its {arr.size} values"
    return name, arr.reshape(shape), ""


def read_onnx_graph(path: str | Path) -> tuple[list[OnnxNode], dict[str, memoryview]]:
    """Read the nodes and the (undecoded) initializers of an ONNX model.

    Parameters
    ----------
    path
        An ``.onnx`` file (a serialised ``onnx.ModelProto``).

    Returns
    -------
    nodes, initializers
        The graph nodes in file (topological) order, and ``name -> TensorProto bytes`` for every initializer;
        decode the ones you need with :func:`decode_onnx_tensor` (the big fully-connected layers of a
        classification network are never copied).
    """
    path = Path(path)
    try:
        data = memoryview(path.read_bytes())
    except OSError as exc:
        raise InputError(f"cannot read ONNX model: {exc.strerror or exc}", path=path) from exc
    nodes: list[OnnxNode] = []
    inits: dict[str, memoryview] = {}
    try:
        graph = None
        for field, wire, value in iter_fields(data):
            if field == 7 and wire == LENGTH:
                graph = value
        if graph is None:
            raise InputError("not an ONNX model: no graph (ModelProto field 7)", path=path)
        for field, wire, value in iter_fields(graph):
            if field == 1 and wire == LENGTH:
                ins: list[str] = []
                outs: list[str] = []
                name = op = ""
                for f2, w2, v2 in iter_fields(value):
                    if w2 != LENGTH:
                        continue
                    if f2 == 1:
                        ins.append(decode_string(v2))
                    elif f2 == 2:
                        outs.append(decode_string(v2))
                    elif f2 == 3:
                        name = decode_string(v2)
                    elif f2 == 4:
                        op = decode_string(v2)
                nodes.append(OnnxNode(op, name, tuple(ins), tuple(outs)))
            elif field == 5 and wire == LENGTH:
                for f2, w2, v2 in iter_fields(value):
                    if f2 == 8 and w2 == LENGTH:
                        inits[decode_string(v2)] = value
                        break
    except ProtobufError as exc:
        raise InputError(f"not a valid ONNX model (protobuf ModelProto): {exc}", path=path) from exc
    return nodes, inits


def decode_onnx_tensor(buf: memoryview, path: str | Path | None = None) -> np.ndarray:
    """Decode an ONNX ``TensorProto`` (float32, float16 or float64 data) into a float32 array of its shape."""
    try:
        name, arr, problem = _parse_onnx_tensor(buf)
    except ProtobufError as exc:
        raise InputError(f"malformed ONNX tensor: {exc}", path=path) from exc
    if arr is None:
        raise InputError(f"ONNX initializer {name!r}: {problem}", path=path)
    return arr
