"""RobotGeometry validation and the H representation (§2): closed forms, round trips, properties."""

import dataclasses

import numpy as np
import pytest
from hypothesis import assume, given, settings
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
    with pytest.raises(dataclasses.FrozenInstanceError):
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


# ---------------------------------------------------------------- motion of λ on the sphere


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=6, max_size=6), st.floats(0.0, 3.0))
def test_slerp_moves_along_the_great_circle_by_the_angle(xs, angle):
    from estimation.hrep import slerp, sphere_angle

    a, b = np.array(xs[:3]), np.array(xs[3:])
    assume(np.linalg.norm(a) > 1e-2 and np.linalg.norm(b) > 1e-2)
    a, b = normalize(a), normalize(b)
    assume(np.linalg.norm(np.cross(a, b)) > 1e-3)
    p = slerp(a, b, angle)
    assert abs(np.linalg.norm(p) - 1.0) < 1e-12
    assert abs(np.dot(p, np.cross(a, b))) < 1e-12  # on the great circle through a and b
    assert abs(sphere_angle(a, p) - min(angle, 2 * np.pi - angle)) < 1e-9
    theta = sphere_angle(a, b)
    np.testing.assert_allclose(slerp(a, b, theta), b, atol=1e-12)


def test_slerp_broadcasts_rows_and_angles_and_keeps_degenerate_pairs():
    from estimation.hrep import slerp

    rng = np.random.default_rng(3)
    a, b = normalize(rng.normal(size=(5, 3))), normalize(rng.normal(size=(5, 3)))
    b[2] = -a[2]  # antipodes: no unique great circle
    ang = rng.uniform(0, 1, size=(5, 7))
    out = slerp(a, b, ang)
    assert out.shape == (5, 7, 3)
    for i in range(5):
        np.testing.assert_array_equal(out[i], slerp(a[i:i + 1], b[i:i + 1], ang[i:i + 1])[0])
    np.testing.assert_array_equal(out[2], np.broadcast_to(a[2], (7, 3)))
    assert slerp(a[0], b[0], ang[0]).shape == (7, 3)


def test_exp_map_is_the_great_circle_of_its_tangent():
    from estimation.hrep import exp_map, slerp, sphere_angle

    rng = np.random.default_rng(4)
    lam = normalize(rng.normal(size=(6, 3)))
    t = rng.normal(size=(6, 3))
    t -= np.sum(t * lam, axis=-1, keepdims=True) * lam  # tangent at λ
    scale = np.array([0.0, 0.1, 0.5, 1.0])
    v = t[:, None, :] * scale[None, :, None]
    out = exp_map(lam, v)
    assert out.shape == (6, 4, 3)
    np.testing.assert_allclose(out[:, 0], lam, atol=1e-15)
    arc = np.linalg.norm(v, axis=-1)
    np.testing.assert_allclose(sphere_angle(lam[:, None, :], out), np.minimum(arc, 2 * np.pi - arc), atol=1e-12)
    np.testing.assert_allclose(out[:, 2], slerp(lam, lam + t, arc[:, 2]), atol=1e-12)


def test_nearer_representative_is_the_same_motion_within_a_quarter_turn():
    from estimation.hrep import nearer_representative, sphere_angle, twist_from_eta

    rng = np.random.default_rng(5)
    lam, lam_d = normalize(rng.normal(size=(50, 3))), normalize(rng.normal(size=(50, 3)))
    mu_d = rng.normal(size=50)
    l2, m2 = nearer_representative(lam, lam_d, mu_d)
    np.testing.assert_allclose(twist_from_eta(l2, m2), twist_from_eta(lam_d, mu_d), atol=1e-15)
    assert np.all(sphere_angle(lam, l2) <= np.pi / 2 + 1e-12)
