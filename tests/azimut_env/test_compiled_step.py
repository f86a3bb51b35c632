"""The pipeline of stages after the physics compiled (``azimut_env.task.pipeline``) against the
same stage functions run as plain Python (``AzimutTask.jit = False``: their ``py_func``, the
reference): the same observations, rewards, flags and info, bit for bit, single env and vector
env, with resets, autoresets, stalls, latency, obstacles, odometry, other robots and reward weights."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from azimut_env.env import AzimutEnv
from azimut_env.vector_env import AzimutVectorEnv


def _same(a, b, where: str) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, tuple):
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{where}[{k}]")
    elif isinstance(a, str) or a is None:
        assert a == b, where
    elif isinstance(a, np.ndarray) and a.dtype == object:
        assert isinstance(b, np.ndarray) and a.shape == b.shape, where
        for k, (x, y) in enumerate(zip(a.ravel(), b.ravel())):
            _same(x, y, f"{where}[{k}]")
    else:
        assert np.array_equal(a, b, equal_nan=True), f"{where}: {a!r} != {b!r}"
        assert np.asarray(a).dtype == np.asarray(b).dtype, where


CONFIGS = [
    {},
    {"track": "random", "robot": "swerve", "stall_time": 0.4, "stall_distance": 0.3},
    {"track": "circle", "robot": "tri", "action_latency": 2, "lookahead_count": 3, "noise_scale": 2.0},
    {"track": "square", "reward_weights": {"progress": 1.0, "slip": 0.5}, "domain_randomization": 0.3,
     "max_lateral_error": 0.05},
    {"track": "crab", "obstacles": [(1.0, 0.6, 0.2)], "imperfections": "paper"},
    {"track": "figure8", "pose_source": "odometry", "robot": "hex"},
]


@pytest.mark.parametrize("config", CONFIGS)
def test_single_env_compiled_step_equals_the_stages(config):
    envs = [AzimutEnv(**config) for _ in range(2)]
    envs[1].task.jit = False
    rng = np.random.default_rng(1)
    outs = [e.reset(seed=5) for e in envs]
    _same(outs[0], outs[1], "reset")
    ends = 0
    for k in range(300):
        a = rng.uniform(-1, 1, envs[0].action_space.shape).astype(np.float32) * (0.0 if k % 97 < 30 else 0.6)
        outs = [e.step(a) for e in envs]
        _same(outs[0], outs[1], f"step {k}")
        if outs[0][2] or outs[0][3]:
            ends += 1
            outs = [e.reset(seed=k) for e in envs]
            _same(outs[0], outs[1], f"reset {k}")
    assert envs[0].task.pipelines()[0].jit and not envs[1].task.pipelines()[0].jit
    if "stall_time" in config:
        assert ends > 0  # stalls ended episodes (the penalty path)


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_vector_env_compiled_step_equals_the_stages(mode):
    envs = [AzimutVectorEnv(num_envs=4, track="random", autoreset_mode=mode, max_episode_steps=60, stall_time=0.3,
                            stall_distance=0.2) for _ in range(2)]
    envs[1].task.jit = False
    rng = np.random.default_rng(2)
    outs = [e.reset(seed=11) for e in envs]
    _same(outs[0], outs[1], "reset")
    for k in range(200):  # autoresets: some steps step a subset of the robots (the stages one by one)
        a = rng.uniform(-1, 1, envs[0].action_space.shape).astype(np.float32) * 0.5
        outs = [e.step(a) for e in envs]
        _same(outs[0], outs[1], f"step {k}")
    for e in envs:
        e.close()


def test_compiled_step_rebuilt_after_pickling():
    import pickle

    env = AzimutEnv(track="figure8")
    env.reset(seed=3)
    a = np.full(env.action_space.shape, 0.2, dtype=np.float32)
    env.step(a)
    twin = pickle.loads(pickle.dumps(env))
    assert twin.task._pipelines is None
    for _ in range(20):
        _same(env.step(a), twin.step(a), "after pickling")
