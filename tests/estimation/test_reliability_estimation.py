"""Regression tests of issue 10 for the estimators: a row's result never depends on its batch (bit
for bit), complex/object inputs are refused, configs refuse NaN, ``quality`` stays in [0, 1]."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimation import METHODS, RobotGeometry, estimate_eta, estimate_icr, quality
from estimation.quality import joint_distance_metric

GEOM = RobotGeometry.azimut3()
FAST = [m for m in METHODS if m != "ORACLE"]


def _batch(seed: int, rows: int = 40) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q = rng.uniform(GEOM.steer_min, GEOM.steer_max, size=(rows, GEOM.n))
    q[::7] = -math.pi / 2 + 2e-16 * np.arange(GEOM.n)  # at the lower stop, in range (−π/2 excluded)
    q[3] = np.nextafter(-math.pi / 2, 0.0)  # −π/2 + 1 ulp: the example of the issue
    return q


@pytest.mark.parametrize("method", METHODS)
def test_row_result_is_independent_of_its_batch(method):
    q = _batch(1, rows=12 if method == "ORACLE" else 40)
    outside = q.copy()
    outside[-1] = [4.0, -7.0, 0.3, 10.0]  # an out-of-range neighbour
    alone = np.array([estimate_icr(row, GEOM, method) for row in q])
    together = estimate_icr(q, GEOM, method)
    with_neighbour = estimate_icr(outside, GEOM, method)[:-1]
    assert np.array_equal(together, alone)
    assert np.array_equal(with_neighbour, alone[:-1])
    lam, mu, beta, qua = estimate_eta(outside, np.ones_like(outside), GEOM, method)
    for i in (0, 3, 7):
        l1, m1, b1, q1 = estimate_eta(outside[i], np.ones(GEOM.n), GEOM, method)
        assert np.array_equal(lam[i], l1) and mu[i] == m1 and np.array_equal(beta[i], b1) and qua[i] == q1


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 30), st.sampled_from(FAST))
def test_row_independence_property(seed, rows, method):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-3 * math.pi, 3 * math.pi, size=(rows, GEOM.n))
    keep = rng.random((rows, GEOM.n)) < 0.7
    q = np.where(keep, rng.uniform(GEOM.steer_min, GEOM.steer_max, size=q.shape), q)
    batch = estimate_icr(q, GEOM, method)
    for i in range(rows):
        assert np.array_equal(batch[i], estimate_icr(q[i], GEOM, method))


@pytest.mark.parametrize("bad, err", [
    (np.zeros(4, complex), TypeError), (np.array([0, 0, 0, 0], dtype=object), TypeError),
    (np.array(["0"] * 4), TypeError), ([0.0, 0.0, float("nan"), 0.0], ValueError), (np.zeros(3), ValueError),
])
def test_estimators_refuse_complex_object_strings(bad, err):
    for method in FAST:
        with pytest.raises(err):
            estimate_icr(bad, GEOM, method)
    with pytest.raises(err):
        estimate_eta(bad, np.zeros(4), GEOM)
    with pytest.raises(TypeError):
        estimate_eta(np.zeros(4), np.zeros(4, complex), GEOM)


@pytest.mark.parametrize("mu_tol, error", [(float("nan"), ValueError), (-1.0, ValueError), (float("inf"), ValueError),
                                           (10**400, ValueError), ("1e-3", TypeError), (None, TypeError),
                                           (True, TypeError), (1j, TypeError)])
def test_estimate_eta_refuses_bad_mu_tol(mu_tol, error):
    with pytest.raises(error, match="mu_tol"):
        estimate_eta(np.zeros(4), np.zeros(4), GEOM, mu_tol=mu_tol)


def test_bad_method_and_geometry_refused():
    with pytest.raises(ValueError):
        estimate_icr(np.zeros(4), GEOM, ["IT"])
    with pytest.raises(TypeError):
        estimate_icr(np.zeros(4), "azimut3")
    with pytest.raises(TypeError):
        estimate_icr(np.zeros(4), GEOM, it_params={"n_starts": 2})


def test_quality_in_unit_interval_or_refused():
    q = np.array([1.5, -1.5, 1.5, -1.5])
    assert 0.0 <= float(quality(-q, q)) <= 1.0  # the largest in-range distance
    with pytest.raises(ValueError, match="steering range"):
        quality(np.zeros(4), np.array([4.0, 0.0, 0.0, 0.0]))  # |Δ| > π would give qua < 0
    with pytest.raises(ValueError):
        joint_distance_metric(np.zeros(4), np.array([0.0, 0.0, 0.0, -3.5]))
    with pytest.raises(TypeError):
        quality(np.zeros(4), np.zeros(4, complex))
    with pytest.raises(ValueError):
        quality(np.zeros(4), np.zeros(4), f=float("nan"))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-math.pi / 2, math.pi / 2), min_size=8, max_size=8))
def test_quality_property_in_unit_interval(x):
    v = float(quality(np.array(x[:4]), np.array(x[4:])))
    assert 0.0 <= v <= 1.0
