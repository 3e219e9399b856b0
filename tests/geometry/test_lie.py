"""Tests of dmtrack.geometry.lie: group laws, exp/log, adjoints, quaternions, numerics."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from dmtrack.geometry import (
    SE3,
    SO3,
    Sim3,
    hat,
    matrix_to_quaternion,
    quaternion_to_matrix,
    rotation_angle,
    so3_exp,
    so3_log,
    vee,
)
from dmtrack.geometry.lie._coeffs import _se3_v_coeffs, _se3_vinv_coeff, _sim3_w_coeffs

SETTINGS = settings(max_examples=100, deadline=None)
EPS_PI = 1e-3  # log∘exp is only an identity for angles below π (the log returns angles in [0, π])

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
vec3 = st.tuples(finite, finite, finite).map(np.array)


@st.composite
def rotvecs(draw: st.DrawFn, max_angle: float = np.pi - EPS_PI) -> np.ndarray:
    """Rotation vectors with angle in [0, max_angle], tiny angles included."""
    d = draw(vec3)
    n = np.linalg.norm(d)
    if n < 1e-3:
        return np.zeros(3)
    kind = draw(st.sampled_from(["uniform", "tiny", "near_max"]))
    if kind == "uniform":
        angle = draw(st.floats(0.0, max_angle))
    elif kind == "tiny":
        angle = 10.0 ** draw(st.floats(-12.0, -2.0))
    else:
        angle = max_angle - 10.0 ** draw(st.floats(-9.0, -1.0))
    return d / n * angle


@st.composite
def rotations(draw: st.DrawFn) -> SO3:
    """Rotations from (unnormalised) quaternions, covering all angles up to π."""
    q = np.array(draw(st.tuples(finite, finite, finite, finite)))
    if np.linalg.norm(q) < 1e-2:
        q = np.array([0.0, 0.0, 0.0, 1.0])
    return SO3.from_quaternion(q)


def translations(scale: float = 10.0) -> st.SearchStrategy[np.ndarray]:
    return vec3.map(lambda v: scale * v)


se3_tangents = st.tuples(translations(5.0), rotvecs()).map(np.concatenate)
se3_elements = st.tuples(rotations(), translations()).map(lambda rt: SE3(*rt))
scales = st.floats(-3.0, 3.0).map(np.exp)
sim3_tangents = st.tuples(translations(5.0), rotvecs(), st.floats(-3.0, 3.0)).map(
    lambda x: np.concatenate([x[0], x[1], [x[2]]])
)
sim3_elements = st.tuples(rotations(), translations(), scales).map(lambda x: Sim3(*x))
points = st.integers(0, 2**32 - 1).map(lambda s: np.random.default_rng(s).uniform(-10, 10, (7, 3)))


def se3_generator(xi: np.ndarray) -> np.ndarray:
    G = np.zeros((4, 4))
    G[:3, :3] = hat(xi[3:])
    G[:3, 3] = xi[:3]
    return G


def sim3_generator(v: np.ndarray) -> np.ndarray:
    G = np.zeros((4, 4))
    G[:3, :3] = hat(v[3:6]) + v[6] * np.eye(3)
    G[:3, 3] = v[:3]
    return G


def same_rotvec_up_to_pi(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    """Equal, or both of angle ≈ π and opposite (log is ambiguous there)."""
    return bool(np.allclose(a, b, atol=atol) or np.allclose(a, -b, atol=atol))


# ----------------------------------------------------------------------------------------------------
# hat / vee / batched helpers
# ----------------------------------------------------------------------------------------------------
@SETTINGS
@given(vec3, vec3)
def test_hat_is_cross_product_and_vee_inverts_it(w: np.ndarray, p: np.ndarray) -> None:
    np.testing.assert_allclose(hat(w) @ p, np.cross(w, p), atol=1e-15)
    np.testing.assert_array_equal(vee(hat(w)), w)
    np.testing.assert_array_equal(SO3.hat(w), hat(w))
    np.testing.assert_array_equal(SO3.vee(hat(w)), w)


def test_hat_vee_batched_shapes() -> None:
    w = np.random.default_rng(0).normal(size=(5, 4, 3))
    H = hat(w)
    assert H.shape == (5, 4, 3, 3)
    np.testing.assert_allclose(H, -np.swapaxes(H, -1, -2))
    np.testing.assert_array_equal(vee(H), w)
    with pytest.raises(ValueError):
        hat(np.zeros(4))
    with pytest.raises(ValueError):
        vee(np.zeros((3, 4)))


def test_so3_exp_batched_matches_scipy() -> None:
    rng = np.random.default_rng(1)
    w = rng.normal(size=(200, 3))
    w *= rng.uniform(0, np.pi, (200, 1)) / np.linalg.norm(w, axis=1, keepdims=True)
    w[:3] = [[0, 0, 0], [1e-9, 0, 0], [0, 0, np.pi]]
    R = so3_exp(w)
    assert R.shape == (200, 3, 3)
    np.testing.assert_allclose(R, Rotation.from_rotvec(w).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(so3_log(R), w, atol=1e-12)
    np.testing.assert_allclose(rotation_angle(R), np.linalg.norm(w, axis=1), atol=1e-13)
    np.testing.assert_allclose(so3_exp(w.reshape(10, 20, 3)), R.reshape(10, 20, 3, 3))


def test_quaternion_helpers_batched_match_scipy() -> None:
    rng = np.random.default_rng(2)
    q = rng.normal(size=(500, 4))
    R = quaternion_to_matrix(q)
    np.testing.assert_allclose(R, Rotation.from_quat(q).as_matrix(), atol=1e-14)
    qn = matrix_to_quaternion(R)
    assert np.all(qn[:, 3] >= 0.0)
    canonical = q / np.linalg.norm(q, axis=1, keepdims=True)
    canonical *= np.sign(canonical[:, 3:4])
    np.testing.assert_allclose(qn, canonical, atol=1e-14)
    np.testing.assert_allclose(qn, Rotation.from_matrix(R).as_quat(canonical=True), atol=1e-14)


def test_quaternion_to_matrix_validation() -> None:
    with pytest.raises(ValueError, match="zero norm"):
        quaternion_to_matrix(np.zeros(4))
    with pytest.raises(ValueError, match="zero norm"):
        quaternion_to_matrix([[0, 0, 0, 1], [0, 0, 0, 0]])
    with pytest.raises(ValueError):
        quaternion_to_matrix(np.ones(3))
    with pytest.raises(ValueError):
        quaternion_to_matrix([np.nan, 0, 0, 1])
    with pytest.raises(ValueError, match="zero norm"):
        SO3.from_quaternion([0, 0, 0, 0])


@pytest.mark.parametrize("delta", [0.0, 1e-12, 1e-9, 1e-6, 1e-3])
def test_near_pi_rotations_round_trip(delta: float) -> None:
    rng = np.random.default_rng(3)
    axes = rng.normal(size=(50, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    w = axes * (np.pi - delta)
    R = Rotation.from_rotvec(w).as_matrix()
    np.testing.assert_allclose(rotation_angle(R), np.pi - delta, atol=1e-14)
    logs = so3_log(R)
    for a, b in zip(logs, w, strict=True):
        if delta == 0.0:
            assert same_rotvec_up_to_pi(a, b, 1e-14)
        else:
            np.testing.assert_allclose(a, b, atol=1e-14)
    np.testing.assert_allclose(so3_exp(logs), R, atol=1e-14)
    q = matrix_to_quaternion(R)
    ref = Rotation.from_matrix(R).as_quat()
    ref *= np.where(ref[:, 3:4] < 0, -1.0, 1.0)
    for a, b in zip(q, ref, strict=True):
        if delta == 0.0:  # w = 0: q and -q both have w >= 0
            assert np.allclose(a, b, atol=1e-14) or np.allclose(a, -b, atol=1e-14)
        else:
            np.testing.assert_allclose(a, b, atol=1e-14)
    np.testing.assert_allclose(quaternion_to_matrix(q), R, atol=1e-14)
    assert_single_matches_batched(w, R)


def assert_single_matches_batched(w: np.ndarray, R: np.ndarray) -> None:
    """The single-element fast paths agree with the vectorised code."""
    q, logs, exps = matrix_to_quaternion(R), so3_log(R), so3_exp(w)
    for i in range(len(w)):
        np.testing.assert_allclose(matrix_to_quaternion(R[i]), q[i], rtol=0, atol=1e-15)
        np.testing.assert_allclose(so3_log(R[i]), logs[i], rtol=0, atol=1e-15)
        np.testing.assert_allclose(so3_exp(w[i]), exps[i], rtol=0, atol=1e-15)


def test_single_paths_match_batched_paths() -> None:
    rng = np.random.default_rng(7)
    w = rng.normal(size=(300, 3))
    w *= (10.0 ** rng.uniform(-12, np.log10(np.pi), (300, 1))) / np.linalg.norm(w, axis=1, keepdims=True)
    w[:4] = [[0, 0, 0], [1e-5, 0, 0], [0, 0, np.pi], [0, -np.pi + 1e-9, 0]]
    assert_single_matches_batched(w, Rotation.from_rotvec(w).as_matrix())


@pytest.mark.parametrize("angle", [0.0, 1e-15, 1e-9, 1e-7, 1e-4, 0.5])
def test_rotation_angle_accurate_for_small_angles(angle: float) -> None:
    R = Rotation.from_rotvec([0.0, angle, 0.0]).as_matrix()
    assert rotation_angle(R) == pytest.approx(angle, rel=1e-12, abs=0)
    assert SO3(R).angle() == pytest.approx(angle, rel=1e-12, abs=0)


# ----------------------------------------------------------------------------------------------------
# SO3
# ----------------------------------------------------------------------------------------------------
@SETTINGS
@given(rotvecs())
def test_so3_exp_matches_scipy_and_log_inverts(w: np.ndarray) -> None:
    R = SO3.exp(w)
    np.testing.assert_allclose(R.matrix(), Rotation.from_rotvec(w).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(R.log(), w, rtol=1e-12, atol=1e-14)
    assert R.angle() == pytest.approx(np.linalg.norm(w), rel=1e-12, abs=1e-15)


@SETTINGS
@given(rotations())
def test_so3_exp_of_log_is_identity(R: SO3) -> None:
    w = R.log()
    assert np.linalg.norm(w) <= np.pi + 1e-15
    assert SO3.exp(w).allclose(R, atol=1e-14)


@SETTINGS
@given(rotations(), rotations(), rotations())
def test_so3_group_laws(a: SO3, b: SO3, c: SO3) -> None:
    assert ((a @ b) @ c).allclose(a @ (b @ c), atol=1e-14)
    assert (a @ a.inverse()).allclose(SO3.identity(), atol=1e-14)
    assert (a.inverse() @ a).allclose(SO3.identity(), atol=1e-14)
    np.testing.assert_allclose((a @ b).matrix(), a.matrix() @ b.matrix(), atol=1e-15)
    np.testing.assert_allclose((a @ b).adjoint(), a.adjoint() @ b.adjoint(), atol=1e-14)


@SETTINGS
@given(rotations(), rotvecs())
def test_so3_adjoint_conjugates_exp(R: SO3, w: np.ndarray) -> None:
    lhs = SO3.exp(R.adjoint() @ w)
    rhs = R @ SO3.exp(w) @ R.inverse()
    assert lhs.allclose(rhs, atol=1e-13)


@SETTINGS
@given(rotations(), points)
def test_so3_acts_on_points_like_its_matrix(R: SO3, pts: np.ndarray) -> None:
    np.testing.assert_allclose(R @ pts, pts @ R.matrix().T, atol=1e-13)
    np.testing.assert_allclose(R @ pts[0], R.matrix() @ pts[0], atol=1e-13)
    assert (R @ pts[0]).shape == (3,)
    np.testing.assert_allclose(R.act(pts), R @ pts)
    np.testing.assert_allclose(R @ pts.tolist(), R @ pts)


@SETTINGS
@given(rotations())
def test_so3_quaternion_round_trip_with_scipy(R: SO3) -> None:
    q = R.to_quaternion()
    assert q[3] >= 0.0
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
    ref = Rotation.from_matrix(R.matrix()).as_quat()
    assert np.allclose(q, ref, atol=1e-14) or np.allclose(q, -ref, atol=1e-14)
    assert SO3.from_quaternion(q).allclose(R, atol=1e-14)
    assert SO3.from_quaternion(-q).allclose(R, atol=1e-14)
    np.testing.assert_allclose(SO3.from_quaternion(ref).matrix(), R.matrix(), atol=1e-14)


def test_so3_tiny_rotation_is_exact_to_rounding() -> None:
    w = np.array([1e-9, -2e-9, 3e-9])
    R = SO3.exp(w)
    np.testing.assert_allclose(R.matrix(), expm(hat(w)), rtol=0, atol=1e-24)
    np.testing.assert_allclose(R.log(), w, rtol=1e-14)
    assert R.angle() == pytest.approx(np.linalg.norm(w), rel=1e-14, abs=0)
    assert SO3.exp(np.zeros(3)).allclose(SO3.identity(), atol=0.0)
    np.testing.assert_array_equal(SO3.identity().log(), np.zeros(3))


def test_so3_validation_and_orthonormalize() -> None:
    with pytest.raises(ValueError, match="shape"):
        SO3(np.eye(4))
    with pytest.raises(ValueError, match="orthonormal"):
        SO3(2.0 * np.eye(3))
    with pytest.raises(ValueError, match="reflection"):
        SO3(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="non-finite"):
        SO3(np.full((3, 3), np.nan))
    with pytest.raises(ValueError):
        SO3.exp(np.zeros(4))
    with pytest.raises(ValueError):
        SO3.from_matrix(np.diag([1.0, 1.0, -1.0]), orthonormalize=True)
    R = Rotation.from_rotvec([0.3, -0.2, 0.1]).as_matrix()
    noisy = R + 1e-4 * np.random.default_rng(4).normal(size=(3, 3))
    with pytest.raises(ValueError, match="orthonormal"):
        SO3.from_matrix(noisy)
    projected = SO3.from_matrix(noisy, orthonormalize=True).matrix()
    np.testing.assert_allclose(projected.T @ projected, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(projected, R, atol=1e-3)
    assert SO3.from_matrix(noisy, atol=1e-2).allclose(SO3(R), atol=1e-3)


def test_instances_are_immutable_and_picklable() -> None:
    T = SE3.exp([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    S = Sim3.exp([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7])
    with pytest.raises(AttributeError):
        T.rotation._R = np.eye(3)  # type: ignore[misc]
    with pytest.raises(AttributeError):
        S.foo = 1  # type: ignore[attr-defined]
    with pytest.raises(ValueError):
        T.translation[0] = 1.0
    M = T.matrix()
    M[0, 0] = 99.0  # a copy: the transform is unchanged
    assert T.matrix()[0, 0] != 99.0
    src = np.eye(3)
    R = SO3(src)
    src[0, 0] = 5.0  # the constructor copied its input
    assert R.allclose(SO3.identity(), atol=0.0)
    for x in (T.rotation, T, S):
        y = pickle.loads(pickle.dumps(x))
        assert type(y) is type(x)
        np.testing.assert_array_equal(y.matrix(), x.matrix())
    assert "SO3(" in repr(T.rotation) and "SE3(" in repr(T) and "scale=" in repr(S)


def test_sample_uniform_is_seeded() -> None:
    a = SO3.sample_uniform(np.random.default_rng(5))
    b = SO3.sample_uniform(np.random.default_rng(5))
    assert a.allclose(b, atol=0.0)
    T1 = SE3.sample(np.random.default_rng(6), translation_scale=2.0)
    T2 = SE3.sample(np.random.default_rng(6), translation_scale=2.0)
    assert T1.allclose(T2, atol=0.0)


# ----------------------------------------------------------------------------------------------------
# SE3
# ----------------------------------------------------------------------------------------------------
@SETTINGS
@given(se3_tangents)
def test_se3_exp_matches_matrix_exponential_and_log_inverts(xi: np.ndarray) -> None:
    T = SE3.exp(xi)
    np.testing.assert_allclose(T.matrix(), expm(se3_generator(xi)), atol=1e-12)
    np.testing.assert_allclose(T.log(), xi, rtol=1e-10, atol=1e-11)


@SETTINGS
@given(se3_elements)
def test_se3_exp_of_log_is_identity(T: SE3) -> None:
    assert SE3.exp(T.log()).allclose(T, atol=1e-11)


@SETTINGS
@given(se3_elements, se3_elements, se3_elements)
def test_se3_group_laws(a: SE3, b: SE3, c: SE3) -> None:
    assert ((a @ b) @ c).allclose(a @ (b @ c), atol=1e-12)
    assert (a @ a.inverse()).allclose(SE3.identity(), atol=1e-13)
    assert (a.inverse() @ a).allclose(SE3.identity(), atol=1e-13)
    np.testing.assert_allclose((a @ b).matrix(), a.matrix() @ b.matrix(), atol=1e-13)
    np.testing.assert_allclose(a.inverse().matrix(), np.linalg.inv(a.matrix()), atol=1e-12)
    np.testing.assert_allclose((a @ b).adjoint(), a.adjoint() @ b.adjoint(), atol=1e-12)
    np.testing.assert_allclose(a.inverse().adjoint(), np.linalg.inv(a.adjoint()), atol=1e-11)


@SETTINGS
@given(se3_elements, se3_tangents)
def test_se3_adjoint_conjugates_exp(T: SE3, xi: np.ndarray) -> None:
    lhs = SE3.exp(T.adjoint() @ xi)
    rhs = T @ SE3.exp(xi) @ T.inverse()
    assert lhs.allclose(rhs, atol=1e-10)


@SETTINGS
@given(se3_elements, points)
def test_se3_acts_on_points_like_its_matrix(T: SE3, pts: np.ndarray) -> None:
    homog = np.concatenate([pts, np.ones((len(pts), 1))], axis=1)
    np.testing.assert_allclose(T @ pts, (homog @ T.matrix().T)[:, :3], atol=1e-12)
    np.testing.assert_allclose(T @ pts[0], T.matrix3x4() @ homog[0], atol=1e-12)
    np.testing.assert_allclose(T.act(pts), T @ pts)
    np.testing.assert_allclose(T.inverse() @ (T @ pts), pts, atol=1e-12)


@SETTINGS
@given(se3_elements)
def test_se3_matrix_and_quaternion_round_trips(T: SE3) -> None:
    assert SE3.from_matrix(T.matrix()).allclose(T, atol=0.0)
    assert SE3.from_matrix(T.matrix3x4()).allclose(T, atol=0.0)
    assert SE3.from_rt(T.rotation, T.translation).allclose(T, atol=0.0)
    assert SE3.from_rt(T.rotation.matrix(), T.translation).allclose(T, atol=0.0)
    t, q = T.to_quaternion()
    assert q[3] >= 0.0
    np.testing.assert_array_equal(t, T.translation)
    assert SE3.from_quaternion(t, q).allclose(T, atol=1e-14)
    ref = Rotation.from_matrix(T.rotation.matrix()).as_quat()
    assert np.allclose(q, ref, atol=1e-14) or np.allclose(q, -ref, atol=1e-14)


def test_se3_left_perturbation_convention() -> None:
    # d/dh [exp(h e_k) T](p) at h = 0 is the k-th generator applied to T(p): translation for k < 3,
    # e_{k-3} × T(p) for k >= 3.
    T = SE3.exp([0.3, -0.1, 0.2, 0.5, -0.4, 0.3])
    p = np.array([1.0, 2.0, 3.0])
    q = T @ p
    h = 1e-6
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        deriv = ((SE3.exp(e) @ T) @ p - (SE3.exp(-e) @ T) @ p) / (2 * h)
        expected = np.eye(3)[k] if k < 3 else np.cross(np.eye(3)[k - 3], q)
        np.testing.assert_allclose(deriv, expected, atol=1e-8)


@pytest.mark.parametrize("scale", [0.0, 1e-12, 1e-9, 1e-6, 1e-3, 1e-1])
def test_se3_small_tangents_are_accurate(scale: float) -> None:
    xi = scale * np.array([0.3, -0.5, 0.8, -0.2, 0.7, 0.4])
    T = SE3.exp(xi)
    np.testing.assert_allclose(T.matrix(), expm(se3_generator(xi)), rtol=0, atol=1e-16)
    np.testing.assert_allclose(T.log(), xi, rtol=1e-13, atol=1e-300)


@pytest.mark.parametrize("theta", [0.0, 1e-12, 1e-6, 1e-2, 0.5, 0.999, 1.001, 2.0, 3.0, np.pi])
def test_se3_v_and_v_inverse_coefficients(theta: float) -> None:
    # V = ∫₀¹ exp(s ω^) ds is W of Sim(3) with σ = 0, and V⁻¹ must invert it.
    b, c = _se3_v_coeffs(theta)
    a_sim, b_sim, _ = _sim3_w_coeffs(0.0, theta)
    assert b == pytest.approx(a_sim, rel=1e-14, abs=0)
    assert c == pytest.approx(b_sim, rel=1e-14, abs=0)
    W = hat(theta * np.array([2.0, -1.0, 2.0]) / 3.0)
    V = np.eye(3) + b * W + c * W @ W
    V_inv = np.eye(3) - 0.5 * W + _se3_vinv_coeff(theta) * W @ W
    np.testing.assert_allclose(V @ V_inv, np.eye(3), rtol=0, atol=2e-15)


def test_se3_exp_log_at_pi() -> None:
    xi = np.array([1.0, -2.0, 0.5, 0.0, 0.0, np.pi])
    T = SE3.exp(xi)
    np.testing.assert_allclose(T.matrix(), expm(se3_generator(xi)), atol=1e-13)
    assert SE3.exp(T.log()).allclose(T, atol=1e-13)


def test_se3_validation() -> None:
    M = np.eye(4)
    M[3, 0] = 1.0
    with pytest.raises(ValueError, match="bottom row"):
        SE3.from_matrix(M)
    with pytest.raises(ValueError, match="shape"):
        SE3.from_matrix(np.eye(3))
    with pytest.raises(ValueError, match="translation"):
        SE3(np.eye(3), np.zeros(4))
    with pytest.raises(ValueError, match="non-finite"):
        SE3(np.eye(3), [0.0, np.inf, 0.0])
    with pytest.raises(ValueError, match="shape"):
        SE3.exp(np.zeros(3))
    with pytest.raises(ValueError, match="points"):
        SE3.identity() @ np.zeros((2, 4))
    with pytest.raises(TypeError):
        SE3.identity() @ 3.0  # type: ignore[operator]


# ----------------------------------------------------------------------------------------------------
# Sim3
# ----------------------------------------------------------------------------------------------------
@SETTINGS
@given(sim3_tangents)
def test_sim3_exp_matches_matrix_exponential_and_log_inverts(v: np.ndarray) -> None:
    S = Sim3.exp(v)
    ref = expm(sim3_generator(v))
    np.testing.assert_allclose(S.matrix(), ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    assert S.scale == pytest.approx(np.exp(v[6]), rel=1e-15, abs=0)
    np.testing.assert_allclose(S.log(), v, rtol=1e-9, atol=1e-10)


# Grid across the branches of the W coefficients: exact zeros, tiny values, both sides of |(σ, θ)| = 1.
@pytest.mark.parametrize("sigma", [0.0, 1e-12, -1e-7, 2e-3, 0.3, -0.999, 1.001, -2.5, 4.0])
@pytest.mark.parametrize("theta", [0.0, 1e-12, 1e-6, 3e-3, 0.5, 0.999, 1.001, 2.0, np.pi])
def test_sim3_exp_on_coefficient_branch_grid(sigma: float, theta: float) -> None:
    axis = np.array([2.0, -1.0, 2.0]) / 3.0
    v = np.concatenate([[0.7, -1.3, 2.1], theta * axis, [sigma]])
    ref = expm(sim3_generator(v))  # expm itself is only accurate to ~1e-12 relative for large σ
    np.testing.assert_allclose(Sim3.exp(v).matrix(), ref, rtol=1e-11, atol=1e-11 * np.abs(ref).max())
    # The coefficients of W = A ω^ + B ω^² + C I against quadrature of their cancellation-free integrals
    # A = ∫ e^{sσ} sin(sθ)/θ ds, B = ∫ e^{sσ} (1 - cos sθ)/θ² ds, C = ∫ e^{sσ} ds over s ∈ [0, 1].
    sinc = lambda x: np.sinc(x / np.pi)  # noqa: E731 - sin(x)/x
    integrands = (
        lambda s: np.exp(s * sigma) * s * sinc(s * theta),
        lambda s: np.exp(s * sigma) * s * s * 0.5 * sinc(0.5 * s * theta) ** 2,
        lambda s: np.exp(s * sigma),
    )
    coeffs = _sim3_w_coeffs(sigma, theta)
    for got, f in zip(coeffs, integrands, strict=True):
        ref_value = quad(f, 0.0, 1.0, epsabs=0.0, epsrel=1e-13, limit=200)[0]
        assert got == pytest.approx(ref_value, rel=1e-14, abs=0)
    if theta < np.pi:
        np.testing.assert_allclose(Sim3.exp(v).log(), v, rtol=1e-11, atol=1e-13)


@SETTINGS
@given(sim3_elements)
def test_sim3_exp_of_log_is_identity(S: Sim3) -> None:
    assert Sim3.exp(S.log()).allclose(S, atol=1e-10)


@SETTINGS
@given(sim3_elements, sim3_elements, sim3_elements)
def test_sim3_group_laws(a: Sim3, b: Sim3, c: Sim3) -> None:
    lhs, rhs = (a @ b) @ c, a @ (b @ c)
    np.testing.assert_allclose(lhs.matrix(), rhs.matrix(), rtol=1e-12, atol=1e-10)
    assert (a @ a.inverse()).allclose(Sim3.identity(), atol=1e-12)
    assert (a.inverse() @ a).allclose(Sim3.identity(), atol=1e-12)
    np.testing.assert_allclose((a @ b).matrix(), a.matrix() @ b.matrix(), rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(a.inverse().matrix(), np.linalg.inv(a.matrix()), rtol=1e-12, atol=1e-11)
    np.testing.assert_allclose((a @ b).adjoint(), a.adjoint() @ b.adjoint(), rtol=1e-12, atol=1e-10)


@SETTINGS
@given(sim3_elements, sim3_tangents)
def test_sim3_adjoint_conjugates_exp(S: Sim3, v: np.ndarray) -> None:
    lhs = Sim3.exp(S.adjoint() @ v).matrix()
    rhs = (S @ Sim3.exp(v) @ S.inverse()).matrix()
    np.testing.assert_allclose(lhs, rhs, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(rhs).max()))


@SETTINGS
@given(sim3_elements, points)
def test_sim3_acts_on_points_like_its_matrix(S: Sim3, pts: np.ndarray) -> None:
    homog = np.concatenate([pts, np.ones((len(pts), 1))], axis=1)
    np.testing.assert_allclose(S @ pts, (homog @ S.matrix().T)[:, :3], rtol=1e-13, atol=1e-11)
    expected = S.scale * pts @ S.rotation.matrix().T + S.translation
    np.testing.assert_allclose(S.act(pts), expected, rtol=1e-13, atol=1e-11)
    assert (S @ pts[0]).shape == (3,)
    np.testing.assert_allclose(S.inverse() @ (S @ pts), pts, atol=1e-10)


@SETTINGS
@given(se3_elements, se3_elements, scales)
def test_sim3_se3_conversions(T: SE3, U: SE3, s: float) -> None:
    S = Sim3.from_se3(T, s)
    assert S.scale == s
    assert S.to_se3().allclose(T, atol=0.0)
    np.testing.assert_allclose(Sim3.from_se3(T).matrix(), T.matrix(), atol=0.0)
    np.testing.assert_allclose((T @ S).matrix(), T.matrix() @ S.matrix(), rtol=1e-13, atol=1e-11)
    np.testing.assert_allclose((S @ U).matrix(), S.matrix() @ U.matrix(), rtol=1e-13, atol=1e-11)
    assert isinstance(T @ S, Sim3) and isinstance(S @ U, Sim3)
    back = Sim3.from_matrix(S.matrix())
    assert back.allclose(S, atol=1e-12)
    # With scale 1 the Sim3 tangent is the SE3 tangent with σ = 0.
    np.testing.assert_allclose(Sim3.from_se3(T).log(), np.concatenate([T.log(), [0.0]]), atol=1e-10)


def test_sim3_small_tangents_are_accurate() -> None:
    v = 1e-9 * np.array([0.3, -0.5, 0.8, -0.2, 0.7, 0.4, 0.6])
    S = Sim3.exp(v)
    np.testing.assert_allclose(S.matrix(), expm(sim3_generator(v)), rtol=0, atol=1e-16)
    np.testing.assert_allclose(S.log(), v, rtol=1e-12)
    # σ is tracked exactly (not recomputed from the rounded scale) through inverse, products and pickling
    assert S.log_scale == v[6]
    assert S.inverse().log_scale == -v[6]
    assert (S @ S).log_scale == 2 * v[6]
    assert pickle.loads(pickle.dumps(S)).log_scale == v[6]
    np.testing.assert_allclose(S.inverse().log(), -v, rtol=1e-12)


def test_sim3_validation() -> None:
    for bad in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="scale"):
            Sim3(np.eye(3), np.zeros(3), bad)
    M = np.eye(4)
    M[:3, :3] = -np.eye(3)
    with pytest.raises(ValueError, match="determinant"):
        Sim3.from_matrix(M)
    M = 2.0 * np.eye(4)
    with pytest.raises(ValueError, match="bottom row"):
        Sim3.from_matrix(M)
    M[3, 3] = 1.0
    assert Sim3.from_matrix(M).scale == pytest.approx(2.0, rel=1e-15, abs=0)
    M[0, 1] = 0.5  # not a scaled rotation
    with pytest.raises(ValueError, match="orthonormal"):
        Sim3.from_matrix(M)
    with pytest.raises(ValueError, match="shape"):
        Sim3.exp(np.zeros(6))
