"""The ``tracknet`` network as a torch module, and its export to the ``.npz`` that the numpy/numba inference reads.

Architecture (the defaults; every size is a constructor argument and is recorded in the export)::

    grey image 0..255 → (I − 128)/64
      → reflect-pad 2, conv 5×5, 1 → 8, leaky ReLU (slope 0.1)
      → reflect-pad 1, conv 3×3, 8 → 8, leaky ReLU (slope 0.1)
      → conv 1×1, 8 → K
      → softsign x/(1 + |x|)                      (K channels in (−1, 1))

Receptive field 7×7 pixels; about 840 multiply-adds per pixel for K = 8. The hidden activation is leaky (a plain
ReLU network died during training: whole hidden channels went to zero and never recovered). The output is bounded
("normalised"), so the default-scale machinery (:mod:`dmtrack.features.scale`) finds its scale and the channel
rule's N_E and κ are measured as for any feature. Padding is reflection without repeating the edge (torch
``"reflect"``, OpenCV's BORDER_REFLECT_101) before every convolution wider than 1, so the map has no border
artefacts and the inference (:mod:`dmtrack.features.tracknet`) can reproduce it exactly.

The ``.npz`` (:func:`export_npz`, read by :func:`dmtrack.features.tracknet.load_tracknet`) holds
``conv{i}.weight`` (C_out, C_in, k, k) and ``conv{i}.bias`` (C_out,) float32 for i = 0, 1, …, and ``meta``, a JSON
string: ``format`` (``"dmtrack-tracknet-1"``), ``layers`` (per layer ``kernel``, ``in``, ``out``, ``activation``),
``input_offset``, ``input_scale``, ``negative_slope`` (of the leaky ReLU), ``output`` (``"softsign"``) and what
the trainer adds (seed, steps, data, …). It is written byte-for-byte deterministically (fixed zip timestamps), so
equal weights give equal files.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dmtrack.io.atomic import atomic_open

#: ``format`` of the exported ``.npz``.
NPZ_FORMAT = "dmtrack-tracknet-1"
#: Slope of the hidden layers' leaky ReLU for x < 0.
NEGATIVE_SLOPE = 0.1
#: The input normalisation (I − offset)/scale of the grey image.
INPUT_OFFSET = 128.0
INPUT_SCALE = 64.0


class TrackNet(torch.nn.Module):
    """Small fully-convolutional feature network (see the module documentation).

    Parameters
    ----------
    channels : int
        Output channels K.
    hidden : int
        Channels of the hidden layers.
    kernels : tuple of int
        Kernel sizes of the hidden layers (odd); a final 1×1 layer maps to K channels.
    """

    def __init__(self, channels: int = 8, hidden: int = 8, kernels: tuple[int, ...] = (5, 3)):
        super().__init__()
        if channels < 1 or hidden < 1 or not kernels or any(k < 1 or k % 2 == 0 for k in kernels):
            raise ValueError(f"bad TrackNet sizes: channels={channels}, hidden={hidden}, kernels={kernels}")
        self.channels = int(channels)
        self.hidden = int(hidden)
        self.kernels = tuple(int(k) for k in kernels)
        convs = []
        cin = 1
        for k in self.kernels:
            convs.append(torch.nn.Conv2d(cin, self.hidden, k))
            cin = self.hidden
        convs.append(torch.nn.Conv2d(cin, self.channels, 1))
        self.convs = torch.nn.ModuleList(convs)

    @property
    def receptive_field(self) -> int:
        """Width of the receptive field in pixels."""
        return 1 + sum(k - 1 for k in self.kernels)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        """(B, 1, H, W) grey 0..255 → (B, K, H, W) in (−1, 1)."""
        f = torch.nn.functional
        x = (image - INPUT_OFFSET) / INPUT_SCALE
        for conv in self.convs[:-1]:
            r = conv.kernel_size[0] // 2
            if r:
                x = f.pad(x, (r, r, r, r), mode="reflect")
            x = f.leaky_relu(conv(x), NEGATIVE_SLOPE)
        x = self.convs[-1](x)
        return x / (1.0 + x.abs())

    def layer_specs(self) -> list[dict[str, Any]]:
        """Per layer: kernel, in, out, activation (as recorded in the export)."""
        specs = []
        for i, conv in enumerate(self.convs):
            last = i == len(self.convs) - 1
            specs.append(
                {
                    "kernel": int(conv.kernel_size[0]),
                    "in": int(conv.in_channels),
                    "out": int(conv.out_channels),
                    "activation": "none" if last else "leaky_relu",
                }
            )
        return specs

    def arrays(self) -> dict[str, np.ndarray]:
        """The parameters as float32 numpy arrays, ``conv{i}.weight`` and ``conv{i}.bias``."""
        out = {}
        for i, conv in enumerate(self.convs):
            out[f"conv{i}.weight"] = conv.weight.detach().to(torch.float32).cpu().numpy().copy()
            out[f"conv{i}.bias"] = conv.bias.detach().to(torch.float32).cpu().numpy().copy()
        return out

    def meta(self, **extra: Any) -> dict[str, Any]:
        """The ``meta`` record of the export (architecture plus ``extra``)."""
        return {
            "format": NPZ_FORMAT,
            "channels": self.channels,
            "layers": self.layer_specs(),
            "input_offset": INPUT_OFFSET,
            "input_scale": INPUT_SCALE,
            "padding": "reflect101",
            "negative_slope": NEGATIVE_SLOPE,
            "output": "softsign",
            **extra,
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> TrackNet:
        """Rebuild the module from an export's arrays and meta."""
        layers = meta["layers"]
        net = cls(channels=int(layers[-1]["out"]), hidden=int(layers[0]["out"]),
                  kernels=tuple(int(s["kernel"]) for s in layers[:-1]))  # fmt: skip
        with torch.no_grad():
            for i, conv in enumerate(net.convs):
                conv.weight.copy_(torch.from_numpy(np.asarray(arrays[f"conv{i}.weight"], np.float32)))
                conv.bias.copy_(torch.from_numpy(np.asarray(arrays[f"conv{i}.bias"], np.float32)))
        return net


def npz_bytes(arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> bytes:
    """A ``.npz`` (uncompressed zip of ``.npy`` members, ``meta`` as a 0-d unicode array) with fixed timestamps."""
    buf = io.BytesIO()
    members = {**arrays, "meta": np.array(json.dumps(meta, sort_keys=True))}
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        for name in sorted(members):
            npy = io.BytesIO()
            np.lib.format.write_array(npy, np.asarray(members[name]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.external_attr = 0o644 << 16
            zf.writestr(info, npy.getvalue())
    return buf.getvalue()


def export_npz(net: TrackNet, path: str | Path, **meta: Any) -> Path:
    """Write ``net`` to ``path`` (atomically, deterministic bytes); ``meta`` goes into the ``meta`` record."""
    path = Path(path)
    data = npz_bytes(net.arrays(), net.meta(**meta))
    with atomic_open(path, "wb", encoding=None) as f:
        f.write(data)
    return path
