"""The physics' boundaries: named columns (physics_layout), writes only through AzimutPhysics'
methods (checked, robot by robot), the timing hook of ``step`` and the blow-up codes."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from azimut_env.params import ChassisParams, RobotParams
from azimut_env.physics.blowup import BLOWUP_MESSAGES, BlowUp, BlowUpLimits
from azimut_env.physics.engine import AzimutPhysics, Obstacle, default_wheel_params
from azimut_env.physics.layout import CMD, CS, JS, MS, RS, RS_POSE, RS_TWIST_BODY, WP, WS
from estimation import eta_from_twist, steering_from_lambda, wheel_speeds


def _driven(n_robots=2, steps=20, **kwargs):
    phys = AzimutPhysics(n_robots=n_robots, **kwargs)
    for i in range(n_robots):
        phys.reset_robot(i, (0.3 * i, 0.0, 0.1 * i), np.full(4, 0.2 * i), twist=(0.3, 0.0, 0.2))
    phys.set_commands(np.full((n_robots, 4), 0.3), np.full((n_robots, 4), 6.0))
    for _ in range(steps):
        phys.step()
    return phys


def test_every_wheel_parameter_column_comes_from_its_parameter_class():
    p = dataclasses.replace(RobotParams(), chassis=ChassisParams(mass=40.0))
    wp = default_wheel_params(p, 3)
    assert wp.shape == (3, p.n, len(WP))
    assert np.array_equal(wp[..., WP.B], np.broadcast_to(p.geometry.b, (3, p.n)))
    assert np.all(wp[..., WP.MU] == p.tire.friction) and np.all(wp[..., WP.I_MOD] == p.steering.module_inertia)
    assert np.all(wp[..., WP.MOTOR_INERTIA] == p.steer_motor.rotor_inertia)
    assert np.allclose(wp[..., WP.LOAD].sum(axis=1), p.total_mass * p.gravity)
    assert np.all(wp[..., [WP.K_S, WP.KP, WP.I_W, WP.C_ALPHA, WP.SIGMA_LAT, WP.STEER_RATE]] > 0)


def test_summary_columns_read_the_state_by_name():
    phys = _driven()
    s = phys.summary
    assert np.array_equal(s[:, RS_POSE], phys.chassis_pose())
    th = s[:, RS.TH]
    # the body-frame velocity is the world velocity rotated by −θ
    assert np.allclose(s[:, RS.BX], np.cos(th) * s[:, RS.VX] + np.sin(th) * s[:, RS.VY])
    assert np.allclose(s[:, RS.BY], -np.sin(th) * s[:, RS.VX] + np.cos(th) * s[:, RS.VY])
    assert np.array_equal(s[:, RS_TWIST_BODY], phys.chassis_twist())
    assert np.array_equal(phys.wheel_summary[..., WS.BETA], phys.joint_state[..., JS.BETA])
    assert np.allclose(phys.wheel_summary[..., WS.BETA_DOT], phys.joint_state[..., JS.OMEGA] - s[:, RS.W, None])
    assert np.array_equal(phys.wheel_speeds(), phys.motor_state[..., MS.PHIDOT])
    assert [m.name for m in RS][: len(CS)] == [m.name for m in CS]
    assert np.all(s[:, RS.CODE] == BlowUp.NONE)


def test_set_wheel_params_one_robot_only_and_refuses_bad_rows():
    phys = _driven(steps=0)
    before = phys.wheel_params.copy()
    row = before[1].copy()
    row[:, WP.MU] *= 0.5
    phys.set_wheel_params(row, robot=1)
    assert np.array_equal(phys.wheel_params[0], before[0])
    assert np.array_equal(phys.wheel_params[1, :, WP.MU], 0.5 * before[1, :, WP.MU])
    bad = row.copy()
    bad[0, WP.K_S] = np.nan
    for args, kwargs in (((bad,), {"robot": 0}), ((row,), {"robot": 2}), ((row,), {"robot": -1}),
                         ((row[None],), {"robot": 0}), ((row,), {})):
        snapshot = phys.wheel_params.copy()
        with pytest.raises(ValueError):
            phys.set_wheel_params(*args, **kwargs)
        assert np.array_equal(phys.wheel_params, snapshot)  # refused, nothing changed


def test_set_setpoints_writes_only_the_given_rows():
    phys = _driven(n_robots=3, steps=0)
    old = phys.commands.copy()
    new = np.zeros((3, 4, len(CMD)))
    new[..., CMD.BETA] = 0.4
    new[..., CMD.PHIDOT] = -3.0
    rows = np.array([True, False, True])
    phys.set_setpoints(new, rows)
    assert np.array_equal(phys.commands[rows], new[rows]) and np.array_equal(phys.commands[1], old[1])
    phys.set_setpoints(new)
    assert np.array_equal(phys.commands, new)


@pytest.mark.parametrize("robot", [-1, 2, 1.0, True, "0"])
def test_robot_index_refused_where_it_enters(robot):
    phys = _driven(steps=0)
    state = (phys.summary.copy(), phys.joint_state.copy(), phys.body_inertia.copy())
    with pytest.raises(ValueError, match="robot index"):
        phys.reset_robot(robot, (1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="robot index"):
        phys.kick(robot, [0], 0.1)
    with pytest.raises(ValueError, match="robot index"):
        phys.set_chassis_mass(robot, 30.0)
    assert all(np.array_equal(a, b) for a, b in zip(state, (phys.summary, phys.joint_state, phys.body_inertia)))


def test_rebuild_with_obstacles_replaces_them_and_replays():
    geom = RobotParams().geometry
    lam, mu = eta_from_twist(np.array([0.8, 0.0, 0.0]))
    beta = steering_from_lambda(lam, geom)
    phidot = wheel_speeds(lam, mu, geom, beta=beta)
    phys = AzimutPhysics()
    phys.rebuild([(2.0, 0.0, 0.3)])
    assert phys.obstacles == (Obstacle(2.0, 0.0, 0.3),)
    assert len(phys.space.shapes) == 2  # the obstacle and the chassis box
    runs = []
    for obstacles in (None, None, ()):
        phys.rebuild(obstacles)
        phys.reset_robot(0, (0.0, 0.0, 0.0), beta, twist=(0.8, 0.0, 0.0))
        phys.set_commands(beta[None], phidot[None])
        for _ in range(150):
            phys.step()
        runs.append(phys.summary.copy())
    assert np.array_equal(runs[0], runs[1])
    assert runs[0][0, RS.X] < 2.0 - 0.3 < 2.0 < runs[2][0, RS.X]  # stopped by the obstacle, then free
    assert phys.obstacles == () and len(phys.space.shapes) == 0


@pytest.mark.parametrize("obstacles", [(), [(5.0, 5.0, 0.5)]])
def test_timing_hook_times_the_stages_and_changes_nothing(obstacles):
    plain, timed = (_driven(steps=0) for _ in range(2))
    for phys in (plain, timed):
        phys.set_obstacles(obstacles)
    timed.stage_times = times = {}
    for _ in range(5):
        plain.step()
        timed.step()
    assert np.array_equal(plain.summary, timed.summary)
    keys = {"read", "force", "summary"} | ({"space_step"} if obstacles else {"write"})
    assert set(times) == keys and all(v > 0 for v in times.values())
    explicit = {}
    timed.stage_times = None
    timed.step(explicit)
    assert set(explicit) == keys and set(times) == keys
    assert pickle.loads(pickle.dumps(timed)).stage_times is None


def test_blowup_codes_are_named_and_reported():
    phys = _driven(n_robots=3, steps=0, blowup=BlowUpLimits(speed=1.0))
    phys.chassis[0].velocity = (float("nan"), 0.0)
    phys.chassis[2].velocity = (3.0, 0.0)
    phys.step()
    codes = phys.summary[:, RS.CODE]
    assert [BlowUp(int(c)) for c in codes] == [BlowUp.NON_FINITE, BlowUp.NONE, BlowUp.SPEED]
    ok, reasons = phys.check()
    assert ok.tolist() == [False, True, False]
    assert reasons == [BLOWUP_MESSAGES[BlowUp.NON_FINITE], "", BLOWUP_MESSAGES[BlowUp.SPEED]]
    assert set(BLOWUP_MESSAGES) == set(BlowUp) - {BlowUp.NONE}
