"""azimut_env: a pymunk AZIMUT-3 with compliant steering, as the Gymnasium env ``Azimut-v1``.

Importing this package only registers the environment (by entry-point string); the physics,
pymunk and numba load when the env is made. Modules: ``params`` (physical parameters, actuator
limits, action <-> set-point map), ``physics`` (N robots in one pymunk Space: ``engine``,
``kernels``, ``layout``, ``tire``, ``actuators``, ``stability``, ...), ``tracks``, ``task`` (the
task over N robots: ``core`` with the step's data flow, ``config`` (``TaskConfig``) and the stages
``actions``, ``sensors``, ``termination``, ``reward``, ``observation``, ``reset_options``,
``localisation`` (the pose source), ``lap_time``), ``frontend`` and ``interface`` (what both envs
share; the controller ``Protocol``), ``env`` (the single env, N = 1), ``vector_env``
(``AzimutVectorEnv``: N robots in one Space, also what ``gymnasium.make_vec("Azimut-v1",
num_envs=N, vectorization_mode="vector_entry_point")`` returns), ``rendering``, ``validation``.
(The SB3 adapter is ``train.sb3_vec_env``; ``azimut bench-env`` and ``azimut sim-paper`` are in
``jobs``.)
"""

from gymnasium.envs.registration import register, registry

__all__ = ["ENV_ID"]

#: The current version. ``Azimut-v0`` (the first reward and physics) is retired: ``gymnasium.make``
#: of it raises ``gymnasium.error.DeprecatedEnv`` naming ``Azimut-v1`` (Gymnasium's versioning:
#: only the latest version of an env is registered). See ``AzimutEnv``'s "Version History".
ENV_ID = "Azimut-v1"

if ENV_ID not in registry:
    # no registry-wide step limit: the env truncates each episode at time_limit_factor (1.5) × the
    # reference controller's nominal lap on its track (gymnasium.make(..., max_episode_steps=K) adds a TimeLimit)
    # disable_env_checker: Gymnasium's PassiveEnvChecker marks its one-time reset check as done
    # *before* the reset runs, so a reset that this env refuses (bad seed or option, validated
    # before any state changes) left the checker without data and the next good step raised a
    # TypeError inside the checker. The env passes gymnasium's and SB3's full ``check_env`` in the
    # tests (tests/azimut_env/test_env_api.py), which is the stronger check.
    register(id=ENV_ID, entry_point="azimut_env.env:AzimutEnv",
             vector_entry_point="azimut_env.vector_env:AzimutVectorEnv",
             max_episode_steps=None, disable_env_checker=True)
