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


def test_split_infos_are_python_scalars_equal_to_each_element():
    env = AzimutSB3VecEnv(num_envs=3)
    env.seed(2)
    env.reset()
    _, _, _, infos = env.step(np.full((3, 8), 0.3, dtype=np.float32))
    for key in ("progress", "lateral_error", "slip_power", "antagonism", "nullspace_force", "off_track", "stalled"):
        for i in range(3):
            value = infos[i][key]
            assert type(value) in (float, bool, int), (key, type(value))
    assert infos[0]["TimeLimit.truncated"] is False
    info = {"progress": np.array([0.5, 1.0, 2.0]), "finished": np.array([True, False, True])}
    split = env._split_info(info)
    for i in range(3):
        assert split[i] == {"progress": info["progress"][i].item(), "finished": info["finished"][i].item()}
        assert type(split[i]["finished"]) is bool and type(split[i]["progress"]) is float


def test_sb3_ppo_learns_a_few_hundred_steps():
    env = VecMonitor(AzimutSB3VecEnv(num_envs=4, max_episode_steps=40))
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=512)
    assert model.num_timesteps >= 512
