"""Weight files: locations, missing-file errors, checksums, download (no network), protobuf and torch readers."""

from __future__ import annotations

import collections
import hashlib
import io
import pickle
import struct
import tarfile
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.features import _caffe
from dmtrack.features import weights as W
from dmtrack.features.weights import torchfile

SHIPPED = {"tfeat": "tfeat-liberty.params", "disk": "disk-depth-save.pth"}


@pytest.fixture
def isolated(tmp_path, monkeypatch):
    """No $DMTRACK_WEIGHTS and an empty home, so only the package directory can hold weights."""
    monkeypatch.delenv(W.WEIGHTS_ENV, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    return tmp_path


# ------------------------------------------------------------------------------------------ protobuf
def _varint(v: int) -> bytes:
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        out.append(b | (0x80 if v else 0))
        if not v:
            return bytes(out)


def test_wire_format_reader_decodes_every_wire_type():
    nested = _varint((1 << 3) | 0) + _varint(300)
    floats = np.array([1.5, -2.0, 3.25], "<f4").tobytes()
    msg = (
        _varint((1 << 3) | 0) + _varint(150)
        + _varint((2 << 3) | 2) + _varint(len(nested)) + nested
        + _varint((3 << 3) | 5) + struct.pack("<f", 0.5)
        + _varint((4 << 3) | 1) + struct.pack("<d", 2.5)
        + _varint((5 << 3) | 2) + _varint(len(floats)) + floats
        + _varint((100 << 3) | 0) + _varint(2**63 + 5)
    )
    fields = list(_caffe.iter_fields(msg))
    assert [(f, w) for f, w, _ in fields] == [(1, 0), (2, 2), (3, 5), (4, 1), (5, 2), (100, 0)]
    assert fields[0][2] == 150
    assert list(_caffe.iter_fields(fields[1][2])) == [(1, 0, 300)]
    assert struct.unpack("<f", fields[2][2])[0] == 0.5
    assert struct.unpack("<d", fields[3][2])[0] == 2.5
    np.testing.assert_array_equal(np.frombuffer(fields[4][2], "<f4"), [1.5, -2.0, 3.25])
    assert _caffe.to_signed64(fields[5][2]) == -(2**63) + 5
    assert _caffe.packed_varints(_varint(3) + _varint(70000)) == [3, 70000]


@pytest.mark.parametrize(
    "bad",
    [b"\x08", b"\x0a\x05abc", b"\x0d\x00\x00", b"\x0b", b"\x00\x01"],
    ids=["truncated-varint", "short-length", "short-fixed32", "group", "field-0"],
)
def test_wire_format_reader_rejects_malformed(bad):
    with pytest.raises(_caffe.ProtobufError):
        list(_caffe.iter_fields(bad))


def test_non_protobuf_caffemodel_is_an_input_error(tmp_path):
    p = tmp_path / "bad.caffemodel"
    p.write_bytes(b"\x0b garbage")
    with pytest.raises(InputError, match="not a valid Caffe model"):
        _caffe.read_caffe_layer(p, "conv1")


# ------------------------------------------------------------------------------------------ locations
def test_shipped_weights_are_packaged_with_their_checksums(isolated):
    for key, filename in SHIPPED.items():
        path = W.find_weights(key)
        assert path == W.package_weights_dir() / filename
        assert W.verify_checksum(path, W.CATALOGUE[key]) == W.CATALOGUE[key].sha256
    prov = (W.package_weights_dir() / "PROVENANCE.md").read_text()
    for key, filename in SHIPPED.items():
        assert filename in prov and W.CATALOGUE[key].sha256 in prov


def test_search_order_env_then_cache(isolated, monkeypatch):
    env_dir = isolated / "env"
    cache = isolated / "home" / ".cache" / "dmtrack" / "weights"
    cache.mkdir(parents=True)
    (cache / "siam_liberty.bin").write_bytes(b"cache")
    assert W.find_weights("siamese") == cache / "siam_liberty.bin"
    env_dir.mkdir()
    (env_dir / "siam_liberty.npz").write_bytes(b"env")  # an alternative name in the first directory wins
    monkeypatch.setenv(W.WEIGHTS_ENV, str(env_dir))
    assert W.find_weights("siamese") == env_dir / "siam_liberty.npz"
    assert W.user_weights_dir() == env_dir
    explicit = isolated / "mine.bin"
    explicit.write_bytes(b"x")
    assert W.find_weights("siamese", explicit) == explicit


@pytest.mark.parametrize("key", ["alexnet", "siamese", "alexnet64"])
def test_missing_weights_error_says_where_to_get_and_put_them(isolated, key):
    with pytest.raises(InputError) as exc:
        W.find_weights(key)
    msg = str(exc.value)
    info = W.CATALOGUE[key]
    assert info.url in msg
    assert "$DMTRACK_WEIGHTS" in msg
    assert str(isolated / "home" / ".cache" / "dmtrack" / "weights") in msg
    assert "weights=PATH" in msg
    assert info.filename in msg


def test_missing_explicit_path(isolated):
    with pytest.raises(InputError, match="weight file not found") as exc:
        W.find_weights("alexnet", isolated / "nope.caffemodel")
    assert exc.value.path == isolated / "nope.caffemodel"


def test_unknown_key():
    with pytest.raises(InputError, match="unknown weight file 'vgg'"):
        W.find_weights("vgg")


# ------------------------------------------------------------------------------------------ download
class _FakeResponse:
    def __init__(self, data: bytes, status: int = 200):
        self._buf = io.BytesIO(data)
        self.status = status
        self.headers = {"Content-Length": str(len(data))}

    def read(self, n: int = -1) -> bytes:
        return self._buf.read(n)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def _serve(monkeypatch, payload: bytes, calls: list):
    def fake_urlopen(req, timeout=None):
        rng = req.get_header("Range")
        calls.append(rng)
        if rng:
            start = int(rng.split("=")[1].rstrip("-"))
            return _FakeResponse(payload[start:], status=206)
        return _FakeResponse(payload)

    monkeypatch.setattr(urllib.request, "urlopen", fake_urlopen)


def _add_entry(monkeypatch, **kw) -> W.WeightFile:
    info = W.WeightFile(key="test-net", description="test", licence="test", **kw)
    monkeypatch.setitem(W.CATALOGUE, "test-net", info)
    return info


def test_download_unreachable_is_a_clear_error(tmp_path, monkeypatch):
    def refuse(req, timeout=None):
        raise urllib.error.URLError("Name or service not known")

    monkeypatch.setattr(urllib.request, "urlopen", refuse)
    with pytest.raises(W.DownloadError, match=r"cannot download http://dl\.caffe.*Name or service not known"):
        W.download("alexnet", tmp_path)
    assert not (tmp_path / "bvlc_alexnet.caffemodel").exists()


def test_download_http_error(tmp_path, monkeypatch):
    def not_found(req, timeout=None):
        raise urllib.error.HTTPError(req.full_url, 404, "Not Found", {}, None)

    monkeypatch.setattr(urllib.request, "urlopen", not_found)
    with pytest.raises(W.DownloadError, match="HTTP 404"):
        W.download("siamese", tmp_path)


def test_download_argument_errors(tmp_path):
    with pytest.raises(InputError, match="unknown weight file"):
        W.download("resnet", tmp_path)
    with pytest.raises(InputError, match="timeout"):
        W.download("alexnet", tmp_path, timeout=0)


def test_download_resumes_and_verifies(tmp_path, monkeypatch):
    payload = bytes(range(256)) * 4096
    _add_entry(monkeypatch, filename="net.bin", url="http://example.invalid/net.bin",
               sha256=hashlib.sha256(payload).hexdigest())
    (tmp_path / "net.bin.part").write_bytes(payload[:1000])  # an interrupted earlier download
    calls: list = []
    _serve(monkeypatch, payload, calls)
    seen = []
    out = W.download("test-net", tmp_path, progress=lambda done, total: seen.append((done, total)))
    assert out == tmp_path / "net.bin"
    assert out.read_bytes() == payload
    assert calls == ["bytes=1000-"]
    assert seen[-1] == (len(payload), len(payload))
    assert not (tmp_path / "net.bin.part").exists()


def test_download_checksum_mismatch_discards_the_file(tmp_path, monkeypatch):
    _add_entry(monkeypatch, filename="net.bin", url="http://example.invalid/net.bin", sha1="0" * 40)
    _serve(monkeypatch, b"not the real file", [])
    with pytest.raises(W.DownloadError, match="sha1"):
        W.download("test-net", tmp_path)
    assert not (tmp_path / "net.bin").exists() and not (tmp_path / "net.bin.part").exists()


def test_download_without_published_checksum_records_one(tmp_path, monkeypatch):
    payload = b"weights"
    _add_entry(monkeypatch, filename="net.onnx", url="http://example.invalid/net.onnx")
    _serve(monkeypatch, payload, [])
    out = W.download("test-net", tmp_path / "sub")
    assert out.read_bytes() == payload
    assert (tmp_path / "sub" / "net.onnx.sha256").read_text().split()[0] == hashlib.sha256(payload).hexdigest()


def test_download_extracts_archive_member(tmp_path, monkeypatch):
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tar:
        for name, data in [("networks/siam/siam_liberty.bin", b"SIAM"), ("networks/2ch/2ch_liberty.bin", b"2CH")]:
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    _add_entry(monkeypatch, filename="siam_liberty.bin", url="http://example.invalid/nets.tar.gz",
               archive_member="siam_liberty.bin")
    _serve(monkeypatch, buf.getvalue(), [])
    out = W.download("test-net", tmp_path)
    assert out.read_bytes() == b"SIAM"
    _add_entry(monkeypatch, filename="siam_x.bin", url="http://example.invalid/nets.tar.gz",
               archive_member="siam_x.bin")
    with pytest.raises(W.DownloadError, match="no member ending in siam_x.bin.*2ch_liberty.bin"):
        W.download("test-net", tmp_path)


def test_cli_list_and_download_error(isolated, monkeypatch, capsys):
    assert W.main(["list"]) == 0
    out = capsys.readouterr().out
    assert "tfeat" in out and "missing" in out and "http://dl.caffe.berkeleyvision.org" in out

    def refuse(req, timeout=None):
        raise urllib.error.URLError("offline")

    monkeypatch.setattr(urllib.request, "urlopen", refuse)
    assert W.main(["download", "alexnet", "--dest", str(isolated)]) == 1
    assert "offline" in capsys.readouterr().err


def test_cli_runs_as_a_module(isolated):
    import subprocess
    import sys

    res = subprocess.run([sys.executable, "-m", "dmtrack.features.weights", "list"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "tfeat" in res.stdout and "siam_liberty.bin" in res.stdout and not res.stderr


# ------------------------------------------------------------------------------------------ torch files
def test_torch_reader_reads_shipped_weights_without_torch():
    sd = W.load_tfeat()
    assert {k: v.shape for k, v in sd.items()} == W.TFEAT_SHAPES
    assert all(v.dtype == np.float32 and np.isfinite(v).all() for v in sd.values())
    disk = W.load_disk()
    assert sum(v.size for v in disk.values()) == 1_092_369


def test_torch_reader_matches_torch_load():
    torch = pytest.importorskip("torch", reason="comparison with torch.load needs PyTorch")
    for name, key in [("tfeat-liberty.params", None), ("disk-depth-save.pth", "extractor")]:
        path = W.package_weights_dir() / name
        ref = torch.load(path, map_location="cpu", weights_only=True)
        ref = ref[key] if key else ref
        mine = W.load_state_dict(path, key=key)
        assert list(mine) == list(ref)
        for k in ref:
            np.testing.assert_array_equal(mine[k], ref[k].numpy())


@pytest.mark.parametrize("zipped", [True, False], ids=["zip", "legacy"])
def test_torch_reader_handles_views_strides_and_dtypes(tmp_path, zipped):
    torch = pytest.importorskip("torch", reason="writing torch.save files needs PyTorch")
    base = torch.arange(24, dtype=torch.float32).reshape(4, 6)
    obj = {
        "transposed": base.t(),  # non-contiguous view
        "slice": base[1:3, 2:],  # storage offset
        "shared": base,  # same storage as the views
        "long": torch.tensor([1, -2, 3], dtype=torch.int64),
        "half": torch.tensor([0.5, 1.5], dtype=torch.float16),
        "double": torch.tensor([[1.25]], dtype=torch.float64),
        "nested": collections.OrderedDict(a=torch.ones(2), meta=[1, "x"]),
        "scalar": torch.tensor(7.0),
    }
    path = tmp_path / "obj.pt"
    torch.save(obj, path, _use_new_zipfile_serialization=zipped)
    got = W.load_torch_file(path)
    for k in ("transposed", "slice", "shared", "long", "half", "double", "scalar"):
        assert got[k].dtype == obj[k].numpy().dtype, k
        np.testing.assert_array_equal(got[k], obj[k].numpy())
    np.testing.assert_array_equal(got["nested"]["a"], np.ones(2, np.float32))
    assert got["nested"]["meta"] == [1, "x"]


def test_torch_reader_refuses_arbitrary_objects(tmp_path):
    path = tmp_path / "evil.pth"
    with open(path, "wb") as f:
        for part in (torchfile._LEGACY_MAGIC, 1001, {"little_endian": True}):
            pickle.dump(part, f, protocol=2)
        pickle.dump(collections.Counter(a=1), f, protocol=2)  # a class that is not a tensor or container
    with pytest.raises(InputError, match="refusing to load collections.Counter"):
        W.load_torch_file(path)
    (tmp_path / "junk.pth").write_bytes(b"definitely not a pickle")
    with pytest.raises(InputError, match="not a readable torch.save"):
        W.load_torch_file(tmp_path / "junk.pth")


def test_state_dict_key_errors(tmp_path):
    with pytest.raises(InputError, match="no 'extractor' entry"):
        W.load_state_dict(W.package_weights_dir() / "tfeat-liberty.params", key="extractor")
    with pytest.raises(InputError, match="no 'unet"):
        W.load_disk(W.package_weights_dir() / "tfeat-liberty.params")
    np.savez(tmp_path / "t.npz", **{"features.1.weight": np.zeros((32, 1, 7, 7))})
    with pytest.raises(InputError, match="no 'features.1.bias'"):
        W.load_tfeat(tmp_path / "t.npz")


def test_package_is_importable_without_torch_side_effects():
    import subprocess
    import sys

    code = (
        "import sys, dmtrack.features as f, dmtrack.features.base as b, dmtrack.features.weights;"
        "b.list_features(); b.get_feature('tfeat');"
        "assert 'torch' not in sys.modules, 'torch imported'; print('ok')"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=Path(__file__).parent)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "ok"


def test_registry_defaults_match_the_feature_classes():
    """learned.py repeats each class's default scale (it must not import the modules); keep them in sync."""
    from dmtrack.features import alexnet, disk, siamese, tfeat
    from dmtrack.features.base import get_entry

    for name, default in [("alexnet", alexnet.PAPER_SCALE), ("siamese", siamese.PAPER_SCALE),
                          ("tfeat", tfeat.DEFAULT_SCALE), ("disk", disk.DEFAULT_SCALE)]:
        assert get_entry(name).default_scale() == pytest.approx(default), name
