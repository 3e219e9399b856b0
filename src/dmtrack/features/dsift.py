"""Dense SIFT at every pixel (paper §2.1.1), in the manner of SIFT flow's ``mexDenseSIFT`` (Liu et al.).

One 128-dimensional descriptor per pixel, single scale (the original resolution), no dominant orientation:
4×4 spatial cells × 8 orientation bins around the pixel.  Exact definition used here:

1. **Gradients** of the grey image ``I`` (0..255): halved central differences
   ``gx = ½(I[x+1] − I[x−1])``, ``gy = ½(I[y+1] − I[y−1])``, zero on the one-pixel border;
   ``m = sqrt(gx² + gy²)``, ``θ = atan2(gy, gx)`` (image axes: x right, y down).
2. **Orientation soft binning** as SIFT flow: bin k ∈ 0..7 at ``θ_k = 2πk/8`` receives
   ``m · max(cos(θ − θ_k), 0)^α`` with ``α = 9`` (SIFT flow's value).
3. **Cells**: cell (i, j), i, j ∈ 0..3, is centred at ``(x + (j − 1.5)·c, y + (i − 1.5)·c)`` for cell size ``c``
   (default 3 px, SIFT flow's default), i.e. the 4×4 grid is centred on the pixel.  A sample at (u, v) adds to
   cell (i, j) with the separable spatial weight ``w(u − cx)·w(v − cy)``:
   ``"box"`` (default): ``w(t)`` = length of ``[t − ½, t + ½] ∩ [−c/2, c/2]`` — a c-pixel box cell, as SIFT flow
   sums the orientation energy over box cells (for odd c the half-integer cell centre gives end taps of ½);
   ``"bilinear"``: ``w(t) = max(0, 1 − |t|/c)`` — Lowe's/VLFeat's bilinear spatial interpolation.
   Samples outside the image contribute nothing.
   Implementation: one separable filtering of the 8 orientation bands (with the kernel centred on the
   fractional part of the cell offsets, only its non-zero taps applied), then the 16 cells are integer-shifted
   reads of the 8 filtered bands, gathered and normalised by a numba kernel; ‖h‖² is the sum of 16 shifted
   reads of the per-position band energy.  All passes are row-parallel on a pool of threads
   (:func:`dmtrack.features._nn.parallel_for`), float32 (norms float64), and independent of the thread count.
4. **Normalisation** per pixel, as SIFT flow: ``d = h / (‖h‖ + ε) · 255`` with ε = 0.01 (SIFT flow's 8-bit
   output range, but float and not quantised); then × the feature scale.  A pixel whose cells hold no gradient
   energy gives the zero vector.  Option ``clamp=0.2`` adds Lowe's step instead: ``d = min(h/(‖h‖+ε), 0.2)``,
   ``d = d/‖d‖ · 255``.

The defaults (box cells, no clamp) follow SIFT flow's code, which the paper adapted; calibrated on the
repository's 7-Scenes sample they give a default feature scale of 0.68, the paper's value for SIFT.

Channel order: ``((i·4 + j)·8 + k)`` — rows of cells, then columns, then orientation (SIFT flow's order).

Differences from SIFT flow's code: grey input (SIFT flow takes, for colour, the channel with the largest
gradient), central differences (SIFT flow uses a 5-tap derivative, later Sobel), a grid centred on the pixel
(SIFT flow's cell centres are at (−1, 0, 1, 2)·c, i.e. shifted by +c/2), an exact c-pixel box (SIFT flow's
cell filter taps are (¼, 0, 1, …, 1)), and float output.
"""

from __future__ import annotations

import math
from typing import Literal

import numba
import numpy as np

from dmtrack.errors import InputError
from dmtrack.features import _nn
from dmtrack.features.base import Feature, prepare_image

N_CELLS = 4  #: cells per side
N_BINS = 8  #: orientation bins
SpatialWeighting = Literal["bilinear", "box"]


def image_gradients(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Halved central differences of a grey image; ``(H, W)`` float32 ``gx``, ``gy``, 0 on the 1-pixel border."""
    f = np.asarray(image, dtype=np.float32)
    gx = np.zeros_like(f)
    gy = np.zeros_like(f)
    if f.shape[0] >= 3 and f.shape[1] >= 3:
        half = np.float32(0.5)
        gx[1:-1, 1:-1] = half * (f[1:-1, 2:] - f[1:-1, :-2])
        gy[1:-1, 1:-1] = half * (f[2:, 1:-1] - f[:-2, 1:-1])
    return gx, gy


def orientation_bands(gx: np.ndarray, gy: np.ndarray, alpha: float = 9.0, n_bins: int = N_BINS) -> np.ndarray:
    """Orientation energy per bin: ``m · max(cos(θ − 2πk/n), 0)^α``; ``(H, W, n_bins)`` float32."""
    mag = np.sqrt(gx * gx + gy * gy)
    safe = np.where(mag > 0, mag, np.float32(1.0))
    u = gx / safe
    v = gy / safe
    bands = np.empty(gx.shape + (n_bins,), np.float32)
    int_alpha = float(alpha).is_integer() and 1 <= alpha <= 64
    for k in range(n_bins):
        theta = 2.0 * math.pi * k / n_bins
        p = np.maximum(u * np.float32(math.cos(theta)) + v * np.float32(math.sin(theta)), np.float32(0.0))
        if int_alpha:
            r = _int_power(p, int(alpha))
        else:
            r = np.power(p, np.float32(alpha))
        np.multiply(r, mag, out=bands[:, :, k])
    return bands


def _int_power(p: np.ndarray, n: int) -> np.ndarray:
    result: np.ndarray | None = None
    base = p
    while n:
        if n & 1:
            result = base.copy() if result is None else result * base
        n >>= 1
        if n:
            base = base * base
    assert result is not None
    return result


def cell_weight(t: np.ndarray | float, cell_size: float, spatial: SpatialWeighting) -> np.ndarray:
    """Spatial weight of a sample at signed distance ``t`` (pixels) from a cell centre (see module docs)."""
    t = np.abs(np.asarray(t, dtype=np.float64))
    c = float(cell_size)
    if spatial == "bilinear":
        return np.maximum(0.0, 1.0 - t / c)
    if spatial == "box":
        lo = np.maximum(t - 0.5, -c / 2)
        hi = np.minimum(t + 0.5, c / 2)
        return np.maximum(0.0, hi - lo)
    raise ValueError(f"spatial must be 'bilinear' or 'box', got {spatial!r}")


def cell_layout(cell_size: int, spatial: SpatialWeighting) -> tuple[np.ndarray, np.ndarray, int]:
    """Integer cell shifts, the 1-D cell kernel and its radius.

    The cell centres are at offsets ``(i − 1.5)·c = a + shifts[i]`` with ``a`` ∈ [0, 1); the kernel
    ``kernel[d + R] = w(d − a)``, d = −R..R, so that correlating a band with it and reading at ``+shifts[i]``
    gives the cell sums.

    Returns
    -------
    shifts : (4,) int64
    kernel : (2R+1,) float32
    radius : int
    """
    centres = (np.arange(N_CELLS) - (N_CELLS - 1) / 2.0) * cell_size
    a = float(centres[0] - math.floor(centres[0]))
    shifts = np.round(centres - a).astype(np.int64)
    radius = int(math.ceil(cell_size + 1))
    d = np.arange(-radius, radius + 1)
    kernel = cell_weight(d - a, cell_size, spatial).astype(np.float32)
    return shifts, kernel, radius


#: Rows per work item of the row-parallel kernels (see :func:`dmtrack.features._nn.parallel_for`).
ROW_BLOCK = 16


@numba.njit(cache=True, nogil=True)
def _bands_rows(img, cosk, sink, alpha, int_alpha, margin, r0, r1, out):  # pragma: no cover - compiled
    """Rows r0..r1-1 of :func:`orientation_bands` of the grey image, float32 and in the same operation order
    (so bit-identical), written at ``out[y + margin, x + margin, :]`` (the margins are left alone)."""
    h, w = img.shape
    nb = cosk.shape[0]
    zero = np.float32(0.0)
    half = np.float32(0.5)
    one = np.float32(1.0)
    mag = np.zeros(w, np.float32)
    u = np.zeros(w, np.float32)
    v = np.zeros(w, np.float32)
    p = np.zeros(w, np.float32)
    r = np.zeros(w, np.float32)
    base = np.zeros(w, np.float32)
    for y in range(r0, r1):
        dst = out[y + margin, margin : margin + w]
        if y == 0 or y == h - 1 or w < 3:
            for x in range(w):
                for k in range(nb):
                    dst[x, k] = zero
            continue
        for x in range(1, w - 1):
            gx = half * (img[y, x + 1] - img[y, x - 1])
            gy = half * (img[y + 1, x] - img[y - 1, x])
            m = np.sqrt(gx * gx + gy * gy)
            safe = m if m > zero else one
            mag[x] = m
            u[x] = gx / safe
            v[x] = gy / safe
        for k in range(nb):
            c = cosk[k]
            sn = sink[k]
            for x in range(1, w - 1):
                q = u[x] * c + v[x] * sn
                p[x] = q if q > zero else zero
            if int_alpha > 0:
                # p^alpha by binary powering in _int_power's order
                n = int_alpha
                first = True
                for x in range(1, w - 1):
                    base[x] = p[x]
                while n:
                    if n & 1:
                        if first:
                            for x in range(1, w - 1):
                                r[x] = base[x]
                            first = False
                        else:
                            for x in range(1, w - 1):
                                r[x] = r[x] * base[x]
                    n >>= 1
                    if n:
                        for x in range(1, w - 1):
                            base[x] = base[x] * base[x]
            else:
                for x in range(1, w - 1):
                    r[x] = np.float32(p[x] ** alpha)
            for x in range(1, w - 1):
                dst[x, k] = r[x] * mag[x]
        for k in range(nb):
            dst[0, k] = zero
            dst[w - 1, k] = zero


@numba.njit(cache=True, nogil=True)
def _hfilter_rows(src, offs, wts, r0, r1, dst):  # pragma: no cover - compiled
    """``dst[y, x] = Σ_t wts[t] · src[y, x + offs[t]]`` (zero outside; taps summed in order) for rows r0..r1-1
    of ``(H, W, B)`` C-contiguous arrays: per row, flat sweeps over the W·B values."""
    _, w, nb = src.shape
    wn = w * nb
    zero = np.float32(0.0)
    for y in range(r0, r1):
        s = src[y].reshape(wn)
        d = dst[y].reshape(wn)
        for i in range(wn):
            d[i] = zero
        for t in range(offs.shape[0]):
            o = offs[t] * nb
            lo = max(0, -o)
            hi = min(wn, wn - o)
            if hi <= lo:
                continue
            wt = wts[t]
            dd = d[lo:hi]
            ss = s[lo + o : hi + o]
            for i in range(hi - lo):
                dd[i] += wt * ss[i]


@numba.njit(cache=True, nogil=True)
def _vfilter_rows(src, offs, wts, r0, r1, dst, energy):  # pragma: no cover - compiled
    """``dst[y] = Σ_t wts[t] · src[y + offs[t]]`` (zero outside; taps summed in order) for rows r0..r1-1, and
    ``energy[y, x] = Σ_k dst[y, x, k]²`` (float64); 8 bands."""
    h, w, nb = src.shape
    wn = w * nb
    zero = np.float32(0.0)
    for y in range(r0, r1):
        d = dst[y].reshape(wn)
        for i in range(wn):
            d[i] = zero
        for t in range(offs.shape[0]):
            yy = y + offs[t]
            if 0 <= yy < h:
                wt = wts[t]
                s = src[yy].reshape(wn)
                for i in range(wn):
                    d[i] += wt * s[i]
        d2 = dst[y]
        e = energy[y]
        for x in range(w):
            c = d2[x]
            ss = 0.0
            for k in range(8):
                val = np.float64(c[k])
                ss += val * val
            e[x] = ss


@numba.njit(cache=True, nogil=True)
def _norm_factors(energy, shifts, margin, eps, gain, y, fac):  # pragma: no cover - compiled
    """Row y's normalisation factors ``gain / (‖h‖ + eps)`` (0 where ‖h‖ = 0), ‖h‖² the sum of the 16 cells'
    band energies at each pixel, into ``fac`` (W,) float64."""
    w = fac.shape[0]
    for x in range(w):
        fac[x] = 0.0
    for i in range(4):
        erow = energy[y + margin + shifts[i]]
        for j in range(4):
            off = margin + shifts[j]
            for x in range(w):
                fac[x] += erow[x + off]
    for x in range(w):
        ss = fac[x]
        fac[x] = gain / (math.sqrt(ss) + eps) if ss > 0.0 else 0.0


@numba.njit(cache=True, nogil=True)
def _assemble_rows(cpad, energy, shifts, margin, eps, gain, r0, r1, out):  # pragma: no cover - compiled
    """Rows r0..r1-1 of the descriptors (no clamp), 4×4 cells × 8 bins: the cells are shifted reads of the
    filtered bands, ``d = gain · h / (‖h‖ + eps)`` with ‖h‖² summed from the per-position band energies
    (0 where ‖h‖ = 0)."""
    w = out.shape[1]
    fac = np.empty(w, np.float64)
    for y in range(r0, r1):
        _norm_factors(energy, shifts, margin, eps, gain, y, fac)
        orow = out[y]
        for i in range(4):
            crow = cpad[y + margin + shifts[i]]
            for x in range(w):
                fx = fac[x]
                o = orow[x]
                for j in range(4):
                    c = crow[x + margin + shifts[j]]
                    b = (i * 4 + j) * 8
                    for k in range(8):
                        o[b + k] = np.float32(np.float64(c[k]) * fx)


@numba.njit(cache=True, nogil=True)
def _band_major_rows(cpad, r0, r1, out):  # pragma: no cover - compiled
    """Rows r0..r1-1 of the padded cell sums, band-major: ``out[k, y, x] = cpad[y, x, k]``."""
    for y in range(r0, r1):
        row = cpad[y]
        for k in range(row.shape[1]):
            o = out[k, y]
            for x in range(row.shape[0]):
                o[x] = row[x, k]


@numba.njit(cache=True, nogil=True)
def _assemble_project_rows(cband, energy, shifts, margin, eps, gain, weight, bias, r0, r1, out):  # pragma: no cover
    """Rows r0..r1-1 of the descriptors (no clamp) projected at once, never formed: ``out = weight d + bias`` per
    pixel (``weight``: (K, 128)), with ``d = fac · h`` as :func:`_assemble_rows` has it, computed as
    ``fac · (weight h) + bias`` — the 128 products summed in float32 over contiguous runs of a row of the band-major
    cell sums ``cband`` (8, H + 2M, W + 2M), so they vectorise."""
    w = out.shape[1]
    kk = weight.shape[0]
    fac = np.empty(w, np.float64)
    acc = np.empty((kk, w), np.float32)
    for y in range(r0, r1):
        _norm_factors(energy, shifts, margin, eps, gain, y, fac)
        acc[:, :] = 0.0
        for i in range(4):
            yy = y + margin + shifts[i]
            for j in range(4):
                off = margin + shifts[j]
                b = (i * 4 + j) * 8
                for k in range(8):
                    src = cband[k, yy, off : off + w]
                    for q in range(kk):
                        wq = weight[q, b + k]
                        arow = acc[q]
                        for x in range(w):
                            arow[x] += wq * src[x]
        orow = out[y]
        for x in range(w):
            f = fac[x]
            for q in range(kk):
                orow[x, q] = np.float32(bias[q] + f * acc[q, x])


@numba.njit(cache=True, nogil=True)
def _assemble_clamp_rows(cpad, shifts, margin, clamp, eps, gain, r0, r1, out):  # pragma: no cover - compiled
    """Rows r0..r1-1 with Lowe's clamp: ``d = min(h / (‖h‖ + eps), clamp)``, ``d = gain · d / ‖d‖``."""
    w, dim = out.shape[1], out.shape[2]
    nb = cpad.shape[2]
    n = shifts.shape[0]
    buf = np.empty(dim, np.float64)
    for y in range(r0, r1):
        for x in range(w):
            ss = 0.0
            idx = 0
            for i in range(n):
                yy = y + margin + shifts[i]
                for j in range(n):
                    xx = x + margin + shifts[j]
                    for k in range(nb):
                        v = np.float64(cpad[yy, xx, k])
                        buf[idx] = v
                        ss += v * v
                        idx += 1
            inv = 1.0 / (math.sqrt(ss) + eps) if ss > 0.0 else 0.0
            ss2 = 0.0
            for d in range(dim):
                v = buf[d] * inv
                if v > clamp:
                    v = clamp
                buf[d] = v
                ss2 += v * v
            f = gain / math.sqrt(ss2) if ss2 > 0.0 else 0.0
            for d in range(dim):
                out[y, x, d] = np.float32(buf[d] * f)


class DenseSiftFeature(Feature):
    """Dense SIFT, 128 channels per pixel (see module docs for the exact definition).

    Parameters
    ----------
    scale : float
        Default feature scale; the unscaled descriptor has L2 norm 255·‖h‖/(‖h‖+ε) (255 with ``clamp``; 0
        where there is no gradient).
    cell_size : int
        Cell width in pixels (SIFT flow's default 3); the descriptor spans 4·cell_size pixels.
    alpha : float
        Exponent of the orientation soft binning ``max(cos, 0)^α`` (SIFT flow: 9).
    spatial : {"box", "bilinear"}
        Spatial weighting of samples into cells (box: SIFT flow).
    clamp : float or None
        If given (Lowe: 0.2), clamp the normalised descriptor and renormalise; None (default, SIFT flow) does not.
    eps : float
        Added to the norm in the first normalisation (SIFT flow: 0.01).
    """

    name = "dsift"
    channels = N_CELLS * N_CELLS * N_BINS
    pyramid = "downsample"
    description = "dense SIFT at every pixel, single scale, no orientation (SIFT flow style, 4x4 cells x 8 bins)"

    def __init__(
        self,
        scale: float = 1.0,
        cell_size: int = 3,
        alpha: float = 9.0,
        spatial: SpatialWeighting = "box",
        clamp: float | None = None,
        eps: float = 0.01,
    ) -> None:
        super().__init__(scale)
        if int(cell_size) != cell_size or cell_size < 1:
            raise ValueError(f"cell_size must be a positive integer, got {cell_size!r}")
        if spatial not in ("bilinear", "box"):
            raise ValueError(f"spatial must be 'bilinear' or 'box', got {spatial!r}")
        if not alpha >= 1:
            raise ValueError(f"alpha must be ≥ 1, got {alpha!r}")
        if clamp is not None and not 0 < clamp <= 1:
            raise ValueError(f"clamp must be in (0, 1] or None, got {clamp!r}")
        if not eps >= 0:
            raise ValueError(f"eps must be ≥ 0, got {eps!r}")
        self.cell_size = int(cell_size)
        self.alpha = float(alpha)
        self.spatial: SpatialWeighting = spatial
        self.clamp = None if clamp is None else float(clamp)
        self.eps = float(eps)
        self._shifts, self._kernel, self._radius = cell_layout(self.cell_size, spatial)
        self._margin = int(np.abs(self._shifts).max())

    def cell_histograms(self, image: np.ndarray, threads: int | None = None) -> np.ndarray:
        """Padded cell-sum images ``(H + 2M, W + 2M, 8)`` float32 (M = max |shift|); see :func:`cell_layout`."""
        return self._cell_sums(image, threads)[0].copy()

    def _cell_sums(self, image: np.ndarray, threads: int | None) -> tuple[np.ndarray, np.ndarray]:
        """The padded cell sums and their per-position energy ``Σ_k cpad[..., k]²`` (float64), in the calling
        thread's scratch arrays (valid until its next call)."""
        img = np.ascontiguousarray(image, dtype=np.float32)
        h, w = img.shape
        m = self._margin
        hp, wp = h + 2 * m, w + 2 * m
        # orientation bands into the zero-padded frame, then the separable cell filter (zero outside), all
        # row-parallel; only the kernel's non-zero taps are applied
        bands = _nn.scratch("dsift.bands", (hp, wp, N_BINS), np.float32)
        bands[:m] = 0.0
        bands[m + h :] = 0.0
        bands[m : m + h, :m] = 0.0
        bands[m : m + h, m + w :] = 0.0
        theta = 2.0 * math.pi * np.arange(N_BINS) / N_BINS
        cosk = np.array([np.float32(math.cos(t)) for t in theta], np.float32)
        sink = np.array([np.float32(math.sin(t)) for t in theta], np.float32)
        int_alpha = int(self.alpha) if float(self.alpha).is_integer() and 1 <= self.alpha <= 64 else 0
        alpha = np.float32(self.alpha)
        _nn.parallel_for(
            lambda a, b: _bands_rows(img, cosk, sink, alpha, int_alpha, m, a, b, bands), h, ROW_BLOCK, threads
        )
        nz = np.flatnonzero(self._kernel)
        offs = (nz - self._radius).astype(np.int64)
        wts = np.ascontiguousarray(self._kernel[nz], dtype=np.float32)
        tmp = _nn.scratch("dsift.tmp", (hp, wp, N_BINS), np.float32)
        _nn.parallel_for(lambda a, b: _hfilter_rows(bands, offs, wts, a, b, tmp), hp, ROW_BLOCK, threads)
        cpad = bands  # reused: the bands are no longer needed
        energy = _nn.scratch("dsift.energy", (hp, wp), np.float64)
        _nn.parallel_for(lambda a, b: _vfilter_rows(tmp, offs, wts, a, b, cpad, energy), hp, ROW_BLOCK, threads)
        return cpad, energy

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        return self.compute_threads(image, gain)

    def compute_threads(self, image: np.ndarray, gain: float, threads: int | None = None) -> np.ndarray:
        """Descriptors of ``image`` (grey or RGB, as :meth:`compute`) times ``gain``, on ``threads`` threads
        (default: numba's count in the calling thread); the result does not depend on the thread count."""
        image = prepare_image(image, colour=False)
        cpad, energy = self._cell_sums(image, threads)
        h, w = image.shape[:2]
        out = np.empty((h, w, self.channels), np.float32)
        g = 255.0 * gain
        m = self._margin
        if self.clamp is None:
            _nn.parallel_for(
                lambda a, b: _assemble_rows(cpad, energy, self._shifts, m, self.eps, g, a, b, out),
                h,
                ROW_BLOCK,
                threads,
            )
        else:
            clamp = self.clamp
            _nn.parallel_for(
                lambda a, b: _assemble_clamp_rows(cpad, self._shifts, m, clamp, self.eps, g, a, b, out),
                h,
                ROW_BLOCK,
                threads,
            )
        return out

    def compute_projected(self, image: np.ndarray, weight: np.ndarray, bias: np.ndarray,
                          threads: int | None = None) -> np.ndarray:
        """``compute(image) @ weight.T + bias`` per pixel, projected where each descriptor is formed (row blocks in
        parallel), so the 128-channel map is never written: ``(H, W, K)`` float32.

        Used by :class:`~dmtrack.features.pca.ReducedFeature` for ``dsift-pcaK``; equal to projecting
        :meth:`compute`'s output within float32 rounding. With ``clamp`` it projects the full
        map (the clamp needs each descriptor's second norm).
        """
        weight = np.asarray(weight, np.float32)
        bias = np.ascontiguousarray(bias, np.float32)
        if weight.ndim != 2 or weight.shape[1] != self.channels or bias.shape != (weight.shape[0],):
            raise InputError(f"projection must be (K, {self.channels}) and (K,), got {weight.shape}, {bias.shape}")
        if self.clamp is not None:
            fm = self.compute(image)
            h, w, n = fm.shape
            return (fm.reshape(h * w, n) @ weight.T + bias).reshape(h, w, weight.shape[0])
        img = prepare_image(image, colour=False)
        cpad, energy = self._cell_sums(img, threads)
        h, w = img.shape[:2]
        out = np.empty((h, w, weight.shape[0]), np.float32)
        g = 255.0 * float(self.scale)
        m = self._margin
        weight = np.ascontiguousarray(weight)
        hp, wp, nb = cpad.shape
        cband = _nn.scratch("dsift.cband", (nb, hp, wp), np.float32)
        _nn.parallel_for(lambda a, b: _band_major_rows(cpad, a, b, cband), hp, ROW_BLOCK, threads)
        _nn.parallel_for(
            lambda a, b: _assemble_project_rows(cband, energy, self._shifts, m, self.eps, g, weight, bias, a, b, out),
            h,
            ROW_BLOCK,
            threads,
        )
        return out

    def __repr__(self) -> str:
        return (
            f"DenseSiftFeature(scale={self.scale:g}, cell_size={self.cell_size}, alpha={self.alpha:g}, "
            f"spatial={self.spatial!r}, clamp={self.clamp}, eps={self.eps:g})"
        )
