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

__all__ = ["robot_text", "controller_robots", "robot_sentence"]


def robot_text(env_kwargs: dict) -> tuple[str, str]:
    """``(robot, imperfections)`` in words of an env's keyword arguments: the preset's name, ``file
    PATH`` or ``azimut3``; the imperfections preset the robot carries (``paper``, ``ideal``) or
    ``the robot's own``."""
    import os

    from azimut_env.imperfections import imperfections_of
    from azimut_env.task.config import robot_of

    robot = env_kwargs.get("robot")
    name = f"file {robot}" if robot and (os.sep in str(robot) or str(robot).endswith(".toml")) else (robot or "azimut3")
    return name, imperfections_of(robot_of(env_kwargs)) or "the robot's own"


def controller_robots(specs: Sequence[str], names: dict[str, str], speed_scale: float,
                      campaign_kwargs: dict, campaign_name: str | None = None) -> dict[str, dict]:
    """Per controller name, the env keyword arguments of its robot (``env_kwargs``: its own under
    ``campaign_kwargs``), and that robot in words (``robot``: ``campaign_name`` where it is the
    campaign's; ``imperfections``)."""
    from jobs.eval.controllers import build_controller

    out = {}
    for spec in specs:
        own = dict(getattr(build_controller(spec, speed_scale), "env_kwargs", None) or {})
        kw = {k: v for k, v in {**own, **campaign_kwargs}.items() if k in ("robot", "imperfections")}
        robot, imperfections = robot_text(kw)
        if campaign_name and kw.get("robot") == campaign_kwargs.get("robot"):
            robot = campaign_name
        out[names.get(spec, spec)] = {"env_kwargs": kw, "robot": robot, "imperfections": imperfections}
    return out


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
