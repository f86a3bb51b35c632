"""The ICR-target and twist action spaces on the vector env: sub-env i matches the single-env
wrapper (control.action_spaces.single) on an env seeded with seed + i, with autoresets."""

from __future__ import annotations

import numpy as np
import pytest

from azimut_env.env import AzimutEnv
from azimut_env.vector_env import AzimutVectorEnv
from control.action_spaces.single import ICRTargetAction, TwistAction
from control.action_spaces.vector import VectorControllerAction


@pytest.mark.parametrize("action,controller", [("icr_target", "icr"), ("twist", "icr"), ("twist", "swerve")])
def test_vector_controller_matches_single_wrappers(action, controller):
    n_envs, max_steps, seed = 2, 40, 3
    venv = VectorControllerAction(AzimutVectorEnv(num_envs=n_envs, max_episode_steps=max_steps, track="circle"),
                                  action=action, controller=controller)
    if action == "icr_target":
        singles = [ICRTargetAction(AzimutEnv(track="circle")) for _ in range(n_envs)]
    else:
        singles = [TwistAction(AzimutEnv(track="circle"), controller=controller) for _ in range(n_envs)]
    vobs, _ = venv.reset(seed=seed)
    for i, env in enumerate(singles):
        assert np.array_equal(env.reset(seed=seed + i)[0], vobs[i])
    rng = np.random.default_rng(0)
    elapsed, pending = [0] * n_envs, [False] * n_envs
    size = venv.single_action_space.shape[0]
    for t in range(100):
        acts = np.clip(rng.normal(0.3, 0.3, (n_envs, size)), -1, 1).astype(np.float32)
        vobs, vrew, vterm, vtrunc, info = venv.step(acts)
        assert info["controller_mode"].shape == (n_envs,)
        for i, env in enumerate(singles):
            if pending[i]:
                obs, _ = env.reset()
                rew, term, trunc, elapsed[i] = 0.0, False, False, 0
            else:
                obs, rew, term, _, _ = env.step(acts[i])
                elapsed[i] += 1
                trunc = elapsed[i] >= max_steps
            pending[i] = term or trunc
            assert np.array_equal(obs, vobs[i]), (t, i)
            assert rew == vrew[i] and (term, trunc) == (vterm[i], vtrunc[i])
