"""Sums over channels in an order fixed by the source: the arithmetic of the multichannel loops, whatever compiles it.

Why not fast-math
-----------------
A loop over channels that sums (Σ_c W r², Σ_c W g gᵀ, …) vectorises only if the compiler may re-associate the sum:
with numba's ``fastmath`` flags LLVM chooses the order, and it chooses it *per compilation*. numba compiles a helper
on its own and again as a copy inside each caller's machine code, and which copy runs depends on what numba's
on-disk cache held when the process started. A cache that holds a kernel but not its helper (a process killed
between two writes, two processes updating one index at once, an index invalidated by an edit) made the same input
give other bits — ``make test`` once failed that way (issue 41: the tracker's chunked and general kernels differed in
the 10th digit of the error) — and the order also follows the CPU (8 lanes on AVX2, 16 on AVX-512, reciprocal-sqrt
estimates of 12 or 14 bits).

The lanes
---------
So there is no fast-math in the odometry. A sum over N channels is written with explicit lanes instead: lane ``l``
accumulates the channels ``c ≡ l (mod LANES)`` in channel order, blocks of ``LANES`` channels first and then the
remaining ``N mod LANES`` channels into lanes ``0 … N mod LANES − 1``, and the lanes are folded in a fixed tree.
Every step is IEEE arithmetic that LLVM may vectorise (the lanes are independent; nothing is re-associated) but not
reorder, so the result is the same for every compilation, every copy, every thread count and every CPU (x86-64
``generic``, ``haswell``, ``znver3``, ``skylake-avx512``: ``tests/faults/test_kernel_targets.py``).

* float32 (the tracker's channel sums): :data:`LANES32` = 8 lanes, folded by :func:`fold8x8` —
  ``((a0 + a1) + (a2 + a3)) + ((a4 + a5) + (a6 + a7))`` for eight sums at once, written as LLVM vector shuffles (an
  8×8 transpose-and-add; without it the fold is 56 scalar adds a point).
* float64 (the stereo search's sums): :data:`LANES64` = 4 lanes, folded as ``(a0 + a1) + (a2 + a3)``.

:func:`lane_sum_numpy` is the numpy reference of the order: with the same per-channel terms it gives the kernels'
bits exactly.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.core.errors import TypingError
from numba.extending import intrinsic

#: float32 lanes of the channel sums (one AVX2 vector; two SSE vectors on a generic x86-64).
LANES32 = 8
#: float64 lanes of the channel sums (one AVX2 vector).
LANES64 = 4
#: Size of the float32 scratch of eight sums in :data:`LANES32` lanes (the ``acc`` of :func:`fold8x8`).
ACC32 = 8 * LANES32


@intrinsic
def select(typingctx, cond, a, b):  # pragma: no cover - compiled
    """``a if cond else b`` without a branch (an LLVM ``select``; both sides are computed, IEEE results).

    numba lowers a conditional expression to branches, which keep LLVM from vectorising a loop; a select does
    not. Both values must have the same numeric type.
    """
    if not isinstance(cond, types.Boolean) or a != b:
        raise TypingError(f"select(bool, x, y) needs x and y of one type, got {cond}, {a}, {b}")
    sig = a(cond, a, b)

    def codegen(context, builder, signature, args):
        return builder.select(args[0], args[1], args[2])

    return sig, codegen


def _scratch(dtype: types.Type):  # type: ignore[no-untyped-def]
    @intrinsic
    def scratch(typingctx, size):  # pragma: no cover - compiled
        if not isinstance(size, types.IntegerLiteral):
            raise TypingError("scratch arrays need a compile-time constant size (a module-level int)")
        n = size.literal_value

        def codegen(context, builder, signature, args):
            with builder.goto_entry_block():
                ptr = builder.alloca(context.get_value_type(dtype), size=context.get_constant(types.intp, n))
                ptr.align = 64
            return ptr

        return types.CPointer(dtype)(size), codegen

    return scratch


#: ``scratch_f64(N)`` / ``scratch_f32(N)`` / ``scratch_i64(N)``: a stack array of N (a module-level constant)
#: float64 / float32 / int64, as a raw pointer indexed ``p[j]``, valid until the calling function returns. LLVM knows
#: that a stack array that never escapes cannot alias any argument, so loops that store into it and read (e.g.
#: gather from) input arrays need no run-time overlap checks and vectorise. Keep one array per quantity: LLVM stops
#: tracking a pointer after a limited number of uses and then assumes it may alias everything.
scratch_f64 = _scratch(types.float64)
scratch_f32 = _scratch(types.float32)
scratch_i64 = _scratch(types.int64)


@intrinsic
def fold8x8(typingctx, acc, out):  # pragma: no cover - compiled
    """``out[s] = ((a[s,0] + a[s,1]) + (a[s,2] + a[s,3])) + ((a[s,4] + a[s,5]) + (a[s,6] + a[s,7]))`` for s < 8,
    with ``a[s, l] = acc[8 s + l]`` (``acc``, ``out``: float32 scratch pointers of 64 and 8).

    Three rounds of "add the even lanes to the odd lanes" of two vectors (IEEE adds of the pairs the formula
    names), so every target computes exactly the formula; AVX lowers each round to two shuffles and an add.
    """
    f32p = types.CPointer(types.float32)
    if acc != f32p or out != f32p:
        raise TypingError(f"fold8x8(acc, out) takes two float32 scratch pointers, got {acc}, {out}")
    sig = types.void(acc, out)

    def codegen(context, builder, signature, args):
        accp, outp = args
        v8 = ir.VectorType(ir.FloatType(), 8)
        i32x8 = ir.VectorType(ir.IntType(32), 8)
        evens = ir.Constant(i32x8, [0, 2, 4, 6, 8, 10, 12, 14])
        odds = ir.Constant(i32x8, [1, 3, 5, 7, 9, 11, 13, 15])
        vp = builder.bitcast(accp, v8.as_pointer())
        rows = [builder.load(builder.gep(vp, [ir.Constant(ir.IntType(64), s)]), align=4) for s in range(8)]

        def pairs(x, y):  # [x0+x1, x2+x3, x4+x5, x6+x7, y0+y1, y2+y3, y4+y5, y6+y7]
            return builder.fadd(builder.shuffle_vector(x, y, evens), builder.shuffle_vector(x, y, odds))

        p = [pairs(rows[2 * k], rows[2 * k + 1]) for k in range(4)]  # sums 2k, 2k+1: 4 pair sums each
        q = [pairs(p[0], p[1]), pairs(p[2], p[3])]  # sums 0-3 / 4-7: 2 quad sums each
        builder.store(pairs(q[0], q[1]), builder.bitcast(outp, v8.as_pointer()), align=4)
        return context.get_dummy_value()

    return sig, codegen


def _c_vector(typ: types.Type) -> bool:
    return isinstance(typ, types.Array) and typ.ndim == 1 and typ.layout == "C" and typ.dtype == types.float64


def _lane_loop(context, builder, out_ptr, n, n_sums, body):  # type: ignore[no-untyped-def]
    """Emit ``for c in range(0, n, LANES64)``: ``acc[s] += body(c)[s]`` on <4 x double> accumulators read from and
    written back to ``out_ptr[4 s : 4 s + 4]`` (IEEE fmul / fadd, no fast-math flags)."""
    v4 = ir.VectorType(ir.DoubleType(), LANES64)
    slots = []
    for k in range(n_sums):
        p = builder.bitcast(builder.gep(out_ptr, [ir.Constant(ir.IntType(64), LANES64 * k)]), v4.as_pointer())
        slot = cgutils.alloca_once(builder, v4)
        builder.store(builder.load(p, align=8), slot)
        slots.append((p, slot))
    zero = ir.Constant(n.type, 0)
    step = ir.Constant(n.type, LANES64)
    with cgutils.for_range_slice(builder, zero, n, step, inc=True) as (c, _count):
        terms = body(c, v4)
        for (_p, slot), t in zip(slots, terms, strict=True):
            builder.store(builder.fadd(builder.load(slot), t), slot)
    for p, slot in slots:
        builder.store(builder.load(slot), p, align=8)


def _load4(builder, array_ptr, c, v4):  # type: ignore[no-untyped-def]
    return builder.load(builder.bitcast(builder.gep(array_ptr, [c]), v4.as_pointer()), align=8)


@intrinsic
def lane_dots4(typingctx, out, xs, ys, n):  # pragma: no cover - compiled
    """``out[4 s + l] += Σ_b xs[s][4 b + l] · ys[s][4 b + l]`` for the blocks b of the first ``n`` channels (``n`` a
    multiple of :data:`LANES64`): the float64 lane sums of the dot products ⟨xs[s], ys[s]⟩, blocks in order, as
    <4 x double> multiplies and adds (IEEE; LLVM's loop vectoriser does not vectorise an in-order sum). ``out``:
    float64 scratch pointer of 4·len(xs); ``xs``, ``ys``: tuples of as many C-contiguous 1-D float64 arrays."""
    if not (isinstance(out, types.CPointer) and out.dtype == types.float64 and isinstance(xs, types.UniTuple)
            and isinstance(ys, types.UniTuple) and xs.count == ys.count and _c_vector(xs.dtype)
            and _c_vector(ys.dtype) and isinstance(n, types.Integer)):  # fmt: skip
        raise TypingError(f"lane_dots4(out, xs, ys, n): got {out}, {xs}, {ys}, {n}")
    n_sums = xs.count
    sig = types.void(out, xs, ys, n)

    def codegen(context, builder, signature, args):
        out_ptr, xsv, ysv, nv = args

        def data(tup_type, tup, k):  # type: ignore[no-untyped-def]
            return context.make_array(tup_type.dtype)(context, builder, builder.extract_value(tup, k)).data

        pairs = [(data(xs, xsv, k), data(ys, ysv, k)) for k in range(n_sums)]

        def body(c, v4):  # type: ignore[no-untyped-def]
            loaded: dict[int, ir.Value] = {}  # a row that appears twice (‖x‖²) is loaded once

            def load(p):  # type: ignore[no-untyped-def]
                key = id(p)
                if key not in loaded:
                    loaded[key] = _load4(builder, p, c, v4)
                return loaded[key]

            return [builder.fmul(load(xp), load(yp)) for xp, yp in pairs]

        _lane_loop(context, builder, out_ptr, nv, n_sums, body)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def lane_window4(typingctx, out, s, sp, k, n):  # pragma: no cover - compiled
    """``out[l] += Σ_b e·e`` and ``out[4 + l] += Σ_b e·(sp − k)`` with ``e = s − k``, at the channels 4 b + l of the
    blocks b of the first ``n`` channels (``n`` a multiple of :data:`LANES64`), as :func:`lane_dots4` does."""
    if not (isinstance(out, types.CPointer) and out.dtype == types.float64 and _c_vector(s) and _c_vector(sp)
            and _c_vector(k) and isinstance(n, types.Integer)):  # fmt: skip
        raise TypingError(f"lane_window4(out, s, sp, k, n): got {out}, {s}, {sp}, {k}, {n}")
    sig = types.void(out, s, sp, k, n)

    def codegen(context, builder, signature, args):
        out_ptr, sv, spv, kv, nv = args
        ptrs = [context.make_array(a)(context, builder, v).data for a, v in ((s, sv), (sp, spv), (k, kv))]

        def body(c, v4):  # type: ignore[no-untyped-def]
            a, b, kk = (_load4(builder, p, c, v4) for p in ptrs)
            e = builder.fsub(a, kk)
            return [builder.fmul(e, e), builder.fmul(e, builder.fsub(b, kk))]

        _lane_loop(context, builder, out_ptr, nv, 2, body)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def lane_sample_stats4(typingctx, out, img, ix, iy, w, ring, row, prow, kfv, n):  # pragma: no cover - compiled
    """The bilinear sample s of channels ``0 … n − 1`` (``n`` a multiple of :data:`LANES64`) of the (H, W, N) float32
    map ``img`` at corner (ix, iy) with weights ``w`` = (w00, w01, w10, w11) — ``s_c = ((w11·d + w01·c) + w10·b) +
    w00·a`` in float64, a … d the corners (ix, iy), (ix+1, iy), (ix, iy+1), (ix+1, iy+1), as
    :func:`~dmtrack.odometry._depth_common._sample` forms it — stored into ``ring[row]``, and the lane sums
    ``out[4 k + l] += Σ_b s·y_k`` with y = (s, kfv[0], …, kfv[4], ring[prow]) at the channels 4 b + l: one pass over
    the channels, <4 x double> arithmetic (IEEE). ``ring`` (·, N') and ``kfv`` (5, N'): C-contiguous float64."""
    f64_2d = isinstance(ring, types.Array) and ring.ndim == 2 and ring.layout == "C" and ring.dtype == types.float64
    ok = (isinstance(out, types.CPointer) and out.dtype == types.float64 and isinstance(img, types.Array)
          and img.ndim == 3 and img.layout == "C" and img.dtype == types.float32 and f64_2d and kfv == ring
          and isinstance(w, types.UniTuple) and w.count == 4 and w.dtype == types.float64
          and all(isinstance(a, types.Integer) for a in (ix, iy, row, prow, n)))  # fmt: skip
    if not ok:
        raise TypingError(f"lane_sample_stats4: got {out}, {img}, {ix}, {iy}, {w}, {ring}, {row}, {prow}, {kfv}, {n}")
    sig = types.void(out, img, ix, iy, w, ring, row, prow, kfv, n)

    def codegen(context, builder, signature, args):
        out_ptr, imgv, ixv, iyv, wv, ringv, rowv, prowv, kfvv, nv = args
        i64 = ir.IntType(64)
        im = context.make_array(img)(context, builder, imgv)
        rg = context.make_array(ring)(context, builder, ringv)
        kf = context.make_array(kfv)(context, builder, kfvv)
        shape = cgutils.unpack_tuple(builder, im.shape, 3)
        width, nch = shape[1], shape[2]
        as64 = [context.cast(builder, v, t, types.int64) for v, t in ((ixv, ix), (iyv, iy), (rowv, row), (prowv, prow))]
        x, y, r, rp = as64
        npad = cgutils.unpack_tuple(builder, rg.shape, 2)[1]
        base = builder.mul(builder.add(builder.mul(y, width), x), nch)  # offset of corner a
        offs = [base, builder.add(base, nch), builder.add(base, builder.mul(width, nch)),
                builder.add(builder.add(base, builder.mul(width, nch)), nch)]  # a, b, c, d
        corners = [builder.gep(im.data, [o]) for o in offs]
        ring_row = builder.gep(rg.data, [builder.mul(r, npad)])
        ring_prev = builder.gep(rg.data, [builder.mul(rp, npad)])
        kf_rows = [builder.gep(kf.data, [builder.mul(ir.Constant(i64, j), npad)]) for j in range(5)]
        v4 = ir.VectorType(ir.DoubleType(), LANES64)
        f4 = ir.VectorType(ir.FloatType(), LANES64)
        ws = [cgutils.unpack_tuple(builder, wv, 4)[k] for k in range(4)]  # w00, w01, w10, w11
        splat = [builder.insert_element(ir.Constant(v4, ir.Undefined), wk, ir.Constant(ir.IntType(32), 0))
                 for wk in ws]  # fmt: skip
        zeros4 = ir.Constant(ir.VectorType(ir.IntType(32), LANES64), [0] * LANES64)
        w00, w01, w10, w11 = (builder.shuffle_vector(sv, sv, zeros4) for sv in splat)
        nn = context.cast(builder, nv, n, types.int64)

        def body(c, _v4):  # type: ignore[no-untyped-def]
            a, b, cc, d = (builder.fpext(builder.load(builder.bitcast(builder.gep(p, [c]), f4.as_pointer()), align=4),
                                         v4) for p in corners)  # fmt: skip
            s = builder.fadd(builder.fadd(builder.fadd(builder.fmul(w11, d), builder.fmul(w01, cc)),
                                          builder.fmul(w10, b)), builder.fmul(w00, a))  # fmt: skip
            builder.store(s, builder.bitcast(builder.gep(ring_row, [c]), v4.as_pointer()), align=8)
            ys = [s, *(_load4(builder, k, c, v4) for k in kf_rows), _load4(builder, ring_prev, c, v4)]
            return [builder.fmul(s, yk) for yk in ys]

        _lane_loop(context, builder, out_ptr, nn, 7, body)
        return context.get_dummy_value()

    return sig, codegen


def lane_sum_numpy(terms: np.ndarray, lanes: int) -> np.ndarray:
    """The kernels' channel sum of per-channel ``terms`` (N, …) in their dtype, bit for bit: lane ``l`` adds the
    channels ``c ≡ l (mod lanes)`` in order (the last ``N mod lanes`` into lanes 0, 1, …), then the lanes fold
    pairwise, ``(a0 + a1) + (a2 + a3)`` for 4 lanes, ``((a0 + a1) + (a2 + a3)) + ((a4 + a5) + (a6 + a7))`` for 8."""
    terms = np.asarray(terms)
    acc = np.zeros((lanes, *terms.shape[1:]), terms.dtype)
    for c in range(terms.shape[0]):
        acc[c % lanes] = acc[c % lanes] + terms[c]
    while acc.shape[0] > 1:
        acc = acc[0::2] + acc[1::2]
    return acc[0]
