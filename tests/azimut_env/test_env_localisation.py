"""pose_source="odometry": the observation's pose from dead reckoning (estimated H state and wheel
encoders) corrected by noisy localisation fixes; closed forms of the odometry in ``estimation``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from azimut_env.env import AzimutEnv
from azimut_env.task.localisation import LocalisationParams
from azimut_env.vector_env import AzimutVectorEnv
from estimation import (
    RobotGeometry,
    eta_from_twist,
    integrate_pose,
    odometry_twist,
    steering_from_lambda,
    twist_from_wheels,
    wheel_speeds,
)

NO_FIX = LocalisationParams(fix_period_s=math.inf, fix_noise_xy_m=0.0, fix_noise_theta_rad=0.0)


def _circle_action(env: AzimutEnv) -> np.ndarray:
    """Constant set-points of a 0.4 m/s motion with a 0.3 rad/s turn (the robot drives a circle)."""
    lam, mu = eta_from_twist(np.array([0.4, 0.0, 0.3]))
    beta = steering_from_lambda(lam, env.geometry)
    return env.action_from_setpoints(beta, wheel_speeds(lam, mu, env.geometry, beta=beta))


def _pose_errors(env: AzimutEnv, steps: int, seed: int = 0) -> np.ndarray:
    env.reset(seed=seed)
    act = _circle_action(env)
    err = []
    for _ in range(steps):
        _, _, term, _, info = env.step(act)
        d = info["pose_estimate"] - info["pose"]
        err.append(math.hypot(d[0], d[1]))
    return np.array(err)


def test_integrate_pose_is_the_exact_arc():
    tw = np.array([0.5, 0.0, 0.5])  # a circle of radius 1 m
    end = integrate_pose(np.zeros(3), tw, 2 * math.pi / 0.5)
    np.testing.assert_allclose(end, [0.0, 0.0, 2 * math.pi], atol=1e-12)
    fine = np.array([1.0, 2.0, 0.3])
    for _ in range(1000):
        fine = integrate_pose(fine, np.array([0.3, -0.2, 0.7]), 1e-3)
    np.testing.assert_allclose(integrate_pose(np.array([1.0, 2.0, 0.3]), np.array([0.3, -0.2, 0.7]), 1.0), fine,
                               atol=1e-12)
    np.testing.assert_allclose(integrate_pose(np.zeros((2, 3)), np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1e-9]]), 2.0),
                               [[2.0, 0.0, 0.0], [-2e-9, 2.0, 2e-9]], atol=1e-15)  # the arc bends left


def test_odometry_twist_matches_the_wheels_and_ignores_turning_in_place():
    geom = RobotGeometry.azimut3()
    tw = np.array([0.3, -0.2, 0.5])
    lam, mu = eta_from_twist(tw)
    beta = steering_from_lambda(lam, geom)
    rate = np.array([0.5, -1.0, 0.2, 0.8])
    phidot = wheel_speeds(lam, mu, geom, beta_rate=rate, beta=beta)
    np.testing.assert_allclose(odometry_twist(lam[None], phidot[None], beta[None], rate[None], geom)[0], tw, atol=1e-12)
    np.testing.assert_allclose(twist_from_wheels(beta, rate, phidot, geom)[0], tw, atol=1e-12)
    # wheels turned in place at rest: r φ̇ = −b β̇ (the steer-to-drive coupling) is no motion
    still = -geom.b * rate / geom.r
    np.testing.assert_allclose(odometry_twist(lam[None], still[None], beta[None], rate[None], geom), 0.0, atol=1e-12)


def test_default_pose_source_is_the_truth():
    env = AzimutEnv(track="circle")
    assert env.pose_source == "true"
    _, info = env.reset(seed=1)
    np.testing.assert_array_equal(info["pose_estimate"], info["pose"])
    np.testing.assert_array_equal(env.estimated_pose, env.true_pose)


def test_odometry_without_fixes_drifts():
    err = _pose_errors(AzimutEnv(track="circle", pose_source="odometry", localisation=NO_FIX), 600)
    assert err[0] < 1e-3  # starts from an exact fix
    assert err[-1] > 5e-3 and err[-1] > 5 * err[50]  # and grows (slip, compliance, noise)


def test_odometry_with_fixes_stays_bounded():
    loc = LocalisationParams(fix_period_s=0.2, fix_noise_xy_m=0.01, fix_noise_theta_rad=0.005)
    err = _pose_errors(AzimutEnv(track="circle", pose_source="odometry", localisation=loc), 600)
    assert err.max() < 0.06
    assert err[-100:].mean() < 0.03


def test_exact_fix_every_step_sees_what_the_truth_sees():
    loc = LocalisationParams(fix_period_s=0.02, fix_noise_xy_m=0.0, fix_noise_theta_rad=0.0)
    odo = AzimutEnv(track="circle", pose_source="odometry", localisation=loc, sensors="ideal")
    tru = AzimutEnv(track="circle", sensors="ideal")
    (oo, _), (ot, _) = odo.reset(seed=2), tru.reset(seed=2)
    sl = odo.observation_slices()
    keys = ("lateral_error", "heading_error", "lookahead")
    for _ in range(50):
        for k in keys:
            np.testing.assert_array_equal(oo[sl[k]], ot[sl[k]])
        act = _circle_action(odo)
        (oo, *_), (ot, *_) = odo.step(act), tru.step(act)


def test_odometry_is_deterministic_and_noisy_fixes_differ_by_seed():
    def run(seed):
        env = AzimutEnv(track="circle", pose_source="odometry", localisation=LocalisationParams(fix_period_s=0.1))
        obs = [env.reset(seed=seed)[0]]
        act = _circle_action(env)
        obs += [env.step(act)[0] for _ in range(60)]
        return np.array(obs)

    a, b, c = run(3), run(3), run(4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_icr_controller_completes_circle_on_odometry():
    from control.episode import episode_metrics
    from control.rollout import run_episode

    log = run_episode("icr", "circle", seed=0, env_kwargs={"pose_source": "odometry"})
    m = episode_metrics(log)
    assert m["completed"] and m["error"] is None and m["limit_violation_steps"] == 0
    assert m["rms_lateral_m"] < 0.05  # true lateral error: the fixes keep the estimate within a few cm


@pytest.mark.parametrize("kwargs", [{"pose_source": "gps"}, {"pose_source": None}, {"pose_source": 1},
                                    {"localisation": {"fix_period_s": 1.0}}])
def test_bad_pose_source_is_refused(kwargs):
    with pytest.raises((ValueError, TypeError)):
        AzimutEnv(**kwargs)
    with pytest.raises((ValueError, TypeError)):
        AzimutVectorEnv(num_envs=2, **kwargs)


@pytest.mark.parametrize("kwargs", [{"fix_period_s": 0.0}, {"fix_period_s": -1.0}, {"fix_period_s": math.nan},
                                    {"fix_noise_xy_m": -0.1}, {"fix_noise_theta_rad": math.inf},
                                    {"fix_period_s": "1"}])
def test_bad_localisation_params_are_refused(kwargs):
    with pytest.raises((ValueError, TypeError)):
        LocalisationParams(**kwargs)


def test_fix_every():
    assert LocalisationParams(fix_period_s=1.0).fix_every(0.02) == 50
    assert LocalisationParams(fix_period_s=0.001).fix_every(0.02) == 1
    assert LocalisationParams(fix_period_s=math.inf).fix_every(0.02) == 0
