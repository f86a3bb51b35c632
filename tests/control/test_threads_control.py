"""Threads (estimation/threads.py) give the same bits: the vector env, every controller and every
controller action space on 1 and 2 threads, episode by episode, with blocks of robots that split
the batch (8 robots: two blocks of 4 on 2 threads)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from azimut_env.vector_env import AzimutVectorEnv
from control import make_controller
from control.action_spaces.vector import VectorControllerAction
from control.rollout import run_episodes
from estimation.threads import max_threads

pytestmark = pytest.mark.skipif(max_threads() < 2, reason="numba's pool has one thread here")

SEEDS = list(range(8))
TRACKS = ["paper", "circle", "figure8", "square", "crab", "random", "spin", "slalom"]


def _arrays(log) -> dict[str, np.ndarray]:
    values = {f.name: getattr(log, f.name) for f in dataclasses.fields(log)}
    return {name: v for name, v in values.items() if isinstance(v, np.ndarray)}


@pytest.mark.parametrize("spec", ["icr", "twist", "twist-setpoint"])
def test_controllers_give_the_same_episodes_on_1_and_2_threads(spec):
    logs = {t: run_episodes(make_controller(spec), TRACKS, SEEDS, max_time=4.0, env_kwargs={"num_threads": t})
            for t in (1, 2)}
    for one, two in zip(logs[1], logs[2]):
        assert one.completed == two.completed and one.error == two.error and one.ret == two.ret
        a, b = _arrays(one), _arrays(two)
        assert a.keys() == b.keys() and len(a["t"]) > 50
        for name in a:
            np.testing.assert_array_equal(a[name], b[name], err_msg=f"{spec} {one.track.name}: {name}")


def _action_space_run(action: str, threads: int, steps: int = 120):
    venv = AzimutVectorEnv(num_envs=8, track="random", max_episode_steps=60, num_threads=threads,
                           autoreset_mode=AutoresetMode.SAME_STEP)
    env = VectorControllerAction(venv, action=action)
    try:
        obs, _ = env.reset(seed=5)
        rng = np.random.default_rng(1)
        out = [obs]
        for _ in range(steps):
            a = rng.uniform(-1, 1, size=env.action_space.shape).astype(np.float32)
            obs, rew, term, trunc, info = env.step(a)
            out += [obs, rew, term, trunc, info["controller_mode"]]
        return out
    finally:
        venv.close()


@pytest.mark.parametrize("action", ["residual", "icr_rate", "icr_target", "twist"])
def test_action_spaces_give_the_same_steps_on_1_and_2_threads(action):
    one, two = _action_space_run(action, 1), _action_space_run(action, 2)
    for a, b in zip(one, two):
        np.testing.assert_array_equal(a, b)


def test_the_env_and_its_controllers_share_the_thread_count():
    venv = AzimutVectorEnv(num_envs=8, num_threads=2)
    env = VectorControllerAction(venv, action="residual")
    assert venv.num_threads == venv.physics.num_threads == 2
    assert env.controller.threads == env.controller.icr.num_threads == env.controller.follower.num_threads == 2
    venv.close()
