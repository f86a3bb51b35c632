"""``twist-setpoint``: the setpoint generator (``control.twist.setpoint``) never commands beyond the
actuator limits, stops the chassis for a flip, keeps headings on a zero command; the compiled batch
equals the NumPy reference bit for bit; ``azimut eval`` runs it."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from azimut_env.params import RobotParams
from control.controller import ControllerSpecError, controller_names, make_controller
from control.icr.config import Mode
from control.limits import limit_violations
from control.twist.setpoint import SetpointBatch, SetpointConfig, SetpointController, braking_step

PRESETS = {name: RobotParams.preset(name) for name in ("azimut3", "swerve", "tri", "hex")}


def _measure(geom, beta, noise):
    """A measured angle near the command: in the steering range, or (unlimited) in ]−π, π]."""
    q = beta + noise
    return np.pi - np.mod(np.pi - q, 2 * np.pi) if geom.unlimited_steering else geom.wrap_steering(q)


def _drive(ctl, targets, noise=None):
    """Step ``ctl`` through ``targets`` (T, 3), the measured angle the last command (plus noise);
    returns the commands."""
    cmds = []
    for j, t in enumerate(targets):
        meas = _measure(ctl.geom, ctl.beta, 0.0 if noise is None else noise[j])
        cmds.append(ctl.step(t, meas))
    return cmds


def _speeds(ctl, twist):
    """Module speeds [m/s] at the steering axes for a chassis twist."""
    g = ctl.geom
    return np.hypot(twist[0] - twist[2] * g.axis_xy[:, 1], twist[1] + twist[2] * g.axis_xy[:, 0])


# -- never beyond a limit --------------------------------------------------------------------------

_segment = st.tuples(
    st.sampled_from(["zero", "translate", "spin", "mixed", "reverse", "strafe"]),
    st.floats(0.0, 1.0), st.floats(-math.pi, math.pi), st.floats(-1.0, 1.0), st.integers(1, 25))


def _targets(segments, v_max, w_max):
    """Piecewise-constant targets: zero commands, translations, spins in place, mixtures, the previous
    translation reversed through zero, the previous direction turned by 90°."""
    out, last = [], np.array([v_max * 0.5, 0.0, 0.0])
    for kind, speed, ang, w, count in segments:
        v = speed * v_max
        if kind == "zero":
            t = np.zeros(3)
        elif kind == "translate":
            t = np.array([v * math.cos(ang), v * math.sin(ang), 0.0])
        elif kind == "spin":
            t = np.array([0.0, 0.0, w * w_max])
        elif kind == "mixed":
            t = np.array([v * math.cos(ang), v * math.sin(ang), w * w_max])
        elif kind == "reverse":
            t = np.array([-last[0], -last[1], last[2]])
        else:
            t = np.array([-last[1], last[0], 0.0])
        last = t
        out += [t] * count
    return np.array(out)


@pytest.mark.parametrize("preset", list(PRESETS))
@settings(max_examples=25, deadline=None)
@given(segments=st.lists(_segment, min_size=1, max_size=6), seed=st.integers(0, 2**16))
def test_random_targets_never_exceed_a_limit(preset, segments, seed):
    params = PRESETS[preset]
    g, lim = params.geometry, params.limits
    v_max = 1.5 * lim.wheel_speed_max * float(np.min(g.r))  # beyond reach: desaturation is exercised
    targets = _targets(segments, v_max, v_max / float(np.max(g.l)))
    rng = np.random.default_rng(seed)
    ctl = SetpointController(g, lim, 0.02)
    ctl.reset(_measure(g, rng.uniform(-math.pi, math.pi, g.n), 0.0), rng.uniform(-1, 1, g.n))
    cmds = _drive(ctl, targets, rng.normal(0.0, 0.05, (len(targets), g.n)))
    for cmd in cmds:
        assert not limit_violations(cmd.beta_rate, cmd.beta_accel, cmd.phidot, cmd.phiddot, lim).any()
        if not g.unlimited_steering:
            assert np.all((cmd.beta >= g.steer_min) & (cmd.beta <= g.steer_max))
    # the reported rates are the finite differences of the commands
    beta = np.array([c.beta for c in cmds])
    np.testing.assert_allclose(np.array([c.beta_rate for c in cmds])[1:], np.diff(beta, axis=0) / 0.02, atol=1e-9)


# -- flips, zero commands ------------------------------------------------------------------------------


def test_a_flip_across_the_stops_stops_the_chassis_before_the_modules_turn():
    """azimut3 driving along x, then along y: modules must turn 90° across their ±90° stops, so
    they turn the other way round, with the chassis stopped (254's stop-first)."""
    p = PRESETS["azimut3"]
    ctl = SetpointController(p.geometry, p.limits, 0.02)
    ctl.reset(np.deg2rad([45.0, -45.0, 45.0, -45.0]), np.zeros(4))  # rolling along x
    _drive(ctl, np.tile([0.6, 0.0, 0.0], (150, 1)))
    np.testing.assert_allclose(ctl.twist, [0.6, 0.0, 0.0])
    before = ctl.beta.copy()
    cmds = _drive(ctl, np.tile([0.0, 0.6, 0.0], (250, 1)))
    speed = np.array([np.max(_speeds(ctl, c.info["twist"])) for c in cmds])
    turned = np.array([np.max(np.abs(c.beta - before)) for c in cmds])
    assert cmds[0].info["stop"] and cmds[0].info["events"] == 1
    stopped = int(np.argmax(speed == 0.0))  # the chassis setpoint reaches exactly 0
    assert stopped > 0 and np.all(np.diff(speed[:stopped + 1]) < 0)  # decelerating all the way
    assert np.all(turned[:stopped + 1] == 0.0)  # headings held while it stops
    assert {c.info["mode"] for c in cmds[:stopped + 1]} == {int(Mode.STOPPING)}
    # then every module turns by 90° the other way round (through 0, never past a stop) ...
    np.testing.assert_allclose(ctl.beta, np.deg2rad([-45.0, 45.0, -45.0, 45.0]), atol=1e-6)
    np.testing.assert_allclose(ctl.twist, [0.0, 0.6, 0.0])
    assert all(c.info["events"] == 1 for c in cmds)  # one stop-first sequence
    # ... while the chassis crawls: no module slips sideways faster than slip_speed
    for c in cmds[stopped:]:
        g = ctl.geom
        t = c.info["twist"]
        vx, vy = t[0] - t[2] * g.axis_xy[:, 1], t[1] + t[2] * g.axis_xy[:, 0]
        gamma = g.alpha + c.beta
        assert np.max(np.abs(vx * np.cos(gamma) + vy * np.sin(gamma))) <= SetpointConfig().slip_speed * (1 + 1e-9)


def test_unlimited_steering_reverses_the_wheels_instead_of_turning_them_round():
    """swerve: along x, then back at 170°: every module would turn by more than 90°, so the chassis
    stops and each module takes the nearer of β and β + π (a 10° turn, its wheel reversed)."""
    p = PRESETS["swerve"]
    ctl = SetpointController(p.geometry, p.limits, 0.02)
    ctl.reset(np.zeros(4), np.zeros(4))
    _drive(ctl, np.tile([2.0, 0.0, 0.0], (100, 1)))
    before, rolling = ctl.beta.copy(), np.sign(ctl.phidot)
    back = np.deg2rad(170.0)
    cmds = _drive(ctl, np.tile([2.0 * math.cos(back), 2.0 * math.sin(back), 0.0], (200, 1)))
    assert cmds[0].info["stop"]
    speed = np.array([np.max(_speeds(ctl, c.info["twist"])) for c in cmds])
    stopped = int(np.argmax(speed == 0.0))
    assert stopped > 0 and all(np.array_equal(c.beta, before) for c in cmds[:stopped + 1])
    np.testing.assert_allclose(ctl.beta - before, np.deg2rad(-10.0), atol=1e-6)  # 170° − 180°: the nearer axis
    np.testing.assert_array_equal(np.sign(ctl.phidot), -rolling)  # each wheel now rolls the other way


@pytest.mark.parametrize("preset", list(PRESETS))
def test_a_zero_command_keeps_the_headings(preset):
    p = PRESETS[preset]
    g = p.geometry
    rng = np.random.default_rng(5)
    start = _measure(g, rng.uniform(-1.2, 1.2, g.n), 0.0)
    ctl = SetpointController(g, p.limits, 0.02)
    ctl.reset(start, np.zeros(g.n))
    for cmd in _drive(ctl, np.zeros((50, 3)), rng.normal(0.0, 0.02, (50, g.n))):  # at rest
        np.testing.assert_array_equal(cmd.beta, start)
        np.testing.assert_array_equal(cmd.phidot, 0.0)
    v = 0.3 * p.limits.wheel_speed_max * float(np.min(g.r))
    _drive(ctl, np.tile([v, 0.5 * v, 0.5], (200, 1)))  # a steady turn
    held = ctl.beta.copy()
    cmds = _drive(ctl, np.zeros((100, 3)))
    assert all(np.array_equal(c.beta, held) for c in cmds)  # the turn's headings, while it stops
    np.testing.assert_array_equal(cmds[-1].phidot, 0.0)
    np.testing.assert_array_equal(ctl.twist, 0.0)


def test_braking_step_stops_at_the_goal():
    a, dt = 30.0, 0.02
    for d in (0.0, 0.005, a * dt * dt, 0.013, 0.3, 2.0):
        step = float(braking_step(d, a, dt))
        assert 0.0 <= step <= d
        rate = step / dt  # braking at a from this rate stops within the rest of the way
        assert rate * rate / (2 * a) <= d - step + 1e-12 or (d <= a * dt * dt and step == d)


# -- the compiled batch against the reference -------------------------------------------------------


class _Recorder:
    def __init__(self, monkeypatch):
        self.calls, self.batches = [], []
        rec, step, reset = self, SetpointBatch.step, SetpointBatch.reset

        def recording_step(batch, rows, twists, beta_meas):
            if batch not in rec.batches:
                rec.batches.append(batch)
            cmd = step(batch, rows, twists, beta_meas)
            rec.calls.append(("step", batch, rows, np.array(twists), np.array(beta_meas), cmd))
            return cmd

        def recording_reset(batch, rows, beta, phidot):
            rec.calls.append(("reset", batch, np.array(rows), np.array(beta), np.array(phidot)))
            return reset(batch, rows, beta, phidot)

        monkeypatch.setattr(SetpointBatch, "step", recording_step)
        monkeypatch.setattr(SetpointBatch, "reset", recording_reset)


def _check(calls, batches) -> tuple[int, int]:
    """Replay every robot's calls through its own SetpointController; (steps checked, stop steps)."""
    checked = stops = 0
    for batch in batches:
        ref = [None] * batch.num
        for call in calls:
            if call[1] is not batch:
                continue
            if call[0] == "reset":
                for k, i in enumerate(call[2]):
                    ref[i] = SetpointController(batch.geom, batch.limits, batch.dt, batch.config)
                    ref[i].reset(call[3][k], call[4][k])
                continue
            rows, twists, beta_meas, cmd = call[2:]
            idx = np.arange(batch.num) if rows is None else np.asarray(rows)
            for k, i in enumerate(idx):
                want = ref[i].step(twists[k], beta_meas[k])
                for name in ("beta", "phidot", "beta_rate", "beta_accel", "phiddot"):
                    np.testing.assert_array_equal(getattr(cmd, name)[k], getattr(want, name), err_msg=name)
                np.testing.assert_array_equal(cmd.info["twist"][k], want.info["twist"])
                np.testing.assert_array_equal(cmd.info["decoupled"][k], want.info["decoupled"])
                assert (cmd.info["s"][k], cmd.info["stop"][k], cmd.mode[k], cmd.events[k]) == \
                    (want.info["s"], want.info["stop"], want.info["mode"], want.info["events"])
                checked += 1
                stops += bool(want.info["stop"])
    return checked, stops


@pytest.mark.parametrize("robot, tracks", [("azimut3", ["strafe90", "reverse", "square"]),
                                           ("swerve", ["spin", "figure8"]), ("tri", ["icr-axis", "crab"]),
                                           ("hex", ["hold", "slalom"])])
def test_eval_episodes_bit_for_bit(monkeypatch, robot, tracks):
    from control.path_controllers import SetpointPathController
    from control.rollout import run_episodes

    rec = _Recorder(monkeypatch)
    run_episodes(SetpointPathController(), tracks, list(range(len(tracks))), max_time=6.0,
                 env_kwargs={"robot": robot})
    checked, stops = _check(rec.calls, rec.batches)
    assert checked == len(tracks) * 300
    if robot == "azimut3":
        assert stops > 0  # the stop-first path is replayed too


@pytest.mark.parametrize("preset", list(PRESETS))
def test_random_targets_bit_for_bit(preset):
    """Random targets (zero commands, reversals, spins) for a batch whose rows are stepped and reset
    in turn, against one reference per row."""
    p = PRESETS[preset]
    g = p.geometry
    rng = np.random.default_rng(11)
    batch = SetpointBatch(3, g, p.limits, 0.02, SetpointConfig(cosine_compensation=preset != "hex"))
    calls = []
    reset0 = (np.arange(3), _measure(g, rng.uniform(-3, 3, (3, g.n)), 0.0), rng.normal(0, 1, (3, g.n)))
    batch.reset(*reset0)
    calls.append(("reset", batch, *reset0))
    v = p.limits.wheel_speed_max * float(np.min(g.r))
    kinds = rng.integers(0, 4, 400)
    for j in range(400):
        rows = None if j % 5 else np.array([0, 2])
        m = 3 if rows is None else 2
        t = rng.uniform(-v, v, (m, 3)) * [1, 1, 1 / float(np.max(g.l))]
        t[kinds[j] == 0] = 0.0
        meas = _measure(g, batch.beta[rows if rows is not None else slice(None)], rng.normal(0, 0.05, (m, g.n)))
        calls.append(("step", batch, rows, t, meas, batch.step(rows, t, meas)))
        if j == 200:
            r = (np.array([1]), _measure(g, rng.uniform(-3, 3, (1, g.n)), 0.0), np.zeros((1, g.n)))
            batch.reset(*r)
            calls.append(("reset", batch, *r))
    checked, _ = _check(calls, [batch])
    assert checked == 400 * 3 - 80 * 1


# -- the registry, the CLI, bad input ----------------------------------------------------------------


def test_registered_and_run_by_azimut_eval(tmp_path):
    from jobs.cli import main

    assert "twist-setpoint" in controller_names()
    assert make_controller("twist-setpoint").name == "twist-setpoint"
    assert main(["eval", "--controllers", "twist-setpoint", "--tracks", "hold", "--max-time", "3", "--no-plots",
                 "--out", str(tmp_path)]) == 0
    row = json.loads((tmp_path / "metrics.json").read_text())["episodes"][0]
    assert row["controller"] == "twist-setpoint" and row["status"] == "ok"
    assert row["limit_violation_steps"] == 0 and np.isfinite(row["rms_lateral_m"])


@pytest.mark.parametrize("kwargs", [
    {"grid": 0}, {"iterations": -1}, {"speed_deadband": -0.1}, {"zero_twist": math.nan}, {"slip_speed": 0.0005},
    {"steer_rate_scale": 1.5}, {"wheel_accel_scale": 0.0}, {"grid": 2.5}, {"stop_hysteresis": math.inf}])
def test_the_config_refuses_bad_values(kwargs):
    with pytest.raises(ValueError, match=f"SetpointConfig.{next(iter(kwargs))}") as err:
        SetpointConfig(**kwargs)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("kwargs, match", [({"discretize": 1}, "SetpointConfig.discretize"),
                                           ({"grid": "8"}, "SetpointConfig.grid")])
def test_the_config_refuses_bad_types(kwargs, match):
    with pytest.raises(TypeError, match=match):
        SetpointConfig(**kwargs)


def test_bad_input_is_refused_before_any_change(geom, limits):
    with pytest.raises(ControllerSpecError, match="setpoint_config"):
        make_controller("twist-setpoint", setpoint_config={"grid": 4})
    with pytest.raises(TypeError, match="config"):
        SetpointController(geom, limits, 0.02, config={"grid": 4})
    batch = SetpointBatch(2, geom, limits)
    with pytest.raises(RuntimeError, match="never reset"):
        batch.step(None, np.zeros((2, 3)), np.zeros((2, geom.n)))
    batch.reset([0, 1], np.zeros((2, geom.n)), np.zeros((2, geom.n)))
    batch.step(None, np.array([[0.3, 0.0, 0.1], [0.0, 0.2, 0.0]]), np.zeros((2, geom.n)))
    before = [a.copy() for a in (batch.twist, batch.beta, batch.rate, batch.phidot)]
    with pytest.raises(ValueError, match="twist must be finite"):
        batch.step(None, np.array([[0.0, np.nan, 0.0], [0.0, 0.0, 0.0]]), np.zeros((2, geom.n)))
    with pytest.raises(ValueError, match="beta_meas must be finite"):
        batch.step([1], np.zeros((1, 3)), np.full((1, geom.n), np.inf))
    with pytest.raises(ValueError, match="shape"):
        batch.step(None, np.zeros((1, 3)), np.zeros((2, geom.n)))
    for a, b in zip(before, (batch.twist, batch.beta, batch.rate, batch.phidot)):
        np.testing.assert_array_equal(a, b)
    ref = SetpointController(geom, limits)
    with pytest.raises(ValueError, match="twist"):
        ref.step(np.array([0.0, np.inf, 0.0]), np.zeros(geom.n))
