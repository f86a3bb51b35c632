"""Load a policy that ``azimut train`` wrote, with its observation normalisation, and act with it;
:class:`PolicyController` drives an env with it as a :class:`control.controller.Controller`.

A run folder holds ``model.zip`` (the SB3 model), ``vecnormalize.pkl`` (the ``VecNormalize``
statistics, beside the model file; a checkpoint's ``*_vecnormalize_*`` file is found too) and
``run.json`` (algorithm, action space, env keyword arguments). Loading needs only the ``rl`` extra
(stable-baselines3 and torch). A run of ``azimut train --engine rllib`` holds ``model.pt`` instead
(TorchScript of the deterministic policy, :mod:`train.rllib_engine`), loaded with torch alone.
"""

from __future__ import annotations

import json
import pickle
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from azimut_env.validation import check_real_array
from control.action_spaces.controller import ActionController
from control.commands import WheelCommand
from train.envs import ACTIONS
from train.saved_files import check_model_file, check_vecnormalize_file, vecnormalize_path  # re-exported

__all__ = ["TrainedPolicy", "load_policy", "check_policy_spaces", "vecnormalize_path", "PolicyController",
           "policy_controller", "policy_name", "model_file", "policy_files",
           "TorchScriptPolicy"]

#: the spelling of a policy's short name in ``ppo:NAME=PATH``
_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")


@dataclass
class TrainedPolicy:
    """A trained SB3 policy with its observation normaliser.

    Attributes:
        model: the SB3 algorithm (PPO or SAC). algo: ``"ppo"`` or ``"sac"``. action: the action
        space (``raw``, ``residual``, ``icr-rate``). env_kwargs: ``AzimutVectorEnv`` keyword
        arguments it was trained with. obs_rms: observation mean/var (None: not normalised).
    """

    model: Any
    algo: str
    action: str
    env_kwargs: dict = field(default_factory=dict)
    obs_rms: Any = None
    clip_obs: float = 10.0
    epsilon: float = 1e-8

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        if self.obs_rms is None:
            return obs
        return np.clip((obs - self.obs_rms.mean) / np.sqrt(self.obs_rms.var + self.epsilon), -self.clip_obs,
                       self.clip_obs).astype(np.float32)

    def act(self, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """Actions (N, A) for raw observations (N, D).

        Deterministic actions are computed one row at a time: a batched matrix product rounds
        differently with the batch's size (PyTorch's CPU kernels block by it; 2.4e-7 apart at N = 33
        for a PPO policy), so a robot's action, and with it its whole closed-loop episode, would
        depend on which other episodes share its vector env. Row by row, an episode of a batch is
        the episode stepped alone, bit for bit. Sampled actions keep the batch."""
        x = self.normalize(np.asarray(obs, dtype=np.float32))
        if not deterministic or x.ndim != 2 or x.shape[0] <= 1:
            action, _ = self.model.predict(x, deterministic=deterministic)
            return action
        return np.concatenate([self.model.predict(x[i:i + 1], deterministic=True)[0] for i in range(x.shape[0])])


def load_policy(path: str | Path, algo: str | None = None, device: str = "cpu") -> TrainedPolicy:
    """Load the model file ``path`` (``model.zip`` of a run folder, a checkpoint, or a run folder).

    ``algo`` defaults to the run's ``run.json`` (the ``ppo:``/``sac:`` prefix of ``azimut eval``
    passes it); the action space and env arguments come from ``run.json`` (raw if absent).
    Its companions are checked before any episode (``ValueError``, one line, saying what was
    found): the archive (:func:`train.saved_files.check_model_file`), the VecNormalize statistics
    beside it (required: without them the policy acted on raw observations without a word) and
    the model's spaces against its env's (:func:`check_policy_spaces`).
    """
    path = model_file(path)
    if path.suffix == ".pt":  # azimut train --engine rllib: the deterministic policy as TorchScript
        return _load_torchscript(path, algo, device)
    from stable_baselines3 import PPO, SAC

    path = check_model_file(path)  # a corrupted or truncated archive: one line, before SB3
    meta_file = next((p / "run.json" for p in (path.parent, path.parent.parent) if (p / "run.json").is_file()), None)
    try:
        meta = json.loads(meta_file.read_text()) if meta_file else {}
    except (OSError, ValueError) as exc:
        raise ValueError(f"{meta_file}: unreadable run record ({type(exc).__name__})") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{meta_file}: not a run record (a JSON {type(meta).__name__})")
    if algo and meta.get("algo") in ("ppo", "sac") and algo != meta["algo"]:
        raise ValueError(f"{path}: trained with {meta['algo'].upper()} ({meta_file}), not {algo.upper()}: "
                         f"load it as {meta['algo']}:PATH")
    algo = algo or meta.get("algo")
    if algo not in ("ppo", "sac"):
        raise ValueError(f"{path}: unknown algorithm {algo!r} (give ppo:PATH or sac:PATH)")
    action, env_kwargs = meta.get("action", "raw"), meta.get("env_kwargs") or {}
    if action not in ACTIONS or not isinstance(env_kwargs, dict):
        raise ValueError(f"{meta_file}: action {action!r} is not one of {', '.join(ACTIONS)}, or env_kwargs "
                         "is not a dict")
    vn = check_vecnormalize_file(vecnormalize_path(path), path)  # missing: refused (raw observations otherwise)
    model = (PPO if algo == "ppo" else SAC).load(str(path), device=device)
    with open(vn, "rb") as fh:
        stats = pickle.load(fh)
    check_policy_spaces(path, model, stats, action, env_kwargs)
    obs_rms, clip_obs, eps = None, 10.0, 1e-8
    if getattr(stats, "norm_obs", True):
        obs_rms, clip_obs, eps = stats.obs_rms, float(stats.clip_obs), float(stats.epsilon)
    return TrainedPolicy(model=model, algo=algo, action=action, env_kwargs=env_kwargs, obs_rms=obs_rms,
                         clip_obs=clip_obs, epsilon=eps)


def _space_text(space) -> str:
    low, high = getattr(space, "low", None), getattr(space, "high", None)
    if low is not None and np.all(low == low.flat[0]) and np.all(high == high.flat[0]):
        return f"{type(space).__name__}({low.flat[0]:g}, {high.flat[0]:g}, {space.shape})"
    return f"{type(space).__name__}{getattr(space, 'shape', '')}"


def check_policy_spaces(path: Path, model, stats, action: str, env_kwargs: dict) -> None:
    """The companions of a loaded policy against the env it will act in (the action space
    ``action`` of an ``AzimutVectorEnv`` built with ``env_kwargs``), before any episode:
    ``ValueError`` saying what was found and what the env has when the model's action or
    observation space, or the normalisation statistics' observation size, differ (a model of
    another action space passed the argument check and then failed every episode)."""
    from gymnasium import spaces

    from train.envs import make_vector_env

    try:
        env = make_vector_env(action, 1, "paper", env_kwargs=env_kwargs)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{path}: its run's env arguments are refused: {exc}") from None
    try:
        want_a, want_o = env.single_action_space, env.single_observation_space
        got_a, got_o = model.action_space, model.observation_space
        if not (isinstance(got_a, spaces.Box) and got_a.shape == want_a.shape and np.array_equal(got_a.low, want_a.low)
                and np.array_equal(got_a.high, want_a.high)):
            raise ValueError(f"{path}: the model acts in {_space_text(got_a)}, the {action!r} action space of its env "
                             f"is {_space_text(want_a)} (a model of another action space, or run.json of another run)")
        if not (isinstance(got_o, spaces.Box) and got_o.shape == want_o.shape):
            raise ValueError(f"{path}: the model observes {_space_text(got_o)}, its env gives "
                             f"{_space_text(want_o)} (trained with other env arguments or another version)")
        mean = getattr(getattr(stats, "obs_rms", None), "mean", None)
        if getattr(stats, "norm_obs", True) and np.shape(mean) != want_o.shape:
            raise ValueError(f"{path}: its VecNormalize statistics are of observations of shape {np.shape(mean)}, "
                             f"its env gives {want_o.shape} (statistics of another run)")
    finally:
        env.close()


def policy_files(path: str | Path) -> dict[str, Path]:
    """The files a policy loaded from ``path`` reads (what its results depend on): ``model``, and
    those present of ``vecnormalize`` and ``run.json``."""
    model = model_file(path)
    files = {"model": model}
    vn = vecnormalize_path(model)
    if vn is not None:
        files["vecnormalize"] = vn
    meta = next((p / "run.json" for p in (model.parent, model.parent.parent) if (p / "run.json").is_file()), None)
    if meta is not None:
        files["run.json"] = meta
    return files


def model_file(path: str | Path) -> Path:
    """The model file of ``path`` (a model file, or a run folder holding ``model.zip``, or
    ``model.pt`` for an ``--engine rllib`` run)."""
    path = Path(path)
    if not path.is_dir():
        return path
    return path / "model.pt" if not (path / "model.zip").exists() and (path / "model.pt").is_file() else \
        path / "model.zip"


def _load_torchscript(path: Path, algo: str | None, device: str) -> TrainedPolicy:
    """The policy of an ``--engine rllib`` run: ``model.pt`` (TorchScript; no observation
    normalisation) and its ``run.json`` beside it."""
    import torch

    meta_file = path.parent / "run.json"
    try:
        meta = json.loads(meta_file.read_text()) if meta_file.is_file() else {}
    except (OSError, ValueError) as exc:
        raise ValueError(f"{meta_file}: unreadable run record ({type(exc).__name__})") from None
    algo = algo or meta.get("algo")
    action, env_kwargs = meta.get("action"), meta.get("env_kwargs") or {}
    if algo != "ppo" or action not in ACTIONS or not isinstance(env_kwargs, dict):
        raise ValueError(f"{meta_file}: an --engine rllib run records algo 'ppo', its action space and env_kwargs")
    try:
        module = torch.jit.load(str(path), map_location=device)
    except (RuntimeError, OSError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable TorchScript policy ({type(exc).__name__})") from None
    return TrainedPolicy(model=TorchScriptPolicy(module), algo=algo, action=action, env_kwargs=env_kwargs)


class TorchScriptPolicy:
    """The ``predict`` of an SB3 model for a TorchScript module mapping observations (N, D) to
    deterministic actions (N, A) (``azimut train --engine rllib``'s ``model.pt``; it acts with
    its mean action whether or not ``deterministic`` is asked)."""

    def __init__(self, module) -> None:
        self.module = module

    def predict(self, obs: np.ndarray, deterministic: bool = True):
        import torch

        with torch.no_grad():
            return self.module(torch.as_tensor(np.asarray(obs, dtype=np.float32))).numpy(), None


def policy_name(arg: str) -> tuple[str, Path]:
    """(name, path) of the ``ARG`` of ``ppo:ARG`` / ``sac:ARG``: ``NAME=PATH``, or ``PATH`` alone,
    named after its run folder (the folder holding ``run.json``, else the model file's folder)."""
    head, sep, tail = arg.partition("=")
    if not arg.strip() or (sep and _NAME.match(head) and not tail.strip()):
        raise ValueError(f"{arg!r}: no model path (give ppo:PATH, sac:PATH or ppo:NAME=PATH)")
    if sep and not head.strip():
        raise ValueError(f"{arg!r}: no name before '=' (give ppo:NAME=PATH, or ppo:PATH)")
    if sep and _NAME.match(head) and tail:
        return head, Path(tail)
    path = Path(arg)
    model = model_file(path)
    run = next((p for p in (model.parent, model.parent.parent) if (p / "run.json").is_file()), model.parent)
    name = run.resolve().name if run.name in ("", ".", "..") else run.name
    return name or str(path), path


class PolicyController:
    """A trained policy as a :class:`control.controller.Controller` for the N robots of an env.

    Each control period the policy's action for the (normalised) observation goes
    through its action space: for ``raw`` the action is sent to the env as it is (the command's
    ``action``; β̇, β̈ and φ̈ are finite differences of the set-points the env applies, from those
    of its reset); for ``residual`` and ``icr-rate`` the action sets the target of the
    :class:`~control.action_spaces.controller.ActionController` it was trained with, whose ICR
    controller gives the set-points, their rates, the mode and the reconfigure events.

    Args:
        policy: a :class:`TrainedPolicy`. name: the short name of its rows, legends and files.
        deterministic: act with the policy's mean action (default) or sample it.
    """

    def __init__(self, policy: TrainedPolicy, name: str, deterministic: bool = True) -> None:
        if policy.action not in ACTIONS:
            raise ValueError(f"unknown action space {policy.action!r} of the policy; choose from {', '.join(ACTIONS)}")
        self.policy, self.name, self.deterministic = policy, str(name), bool(deterministic)
        self.kind = ACTIONS[policy.action]
        #: the env arguments the policy was trained with (the episode loop builds its env with them)
        self.env_kwargs = dict(policy.env_kwargs)
        self._action_controller: ActionController | None = None
        self._prev: dict[str, np.ndarray] = {}

    def reset(self, env, rows) -> None:
        rows = np.asarray(rows, dtype=np.intp)
        if self.kind is not None:
            ctl = self._action_controller
            if ctl is None or ctl.num != np.shape(env.measured_beta)[0]:
                self._action_controller = ctl = ActionController(env, self.kind)
            ctl.reset(env, rows)
            return
        # raw: the set-points the env holds after its reset (its previous action)
        beta, phidot = env.setpoints_from_action(env.task.prev_action)
        if not self._prev or self._prev["beta"].shape != beta.shape:
            self._prev = {"beta": beta.copy(), "phidot": phidot.copy(), "rate": np.zeros_like(beta)}
        self._prev["beta"][rows], self._prev["phidot"][rows], self._prev["rate"][rows] = beta[rows], phidot[rows], 0.0

    def act(self, env, obs) -> WheelCommand:
        action = self.policy.act(obs, deterministic=self.deterministic)
        if self.kind is not None:
            a = check_real_array("actions", action)
            if a.shape != (np.shape(obs)[0], self._action_controller.action_size) or not np.all(np.isfinite(a)):
                raise ValueError(f"policy {self.name!r}: actions must be a finite "
                                 f"({np.shape(obs)[0]}, {self._action_controller.action_size}) array")
            rows = np.arange(a.shape[0])
            return self._action_controller.command(env, np.clip(a, -1.0, 1.0), rows)
        applied = np.clip(np.asarray(action, dtype=np.float32), -1.0, 1.0)  # what the env applies
        beta, phidot = env.setpoints_from_action(applied)
        dt, prev = env.control_period, self._prev
        rate = (beta - prev["beta"]) / dt
        accel, phiddot = (rate - prev["rate"]) / dt, (phidot - prev["phidot"]) / dt
        self._prev = {"beta": beta, "phidot": phidot, "rate": rate}
        return WheelCommand(beta=beta, phidot=phidot, beta_rate=rate, beta_accel=accel, phiddot=phiddot,
                            action=action)


def policy_controller(algo: str, arg: str, speed_scale: float = 1.0, deterministic: bool = True) -> PolicyController:
    """The controller of spec ``ppo:ARG`` / ``sac:ARG`` (``ARG`` = ``NAME=PATH`` or ``PATH``, see
    :func:`policy_name`): the policy loaded (:func:`load_policy`) and named.

    ``speed_scale`` must be 1: a policy drives at the speed it learned (``--speed-scale`` scales
    the path-following controllers' speed profile only)."""
    if speed_scale != 1.0:
        raise ValueError(f"a trained policy drives at the speed it learned; speed_scale must be 1, got {speed_scale!r}")
    name, path = policy_name(arg)
    return PolicyController(load_policy(path, algo), name, deterministic=deterministic)
