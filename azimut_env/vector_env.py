"""``AzimutVectorEnv``: N ``Azimut-v2`` robots in one pymunk Space, stepped as one batch.

A :class:`gymnasium.vector.VectorEnv` over :class:`~azimut_env.task.core.AzimutTask`, the same task and
physics code as the single env (which is its N = 1 case); the constructor, the controller
interface and rendering are the shared front end (:mod:`azimut_env.frontend`). Per control step
each stage runs once for all robots (the data flow is in :mod:`azimut_env.task.core`): the compiled
action check and set-point map, ``substeps`` physics substeps (one compiled call per control step
without obstacles), the compiled sensor model over all wheels, one batched IT estimate
(``estimation.estimate_eta``), one compiled track query (each robot on its own track), then the
compiled termination, reward and observation fill. This module adds seeding per sub-env, the
autoreset modes, the batched info and the per-sub-env blow-up bookkeeping. Robots never collide
with each other.

``gymnasium.make_vec("Azimut-v2", num_envs=N, vectorization_mode="vector_entry_point")`` returns it
(keyword arguments as for ``gymnasium.make("Azimut-v2", ...)``; ``"Azimut-v1"``: :func:`make_v1_vector`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space
from numba.typed import List as NumbaList

from azimut_env.frontend import AzimutFrontEnd
from azimut_env.params import RobotParams, SensorParams
from azimut_env.task.config import front_signature, v1_kwargs
from azimut_env.task.info import batch_info, robot_info
from azimut_env.tracks import Track
from azimut_env.typed_lists import generator_list
from azimut_env.validation import ResetNeeded, check_finite, check_index_list, check_int, check_seed

__all__ = ["AzimutVectorEnv", "make_v1_vector"]


class AzimutVectorEnv(AzimutFrontEnd, gym.vector.VectorEnv):
    """
    ## Description
    ``num_envs`` independent copies of :class:`~azimut_env.env.AzimutEnv` (``Azimut-v2``) that share
    one pymunk Space (no robot-robot collisions) and run every stage batched. Sub-env i behaves
    exactly as a single ``Azimut-v2`` seeded with ``seed + i`` and given the same actions: the
    same observations, rewards and terminations to the bit (its robot gets fresh joints at each
    reset, so the shared Space's solver state does not leak between episodes; with obstacle
    contacts this holds to floating-point tolerance only).

    ## Spaces
    ``single_action_space`` and ``single_observation_space`` are the single env's (see
    :class:`~azimut_env.env.AzimutEnv` for the layout); ``action_space`` and
    ``observation_space`` are them batched: ``(num_envs, 2n)`` and ``(num_envs, D)`` float32.

    ## Autoreset
    ``autoreset_mode`` is ``AutoresetMode.NEXT_STEP`` by default (Gymnasium 1.x's default): a
    sub-env that terminated or truncated is reset by the next :meth:`step`, which ignores its
    action and returns its first observation with reward 0, ``terminated = truncated = False``.
    ``AutoresetMode.SAME_STEP`` resets it within the step that ended it and puts the last
    observation in ``info["final_obs"]`` (object array) and the step's info in
    ``info["final_info"]`` (used by the SB3 adapter). ``AutoresetMode.DISABLED`` never resets.

    ## Episode End
    As the single env, per sub-env: off the track or finished (terminated), a physics blow-up of
    that robot (terminated, reward −``reward_weights["off_track"]``, the last finite observation, and
    ``info["error"][i]``; the other robots go on), a stall (``stall_time``, terminated), and the
    step limits (truncated): the per-track limit of ``time_limit_factor`` (1.5 × the reference
    controller's nominal lap on the track by default, see the single env) and ``max_episode_steps``
    if given (default ``None``).

    ## Info
    ``step`` and ``reset`` return the single env's info (the table ``info.INFO_FIELDS``) batched
    with the Gymnasium vector convention: each value with a leading ``num_envs`` axis (the pairs
    ``eta_true``, ``eta_hat``: a pair of batched arrays; ``reward_terms``: a dict of (N,) arrays
    with their masks) and a boolean mask ``"_key"`` saying which sub-envs have the key. A sub-env
    whose physics blew up on the step has only ``reward_terms``, the end conditions' keys
    (``off_track``, ``finished``, ``stalled``) and ``error`` (an object array).
    ``info.sub_info(info, i)`` gives sub-env i's info, equal to the single env's key by key;
    :meth:`sub_env_info` gives it from the current state.

    The keys, their shapes and units are the single env's table (:class:`~azimut_env.env.AzimutEnv`,
    "Info"; ``docs/env.md``), generated from ``info.INFO_FIELDS``.

    ## Arguments
    ``num_envs``; ``max_episode_steps`` (default None: the per-track limit only); ``autoreset_mode``; ``render_index``
    (the sub-env :meth:`render` draws; settable); and all the single env's keyword arguments:
    ``track`` (one for all sub-envs; ``"random"`` draws a track per sub-env and episode),
    ``control_period``, ``substeps``, ``solver_iterations``, ``params``, ``sensors``, ``noise_scale``,
    ``domain_randomization`` (drawn per sub-env and reset), reward weights,
    ``max_lateral_error``, ``lookahead_count``, ``lookahead_spacing``, ``obstacles`` (shared by all
    sub-envs, at the same world positions), ``start_noise``, ``render_mode``, ``action_latency``
    (a FIFO per sub-env, emptied at its reset), ``pose_source``, ``localisation`` (each sub-env has
    its own pose estimate and fix noise, drawn from its generator), ``num_threads`` (the physics
    substeps, the step pipeline and the controllers that read :attr:`num_threads` run in blocks of
    robots, one per thread; default: the cores this process may use; any count gives the same bits).

    ``reset(seed=..., options=...)``: ``seed`` an int (sub-env i gets ``seed + i``) or a list of
    ``num_envs`` ints/None; ``options`` a dict applied to every reset sub-env, or a sequence of
    ``num_envs`` dicts (or None), one per sub-env; a dict may carry ``"reset_mask"`` (bool
    array (num_envs,)) to reset only some sub-envs. Per-sub-env options are those of the single
    env (``track``, ``start_progress``, ``kick``) except ``obstacles``, which are shared.

    ## Controller interface
    As the single env's, batched: ``limits``, ``geometry``, ``params``, ``control_period``;
    ``measured_beta``, ``measured_phidot``, ``measured_motor_angles`` (N, n);
    ``estimated_eta`` -> (λ̂ (N, 3), μ̂ (N,)); ``progress`` (N,); ``tracks`` (one per sub-env);
    ``true_pose``, ``true_twist`` (N, 3); ``setpoints_from_action`` and
    ``action_from_setpoints`` on (N, ...) arrays; :meth:`kick`.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 50, "autoreset_mode": AutoresetMode.NEXT_STEP}
    _robots = slice(None)  # the controller interface reads the task's arrays over all robots

    def __init__(self, num_envs: int = 1, track: str | Track = "paper", *, robot: str | os.PathLike | None = None,
                 params: RobotParams | None = None, imperfections: str | None = None,
                 sensors: SensorParams | str | None = None, noise_scale: float = 1.0, obstacles=(),
                 render_mode: str | None = None, max_episode_steps: int | None = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, render_index: int = 0,
                 **config: Any) -> None:
        # **config: the TaskConfig fields (as the single env's; __signature__ below spells them out)
        num_envs = check_int("num_envs", num_envs, min_value=1, max_value=1_000_000)
        if max_episode_steps is not None:
            max_episode_steps = check_int("max_episode_steps", max_episode_steps, min_value=1)
        render_index = check_int("render_index", render_index, min_value=0, max_value=num_envs - 1)
        try:
            autoreset_mode = AutoresetMode(autoreset_mode)
        except (ValueError, TypeError):
            raise ValueError(f"autoreset_mode must be an AutoresetMode, got {autoreset_mode!r}") from None
        self._build(num_envs, track, obstacles, render_mode, dict(
            robot=robot, params=params, imperfections=imperfections, sensors=sensors, noise_scale=noise_scale,
            **config))
        self.num_envs = N = int(num_envs)
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        self.autoreset_mode = autoreset_mode
        self.render_index = int(render_index)
        self.metadata["autoreset_mode"] = autoreset_mode
        self.single_action_space = self._single_action_space
        self.single_observation_space = self._single_observation_space
        self.action_space = batch_space(self.single_action_space, N)
        self.observation_space = batch_space(self.single_observation_space, N)
        self._rngs: list[np.random.Generator] = [None] * N  # type: ignore[list-item]
        self._seeds: list[int | None] = [None] * N
        self._rng_list: NumbaList | None = None
        self._autoreset = np.zeros(N, dtype=np.bool_)
        self._needs_reset = True
        self._errors: list[str | None] = [None] * N

    # ------------------------------------------------------------------ controller interface (batched)

    @property
    def tracks(self) -> list[Track]:
        """Each sub-env's track of the current episode."""
        return list(self.task.tracks)

    @property
    def np_random(self) -> list[np.random.Generator]:
        """The sub-envs' generators (sub-env i's is that of a single env seeded with seed + i)."""
        return list(self._rngs)

    def kick(self, env_index: int, wheels, impulse: float) -> None:
        """Knock sub-env ``env_index``'s modules ``wheels`` with an angular impulse [N·m·s]."""
        i = check_int("env_index", env_index, min_value=0, max_value=self.num_envs - 1)
        wheels = check_index_list("wheels", wheels, self.n)
        impulse = check_finite("impulse", impulse)
        if self._needs_reset or not self.task.ready[i]:
            raise ResetNeeded(f"sub-env {i} has not been reset (or its last reset failed): call reset() first")
        self.physics.kick(i, wheels, impulse)

    def sub_env_info(self, i: int) -> dict[str, Any]:
        """Sub-env i's info dict as the single env gives it (ground truth, estimate, terms)."""
        return robot_info(self.task, check_int("i", i, min_value=0, max_value=self.num_envs - 1))

    # ------------------------------------------------------------------ vector API

    def __getstate__(self) -> dict:
        """Pickling and deep copy at any time: the numba typed list of the generators (a cache of
        ``_rngs``, which pickles) is dropped and rebuilt on the next step; the copy goes on bit for
        bit (the typed list had made every env that had stepped unpicklable)."""
        d = super().__getstate__()
        d["_rng_list"] = None
        return d

    def _typed_rngs(self) -> NumbaList:
        """The generators as a numba typed list (rebuilt when one is replaced by a reseed)."""
        if self._rng_list is None:
            self._rng_list = generator_list(self._rngs)
        return self._rng_list

    def _seed_list(self, seed) -> list[int | None]:
        N = self.num_envs
        if seed is None:
            return [None] * N
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)):
            seed = check_seed("seed", seed)
            return [seed + i for i in range(N)]
        if isinstance(seed, (str, bytes, dict)) or not hasattr(seed, "__iter__"):
            raise TypeError(f"seed must be None, an int or a list of {N} ints/None, got {type(seed).__name__}")
        seeds = list(seed)
        if len(seeds) != N:
            raise ValueError(f"seed must be an int or a list of {N} seeds, got {len(seeds)}")
        return [check_seed(f"seed[{i}]", s) for i, s in enumerate(seeds)]

    def _check_sub_env_options(self, i: int, options) -> dict:
        """Sub-env i's options, checked; a refusal names the sub-env (``options[i]: ...``)."""
        try:
            return self.task.check_reset_options(options)
        except (ValueError, TypeError) as exc:
            raise type(exc)(f"options[{i}] (sub-env {i}): {exc}") from None

    def _options_list(self, options) -> tuple[list[dict], np.ndarray]:
        """Per-sub-env validated options (``AzimutTask.check_reset_options``) and the reset mask."""
        N, task = self.num_envs, self.task
        mask = np.ones(N, dtype=np.bool_)
        if options is None:
            per: list = [{}] * N
        elif isinstance(options, dict):
            options = dict(options)
            if "reset_mask" in options:
                m = np.asarray(options.pop("reset_mask"))
                if m.shape != (N,) or m.dtype != np.bool_:
                    raise ValueError(f"options['reset_mask'] must be a bool array of shape ({N},)")
                if not m.any():
                    raise ValueError("options['reset_mask'] must select at least one sub-env")
                mask = m.copy()
            checked = task.check_reset_options(options)
            per = [checked] * N
        elif isinstance(options, (str, bytes)) or not hasattr(options, "__iter__"):
            raise TypeError(f"options must be a dict or a sequence of {N} dicts (or None), "
                            f"got {type(options).__name__}")
        else:
            per = list(options)
            if len(per) != N or not all(o is None or isinstance(o, dict) for o in per):
                raise ValueError(f"options must be a dict or a sequence of {N} dicts (or None)")
            per = [self._check_sub_env_options(i, o) for i, o in enumerate(per)]
        if self._needs_reset and not mask.all() and not task.ready[~mask].all():
            never = np.flatnonzero(~mask & ~task.ready).tolist()
            raise ValueError(f"options['reset_mask'] leaves out sub-envs {never}, which have not been reset "
                             "(the first reset, and the one after a failed reset, must include them)")
        return [dict(o) for o in per], mask

    def reset(self, *, seed: int | Sequence[int | None] | None = None,
              options: dict | Sequence[dict | None] | None = None):
        """Reset all sub-envs (or those of ``options["reset_mask"]``); see the class docstring.

        Seeds and every sub-env's options are validated before any sub-env is touched. If a
        sub-env's reset fails (an obstacle over its start), the whole vector env refuses ``step``
        until a reset that includes that sub-env succeeds."""
        seeds = self._seed_list(seed)
        opts, mask = self._options_list(options)
        task = self.task
        self._needs_reset = True
        for i in np.flatnonzero(mask):
            rng, seed_i = self._rngs[i], self._seeds[i]
            if seeds[i] is not None or self._rngs[i] is None:
                rng, seed_i = seeding.np_random(seeds[i])
            task.reset_robot(int(i), rng, opts[i], checked=True)
            if rng is not self._rngs[i]:
                self._rngs[i], self._seeds[i] = rng, seed_i
                self._rng_list = None
            self._errors[i] = None
        self._autoreset[mask] = False
        self._needs_reset = not bool(task.ready.all())
        self._start_trail()
        obs = task.obs.copy()
        return obs, self._vector_info(np.zeros(self.num_envs, dtype=np.bool_))

    def check_can_step(self) -> None:
        """Raise what :meth:`step` would raise for the env's state, whatever the actions:
        ``ResetNeeded`` before a successful reset, ``RuntimeError`` when, with autoreset
        disabled, a sub-env has ended. A wrapper calls it before moving any state of its own (its
        controllers advanced, then the step was refused)."""
        if self._needs_reset:
            raise ResetNeeded("call reset() before step(): the vector env has not been reset, or a sub-env's "
                              "last reset failed")
        if self.autoreset_mode == AutoresetMode.DISABLED and self._autoreset.any():
            raise RuntimeError(f"sub-envs {np.flatnonzero(self._autoreset).tolist()} ended: with autoreset "
                               "disabled, reset them (options={'reset_mask': ...}) before stepping")

    def step(self, actions):
        """Step every sub-env (autoresetting those that ended, in NEXT_STEP mode)."""
        self.check_can_step()
        task, N = self.task, self.num_envs
        resetting = self._autoreset.copy() if self.autoreset_mode == AutoresetMode.NEXT_STEP else None
        any_reset = resetting is not None and bool(resetting.any())
        active = ~resetting if any_reset else None
        a = task.apply_actions(actions, active)
        errored, messages = task.end_blown_up(task.step_physics(), active)
        any_error = bool(errored.any())
        if any_error:
            for i in np.flatnonzero(errored):
                self._errors[i] = messages[i]
        if any_reset or any_error:
            ok = np.ones(N, dtype=np.bool_)
            if any_reset:
                ok &= active
            if any_error:
                ok &= ~errored
            task.observe(a, self._typed_rngs(), ok)
        else:
            task.observe(a, self._typed_rngs())
        reward = task.reward.copy()
        terminated = task.terminated() | errored
        truncated = task.truncated()
        if self.max_episode_steps is not None:
            truncated |= task.steps >= self.max_episode_steps
        if any_reset:
            for i in np.flatnonzero(resetting):
                self._autoreset_robot(int(i))
            reward[resetting] = 0.0
            terminated[resetting] = False
            truncated[resetting] = False
        done = terminated | truncated
        infos = self._vector_info(errored if any_error else None)
        obs = task.obs.copy()
        if self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            final_obs = np.full(N, None, dtype=object)
            for i in np.flatnonzero(done):
                final_obs[i] = obs[i].copy()
            final_info = infos
            for i in np.flatnonzero(done):
                self._autoreset_robot(int(i))
            obs = task.obs.copy()
            infos = self._vector_info(None)
            infos["final_obs"] = final_obs
            infos["_final_obs"] = done.copy()
            infos["final_info"] = final_info
            infos["_final_info"] = done.copy()
            if self.render_index < N and done[self.render_index]:
                self._start_trail()
        else:
            self._autoreset = done
        if any_reset and self.render_index < N and resetting[self.render_index]:
            self._start_trail()
        self._extend_trail()
        if self.render_mode == "human":
            self.render()
        return obs, reward, terminated, truncated, infos

    def _autoreset_robot(self, i: int) -> None:
        """Reset sub-env i inside ``step``; if that fails, the env refuses ``step`` until reset."""
        try:
            self.task.reset_robot(i, self._rngs[i])
        except BaseException:
            self._needs_reset = True
            raise
        self._errors[i] = None

    def _vector_info(self, errored: np.ndarray | None) -> dict[str, Any]:
        """The batched info (:func:`~azimut_env.task.info.batch_info`) of the current state;
        ``errored``: the sub-envs whose physics blew up on this step."""
        if errored is None or not errored.any():
            return batch_info(self.task)
        return batch_info(self.task, [self._errors[i] if errored[i] else None for i in range(self.num_envs)])

    # ------------------------------------------------------------------ rendering

    def _render_robot(self) -> int:
        return self.render_index

    def close_extras(self, **kwargs: Any) -> None:
        self._close_renderer()


AzimutVectorEnv.__init__.__signature__ = front_signature(AzimutVectorEnv.__init__)


def make_v1_vector(**kwargs: Any) -> AzimutVectorEnv:
    """``gymnasium.make_vec("Azimut-v1", ...)``: this env with v1's robot and reward
    (:func:`~azimut_env.task.config.v1_kwargs`), the keyword arguments otherwise as given."""
    return AzimutVectorEnv(**v1_kwargs(kwargs))
