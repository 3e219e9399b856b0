"""Small matrix products in an order fixed by the source: the same bits on every CPU.

numpy's ``@`` and ``np.dot`` hand float64 products to BLAS, and BLAS picks its kernel by the CPU it runs on
(OpenBLAS has Haswell, Zen, SkylakeX… kernels): they add the products in different orders, some with fused
multiply-adds, so a 4×4 pose product differs in its last bits from one machine to the next. A visual odometry
feeds every pose into the next frame's tracking and amplifies such a difference: on the same input a grey run gave
poses 1e-20 apart after two frames and 3e-3 apart after 27 (OpenBLAS's Haswell against its SkylakeX kernels, issue
41). The odometry therefore composes poses, warps rays and forms dot products with these functions: Σ_k a_ik b_kj
as elementwise IEEE products added in k order (numpy's elementwise loops never fuse a multiply and an add), which
every CPU computes alike.
"""

from __future__ import annotations

import numpy as np

__all__ = ["dot", "matmul", "norm", "solve"]


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` for a (m, k) matrix ``a`` and a (k, n) matrix or (k,) vector ``b``, in float64, with each entry
    ``((a_i0 b_0j + a_i1 b_1j) + a_i2 b_2j) + …`` (IEEE, the same bits on every CPU)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    if a.ndim != 2 or b.ndim not in (1, 2) or a.shape[1] != b.shape[0] or a.shape[1] == 0:
        raise ValueError(f"matmul: cannot multiply shapes {a.shape} and {b.shape}")
    if b.ndim == 1:
        out = a[:, 0] * b[0]
        for k in range(1, a.shape[1]):
            out = out + a[:, k] * b[k]
        return out
    out = a[:, 0:1] * b[0:1, :]
    for k in range(1, a.shape[1]):
        out = out + a[:, k : k + 1] * b[k : k + 1, :]
    return out


def dot(u: np.ndarray, v: np.ndarray) -> float:
    """``u · v`` of two vectors, ``((u0 v0 + u1 v1) + u2 v2) + …`` in float64 (the same bits on every CPU)."""
    u = np.asarray(u, np.float64).ravel()
    v = np.asarray(v, np.float64).ravel()
    if u.shape != v.shape:
        raise ValueError(f"dot: vectors of {u.size} and {v.size} entries")
    s = 0.0
    for x, y in zip(u.tolist(), v.tolist(), strict=True):
        s += x * y
    return s


def norm(v: np.ndarray) -> float:
    """Euclidean norm of a vector, ``sqrt(dot(v, v))`` (the same bits on every CPU)."""
    return float(np.sqrt(dot(v, v)))


def solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``x`` with ``a x = b`` for a square ``a`` and a vector ``b``: Gaussian elimination with partial pivoting (as
    LAPACK's ``gesv``) by whole-row updates — elementwise products and differences only, so the same bits on every
    CPU. Raises ``numpy.linalg.LinAlgError`` on a zero or non-finite pivot. Meant for small systems (a few dozen
    unknowns: O(n) numpy calls)."""
    m = np.array(a, np.float64)
    x = np.array(b, np.float64).ravel()
    n = m.shape[0]
    if m.shape != (n, n) or x.shape != (n,):
        raise ValueError(f"solve: a {m.shape} and b {np.shape(b)} do not form a square system")
    for k in range(n):
        p = k + int(np.argmax(np.abs(m[k:, k])))
        if not (np.isfinite(m[p, k]) and m[p, k] != 0.0):
            raise np.linalg.LinAlgError(f"singular matrix (pivot {k})")
        if p != k:
            m[[k, p]] = m[[p, k]]
            x[[k, p]] = x[[p, k]]
        f = m[k + 1 :, k] / m[k, k]
        m[k + 1 :, k:] -= f[:, None] * m[k, k:]
        x[k + 1 :] -= f * x[k]
    for k in range(n - 1, -1, -1):  # back substitution, column by column
        x[k] = x[k] / m[k, k]
        x[:k] -= m[:k, k] * x[k]
    return x
