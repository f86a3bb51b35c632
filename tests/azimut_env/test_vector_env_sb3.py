"""The SB3 VecEnv adapter: SB3's auto-reset semantics and a short PPO run, in-process."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.vec_env import VecMonitor  # noqa: E402

from azimut_env.vector_env import AzimutVectorEnv  # noqa: E402
from train.sb3_vec_env import AzimutSB3VecEnv  # noqa: E402


def test_sb3_semantics_terminal_observation_and_time_limit():
    env = AzimutSB3VecEnv(num_envs=3, max_episode_steps=4)
    env.seed(5)
    obs = env.reset()
    assert obs.shape == (3, env.observation_space.shape[0]) and obs.dtype == np.float32
    act = np.zeros((3, 8), dtype=np.float32)
    for _ in range(3):
        obs, rew, dones, infos = env.step(act)
        assert not dones.any() and rew.dtype == np.float32 and len(infos) == 3
    obs, rew, dones, infos = env.step(act)
    assert dones.all()
    for i in range(3):
        assert infos[i]["TimeLimit.truncated"] is True
        term = infos[i]["terminal_observation"]
        assert term.shape == obs[i].shape and not np.array_equal(term, obs[i])
    obs, rew, dones, infos = env.step(act)
    assert not dones.any() and "terminal_observation" not in infos[0]
    assert env.get_attr("num_envs") == [3, 3, 3]
    with pytest.raises(ValueError, match="SAME_STEP"):
        AzimutSB3VecEnv(venv=AzimutVectorEnv(num_envs=2))


def test_sb3_ppo_learns_a_few_hundred_steps():
    env = VecMonitor(AzimutSB3VecEnv(num_envs=4, max_episode_steps=40))
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=512)
    assert model.num_timesteps >= 512
