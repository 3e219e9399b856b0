"""dmtrack.geometry.exact: small products in the order the source writes (no BLAS), checked against that order
written out in Python floats (IEEE doubles, one rounding per operation) and against numpy's own results."""

from __future__ import annotations

import numpy as np
import pytest

from dmtrack.geometry import exact


def _python_matmul(a: np.ndarray, b: np.ndarray) -> list[list[float]]:
    out = []
    for i in range(a.shape[0]):
        row = []
        for j in range(b.shape[1]):
            s = float(a[i, 0]) * float(b[0, j])
            for k in range(1, a.shape[1]):
                s = s + float(a[i, k]) * float(b[k, j])
            row.append(s)
        out.append(row)
    return out


def test_matmul_and_dot_are_the_written_order() -> None:
    rng = np.random.default_rng(0)
    for shape in ((4, 4, 4), (3, 3, 50), (2, 5, 3)):
        m, k, n = shape
        a = rng.normal(size=(m, k)) * 10.0 ** rng.uniform(-8, 8, (m, k))
        b = rng.normal(size=(k, n)) * 10.0 ** rng.uniform(-8, 8, (k, n))
        assert exact.matmul(a, b).tolist() == _python_matmul(a, b)
        assert exact.matmul(a, b[:, 0]).tolist() == [r[0] for r in _python_matmul(a, b[:, :1])]
        np.testing.assert_allclose(exact.matmul(a, b), a @ b, rtol=1e-6, atol=1e-12 * np.abs(a @ b).max())
    u, v = rng.normal(size=7), rng.normal(size=7)
    s = 0.0
    for x, y in zip(u.tolist(), v.tolist(), strict=True):
        s += x * y
    assert exact.dot(u, v) == s and exact.norm(u) == float(np.sqrt(exact.dot(u, u)))
    with pytest.raises(ValueError, match="cannot multiply"):
        exact.matmul(a, a)


def test_solve_is_gaussian_elimination_with_partial_pivoting() -> None:
    rng = np.random.default_rng(1)
    for n in (1, 2, 6, 36):
        a = rng.normal(size=(n, n)) + n * np.eye(n)
        a[0, 0] = 1e-9  # the first pivot must be exchanged
        b = rng.normal(size=n)
        x = exact.solve(a, b)
        np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(a @ x, b, atol=1e-9)
    # a Schur complement of a bundle adjustment: symmetric, ill-conditioned
    j = rng.normal(size=(200, 12)) * np.geomspace(1e-3, 1e3, 12)
    h = j.T @ j
    g = rng.normal(size=12)
    np.testing.assert_allclose(exact.solve(h, g), np.linalg.solve(h, g), rtol=1e-6)
    with pytest.raises(np.linalg.LinAlgError, match="singular"):
        exact.solve(np.zeros((3, 3)), np.ones(3))
    with pytest.raises(ValueError, match="square"):
        exact.solve(np.zeros((3, 2)), np.ones(3))
