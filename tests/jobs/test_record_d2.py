"""D2 recorded from the simulated robot under the ICR controller (``azimut record-d2``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from estimation import RobotGeometry, estimate_icr, quality, steering_from_lambda
from estimation.datasets import dataset_d2
from jobs.bench_estimators import order_stats
from jobs.record_d2 import DEFAULT_OUT, record_d2


def test_shipped_d2_is_the_recorded_one():
    geom = RobotGeometry.azimut3()
    q, source = dataset_d2(geom)
    assert source == "recorded"
    assert q.shape == (2450, 4)
    assert np.unique(q, axis=0).shape[0] == len(q)
    assert np.all(q > geom.steer_min - 0.1) and np.all(q <= geom.steer_max + 0.1)
    with np.load(DEFAULT_OUT) as data:
        meta = json.loads(str(data["meta"]))
    assert meta["track"] == "paper" and meta["controller"] == "icr" and meta["completed"]
    assert meta["imperfections"] == "paper"


def _qua(q, geom, method):
    return 100 * np.asarray(quality(steering_from_lambda(estimate_icr(q, geom, method), geom, singular_fill=q), q))


def test_shipped_d2_separates_the_estimators_as_the_papers_fig_11():
    """The paper (§4.1.1, Fig. 11, the real AZIMUT-3): IT gives "always the same or a better
    quality" than NS, with visible differences; LS "performs well only when the propulsion axes are
    not closely parallel". On the recorded D2: IT ≥ NS at every point where they differ, IT > NS +
    0.1 point on at least 5% of the points. NS ≥ LS holds wherever the ICR is farther than 5 m
    (near-parallel axes, where LS loses up to tens of points); with a close ICR, NS and LS
    minimise different residuals (NS on the sphere, LS in the plane), neither of them qua's
    joint-space distance, and either can be the closer, by about a hundredth of a point (0.011 at
    most on the shipped D2)."""
    geom = RobotGeometry.azimut3()
    q, _ = dataset_d2(geom)
    it, ns, ls = (_qua(q, geom, m) for m in ("IT", "NS", "LS"))
    it_ns = order_stats(it, ns)
    assert it_ns["a_at_least_b"] == 1.0 and it_ns["differ"] > 0.9 * len(q)
    assert it_ns["a_over_b_margin"] >= 0.05
    lam = estimate_icr(q, geom, "IT")
    far = np.hypot(lam[:, 0], lam[:, 1]) > 5.0 * np.abs(lam[:, 2])
    assert far.sum() > 100
    assert order_stats(ns[far], ls[far])["a_at_least_b"] == 1.0
    assert order_stats(ns[far], ls[far])["a_over_b_margin"] > 0.1  # LS far behind on near-parallel axes
    assert order_stats(ns, ls)["worst"] > -0.02  # -0.0109 on the D2 of the stop-hold margin (-0.0075 before)


def test_order_stats_closed_form():
    a = np.array([10.0, 10.0, 10.5, 9.0, 50.0])
    b = np.array([10.0, 9.95, 10.0, 9.5, 10.0])
    o = order_stats(a, b)
    assert o == {"points": 5, "differ": 4, "a_at_least_b": 0.75, "worst": -0.5, "a_over_b_margin": 0.4}
    assert order_stats(a, a)["a_at_least_b"] == 1.0 and order_stats(a, a)["differ"] == 0
    with pytest.raises(ValueError, match="qua_a and qua_b"):
        order_stats(a, b[:3])
    with pytest.raises(ValueError, match="qua_a and qua_b"):
        order_stats(np.zeros(0), np.zeros(0))


def test_record_d2_rejects_bad_arguments():
    with pytest.raises(ValueError):
        record_d2(points=0)
    with pytest.raises(ValueError):
        record_d2(speed_scale=-1.0)


@pytest.mark.slow
def test_record_d2_regenerates_the_shipped_file():
    q, meta = record_d2()
    with np.load(DEFAULT_OUT) as data:
        np.testing.assert_array_equal(q, data["q"])
