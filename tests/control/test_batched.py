"""The batched ICR controller: N robots in one call give the same commands as N single-robot
controllers, bit for bit (the single controller is the N = 1 case of the batched code, and the
batched step never mixes rows)."""

from __future__ import annotations

import numpy as np
import pytest
from kinematic_model import KinematicRobot

from control.icr.controller import (
    ICRController,
    ICRControllerConfig,
    arc_check,
    arc_check_batch,
    icr_control_step_batch,
    initial_state_batch,
    project_off_axes,
    project_off_axes_batch,
)
from control.limits import ActuatorLimits, limit_violations
from estimation import RobotGeometry

GEOM = RobotGeometry.azimut3()
LIM = ActuatorLimits()
DT = 0.02


def _random_targets(rng, total):
    """A sequence of (λ_d, μ_d) per step, as in /tmp/stress.py: axes, grid points, stops, jumps."""
    out = []
    while len(out) < total:
        if rng.random() < 0.2:
            lam = GEOM.s_unit[rng.integers(GEOM.n)] * rng.choice([1.0, -1.0])
        elif rng.random() < 0.2:
            lam = np.array([rng.choice([0, 1, -1, 0.25, 0.5]) for _ in range(3)], float)
        else:
            lam = rng.uniform(-1, 1, 3)
        if np.linalg.norm(lam) < 1e-3:
            lam = np.array([0, 0, 1.0])
        mu = rng.choice([rng.uniform(-5, 5), 0.0, 1.0, -1.0])
        out += [(lam, mu)] * int(rng.integers(1, 40))
    return out[:total]


@pytest.mark.parametrize("config", [ICRControllerConfig(), ICRControllerConfig(coupling_from_measurement=True)])
@pytest.mark.parametrize("seed", [0, 1])
def test_batched_matches_single_robots(seed, config):
    n_robots, steps = 12, 160
    rng = np.random.default_rng(seed)
    targets = [_random_targets(rng, steps) for _ in range(n_robots)]
    kicks = rng.random((steps, n_robots)) < 0.01
    singles = [ICRController(GEOM, LIM, DT, config) for _ in range(n_robots)]
    s_robots = [KinematicRobot.at_rest(GEOM) for _ in range(n_robots)]
    b_robots = [KinematicRobot.at_rest(GEOM) for _ in range(n_robots)]
    # some robots start with their wheels out of place (RECONFIGURING from the start)
    for i in range(0, n_robots, 3):
        beta0 = rng.uniform(GEOM.steer_min + 0.1, GEOM.steer_max - 0.1, GEOM.n)
        s_robots[i].beta, b_robots[i].beta = beta0.copy(), beta0.copy()
    lam0 = np.tile([0.0, 0.0, 1.0], (n_robots, 1))
    for ctl, robot in zip(singles, s_robots):
        ctl.reset(np.array([0.0, 0.0, 1.0]), robot.beta.copy(), robot.phidot.copy())
    state = initial_state_batch(lam0, np.array([r.beta for r in b_robots]), np.array([r.phidot for r in b_robots]),
                                GEOM, config)
    modes_seen = set()
    for t in range(steps):
        lam_d = np.array([targets[i][t][0] for i in range(n_robots)])
        mu_d = np.array([targets[i][t][1] for i in range(n_robots)])
        beta_meas = np.array([r.beta for r in b_robots])
        beta_meas[kicks[t]] += 0.8  # a wheel knocked out of place
        state_prev = state
        state, cmd = icr_control_step_batch(state, state_prev.lam, state_prev.mu, beta_meas,
                                            np.array([r.phidot for r in b_robots]), lam_d, mu_d, GEOM, LIM, config, DT)
        for i, (ctl, robot) in enumerate(zip(singles, s_robots)):
            meas = robot.beta.copy()
            if kicks[t, i]:
                meas += 0.8
            one = ctl.step(ctl.state.lam, ctl.state.mu, meas, robot.phidot, lam_d[i], mu_d[i])
            for name in ("beta", "phidot", "beta_rate", "beta_accel", "phiddot"):  # bit for bit: rows independent
                np.testing.assert_array_equal(getattr(cmd, name)[i], getattr(one, name),
                                              err_msg=f"{name} t={t} robot={i}")
            assert int(cmd.info["mode"][i]) == int(one.info["mode"]), (t, i)
            assert int(cmd.info["events"][i]) == one.info["events"]
            assert not limit_violations(one.beta_rate, one.beta_accel, one.phidot, one.phiddot, LIM).any()
            modes_seen.add(int(one.info["mode"]))
            robot.step(one.beta, one.phidot, DT)
            b_robots[i].step(cmd.beta[i], cmd.phidot[i], DT)
        for i in range(n_robots):
            assert singles[i].state.mode == state.mode[i]
            np.testing.assert_array_equal(singles[i].state.lam, state.lam[i])
    assert modes_seen == {0, 1, 2}  # every mode was exercised, side by side


def test_batched_helpers_match_single():
    rng = np.random.default_rng(5)
    lam = rng.normal(size=(40, 3))
    lam_d = rng.normal(size=(40, 3))
    lam_d[:8] = GEOM.s_unit[rng.integers(GEOM.n, size=8)] + 0.01 * rng.normal(size=(8, 3))
    lam_d[8] = GEOM.s_unit[0]
    lam[8] = GEOM.s_unit[0]
    out, idx = project_off_axes_batch(lam_d, lam, GEOM, np.deg2rad(3.0))
    reason, free, theta = arc_check_batch(lam, lam_d, GEOM, np.deg2rad(3.0), np.deg2rad(0.5))
    for i in range(lam.shape[0]):
        o, k = project_off_axes(lam_d[i], lam[i], GEOM, np.deg2rad(3.0))
        assert np.array_equal(o, out[i]) and k == idx[i]
        r, f, th = arc_check(lam[i], lam_d[i], GEOM, np.deg2rad(3.0), np.deg2rad(0.5))
        assert r == (None, "stop", "axis")[reason[i]] and f == free[i] and th == theta[i]
    assert (idx >= 0).sum() >= 8 and set(reason.tolist()) >= {0, 1}


def test_batched_rejects_bad_input():
    state = initial_state_batch(np.tile([0.0, 0.0, 1.0], (2, 1)), np.zeros((2, GEOM.n)), np.zeros((2, GEOM.n)), GEOM)
    args = [state.lam, np.zeros(2), np.zeros((2, GEOM.n)), np.zeros((2, GEOM.n)), state.lam, np.ones(2)]
    cfg = ICRControllerConfig()
    icr_control_step_batch(state, *args, GEOM, LIM, cfg, DT)
    for k, bad in ((4, np.zeros((2, 3))), (1, np.array([0.0, np.nan])), (2, np.zeros((3, GEOM.n))), (5, np.ones(3))):
        a = list(args)
        a[k] = bad
        with pytest.raises(ValueError):
            icr_control_step_batch(state, *a, GEOM, LIM, cfg, DT)


def test_single_robot_state_is_a_batch_of_one():
    from control.icr.controller import ICRControllerState, Mode, icr_control_step, initial_state

    beta0 = np.array([0.3, -0.2, 0.1, 1.2])
    st = initial_state([0.0, 0.0, 1.0], beta0, np.zeros(GEOM.n), GEOM)
    assert st.batch.num == 1
    assert st.mode == Mode.RECONFIGURING and isinstance(st.mode, Mode)
    assert isinstance(st.mu, float) and isinstance(st.events, int) and isinstance(st.mode_time, float)
    np.testing.assert_array_equal(st.lam, st.batch.lam[0])
    np.testing.assert_array_equal(st.reconfig_lam, [0.0, 0.0, 1.0])
    cfg = ICRControllerConfig()
    args = ([0.0, 0.0, 1.0], 0.0, beta0, np.zeros(GEOM.n), [1.0, 0.0, 0.0], 0.5)
    one_state, one = icr_control_step(st, *args, GEOM, LIM, cfg, DT)
    b_state, b = icr_control_step_batch(st.batch, *[np.asarray(a, dtype=float)[None] for a in args], GEOM, LIM, cfg, DT)
    for name in ("beta", "phidot", "beta_rate", "beta_accel", "phiddot"):
        np.testing.assert_array_equal(getattr(one, name), getattr(b, name)[0])
    np.testing.assert_array_equal(one_state.batch.lam, b_state.lam)
    with pytest.raises(AttributeError):
        st.has_beta_meas  # noqa: B018 (the flags stay inside the batch)
    two = initial_state_batch(np.tile([0.0, 0.0, 1.0], (2, 1)), np.zeros((2, GEOM.n)), np.zeros((2, GEOM.n)), GEOM)
    with pytest.raises(ValueError):
        ICRControllerState(two)
    assert two.robot(1).batch.num == 1


def test_batch_controller_steps_any_subset_of_its_robots():
    """BatchICRController: robots reset one by one and stepped in any subset give the commands of
    the whole batch, bit for bit; a robot never reset is refused."""
    from control.icr.batch import BatchICRController

    rng = np.random.default_rng(3)
    n_robots = 5
    lam0 = np.tile([0.0, 0.0, 1.0], (n_robots, 1))
    beta0 = rng.uniform(GEOM.steer_min + 0.1, GEOM.steer_max - 0.1, (n_robots, GEOM.n))
    whole, parts = BatchICRController(n_robots, GEOM, LIM, DT), BatchICRController(n_robots, GEOM, LIM, DT)
    whole.reset(np.arange(n_robots), lam0, beta0, np.zeros((n_robots, GEOM.n)))
    with pytest.raises(RuntimeError, match="never reset"):
        parts.step(None, lam0, np.zeros(n_robots), beta0, np.zeros((n_robots, GEOM.n)), lam0, np.ones(n_robots))
    for i in range(n_robots):
        parts.reset(np.array([i]), lam0[i:i + 1], beta0[i:i + 1], np.zeros((1, GEOM.n)))
    targets = _random_targets(rng, 60)
    beta = beta0.copy()
    for t in range(60):
        lam_d = np.tile(targets[t][0], (n_robots, 1))
        mu_d = np.full(n_robots, targets[t][1])
        args = (whole.state.lam.copy(), whole.state.mu.copy(), beta, np.zeros((n_robots, GEOM.n)), lam_d, mu_d)
        cmd = whole.step(None, *args)
        rows = np.array([0, 3]) if t % 2 else np.array([1, 2, 4])
        other = np.setdiff1d(np.arange(n_robots), rows)
        for sub in (rows, other):
            part = parts.step(sub, *(a[sub] for a in args))
            np.testing.assert_array_equal(part.beta, cmd.beta[sub])
            np.testing.assert_array_equal(part.events, cmd.events[sub])
            np.testing.assert_array_equal(part.mode, cmd.mode[sub])
        beta = cmd.beta
    for name in ("lam", "mu", "beta", "mode", "events"):
        np.testing.assert_array_equal(getattr(parts.state, name), getattr(whole.state, name))
