"""Unlimited steering (no stops): β and β + π are one propulsion axis for the estimators and the
quality metric (RobotGeometry.unlimited_steering)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation import METHODS, RobotGeometry, dataset_d1, estimate_eta, estimate_icr, lambda_distance, quality
from estimation.quality import joint_distance_metric

FAST = [m for m in METHODS if m != "ORACLE"]
SWERVE = RobotGeometry(alpha=np.deg2rad([45.0, 135.0, -135.0, -45.0]), l=0.4356, b=0.0, r=0.05,
                       unlimited_steering=True)
OFFSET = RobotGeometry(alpha=np.deg2rad([0.0, 120.0, -120.0]), l=0.3, b=0.08, r=0.08, unlimited_steering=True)
GEOMS = [SWERVE, OFFSET, RobotGeometry.regular(6, l=0.5, unlimited_steering=True)]


def test_steering_difference_and_nearest():
    g = SWERVE
    assert np.isclose(g.steering_difference(np.pi / 2 - 1e-3, -np.pi / 2 + 1e-3), -2e-3)
    lim = RobotGeometry.azimut3()
    assert np.isclose(lim.steering_difference(np.pi / 2 - 1e-3, -np.pi / 2 + 1e-3), np.pi - 2e-3)
    ref = np.array([3.0, -3.0, 10.0, 0.0])
    near = g.nearest_steering(np.array([0.2, 0.2, 0.2, 1.5]), ref)
    assert np.all(np.abs(near - ref) <= np.pi / 2)
    assert np.allclose(np.sin(near[:3] - 0.2), 0.0, atol=1e-12)  # the same axis: a multiple of π away
    np.testing.assert_array_equal(lim.nearest_steering(np.array([0.2, 0.3, 0.4, 0.5]), ref), [0.2, 0.3, 0.4, 0.5])


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1.5, 1.5), min_size=4, max_size=4), st.lists(st.floats(-1.5, 1.5), min_size=4, max_size=4),
       st.lists(st.integers(-3, 3), min_size=4, max_size=4))
def test_quality_periodic_identifies_beta_and_beta_plus_pi(b, q, k):
    b, q, k = np.array(b), np.array(q), np.array(k)
    a = quality(b, q, periodic=True)
    shifted = quality(b + k * np.pi, q, periodic=True)
    assert np.isclose(a, shifted, atol=1e-9)
    assert quality(b, q, periodic=True) >= quality(b, q) - 1e-12  # the nearer axis angle is never farther
    assert joint_distance_metric(b + k * np.pi, q, periodic=True) <= 0.25 + 1e-12


def test_quality_periodic_across_the_wrap():
    eps = 1e-3
    q = np.array([-np.pi / 2 + eps, 0, 0, 0])
    b = np.array([np.pi / 2 - eps, 0, 0, 0])
    assert quality(b, q) < 0.3  # limited: ~π apart
    assert quality(b, q, periodic=True) > 0.99  # unlimited: 2ε apart
    assert np.isclose(quality(q + np.pi / 2, q, periodic=True), 1 - np.log(500 / 4 + 1) / np.log(501))


@pytest.mark.parametrize("geom", GEOMS, ids=["swerve", "offset3", "hex"])
@pytest.mark.parametrize("method", FAST)
def test_estimators_exact_on_d1_with_any_turn_of_each_wheel(geom, method):
    q, lam = dataset_d1(geom, n_points=60, seed=3)
    k = np.random.default_rng(4).integers(-2, 3, size=q.shape)
    lam_hat = estimate_icr(q + k * np.pi, geom, method)
    keep = ~np.any(np.linalg.norm(np.cross(lam[:, None, :], geom.s_unit[None]), axis=-1) < 1e-3, axis=1)
    assert np.max(lambda_distance(lam_hat[keep], lam[keep])) < 1e-6


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-np.pi, np.pi), min_size=4, max_size=4), st.lists(st.integers(-2, 2), min_size=4, max_size=4),
       st.sampled_from(["IT", "IT+", "NE", "LS", "NS"]))
def test_estimate_invariant_under_pi_shifts(q, k, method):
    q, k = np.array(q), np.array(k)
    a = estimate_icr(q, SWERVE, method)
    b = estimate_icr(q + k * np.pi, SWERVE, method)
    _, _, beta_a, qa = estimate_eta(q, np.zeros(4), SWERVE, method)
    _, _, beta_b, qb = estimate_eta(q + k * np.pi, np.zeros(4), SWERVE, method)
    assert np.isclose(qa, qb, atol=1e-9)
    # the same λ̂, except at a tie: the swerve is square, so every wheel at one angle has
    # symmetric optima of equal quality (found by hypothesis: q = 4 × −1.736, k = (0, 0, 0, −2), IT),
    # and the last bit that wrapping q + kπ changes may pick the other one, as good (qa == qb above)
    tie = bool(np.all(q == q[0]))
    assert lambda_distance(a, b) < 1e-6 or tie
    assert np.all(np.abs(SWERVE.steering_difference(beta_b, q + k * np.pi)) <= np.pi / 2 + 1e-12)


def test_estimate_eta_turns_the_wheel_speed_with_the_wheel():
    # a swerve robot translating along X: every module at β with speed v; the same motion with
    # module 2 turned by π and its wheel spinning the other way gives the same (λ, μ)
    g = SWERVE
    q, lam = dataset_d1(g, n_points=20, seed=5)
    from estimation import wheel_speeds

    phidot = wheel_speeds(lam, np.full(len(lam), 0.7), g, beta=q)
    lam_a, mu_a, beta_a, qua_a = estimate_eta(q, phidot, g)
    q2, ph2 = q.copy(), phidot.copy()
    q2[:, 2] += np.pi
    ph2[:, 2] *= -1
    q2 = np.pi - np.mod(np.pi - q2, 2 * np.pi)  # what an absolute encoder reads
    lam_b, mu_b, beta_b, qua_b = estimate_eta(q2, ph2, g)
    assert np.max(lambda_distance(lam_a, lam_b)) < 1e-9
    np.testing.assert_allclose(mu_b, mu_a, atol=1e-9)
    np.testing.assert_allclose(np.abs(mu_a), 0.7, atol=1e-6)
    np.testing.assert_allclose(qua_b, qua_a, atol=1e-12)
    assert np.max(np.abs(g.steering_difference(beta_b, q2))) < 1e-6
    assert np.max(np.abs(beta_b - q2)) < 1e-6  # S(λ̂) at the measured angles, not their wrapped copies
