"""``azimut train --engine rllib``: one PPO agent whose experience is collected by Ray RLlib's env
runners, on a local Ray instance or a cluster (the ``rllib`` extra: ``ray[rllib]``).

RLlib's current API stack (RLModule, Learner, ``SingleAgentEnvRunner``; Liang et al., *RLlib:
Abstractions for Distributed Reinforcement Learning*, ICML 2018, for the design): the env is
registered with ``ray.tune.registry.register_env`` under :data:`ENV_NAME` (not in Gymnasium's
registry) by a creator that returns the N robots of one
:class:`~azimut_env.vector_env.AzimutVectorEnv` behind the chosen action space, in Gymnasium's
``NEXT_STEP`` autoreset mode, which is what the env runners step. The env runners are told
``gym_env_vectorize_mode=VECTOR_ENTRY_POINT``: the creator already is a Gymnasium vector env of
``num_envs_per_env_runner`` robots, so RLlib wraps no per-robot envs. ``env_runners`` remote runners
(Ray actors, placed on the cluster's nodes with ``ray_address``) sample in parallel; 0 samples in
the driver.

Hyperparameters come from the SB3 defaults (``train/hyperparams/ppo.json``) mapped to RLlib's
names: rollout ``n_steps`` × robots per runner × max(runners, 1) -> ``train_batch_size_per_learner``,
``batch_size`` -> ``minibatch_size``, ``n_epochs`` -> ``num_epochs``, ``learning_rate`` -> ``lr``,
``gae_lambda`` -> ``lambda_``, ``clip_range`` -> ``clip_param``, ``ent_coef`` -> ``entropy_coeff``,
``max_grad_norm`` -> ``grad_clip``, ``net_arch`` -> ``fcnet_hiddens`` (tanh). RLlib's default
module learns its log-std as a network output, so ``log_std_init`` has no counterpart, and no
observation normalisation is applied (the SB3 runs use ``VecNormalize``).

The run folder gets what an SB3 run's has, read by the same tools: ``model.pt`` (the policy's
deterministic action as TorchScript, checked against the RLModule's ``forward_inference`` on
sample observations when written; ``azimut eval --controllers ppo:OUT`` loads it with torch only,
no Ray), ``run.json`` (``"engine": "rllib"``), ``evaluations.json`` (periodic and final
deterministic episodes on the held-out tracks with the ``azimut eval`` metrics) and ``checkpoint/``
(RLlib's own checkpoint of the algorithm).
"""

from __future__ import annotations

import json
import math
import os
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["ENV_NAME", "env_creator", "rllib_config", "export_policy", "train_rllib"]

#: the name the env creator is registered under with ``ray.tune.registry.register_env``
ENV_NAME = "azimut-vector"


def env_creator(config: dict) -> Any:
    """The registered creator: ``config["num_envs"]`` robots (RLlib passes the runner's
    ``num_envs_per_env_runner``) of one vector env behind ``config["action"]``, ``NEXT_STEP``
    autoreset, on ``config["track"]`` with ``config["env_kwargs"]``."""
    from gymnasium.vector import AutoresetMode

    from train.envs import make_vector_env

    venv = make_vector_env(config["action"], int(config.get("num_envs", 1)), config.get("track", "random"),
                           AutoresetMode.NEXT_STEP, dict(config.get("env_kwargs") or {}))
    return _ArrayInfo(venv)


def _array_info(info: dict) -> dict:
    """The info entries Gymnasium's ``DictInfoToList`` (which RLlib's env runners wrap the env
    in) takes: arrays and dicts of arrays, with their ``_key`` masks; tuples (the ICR pairs
    ``eta_true``, ``eta_hat``) left out."""
    out = {}
    for key, value in info.items():
        if key.startswith("_"):
            continue
        if isinstance(value, dict):
            value = _array_info(value)
        elif not isinstance(value, np.ndarray):
            continue
        out[key] = value
        if "_" + key in info:
            out["_" + key] = info["_" + key]
    return out


def _wrapper_class():
    import gymnasium as gym

    class ArrayInfo(gym.vector.VectorWrapper):
        """A vector env whose infos hold arrays only (:func:`_array_info`)."""

        def reset(self, **kwargs):
            obs, info = self.env.reset(**kwargs)
            return obs, _array_info(info)

        def step(self, actions):
            obs, reward, terminated, truncated, info = self.env.step(actions)
            return obs, reward, terminated, truncated, _array_info(info)

    return ArrayInfo


def _ArrayInfo(venv):  # noqa: N802 (a class made when first used: gymnasium is imported lazily)
    return _wrapper_class()(venv)


def rllib_config(action: str, track: str, seed: int, num_robots: int, env_runners: int, hp: dict,
                 env_kwargs: dict | None = None):
    """The ``PPOConfig`` of a run (see the module docstring for the hyperparameter mapping)."""
    import gymnasium as gym
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    batch = int(hp["n_steps"]) * num_robots * max(env_runners, 1)
    net = list((hp.get("policy_kwargs") or {}).get("net_arch", [128, 128]))
    return (PPOConfig()
            .environment(ENV_NAME, env_config={"action": action, "track": track, "env_kwargs": env_kwargs or {}})
            .env_runners(num_env_runners=env_runners, num_envs_per_env_runner=num_robots,
                         gym_env_vectorize_mode=gym.VectorizeMode.VECTOR_ENTRY_POINT,
                         rollout_fragment_length=int(hp["n_steps"]))
            .training(train_batch_size_per_learner=batch, minibatch_size=min(int(hp["batch_size"]), batch),
                      num_epochs=int(hp["n_epochs"]), lr=float(hp["learning_rate"]), gamma=float(hp["gamma"]),
                      lambda_=float(hp["gae_lambda"]), clip_param=float(hp["clip_range"]),
                      entropy_coeff=float(hp.get("ent_coef", 0.0)), grad_clip=float(hp.get("max_grad_norm", 0.5)))
            .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=net, fcnet_activation="tanh"))
            .debugging(seed=int(seed)))


def export_policy(algo, obs_dim: int, action_dim: int, path: Path, check_obs: np.ndarray) -> Path:
    """Write the RLModule's deterministic action (the mean of its Gaussian, clipped to [−1, 1]) as
    TorchScript to ``path``, after checking the traced module against ``forward_inference`` on
    ``check_obs`` (``RuntimeError`` if they differ)."""
    import torch

    module = algo.get_module()

    class _Deterministic(torch.nn.Module):
        def __init__(self, m):
            super().__init__()
            self.m = m

        def forward(self, obs):
            return torch.clamp(self.m.forward_inference({"obs": obs})["action_dist_inputs"][..., :action_dim],
                               -1.0, 1.0)

    wrapper = _Deterministic(module).eval()
    example = torch.as_tensor(np.asarray(check_obs, dtype=np.float32).reshape(-1, obs_dim))
    with torch.no_grad():
        traced = torch.jit.trace(wrapper, example, check_trace=False)
        want = wrapper(example).numpy()
        got = traced(example).numpy()
    if not np.allclose(got, want, rtol=0, atol=1e-6):
        raise RuntimeError("the traced policy differs from the RLModule's forward_inference")
    torch.jit.save(traced, str(path))
    return path


def _start_ray(ray_address: str | None, env_runners: int, quiet: bool) -> bool:
    """Ray started (on the cluster at ``ray_address``, or locally with a CPU per runner and one for
    the learner) unless it runs already; returns whether this call started it."""
    import ray

    started_ray = not ray.is_initialized()
    if started_ray:
        if ray_address:
            ray.init(address=ray_address, log_to_driver=not quiet)
        else:
            ray.init(num_cpus=max(env_runners + 1, 2), include_dashboard=False, log_to_driver=not quiet)
    return started_ray


def _probe_env(action: str, track: str, env_kwargs: dict, seed: int):
    """One env built and reset to read the observation and action sizes and a first observation
    (the exported policy's trace check)."""
    probe = env_creator({"action": action, "num_envs": 1, "track": track, "env_kwargs": env_kwargs})
    obs_dim, act_dim = int(probe.single_observation_space.shape[0]), int(probe.single_action_space.shape[0])
    check_obs, _ = probe.reset(seed=seed)
    probe.close()
    return obs_dim, act_dim, check_obs


def _evaluate(algo, obs_dim: int, act_dim: int, check_obs, out: Path, action: str, seed: int, eval_tracks,
              eval_max_time, quiet: bool, timesteps: int) -> dict:
    """The policy exported to ``model.pt`` and run once on each evaluation track: the
    ``evaluations.json`` entry."""
    from train.policy import load_policy
    from train.rollout import policy_metrics

    export_policy(algo, obs_dim, act_dim, out / "model.pt", check_obs)
    policy = load_policy(out)
    start = time.perf_counter()
    rows = [policy_metrics(policy, t, seed=seed, label=f"ppo-{action}", max_time=eval_max_time)[0]
            for t in eval_tracks]
    entry = {"timesteps": int(timesteps), "eval_wall_s": time.perf_counter() - start, "rows": rows,
             "mean_return": float(np.mean([r["return"] for r in rows]))}
    if not quiet:
        print(f"[eval @ {timesteps}] " + ", ".join(f"{r['track']} ret {r['return']:.0f} lat "
                                                  f"{100 * r['rms_lateral_m']:.2f} cm" for r in rows), flush=True)
    return entry


def train_rllib(action: str, track: str, seed: int, steps: int, out: Path, num_robots: int = 16,
                eval_tracks: tuple[str, ...] = ("circle", "figure8"), eval_every: int = 200_000,
                overrides: dict | None = None, env_kwargs: dict | None = None, ray_address: str | None = None,
                env_runners: int = 1, time_limit_min: float = 0.0, eval_max_time: float | None = None,
                quiet: bool = False, record_extra: dict | None = None) -> dict:
    """Train PPO with RLlib for ``steps`` environment steps (all robots of all runners) and write the
    run folder (module docstring); returns the run record (``run.json``)."""
    import ray
    import torch
    from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME
    from ray.tune.registry import register_env

    from azimut_env import ENV_ID
    from train.envs import action_key
    from train.hyperparams import load_hyperparams

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    hp, hp_version = load_hyperparams("ppo", action_key(action))
    hp.update(overrides or {})
    env_kwargs = dict(env_kwargs or {})
    started_ray = _start_ray(ray_address, env_runners, quiet)
    register_env(ENV_NAME, env_creator)
    obs_dim, act_dim, check_obs = _probe_env(action, track, env_kwargs, seed)
    algo = rllib_config(action, track, seed, num_robots, env_runners, hp, env_kwargs).build_algo()
    meta = {"engine": "rllib", "algo": "ppo", "action": action, "env_kwargs": env_kwargs}
    (out / "run.json").write_text(json.dumps(meta))  # what load_policy reads during the evaluations

    history: list[dict] = []

    def evaluate(timesteps: int) -> dict:
        return _evaluate(algo, obs_dim, act_dim, check_obs, out, action, seed, eval_tracks, eval_max_time, quiet,
                         timesteps)

    t0 = time.perf_counter()
    done, next_eval, stopped_by_guard = 0, eval_every if eval_every > 0 else math.inf, False
    while done < steps:
        result = algo.train()
        done = int(result[ENV_RUNNER_RESULTS][NUM_ENV_STEPS_SAMPLED_LIFETIME])
        if done >= next_eval and done < steps:
            history.append(evaluate(done))
            (out / "evaluations.json").write_text(json.dumps(history, indent=1, allow_nan=True))
            while next_eval <= done:
                next_eval += eval_every
        if time_limit_min > 0 and time.perf_counter() - t0 > 60.0 * time_limit_min:
            stopped_by_guard = True
            break
    learn_s = time.perf_counter() - t0
    final = evaluate(done)
    final["final"] = True
    history.append(final)
    (out / "evaluations.json").write_text(json.dumps(history, indent=1, allow_nan=True))
    algo.save_to_path(str((out / "checkpoint").resolve()))
    algo.stop()
    if started_ray:
        ray.shutdown()
    record = {**meta, "complete": done >= steps and not stopped_by_guard, "time_limit_min": time_limit_min,
              "track": track, "seed": seed, "steps": steps, "num_timesteps": done, "num_robots": num_robots,
              "env_runners": env_runners, "ray_address": ray_address, "eval_tracks": list(eval_tracks),
              "hyperparams": hp, "hyperparams_version": hp_version, "env_id": ENV_ID, "learn_wall_s": learn_s,
              "steps_per_s_in_learn": done / learn_s if learn_s > 0 else math.nan,
              "torch_threads": torch.get_num_threads(), "ray_version": ray.__version__,
              "machine": f"{platform.node()} ({os.cpu_count()} CPUs, shared)", "final_eval": final["rows"],
              **(record_extra or {})}
    (out / "run.json").write_text(json.dumps(record, indent=1, allow_nan=True, default=str))
    return record
