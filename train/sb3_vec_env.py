"""An SB3 ``VecEnv`` over :class:`~azimut_env.vector_env.AzimutVectorEnv`: Stable-Baselines3 trains on
N robots in one pymunk Space directly, in-process (no subprocesses, no per-env Python loop).

The vector env may be wrapped (Gymnasium vector wrappers, e.g. the controller action spaces of
``control.action_spaces.vector.VectorControllerAction``): the adapter steps the outermost wrapper and
takes its spaces; the unwrapped env must run in ``AutoresetMode.SAME_STEP``.

SB3's VecEnv semantics: ``step_wait`` resets a finished sub-env within the same step, returns its
first observation, and puts its last one in ``infos[i]["terminal_observation"]`` with
``infos[i]["TimeLimit.truncated"]`` (truncated and not terminated). The adapter runs the vector
env in ``AutoresetMode.SAME_STEP``, which does exactly that in one batched call. Seeds given with
``seed(s)`` go to sub-env i as ``s + i`` at the next ``reset()`` (as SB3's ``DummyVecEnv``).

Requires ``stable-baselines3`` (the ``[rl]`` extra).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from azimut_env.vector_env import AzimutVectorEnv

__all__ = ["AzimutSB3VecEnv"]


class AzimutSB3VecEnv(VecEnv):
    """SB3 ``VecEnv`` adapter.

    Args:
        num_envs: number of robots N (ignored when ``venv`` is given).
        venv: an existing :class:`AzimutVectorEnv` in ``AutoresetMode.SAME_STEP``, or a vector wrapper
            of one (optional).
        **kwargs: keyword arguments of :class:`AzimutVectorEnv` (track, substeps, reward weights,
            ``max_episode_steps``...) when it is built here.

    ``get_attr``/``set_attr``/``env_method`` act on the vector env, which all sub-envs share: a
    get returns the same value for every index.

    Per-sub-env ``infos`` carry ``progress``, ``lateral_error``, ``heading_error``, ``slip_power``
    [W], ``antagonism`` and ``nullspace_force`` [N], ``off_track``, ``finished``, ``stalled`` and,
    through a controller wrapper, ``controller_mode`` (SB3 callbacks log them; see ``train``).
    """

    def __init__(self, num_envs: int = 1, venv: AzimutVectorEnv | None = None, **kwargs: Any) -> None:
        if venv is None:
            venv = AzimutVectorEnv(num_envs=num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **kwargs)
        elif kwargs:
            raise ValueError("pass either venv or AzimutVectorEnv keyword arguments, not both")
        if not isinstance(venv, gym.vector.VectorEnv) or not isinstance(venv.unwrapped, AzimutVectorEnv):
            raise ValueError(f"venv must be an AzimutVectorEnv or a vector wrapper of one, got {type(venv).__name__}")
        if venv.unwrapped.autoreset_mode != AutoresetMode.SAME_STEP:
            raise ValueError("the SB3 adapter needs the vector env in AutoresetMode.SAME_STEP")
        self.venv = venv
        self._actions: np.ndarray | None = None
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)

    def reset(self) -> np.ndarray:
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        options = [o or None for o in self._options]
        obs, info = self.venv.reset(seed=seeds, options=None if all(o is None for o in options) else options)
        self.reset_infos = self._split_info(info)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_async() must come before step_wait()")
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        self._actions = None
        dones = terminated | truncated
        infos = self._split_info(info.get("final_info", info) if dones.any() else info)
        timeout = truncated & ~terminated
        for sub, flag in zip(infos, timeout.tolist()):
            sub["TimeLimit.truncated"] = flag
        if dones.any():
            final_obs = info["final_obs"]
            for i in np.flatnonzero(dones):
                infos[i]["terminal_observation"] = final_obs[i]
        return obs, reward.astype(np.float32), dones, infos

    def _split_info(self, info: dict[str, Any]) -> list[dict[str, Any]]:
        """Per-sub-env dicts of the few scalar infos SB3 users log (progress, errors...)."""
        out: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for key in ("progress", "lateral_error", "heading_error", "slip_power", "antagonism", "nullspace_force",
                    "off_track", "finished", "stalled", "controller_mode"):
            values = info.get(key)
            if values is not None:  # tolist: Python scalars, as .item() of each element, in one call
                for sub, value in zip(out, np.asarray(values).tolist()):
                    sub[key] = value
        if "error" in info:
            for i in np.flatnonzero(info["_error"]):
                out[i]["error"] = info["error"][i]
        return out

    def close(self) -> None:
        self.venv.close()

    def _count(self, indices: VecEnvIndices) -> int:
        return len(self._get_indices(indices)) if indices is not None else self.num_envs

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        venv = self.__dict__.get("venv")
        if venv is None:
            raise AttributeError(attr_name)
        target = venv if hasattr(venv, attr_name) else venv.unwrapped
        return [getattr(target, attr_name)] * self._count(indices)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result] * self._count(indices)

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False] * self._count(indices)

    def get_images(self) -> Sequence[np.ndarray | None]:
        """One RGB image per sub-env (``render_mode="rgb_array"``)."""
        images = []
        base = self.venv.unwrapped
        keep = base.render_index
        try:
            for i in range(self.num_envs):
                base.render_index = i
                images.append(base.render())
        finally:
            base.render_index = keep
        return images
