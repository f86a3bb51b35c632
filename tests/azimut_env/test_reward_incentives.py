"""The default reward of ``Azimut-v1`` orders behaviours the way training needs them ordered.

Raw set-points on ``circle``, 16 robots for 300 steps (6 s): a constant action taken from the ICR
controller's steady-state set-points, the same with the per-step Gaussian noise of an exploring
PPO policy (σ = 0.135, ``log_std_init`` −2), the wheels stopped (speeds zero) with that noise,
and uniformly random set-points (wheels fighting each other). With ``progress_weight`` 1 (the
first ``Azimut-v1`` default) the exploring mover's per-step reward was negative (−0.58) and
PPO's raw agents settled on standing still; the default (3) must keep it positive, and
antagonism must still cost a wheel-fighting policy most of what it earns.
"""

from __future__ import annotations

import numpy as np

from azimut_env.params import action_from_setpoints
from azimut_env.task.core import TaskConfig
from azimut_env.vector_env import AzimutVectorEnv
from control.rollout import run_episode


def _per_step_rewards(steps: int = 300) -> dict[str, float]:
    log = run_episode("icr", "circle", seed=0, max_time=4.0)  # at 0.5 m/s from 2 s on
    venv = AzimutVectorEnv(num_envs=16, track="circle", time_limit_factor=0.0)
    ideal = action_from_setpoints(log.beta_cmd[-1], log.phidot_cmd[-1], venv.limits).astype(np.float64)
    groups = {"clean": slice(0, 4), "exploring": slice(4, 8), "standing": slice(8, 12), "random": slice(12, 16)}
    rng = np.random.default_rng(0)
    venv.reset(seed=0)
    total = np.zeros(16)
    for _ in range(steps):
        a = np.tile(ideal, (16, 1))
        a[groups["standing"], 4:] = 0.0
        a[4:12] += 0.135 * rng.standard_normal((8, 8))
        a[groups["random"]] = rng.uniform(-1.0, 1.0, (4, 8))
        _, reward, terminated, truncated, _ = venv.step(np.clip(a, -1.0, 1.0).astype(np.float32))
        assert not (terminated.any() or truncated.any())
        total += reward
    venv.close()
    return {name: float(total[sl].mean() / steps) for name, sl in groups.items()}


def test_moving_beats_standing_and_fighting_loses_most_of_the_progress():
    w = TaskConfig().reward_weights["progress"]
    r = _per_step_rewards()
    # the reference motion earns nearly the full progress term (0.78 w on the default robot: its
    # wheels are imperfect, so the open-loop set-points of the nominal geometry drift and fight a
    # little; 0.90 w with imperfections="ideal")
    assert r["clean"] > 0.75 * w
    assert r["exploring"] > 0.2 * w  # an exploring mover is paid for moving ...
    assert r["exploring"] > r["standing"] + 0.5 * w  # ... far more than an exploring robot that stands still
    assert r["standing"] < 0.0  # standing still is never worth it
    assert r["random"] < r["clean"] - 0.6 * w  # wheels that fight lose most of what the motion earns
    assert r["random"] < 0.0
