"""Controller action spaces under an untrained (uniformly random) policy: they must explore.

500 steps of uniform random actions on 4 robots: the robots travel (path length of the chassis
centre), at most 20% of the steps are spent stopping/reconfiguring, and no command exceeds an
actuator limit. For comparison, raw set-points travel 0.56–0.87 m in 500 random steps.
"""

from __future__ import annotations

import numpy as np
import pytest

from azimut_env.vector_env import AzimutVectorEnv
from control.icr_controller import Mode
from control.vector_wrappers import VectorControllerAction


def _random_rollout(kind: str, track: str, steps: int = 500, n: int = 4, seed: int = 1):
    venv = VectorControllerAction(AzimutVectorEnv(num_envs=n, track=track, max_episode_steps=None,
                                                  max_lateral_error=100.0), action=kind)
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
    return path, reconf / steps, exceeded


@pytest.mark.parametrize("kind,track,min_path", [("residual", "circle", 1.0), ("icr_rate", "circle", 1.0),
                                                 ("icr_rate", "paper", 0.5), ("icr_target", "circle", 0.5),
                                                 ("twist", "paper", 0.5)])
def test_random_actions_explore(kind, track, min_path):
    path, reconf, exceeded = _random_rollout(kind, track)
    assert exceeded == 0
    assert np.all(reconf <= 0.2), reconf
    assert path.mean() >= min_path and path.min() > 0.2, path


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
    """Sub-env 0 with zero residual follows the same trajectory as ``azimut eval``'s ICR run."""
    from control.episode import run_episode

    log = run_episode("icr", "circle", seed=5, max_time=2.0)
    venv = VectorControllerAction(AzimutVectorEnv(num_envs=1, track="circle", max_episode_steps=None), action="residual")
    venv.reset(seed=5)
    poses = []
    for _ in range(len(log.t)):
        _, _, _, _, info = venv.step(np.zeros((1, 3)))
        poses.append(info["pose"][0])
    np.testing.assert_allclose(np.array(poses), log.pose, atol=1e-9)
