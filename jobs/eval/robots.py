"""The robot each controller of an ``azimut eval`` campaign actually drives.

An episode's env is made of the controller's own ``env_kwargs`` (a controller of yours, or a
trained policy's run) under the campaign's (``--robot``, ``--robot-file``, ``--imperfections``,
which win where given: :func:`control.rollout.run_episodes`), so a controller whose
``env_kwargs`` say ``imperfections="ideal"`` runs the ideal robot when the command line does not
name the imperfections. The report names that robot, per controller where they differ
(:func:`controller_robots`).
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["ROBOT_KEYS", "robot_text", "controller_robots",
           "robot_sentence", "env_kwargs_sentence", "limits_sentence"]

#: the env keyword arguments that make the robot (the report's robot label)
ROBOT_KEYS = ("robot", "imperfections", "params")
def robot_text(env_kwargs: dict) -> tuple[str, str]:
    """``(robot, imperfections)`` in words of an env's keyword arguments: the preset's name, ``file
    PATH`` or ``azimut3``; the imperfections preset the robot carries (``paper``, ``ideal``) or
    ``the robot's own``."""
    import os

    from azimut_env.imperfections import imperfections_of
    from azimut_env.task.config import robot_of

    robot = env_kwargs.get("robot")
    if env_kwargs.get("params") is not None and not robot:
        params = _params_of(env_kwargs)
        return _preset_of(params) or "its own robot", imperfections_of(params) or "the robot's own"
    name = f"file {robot}" if robot and (os.sep in str(robot) or str(robot).endswith(".toml")) else (robot or "azimut3")
    return name, imperfections_of(robot_of(env_kwargs)) or "the robot's own"


def _params_of(env_kwargs: dict):
    from azimut_env.task.config import resolve_params

    return resolve_params(env_kwargs.get("params"), None, 1.0, env_kwargs.get("robot"),
                          env_kwargs.get("imperfections"))


def _preset_of(params) -> str | None:
    """The preset ``params`` is (whatever its imperfections), or None: a robot of its own."""
    from azimut_env.imperfections import IMPERFECTION_PRESETS, with_imperfections
    from azimut_env.params import RobotParams
    from azimut_env.robot_file import PRESET_NAMES

    for name in PRESET_NAMES:
        base = RobotParams.preset(name)
        try:
            if any(with_imperfections(base, i) == with_imperfections(params, i) for i in IMPERFECTION_PRESETS):
                return name
        except (ValueError, TypeError):  # another number of wheels
            continue
    return None


def _value_text(value) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _jsonable(value):
    import json

    try:
        json.dumps(value, allow_nan=False)
    except (TypeError, ValueError):
        return _value_text(value)
    return value


def controller_robots(specs: Sequence[str], names: dict[str, str], speed_scale: float,
                      campaign_kwargs: dict, campaign_name: str | None = None,
                      campaign_set: Sequence[str] = ()) -> dict[str, dict]:
    """Per controller name, the env keyword arguments of its robot (``env_kwargs``: its own under
    ``campaign_kwargs``), that robot in words (``robot``: ``campaign_name`` where it is the
    campaign's, ``its own robot`` for ``params`` of no preset; ``imperfections``) and its other
    env keyword arguments that took effect (``other``: those neither of the robot nor set by the
    campaign, ``campaign_set``; values as JSON, or their repr)."""
    from jobs.eval.controllers import build_controller, check_env_kwargs

    out = {}
    for spec in specs:
        own = check_env_kwargs(spec, build_controller(spec, speed_scale))
        kw = {k: v for k, v in {**own, **campaign_kwargs}.items() if k in ("robot", "imperfections")}
        if own.get("params") is not None and not campaign_kwargs.get("robot"):
            kw["params"] = own["params"]
        robot, imperfections = robot_text(kw)
        if campaign_name and "params" not in kw and kw.get("robot") == campaign_kwargs.get("robot"):
            robot = campaign_name
        other = {k: _jsonable(v) for k, v in own.items()
                 if k not in ROBOT_KEYS and k not in campaign_kwargs and k not in campaign_set}
        out[names.get(spec, spec)] = {"env_kwargs": kw, "robot": robot, "imperfections": imperfections,
                                      "other": other}
    return out


def env_kwargs_sentence(env_kwargs: dict[str, dict]) -> str | None:
    """``NAME ran with env_kwargs k=v, ...`` per controller (``env_kwargs``: name -> its env keyword
    arguments beyond its robot, :func:`controller_robots`'s ``other``) that has some, or None."""
    parts = [f"{name} ran with env_kwargs " + ", ".join(f"{k}={_value_text(v)}" for k, v in other.items())
             for name, other in env_kwargs.items() if other]
    return "; ".join(parts) + "." if parts else None


def limits_sentence(limits: str | dict) -> str:
    """The actuator limits in words: one text, or per controller (``{name: text}``) grouped."""
    if isinstance(limits, str):
        return limits
    groups: dict[str, list[str]] = {}
    for name, text in limits.items():
        groups.setdefault(text, []).append(name)
    if len(groups) == 1:
        return next(iter(groups))
    return "; ".join(f"limits for {', '.join(members)}: {text}" for text, members in groups.items())


def robot_sentence(robots: dict[str, dict]) -> str:
    """``Robot R (imperfections: I)`` when every controller drove the same robot, else one clause
    per robot naming its controllers."""
    groups: dict[tuple[str, str], list[str]] = {}
    for name, r in robots.items():
        groups.setdefault((r["robot"], r["imperfections"]), []).append(name)
    if len(groups) <= 1:
        robot, imperfections = next(iter(groups), ("azimut3", "paper"))
        return f"Robot {robot} (imperfections: {imperfections})"
    return "Robots differ by controller (a controller's env_kwargs): " + "; ".join(
        f"{robot} (imperfections: {imperfections}) for {', '.join(members)}"
        for (robot, imperfections), members in groups.items())
