"""estimation.logs.motion and .diagnosis, and the report's diagnosis: moving told from standing
against a known motion, statistics while moving without the standing samples, a module's
steering offset named with its sign and size, the gyro's scale and a slip stretch, a frozen
signal, and nothing found on a clean log."""

from __future__ import annotations

import json

import numpy as np
import pytest

from estimation import RobotGeometry, eta_from_twist, integrate_pose, steering_from_lambda, wheel_speeds
from estimation.kinematics import twist_from_wheels
from estimation.logs import ArrayLog, YawTrack, estimate_log
from estimation.logs.diagnosis import diagnose, stretches
from estimation.logs.motion import twist_from_wheels_batch, window_rate

DT = 0.02
MODULES = ("fl", "fr", "bl", "br")
#: (start, end) [s] of the standing stretches of the synthetic log, whose motion lasts 24 s
STANDING = ((0.0, 3.0), (13.0, 16.0))


@pytest.fixture(scope="module")
def swerve() -> RobotGeometry:
    """A coaxial swerve (b = 0, unlimited steering), FRC-sized: modules at (±0.3, ±0.3) m."""
    xy = np.array([[0.3, 0.3], [0.3, -0.3], [-0.3, 0.3], [-0.3, -0.3]])
    return RobotGeometry(alpha=np.arctan2(xy[:, 1], xy[:, 0]), l=np.hypot(xy[:, 0], xy[:, 1]), b=0.0, r=0.0508,
                         unlimited_steering=True)


def synthetic(geom, noise=0.0, seed=0):
    """24 s at 50 Hz: standing 0–3 s and 13–16 s with the wheels at scattered angles, driving
    (curving and crabbing, at least 0.5 m/s) otherwise; the true twist, heading and moving mask."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(24 / DT)) * DT
    twist = np.column_stack([1.0 + 0.4 * np.sin(0.7 * t), 0.3 * np.cos(0.4 * t), 0.9 * np.sin(0.5 * t + 0.3)])
    standing = np.zeros(t.size, bool)
    for a, b in STANDING:
        standing |= (t >= a - 1e-9) & (t < b - 1e-9)
    twist[standing] = 0.0
    lam, mu = eta_from_twist(np.where(standing[:, None], [1.0, 0.0, 0.0], twist))
    mu[standing] = 0.0
    beta = steering_from_lambda(lam, geom)
    for a, b in STANDING:  # scattered angles at rest, one set per stretch
        sel = (t >= a - 1e-9) & (t < b - 1e-9)
        beta[sel] = geom.wrap_steering(rng.uniform(-1.5, 1.5, geom.n))
    if noise:
        beta = geom.wrap_steering(beta + noise * rng.standard_normal(beta.shape))
    rate = np.vstack([np.zeros((1, geom.n)), geom.steering_difference(beta[1:], beta[:-1]) / DT])
    phidot = wheel_speeds(lam, mu, geom, beta_rate=rate, beta=beta)
    pose = np.zeros((t.size, 3))
    for k in range(1, t.size):
        pose[k] = integrate_pose(pose[k - 1], twist[k], DT)
    t_ns = 10**9 + np.rint(t * 1e9).astype(np.int64)
    return {"t": t, "t_ns": t_ns, "beta": beta, "phidot": phidot, "twist": twist, "yaw": pose[:, 2],
            "moving": ~standing}


def run(geom, d, beta=None, yaw=None, **kwargs):
    src = ArrayLog(d["t_ns"], d["beta"] if beta is None else beta, d["phidot"], geom, MODULES, yaw=yaw)
    r = estimate_log(src, ("IT", "LS"), **kwargs)
    return r, diagnose(r, geom, MODULES)


def kinds(diag, severity="check"):
    return [f["kind"] for f in diag["findings"] if f["severity"] == severity]


def test_batched_rigid_fit_equals_twist_from_wheels_row_by_row(geom, swerve):
    rng = np.random.default_rng(3)
    for g in (geom, swerve):
        beta, rate, phidot = rng.uniform(-3, 3, (200, 4)), rng.normal(size=(200, 4)), 10 * rng.normal(size=(200, 4))
        twist, resid = twist_from_wheels_batch(beta, rate, phidot, g)
        for k in range(200):
            ref, res = twist_from_wheels(beta[k], rate[k], phidot[k], g)
            np.testing.assert_allclose(twist[k], ref, rtol=1e-10, atol=1e-12)
            assert resid[k] == pytest.approx(res, rel=1e-9, abs=1e-12)


def test_moving_mask_matches_the_truth_and_stats_leave_standing_out(geom, swerve):
    for g in (geom, swerve):
        d = synthetic(g, noise=0.002)
        r, diag = run(g, d)
        assert np.array_equal(r.moving, d["moving"])
        np.testing.assert_allclose(r.rigid_twist[d["moving"]][1:], d["twist"][d["moving"]][1:], atol=0.05)
        q = diag["quality"]["IT"]
        assert q["moving"]["samples"] == d["moving"].sum() and q["standing"]["samples"] == (~d["moving"]).sum()
        assert q["moving"]["qua_mean"] == pytest.approx(100 * r.qua["IT"][d["moving"]].mean())
        assert q["moving"]["qua_p5"] > 99 > q["standing"]["qua_mean"]  # scattered wheels at rest: set apart
        assert diag["motion"]["moving_s"] == pytest.approx(18.0, abs=0.05)
        assert diag["motion"]["standing_s"] == pytest.approx(6.0, abs=0.05)
    r, _ = run(swerve, d, moving_speed=10.0)
    assert not r.moving.any() and r.moving_speed == 10.0


def test_a_clean_log_has_no_finding(swerve):
    d = synthetic(swerve, noise=0.002)
    _, diag = run(swerve, d, yaw=YawTrack(d["t_ns"], d["yaw"], "gyro"))
    assert kinds(diag) == []
    assert kinds(diag, "info") == ["motion", "quality", "gyro_agree"]
    g = diag["gyro"]["odometry"]
    assert g["slope"] == pytest.approx(1.0, abs=1e-3) and g["correlation"] > 0.999 and g["rms_diff_rad_s"] < 0.01


def test_a_module_offset_is_named_with_its_sign_and_size(swerve, geom):
    for g, k, off in ((swerve, 1, 3.0), (swerve, 2, -3.0), (geom, 3, 3.0)):
        d = synthetic(g, noise=0.002)
        beta = d["beta"].copy()
        beta[:, k] += np.radians(off)
        _, diag = run(g, d, beta=g.wrap_steering(beta))
        found = [f for f in diag["findings"] if f["kind"] == "module_offset"]
        assert kinds(diag) == ["module_offset"], diag["findings"]
        assert found[0]["module"] == MODULES[k] and found[0]["offset_deg"] == pytest.approx(off, abs=0.3)
        dep = diag["departure"]["modules"][MODULES[k]]
        assert np.sign(dep["mean_deg"]) == np.sign(off) and dep["p95_abs_deg"] > abs(dep["mean_deg"])


def test_gyro_scale_error_gives_the_slope(swerve):
    d = synthetic(swerve, noise=0.002)
    _, diag = run(swerve, d, yaw=YawTrack(d["t_ns"][::2] + 3_000_000, 1.05 * d["yaw"][::2], "gyro"))
    f = [f for f in diag["findings"] if f["kind"] == "gyro_scale"]
    assert kinds(diag) == ["gyro_scale"] and f[0]["slope"] == pytest.approx(1 / 1.05, rel=0.01)


def test_a_slip_stretch_is_found(swerve):
    d = synthetic(swerve, noise=0.002)
    extra = 0.8 * np.clip(d["t"] - 8.0, 0.0, 1.5)  # the robot turns 0.8 rad/s more than its wheels for 1.5 s
    _, diag = run(swerve, d, yaw=YawTrack(d["t_ns"], d["yaw"] + extra, "gyro"))
    f = [f for f in diag["findings"] if f["kind"] == "gyro_disagree"]
    assert f and len(f[0]["stretches"]) == 1
    s = f[0]["stretches"][0]
    assert s["t0_s"] == pytest.approx(8.0, abs=0.15) and s["t1_s"] == pytest.approx(9.5, abs=0.15)
    assert s["gyro_rad_s"] - s["wheels_rad_s"] == pytest.approx(0.8, abs=0.1)


def test_a_frozen_steering_signal_is_found(swerve):
    d = synthetic(swerve, noise=0.002)
    beta = d["beta"].copy()
    sel = (d["t"] >= 18.0 - 1e-9) & (d["t"] < 20.0 - 1e-9)
    beta[sel, 1] = beta[np.flatnonzero(sel)[0], 1]
    _, diag = run(swerve, d, beta=beta)
    f = [f for f in diag["findings"] if f["kind"] == "frozen"]
    assert len(f) == 1 and f[0]["module"] == "fr" and f[0]["signal"] == "steering"
    assert f[0]["t0_s"] == pytest.approx(18.0, abs=0.01) and f[0]["t1_s"] == pytest.approx(19.98, abs=0.01)


def test_stretches_and_window_rate():
    t = np.arange(100) * 0.1
    mask = (t > 2) & (t < 3.05) | (t > 3.2) & (t < 4) | (t > 7) & (t < 7.3)
    assert stretches(mask, t, 0.5, 0.35) == [(21, 39)] and stretches(mask, t, 0.5, 0.25) == [(21, 30), (33, 39)]
    ns = np.rint(t * 1e9).astype(np.int64)
    np.testing.assert_allclose(window_rate(ns[5:-5], ns, 2.0 * t), 2.0)
    assert np.isnan(window_rate(ns[:1], ns, t)).all()


def test_the_report_opens_with_the_diagnosis_and_samples_npz_has_moving(tmp_path, swerve):
    from jobs.estimate.report import write_outputs

    d = synthetic(swerve, noise=0.002)
    beta = d["beta"].copy()
    beta[:, 1] += np.radians(3.0)
    src = ArrayLog(d["t_ns"], swerve.wrap_steering(beta), d["phidot"], swerve, MODULES,
                   yaw=YawTrack(d["t_ns"], 1.05 * d["yaw"], "gyro"))
    files = write_outputs(estimate_log(src, ("IT", "LS")), src, tmp_path, elapsed_s=1.0, plots=False, csv=True)
    assert "samples.csv" in files
    npz = np.load(tmp_path / "samples.npz")
    assert np.array_equal(npz["moving"], d["moving"]) and npz["rigid_twist"].shape == (d["t"].size, 3)
    assert npz["steer_departure_deg"].shape == (d["t"].size, 4) and np.isfinite(npz["yaw_rate_gyro"]).any()
    s = json.loads((tmp_path / "summary.json").read_text())
    assert [f["kind"] for f in s["findings"] if f["severity"] == "check"] == ["module_offset", "gyro_scale"]
    assert s["moving"]["moving_speed_m_s"] == 0.05 and s["thresholds"]["moving_speed_m_s"] == 0.05
    assert s["moving"]["quality"]["IT"]["moving"]["samples"] == d["moving"].sum()
    head = (tmp_path / "report.md").read_text().splitlines()[:10]
    text = "\n".join(head)
    assert head[2] == "## Diagnosis" and s["diagnosis"][0] in text
    assert "Moving 75% of the log (18 s); standing 6 s" in text
    slope = [f for f in s["findings"] if f["kind"] == "gyro_scale"][0]["slope"]
    assert "Module fr reads +3.0° off the others" in text and f"slope {slope:.3f}" in text
    report = (tmp_path / "report.md").read_text()
    assert report.index("## While moving") < report.index("## Estimators on this log, all samples")
