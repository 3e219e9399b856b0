"""Where the network features run (dmtrack.features.device, issue 32), checked on a machine without a GPU.

* ``device="cpu"`` takes the CPU kernels, and they equal an independent reference: PyTorch's own ``conv2d`` (AlexNet
  conv1) and the training code's ``torch.nn`` TrackNet, in float64, from the same weights;
* the device path (PyTorch tensors on a device, the PCA projection applied there before the transfer) runs on
  ``torch.device("cpu")`` here and equals the CPU kernels within float32 tolerance, for every network feature
  and its ``-pcaK`` reduction, and the same PyTorch reference;
* ``device="cuda"`` where CUDA is unusable fails in one line naming what is missing, for every feature, before
  any file is written; a bad device spec is refused.
"""

from __future__ import annotations

import importlib.util
import json
import warnings

import numpy as np
import pytest

import dmtrack
from dmtrack.errors import InputError
from dmtrack.features import get_feature
from dmtrack.features.base import prepare_image
from dmtrack.features.device import check_device, cuda_problem, gpu_status, resolve_device
from dmtrack.features.pca import ReducedFeature, fit_pca
from dmtrack.io.images import read_image

needs_torch = pytest.mark.skipif(importlib.util.find_spec("torch") is None, reason="PyTorch not installed")
no_cuda = pytest.mark.skipif(importlib.util.find_spec("torch") is not None and cuda_problem() is None,
                             reason="this machine has a usable CUDA device")  # fmt: skip


@pytest.fixture(scope="module")
def crops(sample_dir) -> list[np.ndarray]:
    """Two 120×160 crops of real frames of the sample (odd offsets)."""
    return [read_image(sample_dir / f"frame-{i:06d}.color.jpg")[37:157, 101:261] for i in (0, 12)]


@pytest.fixture(scope="module")
def alexnet_npz(tmp_path_factory) -> str:
    """conv1 weights of the real shape (96, 3, 11, 11): the BVLC file cannot be shipped."""
    rng = np.random.default_rng(5)
    path = tmp_path_factory.mktemp("alexnet") / "alexnet-conv1.npz"
    np.savez(path, weight=rng.normal(0, 0.01, (96, 3, 11, 11)).astype(np.float32),
             bias=rng.normal(0, 0.1, 96).astype(np.float32))  # fmt: skip
    return str(path)


NETWORKS = ["alexnet", "tfeat", "tracknet", pytest.param("disk", marks=needs_torch)]


def _build(name: str, device, alexnet_npz: str):  # noqa: ANN001, ANN202
    opts = {"weights": alexnet_npz} if name == "alexnet" else {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # alexnet: random weights have no calibration
        return get_feature(name, device=device, **opts)


def _torch_reference(name: str, f, image: np.ndarray) -> np.ndarray | None:  # noqa: ANN001
    """The feature computed by PyTorch's own layers on the CPU from the same weights: a reference that shares no code
    with the CPU kernels (numpy FFT / numba) nor with the device path (dmtrack's torch modules); None where there is
    none here (TFeat, DISK: those are checked against the other path below)."""
    import torch

    fn = torch.nn.functional
    with torch.no_grad():
        if name == "alexnet":
            from dmtrack.features.alexnet import alexnet_input

            x = torch.from_numpy(alexnet_input(prepare_image(image, True), f.conv1)).permute(2, 0, 1)[None]
            w, b = torch.from_numpy(f.conv1.weight), torch.from_numpy(f.conv1.bias)
            y = fn.relu(fn.conv2d(x.double(), w.double(), b.double())) * f.scale
            return y[0].permute(1, 2, 0).float().numpy()
        if name == "tracknet":
            from dmtrack.features.tracknet import packaged_weights
            from dmtrack.training.model import TrackNet

            with np.load(packaged_weights(), allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
            net = TrackNet.from_arrays(arrays, json.loads(str(arrays["meta"]))).double()
            grey = torch.from_numpy(prepare_image(image, False).astype(np.float64))[None, None]
            return (net(grey)[0].permute(1, 2, 0) * f.scale).float().numpy()
    return None


@pytest.mark.parametrize("name", NETWORKS)
def test_device_cpu_is_the_cpu_kernels_and_matches_torch(name, crops, alexnet_npz) -> None:
    f = _build(name, "cpu", alexnet_npz)
    assert f.runner is None and f.device == "cpu" and f.info()["device"] == "cpu"
    if importlib.util.find_spec("torch") is None:
        pytest.skip("PyTorch not installed: no independent reference")
    want = _torch_reference(name, f, crops[0])
    if want is None:
        return
    got = f.compute(crops[0])
    assert got.dtype == np.float32 and got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-5 * float(np.abs(want).max()))


@needs_torch
@pytest.mark.parametrize("name", NETWORKS)
def test_the_device_path_equals_the_cpu_kernels(name, crops, alexnet_npz) -> None:
    import torch

    cpu = _build(name, "cpu", alexnet_npz)
    dev = _build(name, torch.device("cpu"), alexnet_npz)
    assert dev.runner is not None and dev.device == "cpu-torch"
    a, b = cpu.compute(crops[0]), dev.compute(crops[0])
    assert a.shape == b.shape and b.dtype == np.float32 and b.flags.c_contiguous
    np.testing.assert_allclose(b, a, rtol=0, atol=2e-6 * float(np.abs(a).max()))
    # and against PyTorch's own layers, on another frame
    want = _torch_reference(name, cpu, crops[1])
    if want is not None:
        np.testing.assert_allclose(dev.compute(crops[1]), want, rtol=0, atol=2e-5 * float(np.abs(want).max()))


@needs_torch
@pytest.mark.parametrize("name", NETWORKS)
def test_pca_on_the_device_equals_the_cpu_projection(name, crops, alexnet_npz) -> None:
    import torch

    cpu = _build(name, "cpu", alexnet_npz)
    dev = _build(name, torch.device("cpu"), alexnet_npz)
    basis = fit_pca(cpu, crops, k=8, n_samples=3000, seed=0)
    for k in (1, 4, 8):
        want = ReducedFeature(cpu, basis, k=k, scale=0.7).compute(crops[1])
        reduced = ReducedFeature(dev, basis, k=k, scale=0.7)
        assert reduced.device == "cpu-torch"
        calls: list[tuple[int, ...]] = []
        runner = dev.runner
        project = runner.project

        def recorded(y, w, b, calls=calls, project=project):  # noqa: ANN001, ANN202 - records, then projects
            calls.append(w.shape)
            return project(y, w, b)

        runner.project = recorded
        try:
            got = reduced.compute(crops[1])
        finally:
            del runner.project
        assert calls == [(k, cpu.channels)], "the projection is applied on the device, before the transfer"
        assert got.shape == (*crops[1].shape[:2], k)
        np.testing.assert_allclose(got, want, rtol=0, atol=2e-5 * float(np.abs(want).max()))


def test_device_specs() -> None:
    assert check_device(" CUDA:1 ") == "cuda:1" and check_device("auto") == "auto"
    for bad in ("gpu", "cuda:", "cuda:x", "", 3, None):
        with pytest.raises(InputError, match="device must be"):
            check_device(bad)
    assert resolve_device("cpu") is None
    with pytest.raises(InputError, match="device must be"):
        get_feature("tfeat", device="gpu")


@no_cuda
def test_without_cuda_auto_is_the_cpu_and_cuda_is_one_clear_line(tmp_path, sample_dir, alexnet_npz) -> None:
    problem = cuda_problem()
    assert problem and "\n" not in problem
    assert resolve_device("auto") is None
    st = gpu_status()
    assert st["usable"] is False and st["reason"] == problem and st["devices"] == []
    basis = tmp_path / "tracknet-pca4.npz"
    fit_pca(get_feature("tracknet"), [read_image(sample_dir / "frame-000000.color.jpg")], k=4, n_samples=500,
            seed=0).save(basis)  # fmt: skip
    for name, opts in (("tfeat", {}), ("gray", {}), ("dsift", {}), ("tracknet-pca4", {"pca": basis})):
        with pytest.raises(InputError) as exc:
            get_feature(name, device="cuda", **opts)
        assert str(exc.value) == f"device=cuda: {problem}"
    assert _build("tfeat", "auto", alexnet_npz).device == "cpu"

    from dmtrack.cli import main

    out = tmp_path / "run"
    assert main(["run", str(sample_dir), "--feature", "tracknet", "--device", "cuda", "--out", str(out)]) == 1
    assert not out.exists()


def test_hand_crafted_features_take_auto_and_cpu_silently() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for device in ("auto", "cpu"):
            f = get_feature("bitplanes", device=device)
            assert f.device == "cpu" and f.options is None  # no option recorded: the calibration still applies


def test_a_run_records_where_its_feature_ran(tmp_path) -> None:
    res = dmtrack.run_to_directory("synthetic:n_frames=12,width=160,height=128,seed=1", tmp_path / "run",
                                   feature="tracknet", device="cpu", depth_images=False, pointcloud=False)  # fmt: skip
    m = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert m["device"] == "cpu" and m["gpu"] is None and res.metrics["device"] == "cpu"
    with pytest.raises(InputError, match="applies to a feature given by name"):
        dmtrack.track("synthetic:n_frames=4,width=160,height=128", feature=get_feature("gray"), device="cpu")
