"""Fuzz Azimut-v1 with random and extreme actions over seeds and tracks: no exception, no
non-finite observation, blow-ups end the episode with an error instead of NaN."""

from __future__ import annotations

import numpy as np
import pytest

from azimut_env.env import AzimutEnv
from azimut_env.tracks import TRACK_NAMES


def _policy(kind: str, rng: np.random.Generator, t: int) -> np.ndarray:
    if kind == "uniform":
        return rng.uniform(-1, 1, 8).astype(np.float32)
    if kind == "bang":
        return rng.choice([-1.0, 1.0], 8).astype(np.float32)
    if kind == "alternate":
        return np.full(8, 1.0 if t % 2 else -1.0, dtype=np.float32)
    if kind == "huge":
        return (rng.standard_normal(8) * 1e6).astype(np.float32)
    return np.zeros(8, dtype=np.float32)


def fuzz(total_steps: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    kinds = ("uniform", "bang", "alternate", "huge", "zero")
    stats = {"steps": 0, "episodes": 0, "errors": 0}
    envs = {name: AzimutEnv(track=name, domain_randomization=0.3) for name in TRACK_NAMES}
    while stats["steps"] < total_steps:
        name = TRACK_NAMES[stats["episodes"] % len(TRACK_NAMES)]
        env = envs[name]
        kind = kinds[rng.integers(len(kinds))]
        options = {}
        if rng.random() < 0.3:
            options["kick"] = {"step": int(rng.integers(0, 50)), "wheels": [int(rng.integers(4))],
                               "impulse": float(rng.uniform(-2, 2))}
        if rng.random() < 0.3:
            # anywhere but on the start of the track (the env refuses that with a ValueError)
            start = env.track.sample(0.0)[:2]
            ang = rng.uniform(0, 2 * np.pi)
            dist = rng.uniform(0.8, 2.5)
            options["obstacles"] = [(float(start[0] + dist * np.cos(ang)), float(start[1] + dist * np.sin(ang)), 0.3)]
        obs, _ = env.reset(seed=int(rng.integers(1 << 31)), options=options)
        assert env.observation_space.contains(obs)
        stats["episodes"] += 1
        for t in range(int(rng.integers(50, 400))):
            obs, rew, term, trunc, info = env.step(_policy(kind, rng, t))
            stats["steps"] += 1
            assert np.all(np.isfinite(obs)) and np.isfinite(rew)
            assert env.observation_space.contains(obs), (name, kind, t)
            if "error" in info:
                stats["errors"] += 1
                assert term
            if term or trunc:
                break
    return stats


def test_fuzz_small():
    stats = fuzz(3000, seed=1)
    assert stats["steps"] >= 3000


@pytest.mark.slow
def test_fuzz_1e5_steps():
    stats = fuzz(100_000, seed=2)
    assert stats["steps"] >= 100_000


def test_blow_up_terminates_with_error_and_finite_observation(env, zero_action):
    env.reset(seed=0)
    env.step(zero_action)
    env.physics.chassis[0].velocity = (float("nan"), 0.0)
    obs, rew, term, trunc, info = env.step(zero_action)
    assert term and "error" in info and "non-finite" in info["error"]
    assert np.all(np.isfinite(obs)) and np.isfinite(rew)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(zero_action)
    obs, _ = env.reset(seed=1)
    assert np.all(np.isfinite(obs))
