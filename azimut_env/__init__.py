"""azimut_env: a pymunk AZIMUT-3 with compliant steering, as the Gymnasium env ``Azimut-v2``.

Importing this package only registers the environments (by entry-point strings) and names
numba's cache folder (:mod:`estimation.numba_cache`, which does not import numba); the physics,
pymunk, numba and ``estimation``'s modules load when an env is made (``import azimut_env``
takes about gymnasium's import time; ``tests/architecture/test_imports.py`` checks what it
loads). Modules: ``params`` (physical parameters, actuator limits, action <-> set-point map),
``imperfections`` (the "paper"/"ideal" presets), ``physics``
(N robots in one pymunk Space: ``engine``, ``kernels``, ``layout``, ``tire``, ``actuators``,
``stability``, ...), ``tracks``, ``task`` (the task over N robots: ``core`` with the step's data
flow, ``config`` (``TaskConfig``) and the stages ``actions``, ``sensors``, ``termination``,
``reward``, ``observation``, ``reset_options``, ``localisation`` (the pose source),
``lap_time``), ``frontend`` and ``interface`` (what both envs share; the controller
``Protocol``), ``env`` (the single env, N = 1), ``vector_env`` (``AzimutVectorEnv``: N robots in
one Space, also what ``gymnasium.make_vec("Azimut-v2", num_envs=N,
vectorization_mode="vector_entry_point")`` returns), ``rendering``, ``validation``. (The SB3
adapter is ``train.sb3_vec_env``; ``azimut bench-env`` and ``azimut sim-paper`` are in ``jobs``.)
"""

import estimation.numba_cache  # noqa: F401, I001 (first: numba's cache keyed by the sources, before any kernel)
from gymnasium.envs.registration import register, registry

__all__ = ["ENV_ID", "ENV_ID_V1"]

#: The current version: the physics v3 with the imperfections the paper names (``imperfections``
#: default ``"paper"``, :mod:`azimut_env.imperfections`) and the antagonism priced by the reward.
#: ``Azimut-v1`` (physics v2, no steering friction, module mass on the axis, no drive torque–speed
#: line, no geometric imperfections; the null-space force priced) stays registered as the same env
#: with ``imperfections="ideal"`` and v1's reward weights, bit for bit what it was: Gymnasium
#: warns that it is out of date when it is made. ``Azimut-v0`` (the first reward and physics) is
#: retired: ``gymnasium.make`` of it raises ``gymnasium.error.DeprecatedEnv``. See ``AzimutEnv``'s
#: "Version History".
ENV_ID = "Azimut-v2"
#: the previous version, kept: the v2 physics (``imperfections="ideal"``)
ENV_ID_V1 = "Azimut-v1"

# no registry-wide step limit: the env truncates each episode at time_limit_factor (1.5) × the
# reference controller's nominal lap on its track (gymnasium.make(..., max_episode_steps=K) adds a TimeLimit)
# disable_env_checker: Gymnasium's PassiveEnvChecker marks its one-time reset check as done
# *before* the reset runs, so a reset that this env refuses (bad seed or option, validated
# before any state changes) left the checker without data and the next good step raised a
# TypeError inside the checker. The env passes gymnasium's and SB3's full ``check_env`` in the
# tests (tests/azimut_env/test_env_api.py), which is the stronger check.
# Azimut-v1 is the same env with v1's robot and reward: entry points that merge the given keyword
# arguments onto them (azimut_env.task.config.v1_kwargs), so that a reward_weights given to make does
# not drop v1's weights as registration kwargs would.
for _id, _entry, _vector in ((ENV_ID, "azimut_env.env:AzimutEnv", "azimut_env.vector_env:AzimutVectorEnv"),
                             (ENV_ID_V1, "azimut_env.env:make_v1", "azimut_env.vector_env:make_v1_vector")):
    if _id not in registry:
        register(id=_id, entry_point=_entry, vector_entry_point=_vector, max_episode_steps=None,
                 disable_env_checker=True)
