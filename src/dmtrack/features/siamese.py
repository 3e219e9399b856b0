"""Siamese feature (paper §2.1.2): the Zagoruyko–Komodakis "siam" descriptor of the 64×64 patch around every pixel.

Network (szagoruyko/cvpr15deepcompare, ``training/models/siam.lua``, one branch of the siamese pair)::

    64×64 grey patch → conv 96×7×7 stride 3 → ReLU → max-pool 2×2/2 → conv 192×5×5 → ReLU → max-pool 2×2/2
                    → conv 256×3×3 → ReLU → 256-D descriptor

(spatial sizes 64 → 20 → 10 → 6 → 3 → 1).  The authors' patch preprocessing is: values divided by 255, minus the
patch's own mean ("mean subtraction is crucial!", ``opencv/example.cpp``).

Patch geometry: the patch of pixel (y, x) covers rows y-32..y+31 and columns x-32..x+31; the image is extended
by reflection (OpenCV's BORDER_REFLECT_101) for patches that leave it.

Two evaluation modes (``normalise=``):

``"patch"`` – exact: every pixel's patch is normalised by its own mean, as the authors do.  Because the mean is a
    constant offset of the patch, the first convolution is computed once for the whole image and shifted per
    patch (conv1(P - m) = conv1(P) - m·Σw), and since ReLU and the offset are monotone the first max-pool is
    shared as well; the remaining layers (≈17 M multiply-adds) run per pixel.  This equals evaluating each
    64×64 patch separately and costs about as much as the paper's 8 s/frame GPU version did (minutes per
    640×480 frame on a CPU).
``"local"`` (default) – dense "shift-and-stitch" evaluation: each pixel is first normalised by the mean of the
    64×64 window around *it* (instead of the mean of the patch being described), which makes the network
    translation-invariant; the stride-3 convolution and the pools then become stride-1 operations with the later
    layers dilated by 3, 6 and 12, giving *exactly* the per-patch outputs of the pre-normalised image at every
    pixel for ≈0.9 M multiply-adds per pixel.  The only approximation is the normalisation (patch mean vs local
    means), which differs from ``"patch"`` where the local mean varies across the patch.

The evaluation plumbing (padding, batching, backends, the feature class) is shared with the other patch
descriptors in :mod:`dmtrack.features._dense_patch`; this module gives the network's layers (:class:`SiamNet`).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from dmtrack.features import _nn
from dmtrack.features._dense_patch import DensePatchFeature, PatchNet, Stem, reflect_pad

PATCH = 64
#: rows/columns of the patch before and after its pixel (patch = [y - 32, y + 31]).
BEFORE, AFTER = PATCH // 2, PATCH - PATCH // 2 - 1
#: The paper's default feature scale for the Siamese feature (§3: 347.50).
PAPER_SCALE = 347.5


class SiamNet(PatchNet):
    """The "siam" descriptor branch for :mod:`dmtrack.features._dense_patch` (weights as from
    :func:`~dmtrack.features.weights.load_siamese`)."""

    label = "siam"
    patch = PATCH
    dim = 256
    exact_grid = (6, 10)  # conv0 stride 3 × pool 2: the per-pixel layers read 10×10 pooled values 6 apart
    exact_batch = 1024
    exact_chunk = 64  # keep the im2col buffer small (64 × 36 × 2400 floats)

    def patch_torch(self, torch: Any, t: Any, p: dict[str, Any]) -> Any:
        f = torch.nn.functional
        t = f.max_pool2d(f.relu(f.conv2d(t, p["conv0.weight"], p["conv0.bias"], stride=3)), 2, 2)
        t = f.max_pool2d(f.relu(f.conv2d(t, p["conv1.weight"], p["conv1.bias"])), 2, 2)
        return f.relu(f.conv2d(t, p["conv2.weight"], p["conv2.bias"]))

    def patch_numpy(self, patch: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        x = _nn.conv2d_hwc(patch[:, :, None], params["conv0.weight"], params["conv0.bias"])[::3, ::3]
        x = _nn.maxpool_shift(np.maximum(x, 0), 1)[::2, ::2]
        x = _nn.conv2d_hwc(x, params["conv1.weight"], params["conv1.bias"])
        x = _nn.maxpool_shift(np.maximum(x, 0), 1)[::2, ::2]
        x = _nn.conv2d_hwc(x, params["conv2.weight"], params["conv2.bias"])
        return np.maximum(x, 0).reshape(-1)

    def normalise_windows(self, p: np.ndarray, mean: np.ndarray, std: np.ndarray) -> np.ndarray:
        return (p - mean) / 255.0

    def dense_torch(self, torch: Any, t: Any, p: dict[str, Any], params: dict[str, np.ndarray]) -> Any:
        f = torch.nn.functional
        t = f.relu(f.conv2d(t, p["conv0.weight"], p["conv0.bias"]))
        t = f.max_pool2d(t, 2, stride=1, dilation=3).contiguous(memory_format=torch.channels_last)
        t = f.relu(f.conv2d(t, p["conv1.weight"], p["conv1.bias"], dilation=6))
        t = f.max_pool2d(t, 2, stride=1, dilation=6)
        return f.relu(f.conv2d(t, p["conv2.weight"], p["conv2.bias"], dilation=12))

    def dense_numpy(self, x: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        d1 = np.maximum(_nn.conv2d_hwc(x[:, :, None], params["conv0.weight"], params["conv0.bias"]), 0)
        m1 = _nn.maxpool_shift(d1, 3)
        del d1
        d2 = np.maximum(_nn.conv2d_hwc(m1, params["conv1.weight"], params["conv1.bias"], dilation=6), 0)
        del m1
        m2 = _nn.maxpool_shift(d2, 6)
        del d2
        out = _nn.conv2d_hwc(m2, params["conv2.weight"], params["conv2.bias"], dilation=12)
        np.maximum(out, 0, out=out)
        return out

    def exact_stem(self, gray: np.ndarray, params: dict[str, np.ndarray]) -> Stem:
        p = reflect_pad(gray, PATCH) / np.float32(255.0)
        offset = float(p.mean())
        p -= offset  # centre for float32 precision; the per-patch means absorb it exactly
        mean, _ = _nn.box_mean_std(p, PATCH)  # (H, W): mean of each pixel's patch
        w0 = params["conv0.weight"]
        wsum = w0.reshape(w0.shape[0], -1).sum(axis=1).astype(np.float32)
        raw = _nn.conv2d_hwc(p[:, :, None], w0, None)  # (H+57, W+57, 96) without bias
        rmax = _nn.maxpool_shift(raw, 3)  # (H+54, W+54, 96)
        del raw
        b0 = params["conv0.bias"]

        def first(g: np.ndarray, pb: np.ndarray) -> np.ndarray:
            m = mean[pb[:, 0], pb[:, 1]].astype(np.float32)
            return np.maximum(g - m[:, None, None, None] * wsum + b0, 0).astype(np.float32)  # (B, 10, 10, 96)

        return rmax, first

    def tail_torch(self, torch: Any, t: Any, p: dict[str, Any]) -> Any:
        f = torch.nn.functional
        t = f.max_pool2d(f.relu(f.conv2d(t, p["conv1.weight"], p["conv1.bias"])), 2, 2)
        return f.relu(f.conv2d(t, p["conv2.weight"], p["conv2.bias"]))

    def tail_numpy(self, g: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        x = np.maximum(_nn.conv2d_batch_hwc(g, params["conv1.weight"], params["conv1.bias"]), 0)
        x = np.maximum(  # 2×2 max-pool, stride 2 (6×6 → 3×3)
            np.maximum(x[:, 0::2, 0::2], x[:, 1::2, 0::2]), np.maximum(x[:, 0::2, 1::2], x[:, 1::2, 1::2])
        )
        x = _nn.conv2d_batch_hwc(x, params["conv2.weight"], params["conv2.bias"])
        return np.maximum(x, 0).reshape(len(x), -1)


#: The network (stateless; the weights are passed to each call).
SIAM = SiamNet()


def siam_patches_forward(patches: np.ndarray, params: dict[str, np.ndarray], backend: str = "auto") -> np.ndarray:
    """Reference per-patch forward pass of the "siam" descriptor branch.

    Parameters
    ----------
    patches
        ``(B, 64, 64)`` float32, already normalised (the authors: ``patch/255 - mean(patch/255)``).
    params
        Weights from :func:`~dmtrack.features.weights.load_siamese`.
    backend
        ``"auto"``, ``"torch"`` or ``"numpy"``.

    Returns
    -------
    np.ndarray
        ``(B, 256)`` float32 descriptors.
    """
    return SIAM.forward_patches(patches, params, backend)


def local_normalise(gray: np.ndarray) -> np.ndarray:
    """The ``"local"`` mode's input: ``(I - mean of the 64×64 window of each pixel) / 255``, padded for the net.

    Returns
    -------
    np.ndarray
        ``(H + 63, W + 63)`` float32: the reflect-padded image (32 rows/columns before, 31 after), every value
        minus the mean of its own 64×64 window (same geometry as a patch), divided by 255.
    """
    return SIAM.local_normalise(gray)


def dense_siam(x: np.ndarray, params: dict[str, np.ndarray], gain: float = 1.0, backend: str = "auto") -> np.ndarray:
    """Shift-and-stitch evaluation of the "siam" branch at every 64×64 window of ``x``.

    Parameters
    ----------
    x
        ``(H + 63, W + 63)`` float32 input (already normalised).
    params
        Network weights.
    gain
        Factor multiplied into the result.
    backend
        ``"auto"``, ``"torch"`` or ``"numpy"``.

    Returns
    -------
    np.ndarray
        ``(H, W, 256)`` float32: ``out[y, x] = siam(x[y : y + 64, x : x + 64])``.
    """
    return SIAM.dense(x, params, gain, backend)


def exact_siam(
    gray: np.ndarray,
    params: dict[str, np.ndarray],
    pixels: np.ndarray | None = None,
    gain: float = 1.0,
    backend: str = "auto",
    batch: int = SiamNet.exact_batch,
) -> np.ndarray:
    """The authors' per-patch evaluation (patch mean subtracted) at every pixel or at selected pixels.

    Parameters
    ----------
    gray
        ``(H, W)`` grey image, 0..255.
    params
        Network weights.
    pixels
        Optional ``(M, 2)`` integer ``(row, col)`` pixels; default all pixels.
    gain
        Factor multiplied into the result.
    backend
        ``"auto"``, ``"torch"`` or ``"numpy"``.
    batch
        Pixels per batch of the per-patch layers.

    Returns
    -------
    np.ndarray
        ``(H, W, 256)`` for all pixels, or ``(M, 256)`` for ``pixels``; float32.  Equal (to float32 rounding) to
        :func:`siam_patches_forward` on ``patch/255 - mean(patch/255)`` of each pixel's 64×64 patch.
    """
    return SIAM.exact(gray, params, pixels, gain, backend, batch)


class SiameseFeature(DensePatchFeature):
    """Zagoruyko–Komodakis "siam" 256-D descriptor of the 64×64 patch around every pixel (paper §2.1.2).

    Parameters
    ----------
    scale
        Default feature scale (the paper's value is 347.5).
    weights
        The authors' ``siam_<set>.bin`` or a ``.npz`` (see :func:`~dmtrack.features.weights.load_siamese`);
        default: ``siam_liberty.bin`` searched in ``$DMTRACK_WEIGHTS`` and ``~/.cache/dmtrack/weights``.
    normalise
        ``"local"`` (dense, fast; default) or ``"patch"`` (exact per-patch mean, very slow) — see the module
        documentation.
    backend
        ``"auto"`` (PyTorch when installed, else numpy), ``"torch"`` or ``"numpy"``: the CPU kernels.
    device
        ``"auto"``, ``"cpu"``, ``"cuda"`` or ``"cuda:N"`` (:class:`~dmtrack.features._dense_patch.DensePatchFeature`).
    """

    name = "siamese"
    channels = 256
    needs_colour = False
    needs_torch = False
    needs_weights = True
    pyramid = "downsample"
    description = "Zagoruyko-Komodakis 'siam' descriptor of the 64x64 patch at every pixel (dense), 256-D"
    net = SIAM
    weights_key = "siamese"

    def __init__(
        self,
        scale: float = PAPER_SCALE,
        weights: str | os.PathLike[str] | None = None,
        normalise: str = "local",
        backend: str = "auto",
        device: Any = "auto",
    ) -> None:
        super().__init__(scale, weights, normalise, backend, device)
