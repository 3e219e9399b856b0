"""AlexNet conv1 feature: every weight loader on files written here in the exact format, and the output against an
independent direct convolution with Caffe's input convention."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import correlate

from dmtrack.errors import InputError
from dmtrack.features import get_feature, weights
from dmtrack.features.alexnet import AlexNet64Feature, AlexNetFeature

# Caffe's per-channel ILSVRC 2012 means in B, G, R order, written out here independently of the package.
BGR_MEAN = np.array([104.00698793, 116.66876762, 122.67891434])
BACKENDS = ["fft", "numpy", pytest.param("torch", marks=pytest.mark.skipif(
    __import__("importlib").util.find_spec("torch") is None, reason="PyTorch not installed"))]


# ---------------------------------------------------------------------------- minimal protobuf writer
def _varint(v: int) -> bytes:
    v &= (1 << 64) - 1
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        out.append(b | (0x80 if v else 0))
        if not v:
            return bytes(out)


def _key(field: int, wire: int) -> bytes:
    return _varint((field << 3) | wire)


def _ld(field: int, payload: bytes) -> bytes:
    return _key(field, 2) + _varint(len(payload)) + payload


def _str(field: int, s: str) -> bytes:
    return _ld(field, s.encode())


def _uint(field: int, v: int) -> bytes:
    return _key(field, 0) + _varint(v)


def _packed_f32(field: int, a: np.ndarray) -> bytes:
    return _ld(field, np.asarray(a, "<f4").ravel().tobytes())


def _blob(a: np.ndarray, legacy: bool = False) -> bytes:
    """caffe.BlobProto: shape (7, BlobShape.dim = 1 packed) or legacy num/channels/height/width (1-4); data = 5."""
    if legacy:
        dims = [1] * (4 - a.ndim) + list(a.shape)
        head = b"".join(_uint(f, d) for f, d in zip((1, 2, 3, 4), dims, strict=True))
    else:
        head = _ld(7, _ld(1, b"".join(_varint(d) for d in a.shape)))
    return head + _packed_f32(5, a)


def caffemodel_bytes(w: np.ndarray, b: np.ndarray, v1: bool = False) -> bytes:
    """A NetParameter with a data layer, conv1 and conv2, in the current (layer = 100) or V1 (layers = 2) form."""
    rng = np.random.default_rng(5)
    conv2 = rng.standard_normal((4, 96, 5, 5)).astype(np.float32)
    if v1:  # V1LayerParameter: bottom 2, top 3, name 4, type 5 (enum; 4 = CONVOLUTION, 5 = DATA), blobs 6
        layers = [
            _str(4, "data") + _uint(5, 5) + _str(3, "data"),
            _str(2, "data") + _str(3, "conv1") + _str(4, "conv1") + _uint(5, 4)
            + _ld(6, _blob(w, legacy=True)) + _ld(6, _blob(b, legacy=True)),
            _str(4, "conv2") + _uint(5, 4) + _ld(6, _blob(conv2, legacy=True)),
        ]
        return _str(1, "CaffeNet") + b"".join(_ld(2, layer) for layer in layers)
    layers = [  # LayerParameter: name 1, type 2, bottom 3, top 4, blobs 7
        _str(1, "data") + _str(2, "Input") + _str(4, "data"),
        _str(1, "conv1") + _str(2, "Convolution") + _str(3, "data") + _str(4, "conv1")
        + _ld(7, _blob(w)) + _ld(7, _blob(b)),
        _str(1, "relu1") + _str(2, "ReLU"),
        _str(1, "conv2") + _str(2, "Convolution") + _ld(7, _blob(conv2)),
    ]
    return _str(1, "AlexNet") + b"".join(_ld(100, layer) for layer in layers)


def onnx_bytes(w: np.ndarray, b: np.ndarray) -> bytes:
    """ModelProto(ir_version 1, graph 7) with GraphProto(node 1, name 2, initializer 5); TensorProto(dims 1,
    data_type 2, float_data 4, name 8, raw_data 9); NodeProto(input 1, output 2, name 3, op_type 4)."""
    def tensor(name: str, a: np.ndarray, raw: bool) -> bytes:
        dims = b"".join(_uint(1, d) for d in a.shape)  # unpacked repeated int64
        data = _ld(9, np.asarray(a, "<f4").tobytes()) if raw else _packed_f32(4, a)
        return dims + _uint(2, 1) + _str(8, name) + data

    big = np.ones((16, 8), np.float32)  # an unrelated initializer (like fc6) that must be skipped
    node1 = _str(1, "data_0") + _str(1, "conv1_w_0") + _str(1, "conv1_b_0") + _str(2, "conv1_1") + _str(3, "") \
        + _str(4, "Conv")
    node2 = _str(1, "conv1_1") + _str(2, "conv1_2") + _str(4, "Relu")
    graph = (_ld(1, node1) + _ld(1, node2) + _str(2, "alexnet")
             + _ld(5, tensor("fc6_w_0", big, True))
             + _ld(5, tensor("conv1_w_0", w, True)) + _ld(5, tensor("conv1_b_0", b, False)))
    return _uint(1, 3) + _str(2, "test") + _ld(7, graph)


@pytest.fixture(scope="module")
def conv1() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    w = (rng.standard_normal((96, 3, 11, 11)) * 0.01).astype(np.float32)
    b = (rng.standard_normal(96) * 0.5).astype(np.float32)
    return w, b


@pytest.fixture(scope="module")
def npz_path(tmp_path_factory, conv1) -> str:
    p = tmp_path_factory.mktemp("w") / "alexnet-conv1.npz"
    np.savez(p, weight=conv1[0], bias=conv1[1])
    return str(p)


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    rng = np.random.default_rng(1)
    return rng.integers(0, 256, (40, 48, 3), dtype=np.uint8)


def reference_caffe(img: np.ndarray, w: np.ndarray, b: np.ndarray) -> np.ndarray:
    """ReLU(conv1) at stride 1 with zero padding 5 on Caffe's input (BGR, 0..255 minus the ILSVRC means)."""
    bgr = img[:, :, ::-1].astype(np.float64) - BGR_MEAN
    x = np.pad(bgr, ((5, 5), (5, 5), (0, 0)))
    out = np.empty(img.shape[:2] + (w.shape[0],))
    for k in range(w.shape[0]):
        acc = sum(correlate(x[:, :, c], w[k, c].astype(np.float64), mode="valid") for c in range(3))
        out[:, :, k] = np.maximum(acc + b[k], 0)
    return out


# ---------------------------------------------------------------------------------------- loaders
@pytest.mark.parametrize("v1", [False, True], ids=["layer", "v1-layers"])
def test_caffemodel_loader(tmp_path, conv1, v1):
    p = tmp_path / "bvlc_alexnet.caffemodel"
    p.write_bytes(caffemodel_bytes(*conv1, v1=v1))
    c = weights.load_alexnet_conv1(p)
    np.testing.assert_array_equal(c.weight, conv1[0])
    np.testing.assert_array_equal(c.bias, conv1[1])
    assert (c.channel_order, c.convention) == ("BGR", "caffe")


def test_caffemodel_without_conv1_lists_layers(tmp_path, conv1):
    p = tmp_path / "net.caffemodel"
    p.write_bytes(caffemodel_bytes(*conv1).replace(b"conv1", b"convX"))
    with pytest.raises(InputError, match=r"no layer named 'conv1' \(layers: data, convX, relu1, conv2\)"):
        weights.load_alexnet_conv1(p)


def test_onnx_loader(tmp_path, conv1):
    p = tmp_path / "bvlcalexnet-12.onnx"
    p.write_bytes(onnx_bytes(*conv1))
    c = weights.load_alexnet_conv1(p)
    np.testing.assert_array_equal(c.weight, conv1[0])
    np.testing.assert_array_equal(c.bias, conv1[1])
    assert c.channel_order == "BGR"


@pytest.mark.parametrize("zipped", [True, False], ids=["zip", "legacy"])
def test_torchvision_state_dict_loader(tmp_path, zipped):
    torch = pytest.importorskip("torch", reason="writing a torchvision-style state dict needs PyTorch")
    g = torch.Generator().manual_seed(0)
    sd = {
        "features.0.weight": torch.randn(64, 3, 11, 11, generator=g),
        "features.0.bias": torch.randn(64, generator=g),
        "features.3.weight": torch.randn(192, 64, 5, 5, generator=g),
        "classifier.6.bias": torch.randn(1000, generator=g),
    }
    p = tmp_path / "alexnet-owt-7be5be79.pth"
    torch.save(sd, p, _use_new_zipfile_serialization=zipped)
    c = weights.load_alexnet_conv1(p)
    np.testing.assert_array_equal(c.weight, sd["features.0.weight"].numpy())
    assert (c.channel_order, c.convention) == ("RGB", "torchvision")


def test_npz_loader_and_errors(tmp_path, conv1, npz_path):
    c = weights.load_alexnet_conv1(npz_path)
    np.testing.assert_array_equal(c.weight, conv1[0])
    np.savez(tmp_path / "bad.npz", weight=np.zeros((96, 3, 10, 10)), bias=np.zeros(96))
    with pytest.raises(InputError, match="odd k"):
        weights.load_alexnet_conv1(tmp_path / "bad.npz")
    np.savez(tmp_path / "bias.npz", weight=np.zeros((96, 3, 11, 11)), bias=np.zeros(95))
    with pytest.raises(InputError, match="96 values"):
        weights.load_alexnet_conv1(tmp_path / "bias.npz")
    (tmp_path / "x.h5").write_bytes(b"")
    with pytest.raises(InputError, match="unknown AlexNet weight format"):
        weights.load_alexnet_conv1(tmp_path / "x.h5")


# ---------------------------------------------------------------------------------------- output
@pytest.mark.parametrize("backend", BACKENDS)
def test_output_equals_direct_convolution_with_caffe_convention(image, conv1, npz_path, backend):
    f = AlexNetFeature(scale=1.0, weights=npz_path, backend=backend)
    out = f.compute(image)
    assert out.shape == (40, 48, 96) and out.dtype == np.float32 and out.flags.c_contiguous
    ref = reference_caffe(image, *conv1)
    np.testing.assert_allclose(out, ref, rtol=1e-4, atol=1e-3)
    assert 0.2 < (out > 0).mean() < 0.8  # the ReLU is active on part of the map: the test exercises both sides
    scaled = AlexNetFeature(scale=1.23, weights=npz_path, backend=backend).compute(image)
    np.testing.assert_allclose(scaled, 1.23 * out, rtol=1e-4, atol=1e-3)


def test_caffe_loaders_give_the_same_feature(tmp_path, image, conv1, npz_path):
    (tmp_path / "bvlc_alexnet.caffemodel").write_bytes(caffemodel_bytes(*conv1))
    (tmp_path / "bvlcalexnet-9.onnx").write_bytes(onnx_bytes(*conv1))
    ref = AlexNetFeature(weights=npz_path, backend="numpy").compute(image)
    for name in ("bvlc_alexnet.caffemodel", "bvlcalexnet-9.onnx"):
        out = AlexNetFeature(weights=tmp_path / name, backend="numpy").compute(image)
        np.testing.assert_array_equal(out, ref)


def test_grey_input_is_replicated(conv1, npz_path):
    grey = np.random.default_rng(2).integers(0, 256, (24, 30), dtype=np.uint8)
    f = AlexNetFeature(weights=npz_path, backend="numpy")
    np.testing.assert_array_equal(f.compute(grey), f.compute(np.repeat(grey[:, :, None], 3, axis=2)))


@pytest.mark.parametrize("backend", BACKENDS)
def test_alexnet64_uses_torchvision_convention(tmp_path, image, backend):
    rng = np.random.default_rng(3)
    w = (rng.standard_normal((64, 3, 11, 11)) * 0.05).astype(np.float32)
    b = rng.standard_normal(64).astype(np.float32)
    p = tmp_path / "alexnet-owt-7be5be79.npz"
    np.savez(p, weight=w, bias=b, channel_order="RGB")
    out = AlexNet64Feature(weights=p, backend=backend).compute(image)
    x = (image / 255.0 - np.array([0.485, 0.456, 0.406])) / np.array([0.229, 0.224, 0.225])
    x = np.pad(x, ((5, 5), (5, 5), (0, 0)))
    for k in (0, 17, 63):
        ref = np.maximum(sum(correlate(x[:, :, c], w[k, c], mode="valid") for c in range(3)) + b[k], 0)
        np.testing.assert_allclose(out[:, :, k], ref, rtol=1e-4, atol=1e-4)
    assert out.shape == (40, 48, 64)


def test_registry_and_pca_variant(image, npz_path):
    from dmtrack.features.pca import fit_pca

    f = get_feature("alexnet", weights=npz_path, backend="numpy")
    assert f.name == "alexnet" and f.channels == 96 and f.scale == pytest.approx(1.23) and f.needs_colour
    imgs = [np.random.default_rng(s).integers(0, 256, (32, 40, 3), dtype=np.uint8) for s in range(3)]
    basis = fit_pca(f, imgs, n_samples=2000, seed=0)
    reduced = get_feature("alexnet-pca8", pca=basis, weights=npz_path, backend="numpy")
    out = reduced.compute(image)
    assert out.shape == (40, 48, 8)
    full = f.compute(image).reshape(-1, 96).astype(np.float64)
    expected = (full - basis.mean) @ basis.components[:8].T
    np.testing.assert_allclose(out.reshape(-1, 8), expected, rtol=1e-3, atol=1e-2)


@pytest.mark.parametrize("backend", BACKENDS)
def test_fused_projection_equals_projecting_the_map(image, npz_path, backend):
    f = AlexNetFeature(weights=npz_path, backend=backend)
    rng = np.random.default_rng(4)
    pw = rng.standard_normal((5, 96)).astype(np.float32)
    pb = rng.standard_normal(5).astype(np.float32)
    fused = f.compute_projected(image, pw, pb)
    plain = f.compute(image) @ pw.T + pb
    np.testing.assert_allclose(fused, plain, rtol=1e-4, atol=1e-3)


@pytest.mark.parametrize("backend", BACKENDS)
def test_many_tiles_and_partial_edge_tiles(conv1, npz_path, backend):
    """An image several FFT tiles wide and high, not a multiple of the tile size: every tile seam and the cropped
    last row/column of tiles must match the direct convolution (and the fused projection the plain one)."""
    from dmtrack.features.alexnet import fft_length

    img = np.random.default_rng(7).integers(0, 256, (150, 203, 3), dtype=np.uint8)
    fh, fw = fft_length(150, 11), fft_length(203, 11)
    assert 150 % (fh - 10) and 203 % (fw - 10) and 150 > 2 * (fh - 10) and 203 > 2 * (fw - 10)
    f = AlexNetFeature(scale=1.0, weights=npz_path, backend=backend)
    out = f.compute(img)
    ref = reference_caffe(img, *conv1)
    np.testing.assert_allclose(out, ref, rtol=1e-4, atol=1e-3)
    rng = np.random.default_rng(8)
    pw = rng.standard_normal((3, 96)).astype(np.float32)
    pb = rng.standard_normal(3).astype(np.float32)
    np.testing.assert_allclose(f.compute_projected(img, pw, pb), ref @ pw.T + pb, rtol=1e-4, atol=2e-3)


def test_fft_is_deterministic_across_thread_counts(conv1, npz_path):
    from dmtrack.features.alexnet import alexnet_input, conv1_relu

    img = np.random.default_rng(9).integers(0, 256, (120, 170, 3), dtype=np.uint8)
    f = AlexNetFeature(weights=npz_path, backend="fft")
    x = alexnet_input(img, f.conv1)
    proj = (np.random.default_rng(10).standard_normal((4, 96)).astype(np.float32), np.ones(4, np.float32))
    for project in (None, proj):
        one = conv1_relu(x, f.conv1, 1.23, "fft", project=project, threads=1)
        for n in (2, 3):
            np.testing.assert_array_equal(conv1_relu(x, f.conv1, 1.23, "fft", project=project, threads=n), one)


def test_backend_choice(npz_path):
    from dmtrack.features.alexnet import AUTO_BACKEND, resolve_backend

    assert resolve_backend("auto") == AUTO_BACKEND == "fft"
    assert AlexNetFeature(weights=npz_path).backend == "fft"
    with pytest.raises(InputError, match="backend must be one of"):
        AlexNetFeature(weights=npz_path, backend="cuda")


def test_missing_weights_error(tmp_path, monkeypatch):
    monkeypatch.delenv(weights.WEIGHTS_ENV, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    with pytest.raises(InputError) as exc:
        get_feature("alexnet")
    msg = str(exc.value)
    assert "http://dl.caffe.berkeleyvision.org/bvlc_alexnet.caffemodel" in msg
    assert "$DMTRACK_WEIGHTS" in msg and ".cache/dmtrack/weights" in msg
