"""What happens to a robot outside the stages of a step: reset events and interval events.

A reset draws the new episode from the robot's generator through :data:`RESET_EVENTS`, in the
order of the table (the order of the draws, the same whatever N, so that robot i of a vector env
replays a single env seeded the same way), then runs the reset pipeline
(:func:`~azimut_env.task.pipeline.reset_stages`). Each event is ``event(task, i, rng, episode)``:
it reads and writes the :class:`~azimut_env.task.core.AzimutTask` for robot i, drawing from
``rng``, and shares what later events need through ``episode`` (:class:`Episode`: the reset's
options, the track, the start progress, the start pose and steering).

:data:`INTERVAL_EVENTS` run before the physics of every step (``AzimutTask.step_physics``):
``event(task)`` for all robots (the kicks due now).

**To add** a randomisation or a perturbation: its function and its row here (a reset event that
draws goes where its draws should come in the order).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from azimut_env.params import action_from_setpoints
from azimut_env.physics.layout import MS
from azimut_env.physics.wheel_params import randomized_wheel_params
from azimut_env.task.reset_options import start_progress_on
from azimut_env.task.start_state import start_configuration
from azimut_env.tracks import Track

__all__ = ["Episode", "Event", "RESET_EVENTS", "INTERVAL_EVENTS"]


@dataclass
class Episode:
    """What a reset's events share: the options, then what the events draw."""

    options: dict[str, Any]
    fresh_space: bool
    track: Track | None = None
    s0: float = 0.0
    pose: np.ndarray = field(default_factory=lambda: np.zeros(3))
    beta: np.ndarray | None = None


class Event(NamedTuple):
    """One event: a row of :data:`RESET_EVENTS` or :data:`INTERVAL_EVENTS`."""

    name: str
    function: Callable
    doc: str


def _track(task, i: int, rng: np.random.Generator, ep: Episode) -> None:
    spec = ep.options.get("track", task.track_spec)
    ep.track = spec if isinstance(spec, Track) else task.builtin_track(spec, rng)
    ep.s0 = start_progress_on(ep.track, float(ep.options.get("start_progress", 0.0)))  # before any state changes
    task.set_track(i, ep.track)
    if ep.fresh_space:  # per-episode obstacles come with a Space of their own (check_reset_options)
        task.physics.rebuild(ep.options.get("obstacles", task.default_obstacles))


def _kick(task, i: int, rng: np.random.Generator, ep: Episode) -> None:
    task.kicks[i] = dict(ep.options["kick"]) if "kick" in ep.options else None
    task.kick_step[i] = task.kicks[i]["step"] if "kick" in ep.options else -1


def _randomise(task, i: int, rng: np.random.Generator, ep: Episode) -> None:
    wp, mass = randomized_wheel_params(task.default_wheel_params[i], task.params, task.config.domain_randomization,
                                       rng)
    task.physics.set_wheel_params(wp, robot=i)
    task.physics.set_chassis_mass(i, mass)


def _sensor_bias(task, i: int, rng: np.random.Generator, ep: Episode) -> None:
    task.sensors.draw_bias(i, rng)


def _start(task, i: int, rng: np.random.Generator, ep: Episode) -> None:
    phys = task.physics
    ep.pose, ep.beta = start_configuration(ep.track, ep.s0, task.config.start_noise, task.params.geometry, rng)
    phys.reset_robot(i, ep.pose, ep.beta)
    task.commands.reset_robot(i, phys.commands[i])  # latency: the reset set-points are held for k steps
    clash = phys.overlapping_obstacles(i)
    if clash:
        raise ValueError(f"obstacles {clash} overlap the robot's starting footprint at {np.round(ep.pose, 3)}: "
                         "move them off the start of the track")
    task.sensors.start(i, phys.motor_state[i, :, MS.PHI])
    task.prev_action[i] = action_from_setpoints(ep.beta, np.zeros(task.n), task.params.limits)
    task.steps[i] = 0
    task.s[i] = ep.s0  # the track stage starts its projection there


def _sensor_noise(task, i: int, rng: np.random.Generator, ep: Episode) -> None:
    task.sensors.draw_noise_robot(i, rng)


def _localisation(task, i: int, rng: np.random.Generator, ep: Episode) -> None:
    if task.odometry is not None:
        task.odometry.spawn(i, rng)


_V = Event
#: the events of a reset, in the order of their draws from the robot's generator
RESET_EVENTS: tuple[Event, ...] = (
    _V("track", _track, "the episode's track (a random one drawn), start progress, obstacles (single env)"),
    _V("kick", _kick, "the kick of options['kick'] scheduled"),
    _V("randomise", _randomise, "domain randomisation of the wheel parameters and the chassis mass"),
    _V("sensor_bias", _sensor_bias, "the steering encoders' offsets"),
    _V("start", _start, "start pose and steering with start_noise, at rest; the reset set-points"),
    _V("sensor_noise", _sensor_noise, "the first readings' noise"),
    _V("localisation", _localisation, "the localisation's generator (pose_source='odometry')"),
)


def _kicks_due(task) -> None:
    if task.kick_step.max() >= 0:
        for i in np.flatnonzero(task.kick_step == task.steps):
            kick = task.kicks[i]
            task.physics.kick(int(i), kick["wheels"], kick["impulse"])


#: the events before every step's physics
INTERVAL_EVENTS: tuple[Event, ...] = (
    _V("kick", _kicks_due, "the kicks due at this step: an impulse on the wheels named"),
)
del _V
