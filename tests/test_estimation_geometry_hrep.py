"""RobotGeometry validation and the H representation (§2): closed forms, round trips, properties."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from estimation import (
    RobotGeometry,
    canonical_eta,
    canonical_lambda,
    chart_params,
    eta_from_twist,
    lambda_distance,
    lambda_from_chart,
    lambda_from_plane,
    normalize,
    plane_from_lambda,
    point_velocity,
    select_chart,
    twist_from_eta,
)
from estimation.hrep import _canonicalize_batch, chart_tangents

finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
vec3 = arrays(np.float64, 3, elements=st.floats(-1, 1)).filter(lambda v: np.linalg.norm(v) > 1e-3)


def test_azimut3_defaults():
    g = RobotGeometry.azimut3()
    assert g.n == 4
    np.testing.assert_allclose(np.rad2deg(g.alpha), [45, 135, -135, -45])
    np.testing.assert_allclose(g.l, 0.3)
    np.testing.assert_allclose(g.b, 0.08)
    np.testing.assert_allclose(g.r, 0.08)
    np.testing.assert_allclose(g.s[:, 2], 1.0)
    np.testing.assert_allclose(np.linalg.norm(g.axis_xy, axis=1), 0.3)
    assert g == RobotGeometry.azimut3() and hash(g) == hash(RobotGeometry.azimut3())


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(alpha=[0.0, 1.0], l=0.3), "n >= 3"),
        (dict(alpha=[0.0, np.pi, 0.0], l=[0.3, 0.3, 0.6]), "one line"),
        (dict(alpha=[0.0, np.pi, np.pi], l=[0.3, 0.3, 0.6]), "one line"),
        (dict(alpha=[0.0, 1.0, np.nan], l=0.3), "finite"),
        (dict(alpha=[0.0, 1.0, 2.0], l=[0.3, np.inf, 0.3]), "finite"),
        (dict(alpha=[0.0, 1.0, 2.0], l=0.3, r=0.0), "r must be > 0"),
        (dict(alpha=[0.0, 1.0, 2.0], l=[0.3, 0.3]), "expected 3"),
        (dict(alpha=[0.0, 1.0, 2.0], l=0.3, steer_min=-1.0, steer_max=1.0), "width"),
        (dict(alpha=[0.0, 0.0, 2.0, 4.0], l=0.3), "same steering axis"),
    ],
)
def test_geometry_rejects_impossible(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RobotGeometry(**kwargs)


def test_geometry_is_frozen():
    g = RobotGeometry.azimut3()
    with pytest.raises(Exception):
        g.l = np.ones(4)
    with pytest.raises(ValueError):
        g.alpha[0] = 1.0  # read-only arrays


@given(arrays(np.float64, 7, elements=st.floats(-100, 100)))
def test_wrap_steering_range_and_equivalence(beta):
    g = RobotGeometry.azimut3()
    w = g.wrap_steering(beta)
    assert np.all(w > g.steer_min) and np.all(w <= g.steer_max)
    k = (beta - w) / np.pi
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)


@given(arrays(np.float64, 2, elements=finite))
def test_plane_sphere_round_trip(xy):
    lam = lambda_from_plane(xy)
    assert np.isclose(np.linalg.norm(lam), 1) and lam[2] > 0
    np.testing.assert_allclose(plane_from_lambda(lam), xy, rtol=1e-9, atol=1e-9)


def test_plane_from_lambda_equator_is_infinite():
    assert np.all(np.isinf(plane_from_lambda(np.array([1.0, 0.0, 0.0]))[:1]))


@given(vec3)
def test_chart_round_trip_and_selection(v):
    lam = normalize(v)
    chart, p = chart_params(lam)
    assert abs(lam[chart]) == np.max(np.abs(lam))
    back = lambda_from_chart(chart, p)
    assert np.isclose(abs(back @ lam), 1.0)  # same point of Λ
    assert back[chart] >= 0


@given(vec3)
def test_chart_tangents_match_finite_differences(v):
    lam = normalize(v)
    chart, p = chart_params(lam)
    T = chart_tangents(lam, chart)
    eps = 1e-7
    for j in range(2):
        d = np.zeros(2)
        d[j] = eps
        fd = (lambda_from_chart(chart, p + d) - lambda_from_chart(chart, p - d)) / (2 * eps)
        np.testing.assert_allclose(T[j], fd, atol=1e-5)


def test_charts_batched():
    lam = normalize(np.random.default_rng(0).normal(size=(100, 3)))
    chart, p = chart_params(lam)
    assert np.array_equal(chart, select_chart(lam))
    back = lambda_from_chart(chart, p)
    np.testing.assert_allclose(np.abs(np.sum(back * lam, axis=1)), 1.0)


@given(arrays(np.float64, 3, elements=st.floats(-10, 10)).filter(lambda t: np.linalg.norm(t) > 1e-6))
def test_twist_eta_round_trip(twist):
    lam, mu = eta_from_twist(twist)
    assert mu >= 0 and np.isclose(np.linalg.norm(lam), 1)
    np.testing.assert_allclose(twist_from_eta(lam, mu), twist, atol=1e-12)
    # (λ, μ) and (−λ, −μ) are the same motion
    np.testing.assert_allclose(twist_from_eta(-lam, -mu), twist, atol=1e-12)


def test_zero_twist_has_mu_zero():
    lam, mu = eta_from_twist(np.zeros(3))
    assert mu == 0 and np.allclose(lam, [0, 0, 1])


def test_point_velocity_matches_rigid_body_and_icr_is_still():
    twist = np.array([0.4, -0.3, 0.7])
    lam, mu = eta_from_twist(twist)
    p = np.array([[0.2, -0.5], [1.0, 2.0]])
    expected = np.stack([twist[0] - twist[2] * p[:, 1], twist[1] + twist[2] * p[:, 0]], axis=1)
    np.testing.assert_allclose(point_velocity(lam, mu, p), expected, atol=1e-12)
    icr = plane_from_lambda(lam)
    np.testing.assert_allclose(point_velocity(lam, mu, icr), 0, atol=1e-12)


def test_canonical_lambda_rules_and_numba_agree():
    rng = np.random.default_rng(1)
    lam = normalize(rng.normal(size=(1000, 3)))
    lam[:10, 2] = 0
    lam[5:10, 0] = 0
    lam = normalize(lam)
    c = canonical_lambda(lam)
    assert np.all((c[:, 2] > 0) | ((c[:, 2] == 0) & ((c[:, 0] > 0) | ((c[:, 0] == 0) & (c[:, 1] > 0)))))
    k = lam.copy()
    _canonicalize_batch(k)
    np.testing.assert_allclose(k, c, rtol=0, atol=1e-15)
    np.testing.assert_allclose(canonical_lambda(-lam), c)


def test_canonical_eta_makes_mu_positive():
    lam = normalize(np.array([[0.3, -0.2, -0.9], [0.1, 0.2, 0.3]]))
    lam2, mu2 = canonical_eta(lam, np.array([-2.0, 0.0]))
    assert mu2[0] == 2.0 and np.allclose(lam2[0], -lam[0])
    assert mu2[1] == 0.0 and lam2[1, 2] > 0


def test_lambda_distance_identifies_antipodes():
    a = normalize(np.array([0.2, 0.3, 0.9]))
    assert np.isclose(lambda_distance(a, -a), 0, atol=1e-7)
    assert np.isclose(lambda_distance(np.array([1.0, 0, 0]), np.array([0, 1.0, 0])), np.pi / 2)


@pytest.mark.parametrize("bad", [np.array([np.nan, 0, 1.0]), np.array([1.0, 2.0]), np.zeros(3)])
def test_hrep_bad_input(bad):
    with pytest.raises(ValueError):
        normalize(bad)
