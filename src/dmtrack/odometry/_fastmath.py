"""Fast-math flags shared by the multichannel numba loops of the odometry kernels.

Re-association lets LLVM vectorise the sums over channels (AVX2: 8 float32 / 4 float64 lanes); no nnan/ninf, so a
select may see inf/nan in its unused branch safely. Only N > 1 takes these loops: grey keeps the scalar arithmetic
of the numpy references. The order of the vectorised sums is chosen by LLVM per compilation context, so a loop
must reach its callers through one compiled kernel wherever bit-identical results are required (the serial
tracker evaluation and depth update run the parallel build on one thread for that reason); the results equal the
references up to rounding.
"""

FASTMATH = frozenset({"reassoc", "contract", "arcp", "nsz"})
