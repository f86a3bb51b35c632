"""azimut calibrate: steering offsets and wheel factors against known truths (kinematic logs,
simulated episodes, Team 1714's real log where ../shared has it), applying a calibration, and the
refusals."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from estimation import RobotGeometry, eta_from_twist, steering_from_lambda, wheel_speeds
from estimation.calibration import apply_offsets, fit_calibration, linear_start
from estimation.logs import ArrayLog
from estimation.logs.calibrate import calibrate_source
from estimation.logs.csv_log import write_csv_log
from jobs.cli import main

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real-logs"
MODULES = ("fl", "fr", "bl", "br")


def _rel(x):
    """Offsets less their circular mean (what a log fixes without rotation)."""
    return x - np.arctan2(np.sin(x).mean(), np.cos(x).mean())


def _wrap(x):
    return (np.asarray(x) + np.pi) % (2 * np.pi) - np.pi


def _swerve() -> RobotGeometry:
    return RobotGeometry(alpha=np.deg2rad([45.0, -45.0, 135.0, -135.0]), l=0.39, b=0.0, r=0.0508,
                         unlimited_steering=True)


def _kinematic_log(geom, n=3000, dt=0.02, seed=0):
    """A drive in several directions with turns: (t_ns, beta, phidot) exactly on the surface."""
    t = np.arange(n) * dt
    twist = np.column_stack([1.2 * np.cos(0.31 * t), 0.9 * np.sin(0.23 * t), 1.1 * np.sin(0.17 * t + 0.5)])
    lam, mu = eta_from_twist(twist)
    beta = steering_from_lambda(lam, geom)
    return (np.rint(t * 1e9).astype(np.int64), beta, wheel_speeds(lam, mu, geom, beta=beta))


def test_linear_start_finds_any_offsets_of_coaxial_modules():
    """Raw absolute encoders: offsets anywhere in 0-360 deg, each module's 180 deg settled by its
    wheel speed; relative offsets and factors exact on an exact log."""
    geom = _swerve()
    t, beta, phidot = _kinematic_log(geom)
    rng = np.random.default_rng(3)
    for _ in range(5):
        d = rng.uniform(-np.pi, np.pi, 4)
        s = 1 + rng.normal(0, 0.02, 4)
        bl, pl = apply_offsets(beta, phidot, geom, -d, 1 / s)
        off, sc = linear_start(bl, pl, geom)
        assert np.abs(_wrap(_rel(off) - _rel(d))).max() < 1e-8
        assert np.allclose(sc, s / np.exp(np.log(s).mean()), rtol=1e-8)
        fit, moving = fit_calibration(t, bl, pl, geom)
        assert moving.mean() > 0.9
        assert np.abs(_wrap(_rel(fit.steer_offset) - _rel(d))).max() < 1e-6
        assert fit.common_observable  # the drive turns: the common part is fixed modulo 180 deg
        assert np.abs(_wrap(2 * (fit.steer_offset - d))).max() < 1e-6


def test_gyro_fixes_the_common_turn_and_the_scale():
    geom = _swerve()
    t, beta, phidot = _kinematic_log(geom)
    t_s = (t - t[0]) * 1e-9
    omega = 1.1 * np.sin(0.17 * t_s + 0.5)
    d = np.deg2rad([170.0, -30.0, 95.0, -120.0])
    s = np.array([1.01, 0.99, 1.02, 0.985])
    bl, pl = apply_offsets(beta, phidot, geom, -d, 1 / s)
    fit, _ = fit_calibration(t, bl, pl, geom, yaw_rate=omega)
    assert fit.scale_absolute
    assert np.abs(np.rad2deg(_wrap(fit.steer_offset - d))).max() < 1e-6
    assert np.allclose(fit.wheel_scale, s, rtol=1e-6)


def _sim_logs(robot: str, seeds=(0, 1, 2), tracks=("figure8", "square", "crab")):
    """Episodes of the ICR controller on ``robot`` with the paper preset's physics (friction,
    compliance, noise, quantisation) and domain randomisation of it, the geometric imperfections
    left out of the physics: the robot's code knows its own geometry (it drives without fighting)
    and its log records raw angles and speeds, off by the offsets injected below."""
    from azimut_env.task.config import resolve_params
    from control.export import robot_description
    from control.path_controllers import ICRPathController
    from control.rollout import run_episodes

    params = resolve_params(None, None, 1.0, robot, "paper")
    imp = dataclasses.replace(params.imperfections, steer_offset=(), radius_error=(), steer_offset_std=0.0,
                              radius_error_std=0.0)
    params = dataclasses.replace(params, imperfections=imp)
    # the ICR controller without its look-ahead: the tolerances below were measured on its episodes
    # (with it, tri's square under this randomisation stalls in one of the seeds: docs/not-done.md)
    logs = run_episodes(ICRPathController(lookahead=None), list(tracks), list(seeds),
                        env_kwargs={"params": params, "domain_randomization": 0.2})
    geom, modules = robot_description(robot)
    ts, bs, ps, t0 = [], [], [], 0
    for log in logs:
        assert log.completed
        k = np.arange(log.beta_meas.shape[0])
        ts.append(t0 + np.rint(k * log.dt * 1e9).astype(np.int64))
        t0 = int(ts[-1][-1]) + 10**9
        bs.append(log.beta_meas)
        ps.append(log.phidot_meas)
    return geom, modules, np.concatenate(ts), np.concatenate(bs), np.concatenate(ps)


@pytest.mark.parametrize(("robot", "tol_deg", "tol_scale"), [("azimut3", 0.2, 0.002), ("swerve", 0.2, 0.002),
                                                            ("tri", 0.3, 0.003)])
def test_simulated_ground_truth(robot, tol_deg, tol_scale):
    """Offsets and rolling-radius errors injected into simulated logs come back within 0.2 deg and
    0.2% (relative: without a gyro a log fixes neither the common scale nor, for coaxial modules,
    the common 180 deg). Truths: the paper preset's values on azimut3; draws of the domain
    randomisation's spread (N(0, 0.5 deg), N(0, 0.3%)) elsewhere, and offsets anywhere in 0-360 deg
    on the swerve robot (raw absolute encoders). The three-wheeled robot falls short of 0.2 deg
    (0.24 deg and 0.22% measured, also with twice the driving): with three modules each sample holds three
    constraints, against five with four, and the tires' cornering slip biases more
    (docs/results/real-logs.md)."""
    from azimut_env.task.config import resolve_params

    geom, modules, t, beta, phidot = _sim_logs(robot)
    rng = np.random.default_rng({"azimut3": 1, "swerve": 2, "tri": 3}[robot])
    if robot == "azimut3":
        imp = resolve_params(None, None, 1.0, robot, "paper").imperfections
        d, eps = np.asarray(imp.steer_offset), np.asarray(imp.radius_error)
    else:
        eps = np.clip(rng.normal(0, 0.003, geom.n), -0.009, 0.009)
        d = (rng.uniform(-np.pi, np.pi, geom.n) if geom.unlimited_steering
             else np.clip(rng.normal(0, np.deg2rad(0.5), geom.n), -np.deg2rad(1.5), np.deg2rad(1.5)))
    s = 1 + eps
    bl, pl = apply_offsets(beta, phidot, geom, -d, 1 / s)
    result = calibrate_source(ArrayLog(t, bl, pl, geom, modules), moving_speed=0.05)
    off = np.deg2rad([m["steer_offset_deg"] for m in result["modules"]])
    sc = np.array([m["wheel_scale"] for m in result["modules"]])
    assert np.rad2deg(np.abs(_wrap(_rel(off) - _rel(d)))).max() < tol_deg
    assert np.abs(sc / (s / np.exp(np.log(s).mean())) - 1).max() < tol_scale
    assert result["after"]["qua_IT_mean"] > result["before"]["qua_IT_mean"]


@pytest.mark.skipif(not (REAL / "team1714_20230325_214134.wpilog").is_file(), reason="Team 1714's log (../shared)")
def test_team1714_from_raw_encoders(tmp_path):
    """From the raw CANcoder angles, no offsets given: within 4 deg of the team's own offsets
    relative to module 0, and IT's qua while moving at least 0.995 and not below the team's."""
    team = np.array([20.55, 276.05, 203.30, 141.92])  # the code's angleOffset: heading = Cancoder - offset
    out = tmp_path / "c"
    rc = main(["calibrate", str(REAL / "team1714_20230325_214134.wpilog"), "--robot-file",
               str(REAL / "team1714_mk4i.toml"), "--steer-entry", "NT:/SmartDashboard/Mod {i} Cancoder",
               "--wheel-entry", "mod{i}/driveMotorSpeed", "--angle-unit", "deg", "--wheel-scale", "0.0023089",
               "--current-offsets=" + ",".join(str(-x) for x in team), "--out", str(out)])
    assert rc == 0
    cal = json.loads((out / "calibration.json").read_text())
    fitted = np.array([m["steer_offset_deg"] for m in cal["modules"]])
    rel_fit = (fitted - fitted[0] + 180) % 360 - 180
    rel_team = (-team + team[0] + 180) % 360 - 180
    assert np.abs((rel_fit - rel_team + 180) % 360 - 180).max() < 4.0
    assert cal["after"]["qua_IT_mean"] >= 0.995
    assert cal["after"]["qua_IT_mean"] >= cal["current"]["qua_IT_mean"]
    assert "Rotation2d.fromDegrees" in (out / "report.md").read_text()


def _csv(tmp_path, geom, beta, phidot, t_ns, name="run.csv"):
    path = tmp_path / name
    write_csv_log(path, (t_ns - t_ns[0]) * 1e-9, beta, phidot, MODULES)
    return path


def _robot_file(tmp_path, x=0.276) -> Path:
    body = 'schema = 1\nname = "sw"\n[geometry]\nsteering = "unlimited"\nb_m = 0.0\nr_m = 0.0508\n'
    for m, (sx, sy) in zip(MODULES, [(1, 1), (1, -1), (-1, 1), (-1, -1)]):
        body += f'[[geometry.modules]]\nname = "{m}"\nx_m = {sx * x}\ny_m = {sy * 0.276}\n'
    path = tmp_path / f"robot_{x}.toml"
    path.write_text(body)
    return path


def test_cli_applies_and_refuses(tmp_path, capsys):
    robot = _robot_file(tmp_path)
    geom = RobotGeometry.from_file(robot)
    t, beta, phidot = _kinematic_log(geom)
    d = np.deg2rad([3.0, -2.0, 1.0, 0.5])
    bl, pl = apply_offsets(beta, phidot, geom, -d, np.ones(4))
    log = _csv(tmp_path, geom, bl, pl, t)
    cal = tmp_path / "cal"
    assert main(["calibrate", str(log), "--robot-file", str(robot), "--out", str(cal)]) == 0
    data = json.loads((cal / "calibration.json").read_text())
    got = np.deg2rad([m["steer_offset_deg"] for m in data["modules"]])
    assert np.abs(_wrap(got - d)).max() < 1e-6
    est = tmp_path / "est"
    assert main(["estimate", str(log), "--robot-file", str(robot), "--calibration", str(cal / "calibration.json"),
                 "--no-plots", "--out", str(est)]) == 0
    npz = np.load(est / "samples.npz")
    assert np.allclose(geom.steering_difference(npz["beta"], beta), 0.0, atol=1e-9)
    capsys.readouterr()

    def refused(argv, *words):
        out = tmp_path / f"x{len(list(tmp_path.iterdir()))}"
        assert main(argv + ["--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and all(w in err for w in words), err
        assert not out.exists()

    other = _robot_file(tmp_path, x=0.3)
    refused(["estimate", str(log), "--robot-file", str(other), "--calibration", str(cal / "calibration.json"),
             "--no-plots"], "another robot", "alpha_deg")
    refused(["calibrate", str(log), "--robot-file", str(robot), "--current-offsets", "1,2,3"], "3 values", "4 modules")
    still = _csv(tmp_path, geom, beta[:50], 0 * phidot[:50], t[:50], "still.csv")
    refused(["calibrate", str(still), "--robot-file", str(robot)], "0 samples", "at least 200")
    line = _csv(tmp_path, geom, np.repeat(beta[:1], 2000, 0), np.repeat(phidot[:1], 2000, 0),
                np.arange(2000, dtype=np.int64) * 20_000_000, "line.csv")
    refused(["calibrate", str(line), "--robot-file", str(robot)], "too alike")


def test_refusals_and_warnings_found_by_a_new_user(tmp_path):
    """A gyro in the wrong unit, headings read as β, offsets given with the wrong sign, and angles that
    already agree while only the wheel speeds ask for large turns (an inverted drive motor)."""
    from estimation.logs import YawTrack

    geom = _swerve()
    t, beta, phidot = _kinematic_log(geom)
    t_s = (t - t[0]) * 1e-9
    yaw = np.cumsum(np.concatenate([[0.0], 1.1 * np.sin(0.17 * t_s[1:] + 0.5) * np.diff(t_s)]))
    d = np.deg2rad([3.0, -2.0, 1.0, 0.5])
    bl, pl = apply_offsets(beta, phidot, geom, -d, np.ones(4))
    good = calibrate_source(ArrayLog(t, bl, pl, geom, yaw=YawTrack(t, yaw, "gyro")), moving_speed=0.05)
    assert np.allclose([m["steer_offset_deg"] for m in good["modules"]], np.rad2deg(d), atol=0.05)
    assert good["wheel_scale_absolute"] and not good["warnings"]
    with pytest.raises(ValueError, match="gyro and the wheels disagree.*gyro: gyro"):
        calibrate_source(ArrayLog(t, bl, pl, geom, yaw=YawTrack(t, np.rad2deg(yaw), "gyro")), moving_speed=0.05)
    inverted = pl.copy()
    inverted[:, 1] *= -1  # a drive motor inverted: the angles agree, the speeds ask for a 180° turn
    with pytest.raises(ValueError, match="already agree.*wheel speeds"):
        calibrate_source(ArrayLog(t, bl + d, inverted, geom), moving_speed=0.05)
    headings = bl + geom.alpha - np.pi / 2  # WPILib headings read as β
    res = calibrate_source(ArrayLog(t, headings, pl, geom), moving_speed=0.05)
    assert any("--steer-convention heading" in w for w in res["warnings"])
    big = np.deg2rad([20.0, -40.0, 60.0, 10.0])
    braw, praw = apply_offsets(beta, phidot, geom, -big, np.ones(4))
    res = calibrate_source(ArrayLog(t, braw, praw, geom), moving_speed=0.05,
                           current_offsets_deg=list(-np.rad2deg(big)))  # the code's offsets to subtract, as given
    assert any("negatives" in w for w in res["warnings"])


@pytest.mark.skipif(not (REAL / "team1672_20250214_212636.wpilog").is_file(), reason="Team 1672's log (../shared)")
def test_team1672_with_its_gyro_is_refused_not_misfitted(tmp_path, capsys):
    """Team 1672's angles agree (98.8%) while its wheel speeds and gyro disagree (an inverted motor, or
    the robot on blocks): calibrate refuses instead of proposing 90° and 171° corrections."""
    rc = main(["calibrate", str(REAL / "team1672_20250214_212636.wpilog"), "--robot-file",
               str(REAL / "team1672_neo.toml"), "--states-entry",
               "NT:/SmartDashboard/swerve/advantagescope/currentStates",
               "--yaw-entry", "NT:/SmartDashboard/swerve/imu/raw", "--yaw-unit", "deg", "--out", str(tmp_path / "c")])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "already agree" in err, err
    assert not (tmp_path / "c").exists()
