"""Controller action spaces under an untrained (uniformly random) policy: they must explore.

500 steps of uniform random actions on 8 robots (sub-env seeds 1–8): no step exceeds an actuator
limit, at most 20% of the steps are spent stopping/reconfiguring (``circle``; on ``paper`` the
reference itself stops at the start and corners, see the residual test below), and the robots
travel (path length of the chassis centre, per robot):

* ``residual``: ≥ 1 m each (4.6–4.7 m on ``circle``).
* ``twist`` (through the ICR controller, shaped): ≥ 1 m each on ``circle`` and ``paper``.
* ``icr_target`` (shaped, μ_d ≥ 0 and λ_d the direction of motion, the default): ≥ 1 m each
  (2.0–4.7 m on ``circle`` and ``paper``, seeds 1 and 2). With ``signed_mu=True`` (λ_d ∈ Λ,
  μ_d ∈ [−1, 1] m/s, the nearer representative taken) it travels only 0.53–1.17 m: the sign of
  μ_d flips at random, so μ is a mean-reverting walk whose size the wheels' acceleration limit
  sets (E|μ| ≈ 0.14 m/s), as the last test here pins.
* ``icr_rate``: ≥ 1 m on average; μ_d is the integral of the random μ rate, a random walk from
  rest, so some robots move less (0.75–3.1 m with seed 1; 0.36–3.2 m over seeds 1 and 2).

For comparison, raw set-points travel 0.56–0.87 m in 500 random steps.
"""

from __future__ import annotations

import numpy as np
import pytest

from azimut_env.vector_env import AzimutVectorEnv
from control.action_spaces.vector import VectorControllerAction
from control.icr.controller import Mode


def _random_rollout(kind: str, track: str, steps: int = 500, n: int = 8, seed: int = 1, **kwargs):
    venv = VectorControllerAction(AzimutVectorEnv(num_envs=n, track=track, max_episode_steps=None,
                                                  max_lateral_error=100.0), action=kind, **kwargs)
    venv.reset(seed=seed)
    rng = np.random.default_rng(seed)
    pose0 = venv.unwrapped.true_pose
    path, reconf, exceeded = np.zeros(n), np.zeros(n), 0
    for _ in range(steps):
        _, _, term, _, info = venv.step(rng.uniform(-1, 1, venv.action_space.shape))
        assert not term.any()
        pose = venv.unwrapped.true_pose
        path += np.linalg.norm(pose[:, :2] - pose0[:, :2], axis=1)
        pose0 = pose
        reconf += info["controller_mode"] != Mode.RUNNING
        exceeded += int(info["limit_exceeded"].sum())
        assert np.all(np.isfinite(info["mu_lag"]) & (info["mu_lag"] >= 0))  # why the robot lags its target
    venv.close()
    return path, reconf / steps, exceeded


# (action, track, least mean path [m], least path of each robot [m]); see the module docstring
CASES = [("residual", "circle", 1.0, 1.0), ("twist", "circle", 1.0, 1.0), ("twist", "paper", 1.0, 1.0),
         ("icr_target", "circle", 1.0, 1.0), ("icr_target", "paper", 1.0, 1.0), ("icr_rate", "circle", 1.0, 0.75),
         ("icr_rate", "paper", 1.0, 0.6)]


@pytest.mark.parametrize("kind,track,mean_path,min_path", CASES)
def test_random_actions_explore(kind, track, mean_path, min_path):
    path, reconf, exceeded = _random_rollout(kind, track)
    assert exceeded == 0
    assert np.all(reconf <= 0.2), reconf
    assert path.mean() >= mean_path and path.min() >= min_path, path


def test_residual_zero_action_is_the_reference_and_random_residual_adds_no_stops():
    """The residual's zero action reconfigures exactly as the reference controller (paper track:
    start and corners), and random residuals add few stops of their own."""
    venv = VectorControllerAction(AzimutVectorEnv(num_envs=2, track="paper", max_episode_steps=None), action="residual")
    venv.reset(seed=3)
    modes_zero = []
    for _ in range(300):
        _, _, _, _, info = venv.step(np.zeros((2, 3)))
        modes_zero.append(info["controller_mode"] != Mode.RUNNING)
    _, rand, exceeded = _random_rollout("residual", "paper", steps=300, n=2, seed=3)
    assert exceeded == 0
    assert np.all(rand <= np.mean(modes_zero, axis=0) + 0.15)


def test_residual_zero_action_matches_azimut_eval_reference():
    """Sub-env 0 with zero residual follows the same trajectory as ``azimut eval``'s ICR run
    without its look-ahead (the residual corrects the controller of a target of the moment)."""
    from control.path_controllers import ICRPathController
    from control.rollout import run_episode

    log = run_episode(ICRPathController(lookahead=None), "circle", seed=5, max_time=2.0)
    venv = VectorControllerAction(AzimutVectorEnv(num_envs=1, track="circle", max_episode_steps=None),
                                  action="residual")
    venv.reset(seed=5)
    poses = []
    for _ in range(len(log.t)):
        _, _, _, _, info = venv.step(np.zeros((1, 3)))
        poses.append(info["pose"][0])
    np.testing.assert_allclose(np.array(poses), log.pose, atol=1e-9)


def test_residual_follows_the_estimated_pose_as_azimut_eval_does():
    """The residual's path follower reads the pose the observation was computed from, as every
    controller does (the true pose is for evaluation only): with odometry, the zero residual still
    follows ``azimut eval``'s ICR run (which steered on the true pose before, and drifted apart)."""
    from control.path_controllers import ICRPathController
    from control.rollout import run_episode

    kwargs = dict(pose_source="odometry")
    log = run_episode(ICRPathController(lookahead=None), "circle", seed=5, max_time=2.0, env_kwargs=kwargs)
    venv = VectorControllerAction(AzimutVectorEnv(num_envs=1, track="circle", max_episode_steps=None, **kwargs),
                                  action="residual")
    venv.reset(seed=5)
    poses = [venv.step(np.zeros((1, 3)))[4]["pose"][0] for _ in range(len(log.t))]
    assert not np.array_equal(venv.unwrapped.estimated_pose, venv.unwrapped.true_pose)  # odometry drifted
    np.testing.assert_allclose(np.array(poses), log.pose, atol=1e-9)


def test_signed_icr_targets_barely_move_under_random_actions():
    """Why ``icr_target`` defaults to μ_d ≥ 0: with a signed μ_d (and the nearer representative of
    ±λ_d) random actions leave the robots within about 1 m in 500 steps, against ≥ 1 m each
    (2–4.7 m measured) unsigned, with no more stops and no limit exceeded either way."""
    signed, reconf, exceeded = _random_rollout("icr_target", "circle", n=4, signed_mu=True)
    unsigned, reconf_u, exceeded_u = _random_rollout("icr_target", "circle", n=4)
    assert exceeded == exceeded_u == 0 and np.all(reconf <= 0.2) and np.all(reconf_u <= 0.2)
    assert signed.mean() < 1.3 and unsigned.min() > 2.0 * signed.mean(), (signed, unsigned)
