"""Every controller on every robot preset: the ICR controller and the twist baseline complete
``circle``, the renderer draws each robot, and unlimited steering never crosses a stop."""

import numpy as np
import pytest

from azimut_env.params import RobotParams
from azimut_env.robot_file import PRESET_NAMES
from control.episode import episode_metrics
from control.rollout import run_episode
from control.twist.wpilib import optimize_module
from estimation.geometry import RobotGeometry


@pytest.mark.parametrize("robot", PRESET_NAMES)
@pytest.mark.parametrize("controller", ["icr", "twist"])
def test_each_preset_completes_circle(robot, controller):
    log = run_episode(controller, "circle", seed=0, env_kwargs={"robot": robot})
    m = episode_metrics(log)
    assert m["completed"] and log.error is None, (robot, controller, log.error)
    assert m["max_lateral_m"] < 0.05
    if controller == "icr":
        assert m["limit_violation_steps"] == 0
    if RobotParams.preset(robot).geometry.unlimited_steering:
        # no stop: the commands move continuously (no jump of ~π between steps)
        step = np.abs(np.diff(log.beta_cmd, axis=0))
        bound = RobotParams.preset(robot).limits.steer_rate_max * log.dt * 1.001 if controller == "icr" else np.pi / 2
        assert step.max() < bound


@pytest.mark.parametrize("robot", PRESET_NAMES)
def test_renderer_draws_each_preset(robot):
    pytest.importorskip("pygame")
    from azimut_env.env import AzimutEnv

    env = AzimutEnv(track="circle", robot=robot, render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(3):
        env.step(env.action_space.sample() * 0)
    img = env.render()
    assert img.ndim == 3 and img.shape[2] == 3 and img.std() > 0
    env.close()


def test_optimize_unlimited_takes_the_nearer_axis_past_pi():
    g = RobotGeometry.regular(4, unlimited_steering=True)
    rng = np.random.default_rng(0)
    for _ in range(200):
        beta_des = rng.uniform(-np.pi, np.pi, 4)
        now = rng.uniform(-8.0, 8.0, 4)  # any turn of the module
        speed = rng.uniform(-1, 1, 4)
        beta, sp = optimize_module(beta_des, speed, now, g)
        assert np.all(np.abs(beta - now) <= np.pi / 2 + 1e-12)
        # the same wheel velocity vector: speed (cos, sin) unchanged
        np.testing.assert_allclose(sp * np.cos(beta), speed * np.cos(beta_des), atol=1e-12)
        np.testing.assert_allclose(sp * np.sin(beta), speed * np.sin(beta_des), atol=1e-12)
    # limited: flipped back into the range
    lim = RobotGeometry.azimut3()
    beta, _ = optimize_module(np.full(4, 2.0), np.ones(4), np.full(4, 1.5), lim)
    assert np.all((beta > lim.steer_min) & (beta <= lim.steer_max))
