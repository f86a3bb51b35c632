"""Training and evaluation environments for ``train``: N robots of ``Azimut-v2`` in one
:class:`~azimut_env.vector_env.AzimutVectorEnv`, behind the chosen action space, as an SB3 ``VecEnv``.

Action spaces (``ACTIONS``):

* ``raw``: the env's own per-wheel set-points (``Box(-1, 1, (8,))``);
* ``residual``: path follower + ICR controller with a bounded policy correction (zero action = the
  reference controller);
* ``icr_rate``: the policy moves the ICR target on the sphere and changes μ_d (rates);

the last two are :class:`control.action_spaces.vector.VectorControllerAction`. The SB3 adapter is
:class:`train.sb3_vec_env.AzimutSB3VecEnv` (needs the ``rl`` extra).
"""

from __future__ import annotations

from typing import Any

from gymnasium.vector import AutoresetMode

__all__ = ["ACTIONS", "canonical_action", "make_vector_env", "make_sb3_env"]

#: action space name (CLI spelling) -> VectorControllerAction kind (None: raw set-points)
ACTIONS = {"raw": None, "residual": "residual", "icr-rate": "icr_rate"}


def canonical_action(name: str) -> str:
    """The :data:`ACTIONS` key of ``name``, also when written as the tables print it (``icr_rate``,
    the action wrapper's name): ``--action``'s ``type=``. Other names are returned as given, for
    argparse's choices to refuse."""
    return name.replace("_", "-") if name.replace("_", "-") in ACTIONS else name


def action_key(action: str) -> str:
    """The hyperparameter-file key of an action space (``icr-rate`` -> ``icr_rate``)."""
    if action not in ACTIONS:
        raise ValueError(f"unknown action space {action!r}; choose from {', '.join(ACTIONS)}")
    return action.replace("-", "_")


def make_vector_env(action: str, num_envs: int, track: str = "random",
                    autoreset_mode: AutoresetMode = AutoresetMode.SAME_STEP, env_kwargs: dict[str, Any] | None = None,
                    correction_cost: float = 0.0):
    """An ``AzimutVectorEnv`` of ``num_envs`` robots on ``track``, behind ``action``'s wrapper
    (``correction_cost``: the residual's correction cost weight, see
    :class:`~control.action_spaces.vector.VectorControllerAction`)."""
    from azimut_env.vector_env import AzimutVectorEnv

    action_key(action)
    venv = AzimutVectorEnv(num_envs=num_envs, track=track, autoreset_mode=autoreset_mode, **(env_kwargs or {}))
    kind = ACTIONS[action]
    if correction_cost and kind != "residual":
        raise ValueError(f"correction_cost applies to the residual action space only, not {action!r}")
    if kind is None:
        return venv
    from control.action_spaces.vector import VectorControllerAction

    return VectorControllerAction(venv, action=kind, correction_cost=correction_cost)


def make_sb3_env(action: str, num_envs: int, track: str = "random", env_kwargs: dict[str, Any] | None = None,
                 correction_cost: float = 0.0):
    """:func:`make_vector_env` as an SB3 ``VecEnv`` (same-step autoreset)."""
    from train.sb3_vec_env import AzimutSB3VecEnv

    return AzimutSB3VecEnv(venv=make_vector_env(action, num_envs, track, AutoresetMode.SAME_STEP, env_kwargs,
                                                correction_cost))
