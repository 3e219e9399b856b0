"""AlexNet conv1 feature (paper §2.1.2): the first convolution of a pretrained AlexNet + ReLU at every pixel.

The paper takes Caffe's BVLC AlexNet, keeps "conv1" (96 kernels 11×11×3) and its ReLU, and changes the stride from
4 to 1 with a zero padding of 5 so that the H×W×96 output has the input's resolution; the learned kernels are
unchanged.  The input follows Caffe's convention for that model: BGR channel order, values 0..255, minus the
per-channel mean of the ILSVRC 2012 mean image (B 104.00698793, G 116.66876762, R 122.67891434 — the values
Caffe's examples use, :data:`~dmtrack.features.weights.CAFFE_BGR_MEAN`); the zero padding is applied after the
mean subtraction (as Caffe pads its input blob).

``alexnet64`` is the same construction on torchvision's AlexNet (64 conv1 kernels, RGB input, ImageNet
``(x/255 - mean)/std`` normalisation), for users who have PyTorch's weights rather than Caffe's.

Backends: PyTorch (oneDNN convolution, channels-last) when installed, otherwise numpy im2col + BLAS sgemm; both
give the same result to float32 rounding.
"""

from __future__ import annotations

import os

import numpy as np

from dmtrack.errors import InputError
from dmtrack.features import _nn
from dmtrack.features.base import Feature, prepare_image
from dmtrack.features.weights import (
    CAFFE_BGR_MEAN,
    TORCHVISION_MEAN,
    TORCHVISION_STD,
    Conv1Weights,
    find_weights,
    load_alexnet_conv1,
)

#: The paper's default feature scale for AlexNet (§3, "Feature scales ... AlexNet ... 1.23").
PAPER_SCALE = 1.23


def alexnet_input(image: np.ndarray, conv1: Conv1Weights) -> np.ndarray:
    """The network input for ``image`` under the weights' convention, zero-padded by k//2.

    Parameters
    ----------
    image
        ``(H, W, 3)`` RGB, uint8 or float in 0..255.
    conv1
        The weights (their ``convention`` and ``channel_order`` decide the normalisation).

    Returns
    -------
    np.ndarray
        ``(H + 2p, W + 2p, 3)`` float32, channels in the weights' order, p = k // 2.
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 3 or img.shape[2] != 3:
        raise InputError(f"AlexNet input must be (H, W, 3) RGB, got {img.shape}")
    pad = conv1.weight.shape[2] // 2
    h, w = img.shape[:2]
    x = np.zeros((h + 2 * pad, w + 2 * pad, 3), np.float32)
    inner = x[pad : pad + h, pad : pad + w]
    if conv1.convention == "caffe":
        rgb_mean = np.asarray(CAFFE_BGR_MEAN[::-1], np.float32)
        if conv1.channel_order == "BGR":
            np.subtract(img[:, :, ::-1], rgb_mean[::-1], out=inner)
        else:
            np.subtract(img, rgb_mean, out=inner)
    else:  # torchvision
        mean = np.asarray(TORCHVISION_MEAN, np.float32) * np.float32(255.0)
        std = np.asarray(TORCHVISION_STD, np.float32) * np.float32(255.0)
        src = img if conv1.channel_order == "RGB" else img[:, :, ::-1]
        if conv1.channel_order == "BGR":
            mean, std = mean[::-1], std[::-1]
        np.divide(src - mean, std, out=inner)
    return x


def conv1_relu(
    x: np.ndarray,
    conv1: Conv1Weights,
    gain: float = 1.0,
    backend: str = "auto",
    project: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """``gain · ReLU(conv1(x))`` with stride 1 on an already padded input.

    Parameters
    ----------
    x
        ``(H + k - 1, W + k - 1, 3)`` float32 from :func:`alexnet_input`.
    conv1
        Weights ``(N, 3, k, k)`` and bias.
    gain
        Factor multiplied into the result (the feature scale).
    backend
        ``"auto"``, ``"torch"`` or ``"numpy"``.
    project
        Optional ``(weight (K, N), bias (K,))``: return ``weight @ (gain · ReLU(conv1)) + bias`` per pixel
        instead (the paper's PCA reduction as a 1×1 convolution after conv1, §3.4).

    Returns
    -------
    np.ndarray
        ``(H, W, N)`` (or ``(H, W, K)`` with ``project``) float32 C-contiguous.
    """
    backend = _nn.resolve_backend(backend)
    if backend == "torch":
        torch = _nn.torch_module()
        with torch.inference_mode():
            t = torch.from_numpy(np.ascontiguousarray(x)).permute(2, 0, 1).unsqueeze(0)
            t = t.contiguous(memory_format=torch.channels_last)
            # gain > 0 commutes with the ReLU: fold it into the kernels instead of a pass over the output
            g = np.float32(gain if project is None else 1.0)
            wt = torch.from_numpy(conv1.weight * g).contiguous(memory_format=torch.channels_last)
            y = torch.nn.functional.conv2d(t, wt, torch.from_numpy(conv1.bias * g))
            y.clamp_(min=0.0)
            if project is not None:
                pw = torch.from_numpy(np.ascontiguousarray(project[0], np.float32) * np.float32(gain))
                y = torch.nn.functional.conv2d(
                    y,
                    pw[:, :, None, None].contiguous(memory_format=torch.channels_last),
                    torch.from_numpy(np.asarray(project[1], np.float32)),
                )
            y = y.permute(0, 2, 3, 1)[0]
            if not y.is_contiguous():
                y = y.contiguous()
            return y.numpy()
    y = _nn.conv2d_hwc(x, conv1.weight, conv1.bias)
    np.maximum(y, 0.0, out=y)
    if project is not None:
        pw = np.asarray(project[0], np.float32) * np.float32(gain)
        h, w, n = y.shape
        out = y.reshape(h * w, n) @ pw.T
        out += np.asarray(project[1], np.float32)
        return out.reshape(h, w, pw.shape[0])
    if gain != 1.0:
        y *= np.float32(gain)
    return y


class AlexNetFeature(Feature):
    """Caffe BVLC AlexNet conv1 + ReLU, stride 1, zero padding 5: 96 channels (paper §2.1.2).

    Parameters
    ----------
    scale
        Default feature scale (the paper's value is 1.23).
    weights
        Weight file: ``bvlc_alexnet.caffemodel``, an ONNX-zoo ``bvlcalexnet-*.onnx``, a ``.npz`` (``weight``
        (96, 3, 11, 11) BGR, ``bias``) — or a torchvision ``.pth`` (then the torchvision convention is used).
        Default: searched in ``$DMTRACK_WEIGHTS`` and ``~/.cache/dmtrack/weights``
        (see :mod:`dmtrack.features.weights`).
    backend
        ``"auto"`` (PyTorch when installed, else numpy), ``"torch"`` or ``"numpy"``.
    """

    name = "alexnet"
    channels = 96
    needs_colour = True
    needs_torch = False
    needs_weights = True
    pyramid = "downsample"
    description = "Caffe BVLC AlexNet conv1 + ReLU at stride 1, zero padding 5 (BGR, ILSVRC mean), 96-D"
    weights_key = "alexnet"

    def __init__(
        self,
        scale: float = PAPER_SCALE,
        weights: str | os.PathLike[str] | None = None,
        backend: str = "auto",
    ) -> None:
        super().__init__(scale)
        self.backend = _nn.resolve_backend(backend)
        self.weights_path = find_weights(self.weights_key, weights)
        self.conv1 = load_alexnet_conv1(self.weights_path)
        self.channels = int(self.conv1.weight.shape[0])

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        x = alexnet_input(image, self.conv1)
        return conv1_relu(x, self.conv1, gain, self.backend)

    def compute_projected(self, image: np.ndarray, weight: np.ndarray, bias: np.ndarray) -> np.ndarray:
        """``weight @ compute(image) + bias`` per pixel, with the projection fused after conv1 (paper §3.4).

        Used by :class:`~dmtrack.features.pca.ReducedFeature` for ``alexnet-pcaK``.

        Parameters
        ----------
        image
            ``(H, W)`` or ``(H, W, 3)`` uint8/float image.
        weight, bias
            ``(K, N)`` and ``(K,)`` projection.

        Returns
        -------
        np.ndarray
            ``(H, W, K)`` float32.
        """
        weight = np.asarray(weight, np.float32)
        if weight.ndim != 2 or weight.shape[1] != self.channels:
            raise InputError(f"projection must be (K, {self.channels}), got {weight.shape}")
        img = prepare_image(image, colour=True)
        x = alexnet_input(img, self.conv1)
        out = conv1_relu(x, self.conv1, self.scale, self.backend, project=(weight, np.asarray(bias, np.float32)))
        return np.ascontiguousarray(out, dtype=np.float32)


class AlexNet64Feature(AlexNetFeature):
    """torchvision AlexNet conv1 (64 kernels 11×11, RGB, ImageNet mean/std) + ReLU, stride 1, padding 5."""

    name = "alexnet64"
    channels = 64
    description = "torchvision AlexNet conv1 + ReLU at stride 1, zero padding 5 (RGB, ImageNet mean/std), 64-D"
    weights_key = "alexnet64"

    def __init__(
        self,
        scale: float = 1.0,
        weights: str | os.PathLike[str] | None = None,
        backend: str = "auto",
    ) -> None:
        super().__init__(scale, weights, backend)
