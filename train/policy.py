"""Load a policy that ``azimut train`` wrote, with its observation normalisation, and act with it.

A run folder holds ``model.zip`` (the SB3 model), ``vecnormalize.pkl`` (the ``VecNormalize``
statistics, beside the model file; a checkpoint's ``*_vecnormalize_*`` file is found too) and
``run.json`` (algorithm, action space, env keyword arguments). Loading needs only the ``rl`` extra
(stable-baselines3 and torch).
"""

from __future__ import annotations

import json
import pickle
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["TrainedPolicy", "load_policy", "vecnormalize_path"]


def vecnormalize_path(model_path: Path) -> Path | None:
    """The VecNormalize statistics saved beside ``model_path`` (None if there are none):
    ``model.zip`` -> ``vecnormalize.pkl``, ``best_model.zip`` -> ``best_vecnormalize.pkl``, a
    checkpoint ``model_<N>_steps.zip`` -> ``model_vecnormalize_<N>_steps.pkl`` (SB3's
    ``CheckpointCallback`` names)."""
    model_path = Path(model_path)
    stem = model_path.name.removesuffix(".zip")
    names = [stem.replace("model", "vecnormalize", 1) + ".pkl"]
    if stem.startswith("model_") and stem.endswith("_steps"):
        names.insert(0, "model_vecnormalize_" + stem.removeprefix("model_") + ".pkl")
    for name in names:
        if (model_path.parent / name).is_file():
            return model_path.parent / name
    return None


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
        """Actions (N, A) for raw observations (N, D)."""
        action, _ = self.model.predict(self.normalize(np.asarray(obs, dtype=np.float32)), deterministic=deterministic)
        return action


def load_policy(path: str | Path, algo: str | None = None, device: str = "cpu") -> TrainedPolicy:
    """Load the model file ``path`` (``model.zip`` of a run folder, a checkpoint, or a run folder).

    ``algo`` defaults to the run's ``run.json`` (the ``ppo:``/``sac:`` prefix of ``azimut eval``
    passes it); the action space and env arguments come from ``run.json`` (raw if absent).
    """
    from stable_baselines3 import PPO, SAC

    path = Path(path)
    if path.is_dir():
        path = path / "model.zip"
    if not path.is_file():
        raise ValueError(f"{path}: no such model file")
    meta_file = next((p / "run.json" for p in (path.parent, path.parent.parent) if (p / "run.json").is_file()), None)
    meta = json.loads(meta_file.read_text()) if meta_file else {}
    algo = algo or meta.get("algo")
    if algo not in ("ppo", "sac"):
        raise ValueError(f"{path}: unknown algorithm {algo!r} (give ppo:PATH or sac:PATH)")
    model = (PPO if algo == "ppo" else SAC).load(str(path), device=device)
    obs_rms, clip_obs, eps = None, 10.0, 1e-8
    vn = vecnormalize_path(path)
    if vn is not None:
        with open(vn, "rb") as fh:
            stats = pickle.load(fh)
        if getattr(stats, "norm_obs", True):
            obs_rms, clip_obs, eps = stats.obs_rms, float(stats.clip_obs), float(stats.epsilon)
    return TrainedPolicy(model=model, algo=algo, action=meta.get("action", "raw"),
                         env_kwargs=meta.get("env_kwargs", {}), obs_rms=obs_rms, clip_obs=clip_obs, epsilon=eps)
