"""The sums in fixed lanes (dmtrack.odometry._lanes): the kernels compute exactly the order the source writes, so a
numpy reference of that order gives their bits, and no compiler, cached copy or CPU can change them.

Bit-for-bit comparisons, on inputs where other orders of the same sums round differently (checked, so that a kernel
that re-associated its sums would fail here). The tracker's channel sums against their numpy reference:
tests/odometry/test_tracker_multi.py.
"""

from __future__ import annotations

import numba
import numpy as np
import pytest

from dmtrack.odometry._lanes import ACC32, LANES32, LANES64, fold8x8, lane_sum_numpy, scratch_f32


@numba.njit(cache=False)
def _fold_kernel(a):  # (8, 8) float32 -> (8,) float32 through fold8x8
    acc = scratch_f32(ACC32)
    res = scratch_f32(8)
    for s in range(8):
        for lane in range(LANES32):
            acc[s * LANES32 + lane] = a[s, lane]
    fold8x8(acc, res)
    out = np.empty(8, np.float32)
    for s in range(8):
        out[s] = res[s]
    return out


def _order_sensitive(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """float32 values over many magnitudes and both signs: most orders of their sum round differently."""
    mag = 10.0 ** rng.uniform(-3, 7, shape)
    return (rng.choice([-1.0, 1.0], shape) * mag).astype(np.float32)


def test_fold8x8_adds_the_pairs_the_formula_names() -> None:
    rng = np.random.default_rng(0)
    a = _order_sensitive(rng, (300, 8, 8))
    got = np.stack([_fold_kernel(x) for x in a])
    tree = [[((x[0] + x[1]) + (x[2] + x[3])) + ((x[4] + x[5]) + (x[6] + x[7])) for x in row] for row in a]
    assert got.tobytes() == np.array(tree, np.float32).tobytes()  # numpy float32 scalars: IEEE, one add each
    assert got.tobytes() == lane_sum_numpy(np.moveaxis(a, 2, 0), LANES32).tobytes()
    # these values tell orders apart: the channel-order sum and the halves-first tree differ from the fold
    sequential = np.zeros(a.shape[:2], np.float32)
    for lane in range(8):
        sequential = sequential + a[..., lane]
    halves = a[..., :4] + a[..., 4:]
    halves = halves[..., :2] + halves[..., 2:]
    halves = halves[..., 0] + halves[..., 1]
    assert (got != sequential).mean() > 0.2 and (got != halves).mean() > 0.2


def test_lane_sum_numpy_is_the_lane_order() -> None:
    rng = np.random.default_rng(1)
    for n in (1, 3, 4, 5, 8, 11, 33):
        t = _order_sensitive(rng, (n, 50)).astype(np.float64)
        for lanes in (4, 8):
            want = []
            for col in range(t.shape[1]):
                acc = [0.0] * lanes
                for c in range(n):  # lane c mod L, channels in order
                    acc[c % lanes] += float(t[c, col])
                while len(acc) > 1:
                    acc = [acc[i] + acc[i + 1] for i in range(0, len(acc), 2)]
                want.append(acc[0])
            assert lane_sum_numpy(t, lanes).tolist() == want


def _window_cost_numpy(ring: np.ndarray, kfv: np.ndarray, loop: int) -> tuple[float, float]:
    """_window_cost's order: lane l holds the channels c ≡ l (mod 4), for j = 0 … 4 in turn."""
    acc = np.zeros((2, LANES64))
    for j in range(5):
        r, rp = (loop + 6 - j) % 6, (loop + 5 - j) % 6
        for c in range(ring.shape[1]):
            e = ring[r, c] - kfv[j, c]
            acc[0, c % LANES64] += e * e
            acc[1, c % LANES64] += e * (ring[rp, c] - kfv[j, c])
    return tuple(float((a[0] + a[1]) + (a[2] + a[3])) for a in acc)  # type: ignore[return-value]


@pytest.mark.parametrize("n", [2, 3, 4, 7, 8, 13, 24, 128])
def test_the_stereo_sums_are_their_lane_order(n: int) -> None:
    """The line stereo's sums (window cost, keyframe norms, sample statistics) on zero-padded scratch rows, as the
    observe kernel allocates them, against the lane order in numpy."""
    from dmtrack.odometry._epipolar_stereo import _kf_norms, _sample_stats, _window_cost, padded_channels

    rng = np.random.default_rng(n)
    m = padded_channels(n)
    ring = np.zeros((6, m))
    kfv = np.zeros((5, m))
    ring[:, :n] = _order_sensitive(rng, (6, n)).astype(np.float64) * 1e-3
    kfv[:, :n] = _order_sensitive(rng, (5, n)).astype(np.float64) * 1e-3
    for loop in range(6):
        assert _window_cost(ring, kfv, loop) == _window_cost_numpy(ring[:, :n], kfv[:, :n], loop)
    assert _kf_norms(kfv) == tuple(float(lane_sum_numpy(kfv[j, :n] * kfv[j, :n], LANES64)) for j in range(5))
    img = rng.uniform(-50, 50, (8, 8, n)).astype(np.float32)
    st = np.zeros((6, 7))
    _sample_stats(img, 3.3, 4.6, ring, 2, 1, kfv, st)
    s = ring[2, :n]
    want = [lane_sum_numpy(s * y, LANES64) for y in (s, *kfv[:, :n], ring[1, :n])]
    assert st[2].tolist() == want
    assert not ring[:, n:].any()  # the padding stays zero
    if n % LANES64:  # rows that are not padded are refused, not read past their end
        with pytest.raises(ValueError, match="zero-padded"):
            _window_cost(np.ascontiguousarray(ring[:, :n]), kfv, 0)


def test_the_stereo_test_values_tell_orders_apart() -> None:
    """On such inputs the lane order and the channel order round differently, so the test above would see a
    kernel that summed in channel order (or let the compiler choose)."""
    rng = np.random.default_rng(7)
    differ = 0
    for _ in range(200):
        sq = (_order_sensitive(rng, (13,)).astype(np.float64) * 1e-3) ** 2
        sequential = 0.0
        for x in sq.tolist():
            sequential += x
        differ += sequential != float(lane_sum_numpy(sq, LANES64))
    assert differ > 20
