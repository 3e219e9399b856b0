"""Scalar coefficients of the SE(3) and Sim(3) exp/log (power series near 0, closed forms elsewhere)."""

from __future__ import annotations

import math

# Power-series coefficients in θ² (|θ| < 1, 13 terms: truncation error < 1e-20):
#   C(θ) = (θ - sin θ)/θ³ = Σ (-θ²)^k / (2k+3)!
#   E(θ) = (2(1 - cos θ)/θ² - sin θ/θ)/θ² = Σ_{k≥1} (-1)^(k+1) 2k θ^(2k-2) / (2k+2)!
_C_SERIES = tuple((-1) ** k / math.factorial(2 * k + 3) for k in range(13))
_E_SERIES = tuple((-1) ** (k + 1) * 2 * k / math.factorial(2 * k + 2) for k in range(1, 14))
# In σ (|σ| < 1, 25 terms):  F(σ) = (expm1(σ) - σ e^σ)/σ² = -Σ (k+1) σ^k / (k+2)!
_F_SERIES = tuple(-(k + 1) / math.factorial(k + 2) for k in range(25))


def _poly(coeffs: tuple[float, ...], x: float) -> float:
    """``Σ coeffs[k] x^k`` by Horner's rule."""
    total = 0.0
    for c in reversed(coeffs):
        total = total * x + c
    return total


def _se3_v_coeffs(theta: float) -> tuple[float, float]:
    """``B = (1 - cos θ)/θ²`` and ``C = (θ - sin θ)/θ³`` of ``V = I + B ω^ + C ω^²``."""
    if theta == 0.0:
        return 0.5, 1.0 / 6.0
    h = math.sin(0.5 * theta) / theta
    b = 2.0 * h * h  # no cancellation
    if theta < 1.0:
        return b, _poly(_C_SERIES, theta * theta)
    return b, (theta - math.sin(theta)) / theta**3


def _se3_vinv_coeff(theta: float) -> float:
    """``D = (1 - (θ/2)·cot(θ/2))/θ²`` of ``V⁻¹ = I - ½ ω^ + D ω^²`` (θ ≤ π)."""
    if theta < 1.0:
        # D = (1 - A/(2B))/θ² = E/(2B) with A = sin θ/θ, B = (1 - cos θ)/θ²
        h = math.sin(0.5 * theta) / theta if theta > 0.0 else 0.5
        return _poly(_E_SERIES, theta * theta) / (4.0 * h * h)
    half = 0.5 * theta
    return (1.0 - half * math.cos(half) / math.sin(half)) / (theta * theta)


def _sim3_w_coeffs(sigma: float, theta: float) -> tuple[float, float, float]:
    """Coefficients of Sophus' ``W = A ω^ + B ω^² + C I`` (Sim(3) exp), robust for all (σ, θ).

    ``W = ∫₀¹ exp(s(ω^ + σI)) ds``, so with ``E(z) = (eᶻ - 1)/z`` and ``z = σ + iθ``:
    ``C = E(σ)``, ``A = Im E(z)/θ``, ``B = (E(σ) - Re E(z))/θ²``.  For ``|z| < 1`` the power series of
    ``E`` is summed (with polynomial recurrences for the divided parts); otherwise closed forms arranged
    to avoid catastrophic cancellation are used.
    """
    r = math.hypot(sigma, theta)
    if r < 1.0:
        # z^k = p_k + iθ q_k;  (σ^k - p_k)/θ² = r_k;  E(z) = Σ z^k/(k+1)!
        p, q, rk, sk = 1.0, 0.0, 0.0, 1.0
        t2 = theta * theta
        A = B = C = 0.0
        fact = 1.0  # (k+1)!
        for k in range(25):
            fact *= k + 1
            A += q / fact
            B += rk / fact
            C += sk / fact
            p, q, rk, sk = sigma * p - t2 * q, p + sigma * q, sigma * rk + q, sk * sigma
        return A, B, C
    es = math.exp(sigma)
    em1 = math.expm1(sigma)
    C = em1 / sigma if sigma != 0.0 else 1.0
    sinc = math.sin(theta) / theta if theta != 0.0 else 1.0
    half = math.sin(0.5 * theta) / theta if theta != 0.0 else 0.5
    h = 2.0 * half * half  # (1 - cos θ)/θ²
    one_minus_cos = h * theta * theta
    denom = sigma * sigma + theta * theta
    # A = (σ e^σ sinc θ - (e^σ cos θ - 1))/(σ² + θ²)
    A = (sigma * es * sinc - em1 * math.cos(theta) + one_minus_cos) / denom
    # B = (σ e^σ h(θ) + f1(σ) + e^σ g(θ))/(σ² + θ²), f1 = (expm1 σ - σ e^σ)/σ, g = 1 - sinc θ
    if abs(sigma) < 1.0:
        f1 = _poly(_F_SERIES, sigma) * sigma
    else:
        f1 = (em1 - sigma * es) / sigma
    if theta < 1.0:
        g = _poly(_C_SERIES, theta * theta) * theta * theta  # 1 - sinc θ = θ² C(θ)
    else:
        g = 1.0 - sinc
    B = (sigma * es * h + f1 + es * g) / denom
    return A, B, C
