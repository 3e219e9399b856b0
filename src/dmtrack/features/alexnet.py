"""AlexNet conv1 feature (paper §2.1.2): the first convolution of a pretrained AlexNet + ReLU at every pixel.

The paper takes Caffe's BVLC AlexNet, keeps "conv1" (96 kernels 11×11×3) and its ReLU, and changes the stride from
4 to 1 with a zero padding of 5 so that the H×W×96 output has the input's resolution; the learned kernels are
unchanged.  The input follows Caffe's convention for that model: BGR channel order, values 0..255, minus the
per-channel mean of the ILSVRC 2012 mean image (B 104.00698793, G 116.66876762, R 122.67891434 — the values
Caffe's examples use, :data:`~dmtrack.features.weights.CAFFE_BGR_MEAN`); the zero padding is applied after the
mean subtraction (as Caffe pads its input blob).

``alexnet64`` is the same construction on torchvision's AlexNet (64 conv1 kernels, RGB input, ImageNet
``(x/255 - mean)/std`` normalisation), for users who have PyTorch's weights rather than Caffe's.

Backends (:func:`conv1_relu`): ``fft`` (default; overlap-save FFT convolution with numpy's FFT and numba kernels,
≈ 10× fewer operations than a direct convolution of 11×11 kernels), ``numpy`` (im2col + BLAS sgemm) and ``torch``
(oneDNN convolution, channels-last; needs PyTorch).  They give the same result to float32 rounding.
"""

from __future__ import annotations

import math
import os
from typing import Any

import numba
import numpy as np
import scipy.fft

from dmtrack.errors import InputError
from dmtrack.features import _nn
from dmtrack.features.base import Feature, prepare_image
from dmtrack.features.device import DeviceFeatureMixin
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


# ------------------------------------------------------------------------------------------------ backends
#: Backends of :func:`conv1_relu`; ``"auto"`` is :data:`AUTO_BACKEND`.
BACKENDS = ("auto", "fft", "numpy", "torch")

#: What ``"auto"`` means: the fastest backend on a 2-core AVX2 CPU (``benchmarks/bench_features.py``; 640×480,
#: 96 kernels: fft ≈ 2× faster than torch's oneDNN convolution, itself faster than numpy's im2col + sgemm).
AUTO_BACKEND = "fft"

#: FFT lengths tried per axis for large images (a smaller one is used when the whole axis fits in it).
FFT_LENGTHS = (64, 80, 96)

#: Tiles per work item of the FFT backend.
FFT_CHUNK = 2

#: Bytes of im2col buffer per band of output rows of the ``numpy`` backend: few large sgemm calls (each one a
#: parallel region of OpenBLAS's threads) hold up better on a busy machine than cache-sized ones.
IM2COL_BAND_BYTES = 32 << 20


def resolve_backend(backend: str) -> str:
    """``"auto"`` → :data:`AUTO_BACKEND`; validates explicit choices (``"torch"`` needs PyTorch installed).

    Raises
    ------
    InputError
        Unknown backend, or ``"torch"`` without PyTorch.
    """
    if backend not in BACKENDS:
        raise InputError(f"backend must be one of {', '.join(map(repr, BACKENDS))}, got {backend!r}")
    if backend == "auto":
        return AUTO_BACKEND
    if backend == "fft":
        return "fft"
    return _nn.resolve_backend(backend)


def conv1_relu(
    x: np.ndarray,
    conv1: Conv1Weights,
    gain: float = 1.0,
    backend: str = "auto",
    project: tuple[np.ndarray, np.ndarray] | None = None,
    cache: dict | None = None,
    threads: int | None = None,
) -> np.ndarray:
    """``gain · ReLU(conv1(x))`` with stride 1 on an already padded input.

    Parameters
    ----------
    x
        ``(H + k - 1, W + k - 1, 3)`` float32 from :func:`alexnet_input`.
    conv1
        Weights ``(N, 3, k, k)`` and bias.
    gain
        Factor multiplied into the result (the feature scale); must be > 0 (it commutes with the ReLU).
    backend
        ``"auto"`` (:data:`AUTO_BACKEND`), ``"fft"``, ``"numpy"`` or ``"torch"``:

        * ``"fft"`` – overlap-save FFT convolution on 64×64-ish tiles (numpy's pocketfft, float32), the 96
          inverse transforms per tile dominate: ≈ 2 GFLOP per 640×480 frame instead of the 21 GFLOP of a direct
          convolution; tiles are spread over ``threads`` threads (numba kernels + FFTs release the GIL);
        * ``"numpy"`` – im2col on bands of rows + one BLAS sgemm per band, ReLU on the band while in cache;
        * ``"torch"`` – PyTorch's oneDNN convolution, channels-last.

        All compute the same function; they differ by float32 rounding (≈ 1e-6 of the largest output).
    project
        Optional ``(weight (K, N), bias (K,))``: return ``weight @ (gain · ReLU(conv1)) + bias`` per pixel
        instead (the paper's PCA reduction as a 1×1 convolution after conv1, §3.4).  The ``fft`` and ``numpy``
        backends apply it tile by tile / band by band, so the N-channel map is never materialised.
    cache
        Optional dict kept by the caller between calls (the ``fft`` backend stores the kernels' spectra there).
    threads
        Threads of the ``fft`` backend (default: ``numba.get_num_threads()`` of the calling thread).

    Returns
    -------
    np.ndarray
        ``(H, W, N)`` (or ``(H, W, K)`` with ``project``) float32 C-contiguous.
    """
    backend = resolve_backend(backend)
    if backend == "fft" and conv1.weight.shape[1] == 3:
        return _conv1_relu_fft(x, conv1, gain, project, {} if cache is None else cache, threads)
    if backend == "torch":
        return _conv1_relu_torch(x, conv1, gain, project)
    return _conv1_relu_gemm(x, conv1, gain, project)


def _projection(project: tuple[np.ndarray, np.ndarray], gain: float) -> tuple[np.ndarray, np.ndarray]:
    """``(weight.T · gain (N, K) C-contiguous, bias (K,))`` float32."""
    pw = np.asarray(project[0], np.float32) * np.float32(gain)
    return np.ascontiguousarray(pw.T), np.ascontiguousarray(project[1], dtype=np.float32)


# --------------------------------------------------------------------------------------------- torch
def _conv1_relu_torch(
    x: np.ndarray, conv1: Conv1Weights, gain: float, project: tuple[np.ndarray, np.ndarray] | None
) -> np.ndarray:
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


# ------------------------------------------------------------------------------------ numpy (im2col)
@numba.njit(cache=True, nogil=True)
def _im2col_band(xf, y0, wo, kh, seg, cin, p0, p1, cols):  # pragma: no cover - compiled
    # row p (output pixel (y0 + p // wo, p % wo)) of cols = the kh runs xf[y0 + r + u, x·cin : x·cin + seg]
    # (seg = kw·cin), i.e. (u, v, c) order; rows p0 .. p1-1 only
    for p in range(p0, p1):
        r = p // wo
        base = (p - r * wo) * cin
        for u in range(kh):
            src = xf[y0 + r + u]
            off = u * seg
            for q in range(seg):
                cols[p, off + q] = src[base + q]


@numba.njit(cache=True, nogil=True)
def _bias_relu(a, bias):  # pragma: no cover - compiled
    n, m = a.shape
    zero = np.float32(0.0)
    for i in range(n):
        for j in range(m):
            v = a[i, j] + bias[j]
            a[i, j] = v if v > zero else zero


def _conv1_relu_gemm(
    x: np.ndarray, conv1: Conv1Weights, gain: float, project: tuple[np.ndarray, np.ndarray] | None
) -> np.ndarray:
    x = np.ascontiguousarray(x, dtype=np.float32)
    o_ch, c_in, kh, kw = conv1.weight.shape
    hp, wp, _ = x.shape
    ho, wo = hp - kh + 1, wp - kw + 1
    k = kh * kw * c_in
    g = np.float32(gain if project is None else 1.0)
    # gain > 0 commutes with the ReLU: folded into the kernels and the bias
    wmat = np.ascontiguousarray(np.transpose(conv1.weight, (2, 3, 1, 0)).reshape(k, o_ch) * g, dtype=np.float32)
    bias = np.ascontiguousarray(conv1.bias * g, dtype=np.float32)
    proj = None if project is None else _projection(project, gain)
    out = np.empty((ho, wo, o_ch if proj is None else proj[0].shape[1]), np.float32)
    rows = max(1, min(ho, IM2COL_BAND_BYTES // max(1, wo * k * 4)))
    cols = np.empty((rows * wo, k), np.float32)
    band = np.empty((rows * wo, o_ch), np.float32) if proj is not None else None
    xf = x.reshape(hp, wp * c_in)
    for y0 in range(0, ho, rows):
        n = min(rows, ho - y0)
        c = cols[: n * wo]
        # serial gather: OpenBLAS's threads, still spinning after the previous band's product, would compete
        # with gather threads
        _im2col_band(xf, y0, wo, kh, kw * c_in, c_in, 0, n * wo, c)
        dst = out[y0 : y0 + n].reshape(n * wo, out.shape[2])
        if proj is None:
            np.matmul(c, wmat, out=dst)
            _bias_relu(dst, bias)
        else:
            assert band is not None
            b = band[: n * wo]
            np.matmul(c, wmat, out=b)
            _bias_relu(b, bias)
            np.matmul(b, proj[0], out=dst)
            dst += proj[1]
    return out


# ------------------------------------------------------------------------------------------------ FFT
def fft_length(n: int, k: int) -> int:
    """FFT length along an axis of ``n`` output pixels for ``k`` taps (overlap-save: ``L − k + 1`` per tile).

    The smallest fast length holding the whole axis if that is at most :data:`FFT_LENGTHS`' first entry,
    otherwise the entry of :data:`FFT_LENGTHS` (or ``4k``) minimising ``tiles · L · log2 L``.
    """
    need = n + k - 1
    whole = int(scipy.fft.next_fast_len(need, real=True))
    if whole <= FFT_LENGTHS[0]:
        return whole
    cands = [L for L in FFT_LENGTHS if L - k + 1 >= 8] or [int(scipy.fft.next_fast_len(4 * k, real=True))]
    if whole <= max(cands):
        cands.append(whole)
    return min(cands, key=lambda L: (math.ceil(n / (L - k + 1)) * L * math.log2(L), L))


def _fft_spectra(weight: np.ndarray, fh: int, fw: int) -> tuple[np.ndarray, np.ndarray]:
    """Conjugated spectra of the kernels zero-padded to ``(fh, fw)``: real and imaginary parts, ``(fh, fw//2+1,
    C, N)`` float32 each (computed in float64)."""
    spec = np.conj(np.fft.rfft2(np.asarray(weight, np.float64), s=(fh, fw)))  # (N, C, fh, F)
    spec = spec.transpose(2, 3, 1, 0)
    return np.ascontiguousarray(spec.real, np.float32), np.ascontiguousarray(spec.imag, np.float32)


@numba.njit(cache=True, nogil=True)
def _fft_gather(xp, h0s, w0s, tiles):  # pragma: no cover - compiled
    # tiles[t, c] = xp[c, h0:h0+fh, w0:w0+fw]
    n, c_in, fh, fw = tiles.shape
    for t in range(n):
        for c in range(c_in):
            for i in range(fh):
                src = xp[c, h0s[t] + i]
                dst = tiles[t, c, i]
                for j in range(fw):
                    dst[j] = src[w0s[t] + j]


@numba.njit(cache=True, nogil=True, fastmath={"contract"})
def _fft_product(xs, wr, wi, ys):  # pragma: no cover - compiled
    # ys[t, r, f, 2o:2o+2] = Σ_c xs[t, c, r, f] · (wr + i·wi)[r, f, c, o]   (3 input channels)
    n, _, fh, nf = xs.shape
    o_ch = wr.shape[3]
    for r in range(fh):
        for f in range(nf):
            w0r = wr[r, f, 0]
            w1r = wr[r, f, 1]
            w2r = wr[r, f, 2]
            w0i = wi[r, f, 0]
            w1i = wi[r, f, 1]
            w2i = wi[r, f, 2]
            for t in range(n):
                x0 = xs[t, 0, r, f]
                x1 = xs[t, 1, r, f]
                x2 = xs[t, 2, r, f]
                a0, b0 = x0.real, x0.imag
                a1, b1 = x1.real, x1.imag
                a2, b2 = x2.real, x2.imag
                dst = ys[t, r, f]
                for o in range(o_ch):
                    dst[2 * o] = (a0 * w0r[o] - b0 * w0i[o]) + (a1 * w1r[o] - b1 * w1i[o]) + (a2 * w2r[o] - b2 * w2i[o])
                    dst[2 * o + 1] = (
                        (a0 * w0i[o] + b0 * w0r[o]) + (a1 * w1i[o] + b1 * w1r[o]) + (a2 * w2i[o] + b2 * w2r[o])
                    )


@numba.njit(cache=True, nogil=True)
def _fft_store(y, bias, gain, tw, h0s, w0s, out):  # pragma: no cover - compiled
    # out[h0 + i, w0 + j] = gain · max(y[t, i, j] + bias, 0) on the valid part of each tile
    n, th, _, o_ch = y.shape
    h, w, _ = out.shape
    zero = np.float32(0.0)
    for t in range(n):
        h0 = h0s[t]
        w0 = w0s[t]
        hh = min(th, h - h0)
        ww = min(tw, w - w0)
        for i in range(hh):
            src = y[t, i]
            dst = out[h0 + i]
            for j in range(ww):
                for c in range(o_ch):
                    v = (src[j, c] + bias[c]) * gain
                    dst[w0 + j, c] = v if v > zero else zero


@numba.njit(cache=True, nogil=True)
def _fft_bias_relu(y, bias):  # pragma: no cover - compiled
    # y = max(y + bias, 0) in place
    n, th, fw, o_ch = y.shape
    zero = np.float32(0.0)
    for t in range(n):
        for i in range(th):
            for j in range(fw):
                src = y[t, i, j]
                for c in range(o_ch):
                    v = src[c] + bias[c]
                    src[c] = v if v > zero else zero


def _conv1_relu_fft(
    x: np.ndarray,
    conv1: Conv1Weights,
    gain: float,
    project: tuple[np.ndarray, np.ndarray] | None,
    cache: dict,
    threads: int | None,
) -> np.ndarray:
    """Overlap-save FFT convolution: tiles of ``fh × fw`` input pixels give ``(fh − k + 1) × (fw − k + 1)``
    outputs; per tile 3 forward and N inverse 2-D real FFTs (the inverse one with only the valid rows)."""
    o_ch, c_in, kh, kw = conv1.weight.shape
    hp, wp, _ = x.shape
    h, w = hp - kh + 1, wp - kw + 1
    fh, fw = fft_length(h, kh), fft_length(w, kw)
    th, tw = fh - kh + 1, fw - kw + 1
    ny, nx = -(-h // th), -(-w // tw)
    key = ("fft", fh, fw)
    if key not in cache:
        cache[key] = _fft_spectra(conv1.weight, fh, fw)
    wr, wi = cache[key]
    nf = fw // 2 + 1
    # channels-first input, zero-padded so that every tile is whole
    xp = np.zeros((c_in, ny * th + kh - 1, nx * tw + kw - 1), np.float32)
    xp[:, :hp, :wp] = np.moveaxis(np.asarray(x, np.float32), 2, 0)
    n_tiles = ny * nx
    h0s = (np.arange(n_tiles, dtype=np.int64) // nx) * th
    w0s = (np.arange(n_tiles, dtype=np.int64) % nx) * tw
    bias = np.ascontiguousarray(conv1.bias, dtype=np.float32)
    g = np.float32(gain)
    proj = None if project is None else _projection(project, gain)
    out = np.empty((h, w, o_ch if proj is None else proj[0].shape[1]), np.float32)
    chunk = FFT_CHUNK

    def work(t_first: int, t_end: int) -> None:
        tiles = _nn.scratch("alexnet.tiles", (chunk, c_in, fh, fw), np.float32)
        spec = _nn.scratch("alexnet.spec", (chunk, c_in, fh, nf), np.complex64)
        prod = _nn.scratch("alexnet.prod", (chunk, fh, nf, o_ch), np.complex64)
        y = _nn.scratch("alexnet.y", (chunk, th, fw, o_ch), np.float32)
        n = t_end - t_first
        hs, ws = h0s[t_first:t_end], w0s[t_first:t_end]
        _fft_gather(xp, hs, ws, tiles[:n])
        np.fft.rfft2(tiles[:n], out=spec[:n])
        _fft_product(spec[:n], wr, wi, prod[:n].view(np.float32))
        np.fft.ifft(prod[:n], axis=1, out=prod[:n])
        np.fft.irfft(prod[:n, :th], n=fw, axis=2, out=y[:n])
        if proj is None:
            _fft_store(y[:n], bias, g, tw, hs, ws, out)
        else:
            # ReLU in place, then the 1×1 projection of each tile's valid block straight into the output
            # (one small sgemm per tile row, inside numpy's matmul loop)
            _fft_bias_relu(y[:n], bias)
            for t in range(n):
                h0, w0 = int(hs[t]), int(ws[t])
                dst = out[h0 : min(h, h0 + th), w0 : min(w, w0 + tw)]
                np.matmul(y[t, : dst.shape[0], : dst.shape[1]], proj[0], out=dst)
                dst += proj[1]

    _nn.parallel_for(work, n_tiles, chunk, threads)
    return out


class AlexNetFeature(DeviceFeatureMixin, Feature):
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
        ``"auto"`` (:data:`AUTO_BACKEND`, the FFT), ``"fft"``, ``"numpy"`` or ``"torch"`` (see :func:`conv1_relu`):
        the CPU kernels.
    device
        ``"auto"`` (a CUDA GPU when PyTorch sees one, else the CPU kernels), ``"cpu"``, ``"cuda"``, ``"cuda:N"``
        (see :mod:`dmtrack.features.device`); on a GPU, ``alexnet-pcaK`` projects there before the transfer.
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
        device: Any = "auto",
    ) -> None:
        super().__init__(scale)
        self.backend = resolve_backend(backend)
        self._cache: dict = {}
        self.weights_path = find_weights(self.weights_key, weights)
        self.conv1 = load_alexnet_conv1(self.weights_path)
        self.channels = int(self.conv1.weight.shape[0])
        self._init_device(device)
        if self.runner is not None:
            self._device_params = self.runner.params({"weight": self.conv1.weight, "bias": self.conv1.bias})

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        if self.runner is not None:
            return self._on_device(image, gain)
        x = alexnet_input(image, self.conv1)
        return conv1_relu(x, self.conv1, gain, self.backend, cache=self._cache)

    def _forward_device(self, image: np.ndarray, gain: float) -> Any:
        """``gain · ReLU(conv1)`` of the prepared image on the device: ``(1, N, H, W)`` channels-last."""
        runner = self.runner
        assert runner is not None
        torch = runner.torch
        x = runner.tensor(alexnet_input(image, self.conv1)).permute(2, 0, 1).unsqueeze(0)
        x = x.contiguous(memory_format=torch.channels_last)
        p = self._device_params  # gain > 0 commutes with the ReLU: folded into the kernels
        y = torch.nn.functional.conv2d(x, p["weight"] * float(gain), p["bias"] * float(gain))
        return y.clamp_(min=0.0)

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
        if self.runner is not None:
            return self.compute_projected_on_device(img, weight, np.asarray(bias, np.float32))
        x = alexnet_input(img, self.conv1)
        out = conv1_relu(
            x, self.conv1, self.scale, self.backend, project=(weight, np.asarray(bias, np.float32)), cache=self._cache
        )
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
        device: Any = "auto",
    ) -> None:
        super().__init__(scale, weights, backend, device)
