"""The vector env on several threads (estimation/threads.py): the same bits as on one, on every
path a step takes (the compiled substeps, pymunk's contacts with obstacles, the odometry pose
source's Python stage between compiled stages, resets of a few robots, kicks, domain
randomisation), and its thread count checked where it enters."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from azimut_env.env import AzimutEnv
from azimut_env.vector_env import AzimutVectorEnv
from estimation.threads import max_threads

two_threads = pytest.mark.skipif(max_threads() < 2, reason="numba's pool has one thread here")

CASES = {
    "default": {},
    "obstacles": {"obstacles": [(1.0, 0.4, 0.25), (-0.5, -1.0, 0.3)]},
    "odometry": {"pose_source": "odometry", "domain_randomization": 0.2},
    "swerve": {"robot": "swerve", "track": "random"},
    "hex, latency": {"robot": "hex", "action_latency": 2},
}


def _run(threads: int, kwargs: dict, steps: int = 150):
    kw = {"track": "figure8", **kwargs}
    venv = AzimutVectorEnv(num_envs=9, num_threads=threads, max_episode_steps=50,
                           autoreset_mode=AutoresetMode.SAME_STEP, **kw)
    try:
        kick = {"kick": {"step": 5, "wheels": [0, 1], "impulse": 0.4}}
        obs, info = venv.reset(seed=11, options=[kick if i % 3 == 0 else None for i in range(9)])
        rng = np.random.default_rng(2)
        out = [obs, info["eta_hat"][0], info["pose_estimate"]]
        for _ in range(steps):
            obs, rew, term, trunc, info = venv.step(rng.uniform(-1, 1, venv.action_space.shape).astype(np.float32))
            out += [obs, rew, term, trunc, info["eta_hat"][0], info["eta_hat"][1], info["slip_power"],
                    info["tire_forces"], info["pose_estimate"], venv.physics.summary.copy()]
        return out
    finally:
        venv.close()


@two_threads
@pytest.mark.parametrize("case", list(CASES))
def test_the_vector_env_gives_the_same_bits_on_1_and_2_threads(case):
    one, two = _run(1, CASES[case]), _run(2, CASES[case])
    for a, b in zip(one, two):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("bad", [0, -2, max_threads() + 1, 1.5, True, "2"])
def test_a_bad_thread_count_is_refused_by_name(bad):
    kind = (TypeError, ValueError)
    with pytest.raises(kind, match="num_threads"):
        AzimutVectorEnv(num_envs=2, num_threads=bad)
    with pytest.raises(kind, match="num_threads"):
        AzimutEnv(num_threads=bad)


def test_the_thread_count_is_the_envs_and_defaults_to_the_cores():
    from estimation.threads import default_threads

    venv = AzimutVectorEnv(num_envs=8)
    assert venv.num_threads == default_threads() and venv.task.config.num_threads is None
    venv.close()
    assert AzimutVectorEnv(num_envs=8, num_threads=1).num_threads == 1
    assert AzimutEnv(num_threads=max_threads()).num_threads == 1  # one robot: one thread, as it says
