"""DISK feature: the dense 128-D descriptors of the DISK U-Net (Tyszkiewicz et al., NeurIPS 2020) at full resolution.

The shipped ``disk-depth-save.pth`` (Apache-2.0) holds the "depth" model's U-Net (1.09 M parameters, keys
``unet.*``); the architecture is the one of ``kornia.feature.DISK`` / cvlab-epfl/disk, re-implemented here with
``torch.nn.functional`` so that kornia is not needed::

    down:  conv 3→16 (5×5)                                   at 1/1
           [avg-pool 2, InstanceNorm, PReLU, conv 5×5]  16→32, 32→64, 64→64, 64→64   at 1/2 … 1/16
    up:    [bilinear ×2, concat skip, InstanceNorm, PReLU, conv 5×5]  →64, →64, →64, →129   back to 1/1

All convolutions use "same" padding (2), InstanceNorm has no affine parameters (eps 1e-5), upsampling is bilinear
with ``align_corners=False``.  The input is the RGB image scaled to 0..1 (DISK's convention); a grey image is
replicated into three channels.  Height and width are zero-padded at the bottom/right to multiples of 16 and the
output is cropped back (kornia's ``pad_if_not_divisible``).  Of the 129 output channels the first 128 are the
descriptors (returned, un-normalised) and the last is the keypoint heat map (dropped).

Needs PyTorch.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from dmtrack.errors import InputError
from dmtrack.features import _nn
from dmtrack.features.base import Feature
from dmtrack.features.device import DeviceFeatureMixin
from dmtrack.features.weights import load_disk

DESC_DIM = 128
DIVISOR = 16
_DOWN = 5  # path_down blocks
_UP = 4  # path_up blocks
#: Default feature scale (paper §2.4), calibrated with :func:`dmtrack.features.scale.compute_default_scales` on the
#: 20 sample frames of ``default_scales.json`` (the registry entry in :mod:`dmtrack.features.learned` repeats it).
DEFAULT_SCALE = 8.3247


def _expect(sd: dict[str, np.ndarray], key: str, ndim: int) -> None:
    if key not in sd or sd[key].ndim != ndim:
        raise InputError(f"DISK weights lack {key!r} (or it has the wrong rank)")


def _check_state_dict(sd: dict[str, np.ndarray]) -> None:
    _expect(sd, "unet.path_down.0.1.3.weight", 4)
    for i in range(1, _DOWN):
        _expect(sd, f"unet.path_down.{i}.1.1.weight", 1)
        _expect(sd, f"unet.path_down.{i}.1.3.weight", 4)
    for i in range(_UP):
        _expect(sd, f"unet.path_up.{i}.conv.1.weight", 1)
        _expect(sd, f"unet.path_up.{i}.conv.3.weight", 4)
    out = sd[f"unet.path_up.{_UP - 1}.conv.3.weight"].shape[0]
    if out != DESC_DIM + 1:
        raise InputError(f"DISK U-Net outputs {out} channels, expected {DESC_DIM + 1}")


def disk_unet(x: Any, params: dict[str, Any]) -> Any:
    """Forward pass of the DISK U-Net.

    Parameters
    ----------
    x
        ``torch.Tensor`` ``(B, 3, H, W)`` with H, W multiples of 16, RGB in 0..1.
    params
        ``name -> torch.Tensor`` (the ``unet.*`` state dict).

    Returns
    -------
    torch.Tensor
        ``(B, 129, H, W)``: 128 descriptor channels then the heat map.
    """
    torch = _nn.torch_module()
    f = torch.nn.functional

    def block(t: Any, prefix: str, gate: bool) -> Any:
        if gate:
            # InstanceNorm (no affine, eps 1e-5, biased variance) and PReLU written out element-wise: unlike
            # F.instance_norm they keep the channels-last layout, which avoids two layout copies per block
            mean = t.mean(dim=(2, 3), keepdim=True)
            t = t - mean
            t = t * torch.rsqrt(t.square().mean(dim=(2, 3), keepdim=True) + 1e-5)
            t = torch.where(t > 0, t, t * params[prefix + "1.weight"].view(1, -1, 1, 1))
        return f.conv2d(t, params[prefix + "3.weight"], params[prefix + "3.bias"], padding=2)

    feats = [x]
    for i in range(_DOWN):
        t = feats[-1]
        if i > 0:
            t = f.avg_pool2d(t, 2)
        feats.append(block(t, f"unet.path_down.{i}.1.", gate=i > 0))
    bottom = feats[-1]
    for i, hor in enumerate(feats[-2:0:-1]):
        up = f.interpolate(bottom, scale_factor=2, mode="bilinear", align_corners=False)
        bottom = block(torch.cat([up, hor], dim=1), f"unet.path_up.{i}.conv.", gate=True)
    return bottom


class DiskFeature(DeviceFeatureMixin, Feature):
    """DISK dense 128-D descriptors at every pixel (shipped "depth" weights; needs PyTorch).

    Parameters
    ----------
    scale
        Default feature scale (:data:`DEFAULT_SCALE`).
    weights
        A DISK checkpoint (``{'extractor': state_dict}`` or a bare ``unet.*`` state dict); default the shipped
        ``disk-depth-save.pth``.
    device
        ``"auto"`` (a CUDA GPU when PyTorch sees one, else the CPU), ``"cpu"``, ``"cuda"``, ``"cuda:N"``
        (:mod:`dmtrack.features.device`).
    """

    name = "disk"
    channels = DESC_DIM
    needs_colour = True
    needs_torch = True
    needs_weights = False
    pyramid = "downsample"
    description = "DISK U-Net dense descriptors at full resolution (shipped 'depth' weights), 128-D"

    def __init__(
        self, scale: float = DEFAULT_SCALE, weights: str | os.PathLike[str] | None = None, device: Any = "auto"
    ) -> None:
        super().__init__(scale)
        _nn.torch_module()  # a clear InputError when PyTorch is missing
        sd = load_disk(weights)
        _check_state_dict(sd)
        self._init_device(device)
        self._params = _nn.torch_params(sd) if self.runner is None else self.runner.params(sd)

    def _forward_device(self, image: np.ndarray, gain: float) -> Any:
        """The descriptors of the prepared RGB image on the device: ``(1, 128, H, W)`` times ``gain``."""
        runner = self.runner
        assert runner is not None
        f = runner.torch.nn.functional
        h, w = image.shape[:2]
        ph, pw = (-h) % DIVISOR, (-w) % DIVISOR
        x = runner.tensor(image).permute(2, 0, 1)[None].float() / 255.0
        if ph or pw:
            x = f.pad(x, (0, pw, 0, ph), value=0.0)
        x = x.contiguous(memory_format=runner.torch.channels_last)
        y = disk_unet(x, self._params)[:, :DESC_DIM, :h, :w]
        return y * float(gain) if gain != 1.0 else y

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        if self.runner is not None:
            return self._on_device(image, gain)
        torch = _nn.torch_module()
        f = torch.nn.functional
        h, w = image.shape[:2]
        ph, pw = (-h) % DIVISOR, (-w) % DIVISOR
        with torch.inference_mode():
            x = torch.from_numpy(np.ascontiguousarray(image, np.float32)).permute(2, 0, 1)[None] / 255.0
            if ph or pw:
                x = f.pad(x, (0, pw, 0, ph), value=0.0)
            x = x.contiguous(memory_format=torch.channels_last)
            y = disk_unet(x, self._params)[0, :DESC_DIM, :h, :w].permute(1, 2, 0)
            out = np.empty((h, w, DESC_DIM), np.float32)
            torch.mul(y, gain, out=torch.from_numpy(out))  # one pass: crop, channels-last copy and scale
            return out
