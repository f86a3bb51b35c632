"""Fuzz AzimutVectorEnv per sub-env: random and extreme actions (each sub-env its own kind), every
track, kicks, shared obstacles and domain randomisation, with NEXT_STEP autoresets: no exception,
no non-finite observation or reward, observations inside the space, blow-ups confined to their
sub-env."""

from __future__ import annotations

import numpy as np
import pytest

from azimut_env.tracks import TRACK_NAMES
from azimut_env.vector_env import AzimutVectorEnv

KINDS = ("uniform", "bang", "alternate", "huge", "zero")


def _actions(kinds: np.ndarray, rng: np.random.Generator, t: int) -> np.ndarray:
    n_envs = kinds.shape[0]
    out = np.zeros((n_envs, 8), dtype=np.float32)
    for i, kind in enumerate(kinds):
        if kind == "uniform":
            out[i] = rng.uniform(-1, 1, 8)
        elif kind == "bang":
            out[i] = rng.choice([-1.0, 1.0], 8)
        elif kind == "alternate":
            out[i] = 1.0 if t % 2 else -1.0
        elif kind == "huge":
            out[i] = rng.standard_normal(8) * 1e6
    return out


def fuzz_vector(total_steps: int, n_envs: int = 8, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    stats = {"steps": 0, "episodes": 0, "errors": 0}
    for j, name in enumerate(TRACK_NAMES * ((total_steps // (n_envs * 200 * len(TRACK_NAMES))) + 1)):
        if stats["steps"] >= total_steps:
            break
        obstacles = [(30.0, 30.0, 0.5)] if j % 2 else ()
        venv = AzimutVectorEnv(num_envs=n_envs, track=name, domain_randomization=0.3, max_episode_steps=150,
                               obstacles=obstacles)
        options = [{"kick": {"step": int(rng.integers(0, 50)), "wheels": [int(rng.integers(4))],
                             "impulse": float(rng.uniform(-2, 2))}} if rng.random() < 0.3 else None
                   for _ in range(n_envs)]
        obs, _ = venv.reset(seed=int(rng.integers(1 << 31)), options=options)
        assert obs in venv.observation_space
        kinds = rng.choice(KINDS, n_envs)
        for t in range(200):
            obs, rew, term, trunc, info = venv.step(_actions(kinds, rng, t))
            stats["steps"] += n_envs
            assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rew))
            assert obs in venv.observation_space, (name, t)
            if "error" in info:
                stats["errors"] += int(info["_error"].sum())
                assert np.all(term[info["_error"]])
            stats["episodes"] += int(np.sum(term | trunc))
            if (term | trunc).any():  # new kinds for the sub-envs that autoreset next step
                ended = term | trunc
                kinds[ended] = rng.choice(KINDS, int(ended.sum()))
    return stats


def test_vector_fuzz_small():
    stats = fuzz_vector(2 * 8 * 200, n_envs=8, seed=1)
    assert stats["steps"] >= 3200 and stats["episodes"] > 0


@pytest.mark.slow
def test_vector_fuzz_1e5_steps():
    stats = fuzz_vector(100_000, n_envs=32, seed=2)
    assert stats["steps"] >= 100_000
