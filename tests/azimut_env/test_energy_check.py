"""The blow-up detector's energy check (issue 20): physics forced past its stability bound gains
energy step after step with every state within the other limits; the check reports it
(BlowUp.ENERGY) within its window, and never fires on the presets under bang-bang commands, kicks
and obstacle contacts. The compiled energy is the NumPy reference's."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from azimut_env.env import AzimutEnv
from azimut_env.imperfections import with_imperfections
from azimut_env.params import ChassisParams, RobotParams
from azimut_env.physics.blowup import BLOWUP_MESSAGES, BlowUp, BlowUpLimits
from azimut_env.physics.energy_check import energy_kernel
from azimut_env.physics.engine import AzimutPhysics
from azimut_env.physics.layout import RS, WP
from estimation import eta_from_twist, steering_from_lambda, wheel_speeds


def _forced(factor: float, steps: int = 200, limits: BlowUpLimits | None = None):
    """The default robot with its module inertia scaled by ``factor`` (the series spring's ω·dt is
    0.137/√factor against the bound 0.5 that construction enforces), driving straight with every
    wheel commanded 0.3 rad off: (steps run, codes of the last step, energy before, energy after)."""
    p = RobotParams()
    phys = AzimutPhysics(p, blowup=limits)
    wp = phys.wheel_params.copy()
    wp[..., WP.I_MOD] *= factor
    phys.set_wheel_params(wp)  # set_wheel_params does not re-check the stability budget
    lam, mu = eta_from_twist(np.array([0.3, 0.0, 0.0]))
    beta = steering_from_lambda(lam, p.geometry)
    phys.reset_robot(0, (0.0, 0.0, 0.0), beta, (0.3, 0.0, 0.0))
    phys.set_commands(beta[None] + 0.3, wheel_speeds(lam, mu, p.geometry, beta=beta)[None])
    e0 = phys.energy()[0]
    for k in range(steps):
        phys.step()
        if not phys.check()[0][0]:
            return k + 1, phys.summary[:, RS.CODE].copy(), e0, phys.energy()[0]
    return steps, phys.summary[:, RS.CODE].copy(), e0, phys.energy()[0]


@pytest.mark.parametrize("factor", [0.03, 0.02])
def test_physics_past_its_stability_bound_is_a_blow_up(factor):
    steps, codes, e0, e1 = _forced(factor)
    assert codes[0] == BlowUp.ENERGY and steps == BlowUpLimits().energy_window  # flagged as soon as the window is full
    assert e1 > 3 * e0  # it was gaining energy: 2.4 J to 10-13 J in 0.5 s, below every other limit


def test_within_the_bound_no_energy_code():
    steps, codes, e0, e1 = _forced(1.0, steps=300)
    assert steps == 300 and codes[0] == BlowUp.NONE and abs(e1 - e0) < 0.1


def test_the_env_reports_the_blow_up():
    env = AzimutEnv(track="circle", imperfections="ideal")
    env.reset(seed=0)
    phys = env.unwrapped.physics
    wp = phys.wheel_params.copy()
    wp[..., WP.I_MOD] *= 0.02
    phys.set_wheel_params(wp)
    rng = np.random.default_rng(0)
    for _ in range(100):
        _, reward, terminated, _, info = env.step(rng.uniform(-1, 1, 8).astype(np.float32))
        if terminated:
            break
    assert terminated and info["error"] == BLOWUP_MESSAGES[BlowUp.ENERGY]
    env.close()


_PRESETS = {"ideal": RobotParams(), "paper": with_imperfections(RobotParams(), "paper"),
            "swerve": RobotParams.preset("swerve"), "tri": RobotParams.preset("tri"),
            "hex": RobotParams.preset("hex"),
            "load transfer": dataclasses.replace(RobotParams(), chassis=ChassisParams(com_height=0.2))}


@pytest.mark.parametrize("name", sorted(_PRESETS))
def test_no_false_alarm_under_bang_bang_kicks_and_contacts(name):
    """Bang-bang steering and wheel commands every 5 steps, ±3 N·m·s kicks on every module every 40
    steps (a wheel spun past its motor's torque limit: the largest one-step gains of the balance),
    random commands in between, and an obstacle in the way."""
    p = _PRESETS[name]
    lim = p.limits
    phys = AzimutPhysics(p, n_robots=2)
    phys.set_obstacles([(1.0, 0.0, 0.3)])
    phys.reset_robot(1, (0.0, 3.0, 0.0))
    rng = np.random.default_rng(7)
    lo = lim.steer_min if np.isfinite(lim.steer_min) else -3.0
    hi = lim.steer_max if np.isfinite(lim.steer_max) else 3.0
    for j in range(400):
        if j % 5 == 0:
            phys.set_commands(rng.choice([lo, hi], size=(2, p.n)),
                              rng.choice([-1.0, 1.0], size=(2, p.n)) * lim.wheel_speed_max)
        elif j % 5 == 3:
            phys.set_commands(rng.uniform(lo, hi, (2, p.n)), rng.uniform(-1, 1, (2, p.n)) * lim.wheel_speed_max)
        if j % 40 == 20:
            for i in range(2):
                phys.kick(i, list(range(p.n)), float(rng.choice([-3.0, 3.0])))
        phys.step()
        ok, reasons = phys.check()
        assert ok.all(), (j, reasons)


@pytest.mark.parametrize("name", sorted(_PRESETS))
def test_compiled_energy_is_the_reference(name):
    p = _PRESETS[name]
    phys = AzimutPhysics(p, n_robots=3)
    rng = np.random.default_rng(3)
    for _ in range(40):
        phys.set_commands(rng.uniform(-1.2, 1.2, (3, p.n)), rng.uniform(-15, 15, (3, p.n)))
        phys.step()
    out = np.empty(3)
    energy_kernel(phys._state, phys.body_inertia, phys.joint_state, phys.motor_state, phys.tire_state,
                  phys.wheel_params, phys._axis_xy, phys._load_transfer, float(p.chassis.com_height),
                  phys.chassis_accel, out, 0, 3)
    np.testing.assert_allclose(out, phys.energy(), rtol=1e-12)


def test_the_check_survives_pickling_and_resets_with_the_robot():
    phys = AzimutPhysics()
    for _ in range(10):
        phys.step()
    copy = pickle.loads(pickle.dumps(phys))
    assert copy._energy_check.filled[0] == 10 and np.array_equal(copy._energy_check.hist, phys._energy_check.hist)
    phys.reset_robot(0)
    assert phys._energy_check.filled[0] == 0


@pytest.mark.parametrize("bad", [{"energy_window": 1}, {"energy_window": 2.5}, {"energy_window": True},
                                 {"energy_gain": float("nan")}, {"energy_gain": 0.0}, {"energy_gain": "1"}])
def test_energy_limits_are_checked(bad):
    with pytest.raises((ValueError, TypeError), match="BlowUpLimits.energy_"):
        BlowUpLimits(**bad)


def test_a_shorter_window_flags_sooner():
    steps, codes, _, _ = _forced(0.02, limits=BlowUpLimits(energy_window=10))
    assert codes[0] == BlowUp.ENERGY and steps == 10


@settings(max_examples=40, deadline=None, derandomize=True)
@given(inertia=st.floats(0.004, 1.0), stiffness=st.floats(1.0, 60.0), tire=st.floats(1.0, 20.0),
       offset=st.floats(-0.5, 0.5), speed=st.floats(0.0, 1.0))
def test_forced_physics_never_gains_energy_silently(inertia, stiffness, tire, offset, speed):
    """Any substep past its bound (module inertia down, spring and tire stiffnesses up: the modes
    the budget bounds) either stays bounded or ends with a blow-up code: never a run whose energy
    keeps growing with every code clear."""
    p = RobotParams()
    phys = AzimutPhysics(p)
    wp = phys.wheel_params.copy()
    wp[..., WP.I_MOD] *= inertia
    wp[..., WP.K_S] *= stiffness
    wp[..., WP.C_KAPPA] *= tire
    wp[..., WP.C_ALPHA] *= tire
    phys.set_wheel_params(wp)
    lam, mu = eta_from_twist(np.array([speed, 0.0, 0.0]))
    beta = steering_from_lambda(lam, p.geometry)
    phys.reset_robot(0, (0.0, 0.0, 0.0), beta, (speed, 0.0, 0.0))
    phys.set_commands(beta[None] + offset, wheel_speeds(lam, mu, p.geometry, beta=beta)[None])
    energies = []
    for _ in range(200):
        phys.step()
        if not phys.check()[0][0]:
            return  # reported
        energies.append(phys.energy()[0])
    assert energies[-1] < 3.0 * max(energies[:25]) + 2.0, (energies[0], max(energies[:25]), energies[-1])
