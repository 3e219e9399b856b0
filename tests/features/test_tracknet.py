"""tracknet (dmtrack.features.tracknet): numba inference of the exported network, weights loading, the registry entry.

The inference must equal the torch module (dmtrack.training.model.TrackNet) to 1e-5 on a real frame and at odd sizes
(the reflection padding at the borders); the comparisons with torch are skipped when torch is absent.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.features import get_feature, list_features
from dmtrack.features.tracknet import TrackNetFeature, load_tracknet, packaged_weights, tracknet_forward
from dmtrack.io.images import read_image

ATOL = 1e-5


@pytest.fixture(scope="module")
def frame(sample_dir) -> np.ndarray:
    return read_image(sample_dir / "frame-000000.color.jpg")


def torch_output(net, grey: np.ndarray) -> np.ndarray:
    import torch

    with torch.no_grad():
        y = net(torch.from_numpy(np.asarray(grey, np.float32))[None, None])[0]
    return y.permute(1, 2, 0).numpy()


def grey_of(rgb: np.ndarray) -> np.ndarray:
    from dmtrack.features.base import prepare_image

    return prepare_image(rgb, colour=False)


@pytest.mark.parametrize(
    ("channels", "hidden", "kernels"),
    [(8, 8, (5, 3)), (4, 8, (3,)), (16, 12, (5, 1)), (8, 8, (3, 3, 1))],
)
def test_inference_equals_the_torch_module(tmp_path, frame, channels, hidden, kernels) -> None:
    torch = pytest.importorskip("torch")
    from dmtrack.training.model import TrackNet, export_npz

    torch.manual_seed(channels * 100 + hidden)
    net = TrackNet(channels, hidden, kernels)
    with torch.no_grad():  # larger biases than the default init, so that the ReLUs cut
        for conv in net.convs:
            conv.bias.normal_(0.0, 0.5)
    path = export_npz(net, tmp_path / "w.npz", seed=1)
    feat = get_feature("tracknet", weights=str(path), scale=3.0)
    assert feat.channels == channels
    grey = grey_of(frame)
    ref = torch_output(net, grey)
    out = feat.compute_unscaled(frame)
    assert out.shape == (480, 640, channels) and out.dtype == np.float32
    assert np.abs(out - ref).max() < ATOL
    assert np.abs(feat.compute(frame) - 3.0 * ref).max() < 3.0 * ATOL
    assert 0.05 < float(np.mean(ref > 0)) < 0.95  # not a saturated or dead network
    for h, w in ((37, 53), (9, 8)):  # odd sizes: borders everywhere
        crop = np.ascontiguousarray(grey[100 : 100 + h, 200 : 200 + w])
        assert np.abs(tracknet_forward(feat.weights, crop) - torch_output(net, crop)).max() < ATOL
    # float input (the "recompute" pyramid passes float images) gives the same map
    assert np.abs(tracknet_forward(feat.weights, grey.astype(np.float32)) - out).max() < ATOL


def test_export_is_deterministic_and_round_trips(tmp_path) -> None:
    torch = pytest.importorskip("torch")
    from dmtrack.training.model import TrackNet, export_npz

    torch.manual_seed(0)
    net = TrackNet(8, 8, (5, 3))
    a = export_npz(net, tmp_path / "a.npz", seed=0).read_bytes()
    b = export_npz(net, tmp_path / "b.npz", seed=0).read_bytes()
    assert a == b
    with np.load(tmp_path / "a.npz") as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays.pop("meta")))
    back = TrackNet.from_arrays(arrays, meta)
    for p, q in zip(net.parameters(), back.parameters(), strict=True):
        assert torch.equal(p, q)


def test_packaged_weights_are_small_and_registered(frame) -> None:
    path = packaged_weights()
    assert path.is_file() and path.stat().st_size < 1 << 20
    w = load_tracknet()
    assert w.meta["data"] == "both" and w.meta["steps"] == 1500  # the model card's run (weights/TRACKNET.md)
    assert w.meta["scale"] == pytest.approx(get_feature("tracknet").scale)  # the registry has its calibration
    listed = {d["name"]: d for d in list_features()}
    assert listed["tracknet"]["channels"] == w.channels
    assert listed["tracknet"]["needs_torch"] is False
    feat = get_feature("tracknet")
    assert isinstance(feat, TrackNetFeature) and feat.packaged
    out = feat.compute(frame)
    assert out.shape == (480, 640, w.channels)
    assert np.all(np.abs(out) < feat.scale) and float(out.std()) > 0
    assert feat.energy_channels is not None and feat.energy_channels > 0
    # N_E follows the scale (energy ∝ scale²)
    assert get_feature("tracknet", scale=2 * feat.scale).energy_channels == pytest.approx(4 * feat.energy_channels)


def test_packaged_weights_equal_the_torch_module(frame) -> None:
    pytest.importorskip("torch")
    from dmtrack.training.model import TrackNet

    with np.load(packaged_weights()) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays.pop("meta")))
    net = TrackNet.from_arrays(arrays, meta)
    grey = grey_of(frame)
    assert np.abs(tracknet_forward(load_tracknet(), grey) - torch_output(net, grey)).max() < ATOL


def test_bad_weights_files(tmp_path) -> None:
    with pytest.raises(InputError, match="not found"):
        get_feature("tracknet", weights=str(tmp_path / "missing.npz"))
    np.savez(tmp_path / "plain.npz", a=np.zeros(3))
    with pytest.raises(InputError, match="no 'meta'"):
        load_tracknet(tmp_path / "plain.npz")
    (tmp_path / "text.npz").write_text("not a zip")
    with pytest.raises(InputError, match="cannot read"):
        load_tracknet(tmp_path / "text.npz")
    meta = {"format": "dmtrack-tracknet-1", "output": "softsign", "padding": "reflect101", "negative_slope": 0.1,
            "layers": [{"kernel": 3, "in": 1, "out": 4, "activation": "none"}]}
    np.savez(tmp_path / "shape.npz", meta=np.array(json.dumps(meta)), **{"conv0.weight": np.zeros((4, 1, 1, 1)),
                                                                        "conv0.bias": np.zeros(4)})
    with pytest.raises(InputError, match="conv0 has shape"):
        load_tracknet(tmp_path / "shape.npz")
    with pytest.raises(InputError, match="grey"):
        tracknet_forward(load_tracknet(), np.zeros((16, 16, 3), np.uint8))


def test_registry_numbers_are_the_packaged_files_calibration(tmp_path, sample_dir) -> None:
    """The registry's scale, N_E, κ and N_σ of ``tracknet`` are what calibrate_weights measures for the packaged file
    on the 20 sample frames named in weights/TRACKNET.md."""
    pytest.importorskip("torch")
    import shutil

    from dmtrack.training.train import calibrate_weights

    copy = tmp_path / "w.npz"
    shutil.copyfile(packaged_weights(), copy)
    got = calibrate_weights(copy, [sample_dir / f"frame-{i:06d}.color.jpg" for i in range(0, 300, 15)])
    feat = get_feature("tracknet")
    want = {"scale": feat.scale, "energy_channels": feat.energy_channels, "info_channels": feat.info_channels,
            "noise_energy_channels": feat.noise_energy_channels}  # fmt: skip
    assert got == pytest.approx(want, rel=2e-3)
