"""TFeat feature: the TFeat patch descriptor (Balntas et al., BMVC 2016) of the 32×32 patch around every pixel.

TFeat is the closest obtainable relative of the paper's Siamese patch network (its weights ship with dmtrack,
MIT licence).  Network (vbalnt/tfeat ``tfeat_model.py``), on raw 0..255 grey patches::

    32×32 patch → InstanceNorm (no affine, eps 1e-5) → conv 32×7×7 → tanh → max-pool 2×2/2
                → conv 64×6×6 → tanh → flatten (64·8·8) → linear 128 → tanh → 128-D

Patch geometry: the patch of pixel (y, x) covers rows y-16..y+15 and columns x-16..x+15; the image is extended
by reflection (OpenCV's BORDER_REFLECT_101) for patches that leave it.

Two evaluation modes (``normalise=``):

``"patch"`` – exact: every patch is normalised by its own mean and standard deviation, as InstanceNorm does.
    The normalisation is an affine map with a positive slope per patch, so the first convolution is computed
    once for the image and rescaled per patch (conv(( P - m)/σ) = (conv(P) - m·Σw)/σ), and because tanh is
    increasing the first max-pool is shared too; conv2 and the linear layer (≈5.2 M multiply-adds) run per
    pixel.  Equal to evaluating each 32×32 patch separately (tens of seconds per 640×480 frame).
``"local"`` (default) – dense "shift-and-stitch" evaluation: each pixel is normalised by the mean and standard
    deviation of the 32×32 window around *it* (box filters), which makes the network translation-invariant; the
    max-pool becomes a stride-1 pool, conv2 is dilated by 2 and the linear layer is an 8×8 convolution dilated
    by 2.  This gives exactly the per-patch network output (without InstanceNorm) of the pre-normalised image at
    every pixel, for ≈0.6 M multiply-adds per pixel.  The only approximation is that a patch's pixels are
    normalised with their own windows' statistics instead of the patch's; where the local statistics vary
    across the patch the descriptors differ from ``"patch"``: on real images (7-Scenes, Tsukuba crops) the
    median cosine similarity between the two modes' descriptors is 0.86–0.92 and the relative difference of the
    maps 0.44–0.62 (``tests/features/test_tfeat.py`` checks this on a sample crop).

The evaluation plumbing (padding, batching, backends, the feature class) is shared with the other patch
descriptors in :mod:`dmtrack.features._dense_patch`; this module gives the network's layers (:class:`TFeatNet`).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from dmtrack.features import _nn
from dmtrack.features._dense_patch import DensePatchFeature, PatchNet, Stem, reflect_pad

PATCH = 32
BEFORE, AFTER = PATCH // 2, PATCH - PATCH // 2 - 1
#: InstanceNorm2d's default epsilon (added to the biased variance).
EPS = 1e-5
#: Default feature scale (paper §2.4), calibrated with :func:`dmtrack.features.scale.compute_default_scales` on the
#: 20 sample frames of ``default_scales.json`` (the registry entry in :mod:`dmtrack.features.learned` repeats it).
DEFAULT_SCALE = 29.3193


def _linear_as_conv(params: dict[str, np.ndarray]) -> np.ndarray:
    """The 128×4096 linear layer as 128 kernels of 64×8×8 (PyTorch flattens (C, H, W) in C order)."""
    return params["descr.0.weight"].reshape(128, 64, 8, 8)


class TFeatNet(PatchNet):
    """TFeat without its InstanceNorm, for :mod:`dmtrack.features._dense_patch` (weights as from
    :func:`~dmtrack.features.weights.load_tfeat`)."""

    label = "TFeat"
    patch = PATCH
    dim = 128
    window_eps = EPS
    exact_grid = (2, 13)  # pool 2: the per-pixel layers read 13×13 pooled values 2 apart
    exact_batch = 2048
    exact_chunk = 128  # keep the im2col buffer small (128 × 64 × 1152 floats)

    def patch_torch(self, torch: Any, t: Any, p: dict[str, Any]) -> Any:
        f = torch.nn.functional
        t = f.max_pool2d(torch.tanh(f.conv2d(t, p["features.1.weight"], p["features.1.bias"])), 2, 2)
        t = torch.tanh(f.conv2d(t, p["features.4.weight"], p["features.4.bias"]))
        return torch.tanh(f.linear(t.reshape(t.shape[0], -1), p["descr.0.weight"], p["descr.0.bias"]))

    def patch_numpy(self, patch: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        y = np.tanh(_nn.conv2d_hwc(patch[:, :, None], params["features.1.weight"], params["features.1.bias"]))
        y = _nn.maxpool_shift(y, 1)[::2, ::2]
        y = np.tanh(_nn.conv2d_hwc(y, params["features.4.weight"], params["features.4.bias"]))
        flat = np.transpose(y, (2, 0, 1)).reshape(-1)  # (C, H, W) order as torch's view()
        return np.tanh(params["descr.0.weight"] @ flat + params["descr.0.bias"])

    def normalise_windows(self, p: np.ndarray, mean: np.ndarray, std: np.ndarray) -> np.ndarray:
        return (p - mean) / std

    def dense_torch(self, torch: Any, t: Any, p: dict[str, Any], params: dict[str, np.ndarray]) -> Any:
        f = torch.nn.functional
        t = torch.tanh(f.conv2d(t, p["features.1.weight"], p["features.1.bias"]))
        t = f.max_pool2d(t, 2, stride=1).contiguous(memory_format=torch.channels_last)
        t = torch.tanh(f.conv2d(t, p["features.4.weight"], p["features.4.bias"], dilation=2))
        lin = p["descr.0.conv"] if "descr.0.conv" in p else _nn.torch_params({"w": _linear_as_conv(params)})["w"]
        return torch.tanh(f.conv2d(t, lin, p["descr.0.bias"], dilation=2))

    def dense_params(self, params: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {"descr.0.conv": _linear_as_conv(params)}

    def dense_numpy(self, x: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        d1 = np.tanh(_nn.conv2d_hwc(x[:, :, None], params["features.1.weight"], params["features.1.bias"]))
        m1 = _nn.maxpool_shift(d1, 1)
        del d1
        d2 = np.tanh(_nn.conv2d_hwc(m1, params["features.4.weight"], params["features.4.bias"], dilation=2))
        del m1
        out = _nn.conv2d_hwc(d2, _linear_as_conv(params), params["descr.0.bias"], dilation=2)
        np.tanh(out, out=out)
        return out

    def exact_stem(self, gray: np.ndarray, params: dict[str, np.ndarray]) -> Stem:
        p = reflect_pad(gray, PATCH)
        p -= np.float32(p.mean())  # centring changes nothing after normalisation but helps float32 precision
        mean, std = _nn.box_mean_std(p, PATCH, EPS)  # (H, W) statistics of each pixel's patch
        w1 = params["features.1.weight"]
        wsum = w1.reshape(w1.shape[0], -1).sum(axis=1).astype(np.float64)
        raw = _nn.conv2d_hwc(p[:, :, None], w1, None)  # (H+25, W+25, 32), no bias
        rmax = _nn.maxpool_shift(raw, 1)  # (H+24, W+24, 32)
        del raw
        b1 = params["features.1.bias"].astype(np.float64)

        def first(g: np.ndarray, pb: np.ndarray) -> np.ndarray:
            m = mean[pb[:, 0], pb[:, 1]][:, None, None, None]
            sd = std[pb[:, 0], pb[:, 1]][:, None, None, None]
            return np.tanh((g - m * wsum) / sd + b1).astype(np.float32)  # (B, 13, 13, 32)

        return rmax, first

    def tail_torch(self, torch: Any, t: Any, p: dict[str, Any]) -> Any:
        f = torch.nn.functional
        t = torch.tanh(f.conv2d(t, p["features.4.weight"], p["features.4.bias"]))
        return torch.tanh(f.linear(t.reshape(t.shape[0], -1), p["descr.0.weight"], p["descr.0.bias"]))

    def tail_numpy(self, g: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        y = _nn.conv2d_batch_hwc(g, params["features.4.weight"], params["features.4.bias"])
        np.tanh(y, out=y)
        flat = y.transpose(0, 3, 1, 2).reshape(len(y), -1)  # (C, H, W) order as torch's view()
        return np.tanh(flat @ params["descr.0.weight"].T + params["descr.0.bias"])


#: The network (stateless; the weights are passed to each call).
TFEAT = TFeatNet()


def tfeat_patches_forward(
    patches: np.ndarray, params: dict[str, np.ndarray], instance_norm: bool = True, backend: str = "auto"
) -> np.ndarray:
    """Reference per-patch forward pass of TFeat.

    Parameters
    ----------
    patches
        ``(B, 32, 32)`` grey patches (0..255).
    params
        Weights from :func:`~dmtrack.features.weights.load_tfeat`.
    instance_norm
        Apply the network's InstanceNorm (False: the patches are fed to the first convolution as they are).
    backend
        ``"auto"``, ``"torch"`` or ``"numpy"``.

    Returns
    -------
    np.ndarray
        ``(B, 128)`` float32.
    """
    x = TFEAT.check_patches(patches)
    if instance_norm:
        xd = x.astype(np.float64)
        m = xd.mean(axis=(1, 2), keepdims=True)
        v = xd.var(axis=(1, 2), keepdims=True)
        x = ((xd - m) / np.sqrt(v + EPS)).astype(np.float32)
    return TFEAT.forward_patches(x, params, backend)


def local_normalise(gray: np.ndarray) -> np.ndarray:
    """The ``"local"`` mode's input: each pixel minus its 32×32 window's mean, over the window's std.

    Returns
    -------
    np.ndarray
        ``(H + 31, W + 31)`` float32: the reflect-padded image (16 rows/columns before, 15 after), every value
        normalised with the mean and ``sqrt(biased variance + 1e-5)`` of its own 32×32 window (the geometry of a
        patch centred on it).
    """
    return TFEAT.local_normalise(gray)


def dense_tfeat(x: np.ndarray, params: dict[str, np.ndarray], gain: float = 1.0, backend: str = "auto") -> np.ndarray:
    """Shift-and-stitch evaluation of TFeat (without InstanceNorm) at every 32×32 window of ``x``.

    Parameters
    ----------
    x
        ``(H + 31, W + 31)`` float32 normalised input.
    params
        Network weights.
    gain
        Factor multiplied into the result.
    backend
        ``"auto"``, ``"torch"`` or ``"numpy"``.

    Returns
    -------
    np.ndarray
        ``(H, W, 128)`` float32: ``out[y, x] = tfeat_without_norm(x[y : y + 32, x : x + 32])``.
    """
    return TFEAT.dense(x, params, gain, backend)


def exact_tfeat(
    gray: np.ndarray,
    params: dict[str, np.ndarray],
    pixels: np.ndarray | None = None,
    gain: float = 1.0,
    backend: str = "auto",
    batch: int = TFeatNet.exact_batch,
) -> np.ndarray:
    """TFeat with each pixel's own InstanceNorm (exact per-patch evaluation), at all or selected pixels.

    Parameters
    ----------
    gray
        ``(H, W)`` grey image, 0..255.
    params
        Network weights.
    pixels
        Optional ``(M, 2)`` integer ``(row, col)``; default all pixels.
    gain
        Factor multiplied into the result.
    backend
        ``"auto"``, ``"torch"`` or ``"numpy"``.
    batch
        Pixels per batch of the per-patch layers.

    Returns
    -------
    np.ndarray
        ``(H, W, 128)`` or ``(M, 128)`` float32, equal (to float32 rounding) to :func:`tfeat_patches_forward`
        on each pixel's 32×32 patch.
    """
    return TFEAT.exact(gray, params, pixels, gain, backend, batch)


class TFeatFeature(DensePatchFeature):
    """TFeat 128-D descriptor of the 32×32 patch around every pixel (shipped Liberty weights).

    Parameters
    ----------
    scale
        Default feature scale (:data:`DEFAULT_SCALE`).
    weights
        A TFeat state dict (``.params``/``.pth``) or ``.npz``; default the shipped ``tfeat-liberty.params``.
    normalise
        ``"local"`` (dense, default) or ``"patch"`` (exact per-patch InstanceNorm, slow) — see the module docs.
    backend
        ``"auto"`` (PyTorch when installed, else numpy), ``"torch"`` or ``"numpy"``: the CPU kernels.
    device
        ``"auto"``, ``"cpu"``, ``"cuda"`` or ``"cuda:N"`` (:class:`~dmtrack.features._dense_patch.DensePatchFeature`).
    """

    name = "tfeat"
    channels = 128
    needs_colour = False
    needs_torch = False
    needs_weights = False
    pyramid = "downsample"
    description = "TFeat (Liberty) descriptor of the 32x32 patch at every pixel (dense), 128-D"
    net = TFEAT
    weights_key = "tfeat"

    def __init__(
        self,
        scale: float = DEFAULT_SCALE,
        weights: str | os.PathLike[str] | None = None,
        normalise: str = "local",
        backend: str = "auto",
        device: Any = "auto",
    ) -> None:
        super().__init__(scale, weights, normalise, backend, device)
