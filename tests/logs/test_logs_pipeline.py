"""estimation.logs.pipeline: the estimates of a log are estimate_eta's on the same samples (bit for
bit, whatever the chunking), dead reckoning follows the true motion, bad samples are skipped and
counted, unsorted timestamps refuse the log."""

from __future__ import annotations

import numpy as np
import pytest
from logs_data import MODULES4, motion

from estimation import RobotGeometry, estimate_eta, integrate_pose
from estimation.logs import (
                             LogError,
                             compare_estimators,
                             compose_increments,
                             estimate_log,
                             fold_coaxial,
                             odometry_drift,
                             open_log,
)
from estimation.logs.csv_log import write_csv_log


def _csv(tmp_path, geom, m, beta=None, phidot=None, t_s=None, pose=None, name="log.csv"):
    path = tmp_path / name
    write_csv_log(path, m.t_s if t_s is None else t_s, m.beta if beta is None else beta,
                  m.phidot if phidot is None else phidot, MODULES4[:geom.n] if geom.n == 4 else
                  [f"module_{k}" for k in range(geom.n)], pose=pose)
    return open_log(path, geom, MODULES4 if geom.n == 4 else None)


def test_every_estimator_matches_estimate_eta_bit_for_bit_whatever_the_chunks(tmp_path, geom):
    m = motion(geom, 300, noise=0.02)
    assert np.abs(m.beta).max() < 1.5  # away from the stops: no wrap in the data
    results = [estimate_log(_csv(tmp_path, geom, m), chunk_size=size) for size in (7, 300, 10_000)]
    for method in results[0].methods:
        lam, mu, _, qua = estimate_eta(m.beta, m.phidot, geom, method)
        for r in results:
            assert np.array_equal(r.lam[method], lam) and np.array_equal(r.mu[method], mu)
            assert np.array_equal(r.qua[method], qua)
    for r in results[1:]:
        assert np.array_equal(r.pose, results[0].pose) and np.array_equal(r.odom_twist, results[0].odom_twist)


def test_dead_reckoning_follows_the_true_motion_and_reports_no_drift(tmp_path, geom):
    m = motion(geom, 500)
    r = estimate_log(_csv(tmp_path, geom, m, pose=m.pose))
    assert r.aligned_at == 0
    np.testing.assert_allclose(r.odom_twist[1:], m.twist[1:], atol=1e-9)
    np.testing.assert_allclose(r.pose, m.pose, atol=1e-8)
    d = odometry_drift(r)
    assert d["samples"] == 500 and d["final_error_m"] < 1e-8 and d["drift_per_m"] < 1e-8
    assert d["distance_m"] == pytest.approx(np.sum(np.hypot(*np.diff(m.pose[:, :2], axis=0).T)))


def test_a_biased_wheel_speed_shows_as_drift(tmp_path, geom):
    m = motion(geom, 500)
    r = estimate_log(_csv(tmp_path, geom, m, phidot=m.phidot * 1.02, pose=m.pose))
    d = odometry_drift(r)
    assert 0.01 < d["drift_per_m"] < 0.03  # 2% too fast on every wheel: about 2% of the distance


def test_compose_increments_is_integrate_pose_in_sequence():
    rng = np.random.default_rng(3)
    twist = rng.normal(size=(50, 3))
    dt = rng.uniform(0.001, 0.05, 50)
    inc = integrate_pose(np.zeros((50, 3)), twist, dt)
    got = compose_increments(np.array([0.3, -1.0, 2.0]), inc)
    pose = np.array([0.3, -1.0, 2.0])
    for k in range(50):
        pose = integrate_pose(pose, twist[k], dt[k])
        np.testing.assert_allclose(got[k], pose, atol=1e-12)


def test_nan_samples_are_skipped_and_counted_the_rest_unchanged(tmp_path, geom):
    m = motion(geom, 200, noise=0.01)
    beta, phidot = m.beta.copy(), m.phidot.copy()
    beta[[5, 50], 1] = np.nan
    phidot[120, 3] = np.inf
    r = estimate_log(_csv(tmp_path, geom, m, beta=beta, phidot=phidot), chunk_size=64)
    good = np.ones(200, bool)
    good[[5, 50, 120]] = False
    assert r.n_read == 200 and r.t_ns.size == 197
    assert r.skipped == {"a steering angle or wheel speed is NaN or infinite": 3}
    lam, mu, _, qua = estimate_eta(m.beta[good], m.phidot[good], geom)
    assert np.array_equal(r.lam["IT"], lam) and np.array_equal(r.mu["IT"], mu)
    assert np.isfinite(r.pose).all()


def test_all_samples_bad_refuses_the_log(tmp_path, geom):
    m = motion(geom, 20)
    with pytest.raises(LogError, match="no good sample among the 20 read"):
        estimate_log(_csv(tmp_path, geom, m, beta=np.full_like(m.beta, np.nan)))


@pytest.mark.parametrize("chunk", [3, 1000])
@pytest.mark.parametrize("case, match", [("duplicate", "duplicated at sample 10"),
                                         ("unsorted", "not increasing at sample 10")])
def test_unsorted_or_duplicated_timestamps_refuse_the_log(tmp_path, geom, case, match, chunk):
    m = motion(geom, 30)
    t = m.t_s.copy()
    t[10] = t[9] if case == "duplicate" else t[9] - 0.005
    with pytest.raises(LogError, match=match):
        estimate_log(_csv(tmp_path, geom, m, t_s=t), chunk_size=chunk)


def test_comparison_table_as_bench_estimators(tmp_path, geom):
    m = motion(geom, 100, noise=0.05)
    r = estimate_log(_csv(tmp_path, geom, m), methods=("IT", "NE", "LS", "ORACLE"))
    c = compare_estimators(r)
    assert set(c["methods"]) == {"IT", "NE", "LS", "ORACLE"}
    assert set(c["IT_at_least_as_good_fraction"]) == {"NE", "LS"}
    for row in c["methods"].values():
        assert 0 <= row["qua_min"] <= row["qua_mean"] <= 100 and row["valid_unit"] == 1.0
        assert row["us_per_sample"] > 0 and "gap_to_oracle_mean" in row


def test_out_of_range_samples_are_flagged_not_changed(tmp_path, geom):
    m = motion(geom, 40)
    beta = m.beta.copy()
    beta[7, 0] = geom.steer_max + 0.01  # past the stop: a b != 0 wheel is not folded
    r = estimate_log(_csv(tmp_path, geom, m, beta=beta))
    assert np.flatnonzero(r.out_of_range).tolist() == [7]
    lam, mu, _, _ = estimate_eta(beta, m.phidot, geom)
    assert np.array_equal(r.lam["IT"], lam) and np.array_equal(r.mu["IT"], mu)


def test_fold_coaxial_is_the_same_wheel_state():
    geom = RobotGeometry.regular(4, l=0.3, b=0.0, r=0.05)
    m = motion(geom, 60)
    turns = np.random.default_rng(0).integers(-3, 4, size=m.beta.shape)
    beta, phidot = fold_coaxial(m.beta + turns * np.pi, m.phidot, geom)
    np.testing.assert_allclose(beta, m.beta, atol=1e-12)
    np.testing.assert_array_equal(phidot, np.where(turns % 2 == 0, m.phidot, -m.phidot))
    offset = RobotGeometry.azimut3()  # b != 0: left alone
    same, w = fold_coaxial(m.beta + np.pi, m.phidot, offset)
    assert np.array_equal(same, m.beta + np.pi) and np.array_equal(w, m.phidot)


def test_bad_arguments(tmp_path, geom):
    src = _csv(tmp_path, geom, motion(geom, 10))
    with pytest.raises(ValueError, match="methods"):
        estimate_log(src, methods=("IT", "XX"))
    with pytest.raises(ValueError, match="odometry_method"):
        estimate_log(src, methods=("NE",), odometry_method="IT")
    with pytest.raises(ValueError, match="chunk_size"):
        estimate_log(src, chunk_size=0)
