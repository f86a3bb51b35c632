"""Versioned default hyperparameters per algorithm × action space (``ppo.json``, ``sac.json``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["load_hyperparams", "check_hyperparams", "ALGOS"]

ALGOS = ("ppo", "sac")


def load_hyperparams(algo: str, action_key: str) -> tuple[dict[str, Any], int]:
    """(keyword arguments of the SB3 algorithm, file version) for ``algo`` and ``action_key``
    (``raw``, ``residual``, ``icr_rate``)."""
    if algo not in ALGOS:
        raise ValueError(f"unknown algorithm {algo!r}; choose from {', '.join(ALGOS)}")
    data = json.loads((Path(__file__).parent / f"{algo}.json").read_text())
    if action_key not in data:
        raise ValueError(f"{algo}.json has no defaults for action space {action_key!r}")
    return dict(data[action_key]), int(data["version"])


# keys the trainer sets itself (not overridable from a hyperparameter file)
_RESERVED = ("policy", "env", "seed", "device", "verbose", "tensorboard_log", "_init_setup_model")
# simple ranges: (low, high, low inclusive); numbers only (SB3 also takes schedules and "auto")
_RANGES = {
    "learning_rate": (0.0, None, False), "n_steps": (1, None, True), "batch_size": (2, None, True),
    "n_epochs": (1, None, True), "gamma": (0.0, 1.0, False), "gae_lambda": (0.0, 1.0, True),
    "clip_range": (0.0, None, False), "ent_coef": (0.0, None, True), "vf_coef": (0.0, None, True),
    "max_grad_norm": (0.0, None, False), "buffer_size": (1, None, True), "learning_starts": (0, None, True),
    "tau": (0.0, 1.0, False), "gradient_steps": (-1, None, True), "train_freq": (1, None, True),
}


def check_hyperparams(algo: str, action_key: str, overrides: dict[str, Any]) -> dict[str, Any]:
    """Refuse a hyperparameter override that the SB3 constructor would reject or misuse
    (``ValueError``, one line): unknown keys (checked against ``inspect.signature`` of PPO/SAC),
    a wrong type where the default is a number, a number out of its range, and whatever the
    constructor itself raises for the merged set on a small stand-in environment with the same
    kinds of spaces. Returns the merged hyperparameters."""
    import inspect
    import math
    import numbers

    if not isinstance(overrides, dict):
        raise ValueError("hyperparameters must be a JSON object of keyword arguments")
    from stable_baselines3 import PPO, SAC

    cls = PPO if algo == "ppo" else SAC
    params = inspect.signature(cls.__init__).parameters
    allowed = sorted(k for k in params if k not in _RESERVED and k != "self")
    reserved = sorted(k for k in overrides if k in _RESERVED)
    if reserved:
        raise ValueError(f"{', '.join(map(repr, reserved))} cannot be set in a hyperparameter file "
                         f"(azimut train sets it; use its flags)")
    unknown = sorted(k for k in overrides if k not in params)
    if unknown:
        raise ValueError(f"unknown {algo.upper()} hyperparameter(s) {', '.join(map(repr, unknown))}; "
                         f"allowed: {', '.join(allowed)}")
    hp, _ = load_hyperparams(algo, action_key)
    for key, value in overrides.items():
        default = params[key].default
        if key in _RANGES or (isinstance(default, numbers.Real) and not isinstance(default, bool)):
            if key == "ent_coef" and isinstance(value, str) and value.startswith("auto"):
                continue
            if key == "train_freq" and isinstance(value, list):
                continue
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise ValueError(f"hyperparameter {key!r} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"hyperparameter {key!r} must be finite, got {value!r}")
            if isinstance(default, int) and not isinstance(default, bool) and not float(value).is_integer():
                raise ValueError(f"hyperparameter {key!r} must be an integer, got {value!r}")
            if key in _RANGES:
                lo, hi, lo_inc = _RANGES[key]
                if (value < lo if lo_inc else value <= lo) or (hi is not None and value > hi):
                    span = (f"{'[' if lo_inc else '('}{lo}, "
                            f"{hi if hi is not None else 'inf'}{']' if hi is not None else ')'}")
                    raise ValueError(f"hyperparameter {key!r} must be in {span}, got {value!r}")
        elif isinstance(default, bool) and not isinstance(value, bool):
            raise ValueError(f"hyperparameter {key!r} must be true or false, got {value!r}")
    hp.update(overrides)
    _try_constructor(cls, hp)
    return hp


def _try_constructor(cls, hp: dict[str, Any]) -> None:
    """Build the algorithm on a one-robot stand-in with Box spaces (no env, no files): the
    constructor's own TypeError/ValueError/AssertionError become one-line ValueErrors."""
    import gymnasium as gym
    import numpy as np
    from stable_baselines3.common.vec_env import DummyVecEnv

    class _StandIn(gym.Env):
        observation_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
        action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

        def reset(self, *, seed=None, options=None):
            return np.zeros(4, np.float32), {}

        def step(self, action):
            return np.zeros(4, np.float32), 0.0, False, False, {}

    kwargs = dict(hp)
    if "buffer_size" in kwargs:  # the check needs no replay memory
        kwargs["buffer_size"] = min(int(kwargs["buffer_size"]), 1000)
    import warnings

    venv = DummyVecEnv([_StandIn])
    try:
        with warnings.catch_warnings():  # e.g. batch size vs n_steps × 1 stand-in robot: not the real run's
            warnings.simplefilter("ignore")
            cls("MlpPolicy", venv, device="cpu", verbose=0, **kwargs)
    except (TypeError, ValueError, AssertionError, KeyError, RuntimeError) as exc:
        msg = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"the {cls.__name__} constructor refuses these hyperparameters: {msg}") from None
    finally:
        venv.close()
