"""Unlimited steering in the simulator (the swerve preset): no stops, the short way to a
set-point, the joint angle kept in ]−π, π] with a continuous motion, encoders modulo 2π."""

import numpy as np
import pytest

from azimut_env.env import AzimutEnv
from azimut_env.params import RobotParams, action_from_setpoints, setpoints_from_action
from azimut_env.physics.engine import WP, AzimutPhysics


@pytest.fixture(scope="module")
def swerve():
    return RobotParams.preset("swerve")


def _drive(phys, beta_cmd, steps, phidot=0.0):
    betas = []
    for _ in range(steps):
        phys.set_commands(np.full((1, phys.n), beta_cmd), np.full((1, phys.n), phidot))
        phys.step()
        betas.append(phys.steering_angles()[0].copy())
    return np.array(betas)


def test_the_short_way_across_pi_and_no_stop(swerve):
    phys = AzimutPhysics(swerve)
    phys.reset_robot(0, beta=np.full(4, np.deg2rad(170.0)))
    betas = _drive(phys, np.deg2rad(-170.0), 40)
    # 20° the short way (through ±180°), not 340° the long way
    travel = np.abs(np.angle(np.exp(1j * np.diff(betas, axis=0)))).sum(axis=0)
    assert np.all(travel < np.deg2rad(25.0))
    assert np.allclose(np.angle(np.exp(1j * (betas[-1] - np.deg2rad(-170.0)))), 0.0, atol=np.deg2rad(1.0))
    assert np.all(betas > -np.pi) and np.all(betas <= np.pi)


def test_whole_turns_without_stops_and_a_continuous_rate(swerve):
    phys = AzimutPhysics(swerve)
    phys.reset_robot(0)
    rates = []
    for target in np.deg2rad(np.arange(60.0, 60.0 * 13, 60.0)):  # two whole turns, 60° at a time
        for _ in range(10):
            phys.set_commands(np.full((1, 4), target), np.zeros((1, 4)))
            phys.step()
            rates.append(phys.steering_rates()[0].copy())
    _drive(phys, np.deg2rad(720.0), 30)  # settle
    beta = phys.steering_angles()[0]
    assert np.allclose(np.angle(np.exp(1j * (beta - np.deg2rad(720.0)))), 0.0, atol=np.deg2rad(1.0))
    rates = np.array(rates)
    assert np.all(rates >= -1e-6)  # turning one way all along: the wrap of β is not a jump of β̇
    assert np.max(rates) <= swerve.limits.steer_rate_max * 1.2
    spring = phys.motor_angles()[0] - beta  # the spring's twist stays small (θ_m shifted with β)
    assert np.all(np.abs(spring) < 0.1)


def test_limited_robot_keeps_its_stops():
    phys = AzimutPhysics(RobotParams())
    phys.reset_robot(0)
    betas = _drive(phys, np.pi, 60)
    assert betas.max() <= np.pi / 2 + 1e-12


def test_action_map_covers_every_angle_once(swerve):
    lim = swerve.limits
    a = action_from_setpoints(np.array([np.pi, -np.pi, 3 * np.pi / 2, 0.3]), np.zeros(4), lim)
    np.testing.assert_allclose(a[:4], [1.0, 1.0, -0.5, 0.3 / np.pi], atol=1e-7)
    beta, _ = setpoints_from_action(np.array([-1.0, 1.0, 0.5, 0, 0, 0, 0, 0]), lim, 4)
    np.testing.assert_allclose(beta, [-np.pi, np.pi, np.pi / 2, 0.0])


def test_env_measures_angles_modulo_two_pi_and_randomises(swerve):
    env = AzimutEnv(track="circle", robot="swerve", domain_randomization=0.2)
    env.reset(seed=1)
    assert np.all(np.isinf(env.physics.wheel_params[..., [WP.STEER_MIN, WP.STEER_MAX]]))
    for _ in range(60):
        env.step(env.action_from_setpoints(np.full(4, 3.1), np.full(4, 5.0)))
    b = env.measured_beta
    assert np.all(b > -np.pi) and np.all(b <= np.pi)
    assert np.all(np.abs(np.angle(np.exp(1j * (b - 3.1)))) < 0.05)


def test_unlimited_env_is_deterministic_and_vector_matches_single():
    from azimut_env.vector_env import AzimutVectorEnv

    env = AzimutEnv(track="circle", robot="swerve")
    venv = AzimutVectorEnv(2, track="circle", robot="swerve")
    o1, _ = env.reset(seed=3)
    ov, _ = venv.reset(seed=[3, 4])
    np.testing.assert_array_equal(o1, ov[0])
    rng = np.random.default_rng(0)
    for _ in range(30):
        a = rng.uniform(-1, 1, size=8).astype(np.float32)
        o1, r1, *_ = env.step(a)
        ov, rv, *_ = venv.step(np.stack([a, a]))
        np.testing.assert_array_equal(o1, ov[0])
        assert r1 == rv[0]
