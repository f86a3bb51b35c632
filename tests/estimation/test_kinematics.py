"""Kinematics: β = F(λ) (eq. 15–17), its derivatives (checked against finite differences, since
the printed eq. (18) carries sign errors), singularities (eq. 21), wheel speeds and μ."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from estimation import (
    RobotGeometry,
    eta_from_twist,
    mu_from_wheel_speeds,
    normalize,
    s_perp,
    singular_wheels,
    steering_chart_jacobian,
    steering_from_lambda,
    steering_gradient,
    steering_path_derivatives,
    wheel_speed_path_derivative,
    wheel_speeds,
)
from estimation.hrep import chart_params, lambda_from_chart

G = RobotGeometry.azimut3()
GEOMS = [G, RobotGeometry.regular(3, b=0.05), RobotGeometry.regular(6, l=0.5, b=-0.03),
         RobotGeometry(alpha=[0.1, 2.0, 3.5, 4.4, 5.5], l=[0.3, 0.5, 0.4, 0.35, 0.6], b=0.02,
                       r=[0.1, 0.1, 0.12, 0.1, 0.1])]
unit = arrays(np.float64, 3, elements=st.floats(-1, 1)).filter(lambda v: np.linalg.norm(v) > 1e-2).map(normalize)


def _regular_points(geom, n=500, seed=0, margin=1e-2):
    """Random λ away from the steering axes (where F is smooth)."""
    lam = normalize(np.random.default_rng(seed).normal(size=(n, 3)))
    keep = ~singular_wheels(lam, geom, tol=margin).any(axis=1)
    return lam[keep]


@pytest.mark.parametrize("geom", GEOMS)
def test_F_satisfies_the_constraint_and_range(geom):
    lam = _regular_points(geom)
    beta = steering_from_lambda(lam, geom)
    assert beta.shape == (len(lam), geom.n)
    assert np.all(beta > geom.steer_min) and np.all(beta <= geom.steer_max)
    s1, s2 = s_perp(beta, geom)
    np.testing.assert_allclose(np.einsum("nki,ni->nk", s1, lam), 0, atol=1e-12)  # eq. (15)
    # F is defined on Λ: λ and −λ, and any positive scale, give the same β
    np.testing.assert_allclose(steering_from_lambda(-3 * lam, geom), beta, atol=1e-12)


def test_F_closed_forms():
    # λ = (0, 0, 1): ICR at the chassis centre, rotation in place: every propulsion axis points
    # at the centre, β = 0 (γ = α).
    np.testing.assert_allclose(steering_from_lambda([0, 0, 1], G), 0, atol=1e-15)
    # λ = (1, 0, 0): translation along ... ICR at infinity along x: propulsion axes parallel to
    # X_R (γ = 0 mod π), so β = −α wrapped.
    np.testing.assert_allclose(steering_from_lambda([1, 0, 0], G), G.wrap_steering(-G.alpha), atol=1e-12)
    np.testing.assert_allclose(steering_from_lambda([0, 1, 0], G), G.wrap_steering(np.pi / 2 - G.alpha), atol=1e-12)


def test_F_single_and_batched_shapes_and_errors():
    assert steering_from_lambda([0.1, 0.2, 0.9], G).shape == (4,)
    assert steering_from_lambda(np.ones((2, 5, 3)), G).shape == (2, 5, 4)
    for bad in ([np.nan, 0, 1], [1, 2], [0, 0, 0]):
        with pytest.raises(ValueError):
            steering_from_lambda(bad, G)


@pytest.mark.parametrize("geom", GEOMS)
def test_gradient_matches_finite_differences(geom):
    lam = _regular_points(geom, 300, seed=2, margin=5e-2)
    grad = steering_gradient(lam, geom)
    eps = 1e-7
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        bp, bm = steering_from_lambda(lam + d, geom), steering_from_lambda(lam - d, geom)
        fd = (bp - bm) / (2 * eps)
        ok = np.abs(bp - bm) < 1.0  # skip the wrap discontinuity at ±π/2
        np.testing.assert_allclose(fd[ok], grad[..., i][ok], rtol=1e-5, atol=1e-5)
    # homogeneous of degree 0: gradient orthogonal to λ; and odd in λ
    np.testing.assert_allclose(np.einsum("nki,ni->nk", grad, lam), 0, atol=1e-9)
    np.testing.assert_allclose(steering_gradient(-lam, geom), -grad, atol=1e-12)


def test_printed_eq18_differs_from_the_derivative():
    """The paper's printed eq. (18) is not the derivative of F: documented, not used."""
    lam = normalize(np.array([0.3, -0.4, 0.8]))
    N, D = G.a_perp @ lam, G.a_minus_l @ lam
    dlam = np.array([1.0, 0.0, -lam[0] / lam[2]])
    printed = -((N[:, None] * G.a_minus_l + D[:, None] * G.a_perp) @ dlam) / np.einsum(
        "ki,i->k", D[:, None] * G.a_minus_l - N[:, None] * G.a_perp, lam)
    ours = steering_gradient(lam, G) @ dlam
    eps = 1e-7
    fd = (steering_from_lambda(lam + eps * dlam, G) - steering_from_lambda(lam - eps * dlam, G)) / (2 * eps)
    np.testing.assert_allclose(ours, fd, rtol=1e-6)
    assert not np.allclose(printed, fd, rtol=1e-3)


@given(unit)
def test_chart_jacobian_matches_finite_differences(lam):
    if singular_wheels(lam, G, tol=5e-2).any():
        return
    chart, J = steering_chart_jacobian(lam, G)
    _, p = chart_params(lam, chart)
    eps = 1e-7
    for j in range(2):
        d = np.zeros(2)
        d[j] = eps
        if np.sum((p + d) ** 2) >= 1:
            continue
        bp = steering_from_lambda(lambda_from_chart(chart, p + d), G)
        bm = steering_from_lambda(lambda_from_chart(chart, p - d), G)
        ok = np.abs(bp - bm) < 1.0
        np.testing.assert_allclose(((bp - bm) / (2 * eps))[ok], J[:, j][ok], rtol=1e-4, atol=1e-4)


def test_singularity_test_eq21():
    sing = singular_wheels(G.s_unit, G)
    np.testing.assert_array_equal(sing, np.eye(4, dtype=bool))
    assert not singular_wheels([0, 0, 1], G).any()
    # F stays finite at the singular point; the gradient row of the singular wheel is zero
    assert np.all(np.isfinite(steering_from_lambda(G.s_unit, G)))
    grad = steering_gradient(G.s_unit, G)
    np.testing.assert_array_equal(grad[np.arange(4), np.arange(4)], 0)
    fill = np.full((4, 4), 0.7)
    beta = steering_from_lambda(G.s_unit, G, singular_fill=fill)
    np.testing.assert_array_equal(np.diag(beta), 0.7)


@pytest.mark.parametrize("geom", GEOMS)
def test_wheel_speeds_roll_without_slip(geom):
    """Closed form: contact point velocity from the chassis twist, along the rolling direction,
    equals r φ̇; across it (along the axle) it is zero."""
    rng = np.random.default_rng(3)
    twists = rng.normal(size=(200, 3))
    lam, mu = eta_from_twist(twists)
    beta = steering_from_lambda(lam, geom)
    gamma = geom.alpha + beta
    P = geom.axis_xy + geom.b[:, None] * np.stack([np.cos(gamma), np.sin(gamma)], axis=-1)
    v = np.stack([twists[:, None, 0] - twists[:, None, 2] * P[..., 1],
                  twists[:, None, 1] + twists[:, None, 2] * P[..., 0]], axis=-1)
    roll = np.stack([np.sin(gamma), -np.cos(gamma)], axis=-1)
    axle = np.stack([np.cos(gamma), np.sin(gamma)], axis=-1)
    np.testing.assert_allclose(np.sum(v * axle, axis=-1), 0, atol=1e-12)
    phidot = wheel_speeds(lam, mu, geom)
    np.testing.assert_allclose(geom.r * phidot, np.sum(v * roll, axis=-1), atol=1e-12)
    # steer-to-drive coupling: r φ̇ = v·e − b β̇
    bdot = rng.normal(size=(200, geom.n))
    np.testing.assert_allclose(geom.r * wheel_speeds(lam, mu, geom, beta_rate=bdot),
                               np.sum(v * roll, axis=-1) - geom.b * bdot, atol=1e-12)
    # μ from the wheel speeds, given λ: exact round trip; and the sign of λ does not matter
    np.testing.assert_allclose(mu_from_wheel_speeds(lam, phidot, geom), mu, atol=1e-10)
    np.testing.assert_allclose(mu_from_wheel_speeds(-lam, phidot, geom), -mu, atol=1e-10)


def test_contact_point_moves_with_steering_by_b_beta_dot():
    """The coupling term from first principles: with the chassis still, turning module k at β̇
    moves its contact point at b β̇ along −(sin γ, −cos γ); rolling must cancel it."""
    beta, bdot, dt = 0.3, 0.5, 1e-7
    k = 0
    def contact(b):
        g = G.alpha[k] + b
        return G.axis_xy[k] + G.b[k] * np.array([np.cos(g), np.sin(g)])
    v = (contact(beta + bdot * dt) - contact(beta - bdot * dt)) / (2 * dt)
    g = G.alpha[k] + beta
    np.testing.assert_allclose(v @ np.array([np.sin(g), -np.cos(g)]), -G.b[k] * bdot, rtol=1e-6)


def test_path_derivatives_match_finite_differences():
    lam0 = normalize(np.array([0.2, -0.3, 0.9]))
    target = normalize(np.array([-0.5, 0.4, 0.6]))
    axis = normalize(np.cross(lam0, target))
    def lam_at(s):  # great circle through lam0 toward target, unit speed
        return np.cos(s) * lam0 + np.sin(s) * np.cross(axis, lam0)
    s0, h = 0.3, 1e-4
    lam = lam_at(s0)
    dlam = (lam_at(s0 + h) - lam_at(s0 - h)) / (2 * h)
    ddlam = (lam_at(s0 + h) - 2 * lam + lam_at(s0 - h)) / h**2
    d1, d2 = steering_path_derivatives(lam, dlam, ddlam, G)
    def b(s):
        return np.unwrap(np.stack([steering_from_lambda(lam_at(x), G) for x in s]), period=np.pi, axis=0)
    bb = b([s0 - h, s0, s0 + h])
    np.testing.assert_allclose(d1, (bb[2] - bb[0]) / (2 * h), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(d2, (bb[2] - 2 * bb[1] + bb[0]) / h**2, rtol=1e-3, atol=1e-3)
    # φ̇ along the path with μ(s) = 1 + s: r φ̇(s) = μ c(λ(s)) − b β′(s); its derivative
    def mu(s):
        return 1 + s
    def rphi(s):
        l = lam_at(s)
        dl = (lam_at(s + 1e-6) - lam_at(s - 1e-6)) / 2e-6
        bp, _ = steering_path_derivatives(l, dl, np.zeros(3), G)
        return wheel_speeds(l, mu(s), G, beta_rate=bp)
    fd = (rphi(s0 + h) - rphi(s0 - h)) / (2 * h)
    an = wheel_speed_path_derivative(lam, dlam, mu(s0), 1.0, d2, G)
    np.testing.assert_allclose(an, fd, rtol=1e-3, atol=1e-3)


def test_estimate_eta_recovers_the_twist_and_matches_the_public_pieces():
    from estimation import canonical_eta, estimate_eta, estimate_icr
    rng = np.random.default_rng(5)
    twists = rng.normal(size=(300, 3))
    lam, mu = eta_from_twist(twists)
    q = steering_from_lambda(lam, G)
    phidot = wheel_speeds(lam, mu, G)
    lam_hat, mu_hat, beta, qua_hat = estimate_eta(q, phidot, G)
    assert np.all(qua_hat >= 0.99999)
    # exact data: the twist comes back (μ > 0 convention)
    from estimation import twist_from_eta
    np.testing.assert_allclose(twist_from_eta(lam_hat, mu_hat), twists, atol=1e-8)
    # noisy data: same as composing the public functions
    qn = G.wrap_steering(q + rng.normal(scale=0.05, size=q.shape))
    lam_hat, mu_hat, beta, qua_hat = estimate_eta(qn, phidot, G)
    lam_it = estimate_icr(qn, G, "IT")
    beta_ref = steering_from_lambda(lam_it, G, singular_fill=qn)
    mu_ref = mu_from_wheel_speeds(lam_it, phidot, G, beta=beta_ref)
    lam_ref, mu_ref = canonical_eta(lam_it, mu_ref, mu_tol=1e-3)
    np.testing.assert_allclose(lam_hat, lam_ref, atol=1e-12)
    np.testing.assert_allclose(mu_hat, mu_ref, atol=1e-12)
    np.testing.assert_allclose(beta, beta_ref, atol=1e-12)
    from estimation import quality
    np.testing.assert_allclose(qua_hat, quality(beta_ref, qn), atol=1e-12)
    # single point and input checking
    l1, m1, b1, q1 = estimate_eta(qn[0], phidot[0], G)
    assert l1.shape == (3,) and np.shape(m1) == () and b1.shape == (4,) and np.shape(q1) == ()
    with pytest.raises(ValueError):
        estimate_eta(qn[0], phidot[0, :3], G)
    with pytest.raises(ValueError):
        estimate_eta(qn[0], np.full(4, np.nan), G)


@pytest.mark.parametrize("geom", GEOMS)
def test_twist_from_wheels_inverts_wheel_speeds(geom):
    """Odometry: the twist comes back from (β, β̇, φ̇) built by the inverse kinematics, with zero
    slip; non-concurrent axes leave a residual."""
    from estimation import twist_from_wheels
    rng = np.random.default_rng(9)
    for _ in range(20):
        twist = rng.normal(size=3)
        lam, mu = eta_from_twist(twist)
        beta = steering_from_lambda(lam, geom)
        bdot = rng.normal(size=geom.n)
        phidot = wheel_speeds(lam, mu, geom, beta_rate=bdot)
        est, slip = twist_from_wheels(beta, bdot, phidot, geom)
        np.testing.assert_allclose(est, twist, atol=1e-10)
        assert slip < 1e-10
    _, slip = twist_from_wheels(beta + np.deg2rad(10) * np.arange(geom.n), bdot, phidot, geom)
    assert slip > 1e-3


@pytest.mark.parametrize("scale", [2.0**-1000, 1e-300, 1e-200, 1e150, 1e155, 1e200, 1e300, 1e308, 2.0**1000])
def test_steering_from_lambda_at_any_scale(scale):
    """``steering_from_lambda`` of a λ scaled by 1e155…1e308 returned zeros (‖λ‖ overflowed)."""
    from estimation.hrep import eta_from_twist, normalize

    geom = RobotGeometry.azimut3()
    lam = np.array([[0.3, -0.5, 0.8], [-0.9, 0.1, 0.05], [0.0, 0.0, 1.0]])
    want = steering_from_lambda(lam, geom)
    got = steering_from_lambda(lam * scale, geom)
    assert np.allclose(got, want, rtol=0, atol=1e-12)  # the scaled λ is itself rounded (a power of two: exact)
    if math.frexp(scale)[0] == 0.5:
        assert np.array_equal(got, want)
    assert np.allclose(normalize(lam * scale), normalize(lam), rtol=0, atol=1e-15)
    lam_t, mu = eta_from_twist(np.array([2.0, -1.0, 0.5]) * min(scale, 1e300))
    assert np.allclose(lam_t, eta_from_twist(np.array([2.0, -1.0, 0.5]))[0], rtol=0, atol=1e-15)
    assert math.isfinite(float(mu)) and mu > 0
