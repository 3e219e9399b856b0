"""``tracknet``: a small convolutional feature trained through the tracker's own alignment (issue 15).

Inference without PyTorch: numba kernels evaluate the network exported by :mod:`dmtrack.training.model` (an
``.npz``: ``conv{i}.weight`` (C_out, C_in, k, k), ``conv{i}.bias``, and a JSON ``meta`` record; see that module for
the architecture). Per layer: reflection padding (BORDER_REFLECT_101) to keep the size, the convolution, a leaky
ReLU (slope ``meta["negative_slope"]`` below 0) on hidden layers; the last layer's output goes through softsign
x/(1 + |x|), so every channel lies in (−1, 1) before the feature scale multiplies it. The input is the grey image,
(I − 128)/64, folded into the first layer.

Weights: ``weights=PATH`` (an ``.npz`` written by ``dmtrack train-feature``), else the packaged default
:data:`DEFAULT_WEIGHTS` in ``dmtrack/weights/`` beside TFeat's and DISK's: trained on synthetic pairs and on the shared
7-Scenes frames (non-commercial research use only, like that data; ``tracknet-prelim.npz`` beside it was trained on
synthetic data alone). See ``TRACKNET.md`` there. The channel count is the file's.

The channel statistics of the balanced cost rule (N_E, κ) and the scale they were measured at are read from the
file's ``meta`` (``energy_channels``, ``info_channels``, ``scale``) when present, so a retrained file brings its own;
the registry's default scale applies to the packaged file.
"""

from __future__ import annotations

import json
import os
import zipfile
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

import numba
import numpy as np

from dmtrack.errors import InputError
from dmtrack.features.base import Feature
from dmtrack.features.device import DeviceFeatureMixin

#: File name of the packaged default weights (in ``dmtrack/weights/``).
DEFAULT_WEIGHTS = "tracknet-7s-synth.npz"
NPZ_FORMAT = "dmtrack-tracknet-1"


# ------------------------------------------------------------------------------------------------ weights
class TrackNetWeights:
    """A loaded ``.npz``, arranged for the kernels.

    Attributes
    ----------
    spatial : list of (np.ndarray, np.ndarray)
        The layers before the pointwise tail, each (kernel (C_out, C_in, k, k), bias (C_out,)) float32, followed
        by leaky ReLU; the input normalisation (I − offset)/scale is folded into the first.
    tail : tuple
        ((w1 (C_mid, C_in), b1), (w2 (K, C_mid), b2)): the trailing 1×1 layers; C_mid = 0 when there is one.
    meta : dict
        The file's ``meta`` record.
    path : Path
        The file.
    """

    def __init__(self, spatial: list[tuple[np.ndarray, np.ndarray]], tail: Any, meta: dict[str, Any], path: Path):
        self.spatial = spatial
        self.tail = tail
        self.meta = meta
        self.path = path

    @property
    def channels(self) -> int:
        """Output channels K."""
        return int(self.tail[1][0].shape[0])

    @property
    def slope(self) -> np.float32:
        """Slope of the hidden layers' leaky ReLU below 0."""
        return np.float32(self.meta["negative_slope"])

    @property
    def radius(self) -> int:
        """Largest kernel radius."""
        return max([k.shape[0] // 2 for k, _ in self.spatial] + [0])


def packaged_weights() -> Path:
    """The packaged default weights file."""
    return Path(str(resources.files("dmtrack") / "weights" / DEFAULT_WEIGHTS))


@lru_cache(maxsize=8)
def _load_cached(path: str, mtime_ns: int, size: int) -> TrackNetWeights:
    p = Path(path)
    try:
        with np.load(p, allow_pickle=False) as z:
            arrays = {k: np.asarray(z[k]) for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise InputError(f"cannot read tracknet weights ({exc})", path=p) from None
    if "meta" not in arrays:
        raise InputError("not a tracknet weights file (no 'meta' record)", path=p)
    try:
        meta = json.loads(str(arrays["meta"]))
    except ValueError:
        raise InputError("tracknet weights: 'meta' is not JSON", path=p) from None
    if not isinstance(meta, dict) or meta.get("format") != NPZ_FORMAT:
        raise InputError(f"tracknet weights: format {meta.get('format')!r}, expected {NPZ_FORMAT!r}", path=p)
    if meta.get("output") != "softsign" or meta.get("padding") != "reflect101":
        raise InputError("tracknet weights: unsupported output or padding in 'meta'", path=p)
    if not isinstance(meta.get("negative_slope"), (int, float)):
        raise InputError("tracknet weights: no negative_slope in 'meta'", path=p)
    specs = meta.get("layers")
    if not isinstance(specs, list) or not specs:
        raise InputError("tracknet weights: no layers in 'meta'", path=p)
    layers = []
    cin = 1
    for i, spec in enumerate(specs):
        w = arrays.get(f"conv{i}.weight")
        b = arrays.get(f"conv{i}.bias")
        if w is None or b is None:
            raise InputError(f"tracknet weights: conv{i}.weight or conv{i}.bias missing", path=p)
        k = int(spec["kernel"])
        cout = int(spec["out"])
        if w.shape != (cout, cin, k, k) or b.shape != (cout,) or k % 2 == 0:
            raise InputError(f"tracknet weights: conv{i} has shape {w.shape}, {b.shape}; expected "
                             f"({cout}, {cin}, {k}, {k}), ({cout},)", path=p)  # fmt: skip
        last = i == len(specs) - 1
        if spec.get("activation") != ("none" if last else "leaky_relu"):
            raise InputError(f"tracknet weights: conv{i} has activation {spec.get('activation')!r}", path=p)
        layers.append((w.astype(np.float64), b.astype(np.float64)))
        cin = cout
    if layers[-1][0].shape[2] != 1:
        raise InputError("tracknet weights: the last layer must be 1x1", path=p)
    # fold (I − offset)/scale into the first layer (exact: reflection padding commutes with it)
    offset, scale = float(meta.get("input_offset", 128.0)), float(meta.get("input_scale", 64.0))
    w0, b0 = layers[0]
    layers[0] = (w0 / scale, b0 - offset / scale * w0.sum(axis=(1, 2, 3)))
    n_tail = 2 if len(layers) >= 3 and layers[-2][0].shape[2] == 1 else 1
    spatial = [(np.ascontiguousarray(w, np.float32), np.ascontiguousarray(b, np.float32))
               for w, b in layers[: len(layers) - n_tail]]  # fmt: skip
    cin = 1 if not spatial else spatial[-1][0].shape[0]

    def pointwise(w: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.ascontiguousarray(w[:, :, 0, 0], np.float32), np.ascontiguousarray(b, np.float32)

    if n_tail == 2:
        tail = (pointwise(*layers[-2]), pointwise(*layers[-1]))
    else:
        tail = ((np.zeros((0, cin), np.float32), np.zeros(0, np.float32)), pointwise(*layers[-1]))
    return TrackNetWeights(spatial, tail, meta, p)


def load_tracknet(path: str | os.PathLike[str] | None = None) -> TrackNetWeights:
    """Load (and cache) a tracknet ``.npz``; ``None`` loads the packaged default.

    Raises
    ------
    InputError
        The file is missing, unreadable or not a tracknet export.
    """
    p = packaged_weights() if path is None else Path(path).expanduser()
    if not p.is_file():
        if path is None:
            raise InputError(
                "the packaged tracknet weights are missing; train some with `dmtrack train-feature --out DIR` and "
                "pass weights=DIR/tracknet.npz",
                path=p,
            )
        raise InputError("tracknet weights file not found", path=p)
    st = p.stat()
    return _load_cached(str(p.resolve()), st.st_mtime_ns, st.st_size)


# ------------------------------------------------------------------------------------------------ kernels
@numba.njit(cache=True, nogil=True, parallel=True, fastmath={"contract"})
def _conv_layer(x, kern, bias, slope, out):  # pragma: no cover - compiled
    """out[o, y, x] = leaky(bias[o] + Σ kern[o, i, dy, dx]·x[i, refl(y+dy−r), refl(x+dx−r)]), leaky(v) = v for
    v > 0, else ``slope``·v.

    Planar layout: x (C_in, H, W) (float32, or uint8 for the first layer), kern (C_out, C_in, k, k), out
    (C_out, H, W) float32; refl is BORDER_REFLECT_101. Each input row is copied once per (channel, dy) into a
    reflection-padded buffer, and every tap is a multiply-add over a whole output row (indices unsigned, so the
    loop has no wrap-around test and vectorises). Rows over threads, no reductions across pixels: the result
    does not depend on the thread count.
    """
    cin, h, w = x.shape
    cout = kern.shape[0]
    k = kern.shape[2]
    r = k // 2
    for y in numba.prange(h):
        row = np.empty(w + 2 * r, np.float32)
        for co in range(cout):
            o = out[co, y]
            b = bias[co]
            for xx in range(w):
                o[numba.uint64(xx)] = b
        for ci in range(cin):
            for dy in range(k):
                sy = y + dy - r
                if sy < 0:
                    sy = -sy
                elif sy >= h:
                    sy = 2 * h - 2 - sy
                src = x[ci, sy]
                for xx in range(w):
                    row[numba.uint64(xx + r)] = np.float32(src[numba.uint64(xx)])
                for j in range(r):
                    row[r - 1 - j] = np.float32(src[j + 1])
                    row[w + r + j] = np.float32(src[w - 2 - j])
                for co in range(cout):
                    o = out[co, y]
                    for dx in range(k):
                        kv = kern[co, ci, dy, dx]
                        seg = row[dx : dx + w]
                        for xx in range(w):
                            o[numba.uint64(xx)] += kv * seg[numba.uint64(xx)]
        for co in range(cout):
            o = out[co, y]
            for xx in range(w):
                v = o[numba.uint64(xx)]
                o[numba.uint64(xx)] = v if v > 0 else slope * v


@numba.njit(cache=True, nogil=True, parallel=True, fastmath={"contract"})
def _pointwise_tail(x, w1, b1, slope, w2, b2, gain, out):  # pragma: no cover - compiled
    """The trailing 1×1 layers and the output, planar in, channels-last out:
    out[y, x, :] = gain·softsign(w2·leaky(w1·x[:, y, x] + b1) + b2).

    x (C_in, H, W), w1 (C_mid, C_in), w2 (K, C_mid), out (H, W, K); with C_mid = 0 (w1 empty) the first layer is
    skipped: out = gain·softsign(w2·x + b2).
    """
    cin, h, w = x.shape
    cmid = w1.shape[0]
    cout = w2.shape[0]
    for y in numba.prange(h):
        mid = np.empty((max(cmid, 1), w), np.float32)
        acc = np.empty(w, np.float32)
        for j in range(cmid):
            m = mid[j]
            for xx in range(w):
                m[numba.uint64(xx)] = b1[j]
            for ci in range(cin):
                kv = w1[j, ci]
                src = x[ci, y]
                for xx in range(w):
                    m[numba.uint64(xx)] += kv * src[numba.uint64(xx)]
            for xx in range(w):
                v = m[numba.uint64(xx)]
                m[numba.uint64(xx)] = v if v > 0 else slope * v
        for j in range(cout):
            for xx in range(w):
                acc[numba.uint64(xx)] = b2[j]
            if cmid > 0:
                for ci in range(cmid):
                    kv = w2[j, ci]
                    src = mid[ci]
                    for xx in range(w):
                        acc[numba.uint64(xx)] += kv * src[numba.uint64(xx)]
            else:
                for ci in range(cin):
                    kv = w2[j, ci]
                    src = x[ci, y]
                    for xx in range(w):
                        acc[numba.uint64(xx)] += kv * src[numba.uint64(xx)]
            for xx in range(w):
                a = acc[numba.uint64(xx)]
                out[y, xx, j] = gain * a / (np.float32(1.0) + abs(a))


def _checked_image(weights: TrackNetWeights, image: np.ndarray) -> np.ndarray:
    """``image`` as uint8 or float32 ``(H, W)``; :class:`InputError` for colour or too small an image."""
    img = np.asarray(image)
    if img.ndim != 2:
        raise InputError(f"tracknet needs a grey (H, W) image, got shape {img.shape}")
    if img.dtype != np.uint8:
        img = img.astype(np.float32)
    h, w = img.shape
    if h <= weights.radius or w <= weights.radius:
        raise InputError(f"image {w}x{h} is too small for tracknet (needs more than {weights.radius} pixels a side)")
    return img


def tracknet_torch(weights: TrackNetWeights, x: Any, params: dict[str, Any], gain: float = 1.0) -> Any:
    """The network in PyTorch (the device path): ``(1, 1, H, W)`` float32 tensor → ``(1, K, H, W)`` × ``gain``.

    ``params`` holds the layers as tensors on ``x``'s device: ``spatial{i}.weight`` / ``.bias``, ``tail1.*``
    (absent without a hidden 1×1 layer) and ``tail2.*`` (:meth:`TrackNetFeature.__init__`)."""
    import torch

    f = torch.nn.functional
    slope = float(weights.slope)
    for i, (kern, _) in enumerate(weights.spatial):
        r = kern.shape[2] // 2
        x = f.pad(x, (r, r, r, r), mode="reflect")  # = BORDER_REFLECT_101
        x = f.leaky_relu(f.conv2d(x, params[f"spatial{i}.weight"], params[f"spatial{i}.bias"]), slope)
    if "tail1.weight" in params:
        x = f.leaky_relu(f.conv2d(x, params["tail1.weight"][:, :, None, None], params["tail1.bias"]), slope)
    a = f.conv2d(x, params["tail2.weight"][:, :, None, None], params["tail2.bias"])
    return a.div_(a.abs().add_(1.0)).mul_(float(gain))


def tracknet_forward(weights: TrackNetWeights, image: np.ndarray, gain: float = 1.0) -> np.ndarray:
    """The network on a grey ``(H, W)`` image (uint8 or float 0..255): ``(H, W, K)`` float32 × ``gain``."""
    img = _checked_image(weights, image)
    h, w = img.shape
    x: np.ndarray = np.ascontiguousarray(img)[None]
    for kern, bias in weights.spatial:
        out = np.empty((kern.shape[0], h, w), np.float32)
        _conv_layer(x, kern, bias, weights.slope, out)
        x = out
    (w1, b1), (w2, b2) = weights.tail
    res = np.empty((h, w, w2.shape[0]), np.float32)
    _pointwise_tail(x, w1, b1, weights.slope, w2, b2, np.float32(gain), res)
    return res


# ------------------------------------------------------------------------------------------------ feature
class TrackNetFeature(DeviceFeatureMixin, Feature):
    """The ``tracknet`` feature (see the module documentation).

    Parameters
    ----------
    scale : float
        Feature scale multiplied into the (−1, 1) output.
    weights : str or path, optional
        A tracknet ``.npz``; default: the packaged weights (:data:`DEFAULT_WEIGHTS`). The registry's default scale
        is the packaged file's: with another file pass its own scale too (``meta["scale"]`` after
        :func:`dmtrack.training.train.calibrate_weights`, or ``dmtrack calibrate-scale``).
    device : str
        ``"auto"`` (a CUDA GPU when PyTorch sees one, else the numba kernels), ``"cpu"``, ``"cuda"``, ``"cuda:N"``
        (:mod:`dmtrack.features.device`).
    """

    name = "tracknet"
    channels = 8
    description = "small CNN trained through the tracker's alignment, 8-D"

    def __init__(
        self, scale: float = 1.0, weights: str | os.PathLike[str] | None = None, device: Any = "auto"
    ) -> None:
        super().__init__(scale)
        self.weights = load_tracknet(weights)
        self.channels = self.weights.channels
        self.packaged = weights is None
        self._init_device(device)
        if self.runner is not None:
            arrays = {}
            for i, (kern, bias) in enumerate(self.weights.spatial):
                arrays[f"spatial{i}.weight"], arrays[f"spatial{i}.bias"] = kern, bias
            (w1, b1), (w2, b2) = self.weights.tail
            if w1.shape[0]:
                arrays["tail1.weight"], arrays["tail1.bias"] = w1, b1
            arrays["tail2.weight"], arrays["tail2.bias"] = w2, b2
            self._device_params = self.runner.params(arrays)

    def _forward_device(self, image: np.ndarray, gain: float) -> Any:
        runner = self.runner
        assert runner is not None
        x = runner.tensor(_checked_image(self.weights, image)).float()[None, None]
        return tracknet_torch(self.weights, x, self._device_params, gain)

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        if self.runner is not None:
            return self._on_device(image, gain)
        return tracknet_forward(self.weights, image, gain)

    def _file_stat(self, key: str, power: int) -> float | None:
        meta = self.weights.meta
        if key not in meta or "scale" not in meta:
            return None
        return float(meta[key]) * (float(self.scale) / float(meta["scale"])) ** power

    @property
    def energy_channels(self) -> float | None:
        """N_E at this scale: from the weights file's ``meta`` when measured there, else the registry's."""
        v = self._file_stat("energy_channels", 2)
        return v if v is not None or not self.packaged else super().energy_channels

    @property
    def info_channels(self) -> float | None:
        """κ at this scale: from the weights file's ``meta`` when measured there, else the registry's."""
        v = self._file_stat("info_channels", -2)
        return v if v is not None or not self.packaged else super().info_channels

    @property
    def noise_energy_channels(self) -> float | None:
        """N_σ at this scale: from the weights file's ``meta`` when measured there, else the registry's."""
        v = self._file_stat("noise_energy_channels", 2)
        return v if v is not None or not self.packaged else super().noise_energy_channels

    def __repr__(self) -> str:
        return f"TrackNetFeature(scale={self.scale:g}, channels={self.channels}, weights={str(self.weights.path)!r})"
