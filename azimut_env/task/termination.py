"""When an episode of ``Azimut-v2`` ends: one table of end conditions, and the time limit.

:data:`TERMINATION_TERMS` is the single description of termination, like
:data:`~azimut_env.task.reward.REWARD_TERMS` is of the reward: each row (:class:`EndCondition`)
names a condition (also its ``info`` key, a bool), says whether it is a failure (a failure pays the
off-track penalty: the reward's ``off_track`` term reads ``ta.failed``), gives its function and
what it means. An episode is terminated when any condition holds (``AzimutTask.terminated``);
``ta.ended`` (N, T) holds each condition's flag of the last step, in the table's order. A physics
blow-up ends the episode as well (``AzimutTask.end_blown_up``), with the penalty as its reward.

A condition's function is ``_end_<name>(ta, i) -> bool``, compiled with ``numba.njit``: robot i's
flag, from the task's struct ``ta`` (:data:`azimut_env.task.arrays.FIELDS`: the true track state,
the settings). It may keep state of its own in the struct (``stalled``: the best progress and its
step). **To add a condition**: its function and its row; the ``info`` key, the docs and the
termination follow (:func:`terminate_kernel` is generated from the table).

Truncation: each episode's step limit is ``time_limit_factor`` × the reference controller's
nominal lap on its track (:mod:`azimut_env.task.lap_time`) / the control period
(:func:`episode_step_limit`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numba import njit

from azimut_env.task.codegen import check_table, markdown_table, row_stage
from azimut_env.task.lap_time import reference_lap_time
from azimut_env.tracks import TQ, Track

__all__ = ["EndCondition", "TERMINATION_TERMS", "terminate_kernel", "start_episode", "termination_table",
           "failure_flags", "episode_step_limit", "NO_LIMIT"]

#: the step limit of an episode without one
NO_LIMIT = int(np.iinfo(np.int64).max)

_LAT, _S = int(TQ.LATERAL), int(TQ.S)


@njit(cache=True)
def _end_off_track(ta, i):
    return abs(ta.track_out[i, _LAT]) > ta.max_lateral_error


@njit(cache=True)
def _end_finished(ta, i):
    return ta.track_out[i, _S] >= ta.track_length[i] - 1e-6


@njit(cache=True)
def _end_stalled(ta, i):
    if ta.s[i] > ta.s_best[i] + ta.stall_distance:  # new progress: remembered
        ta.s_best[i] = ta.s[i]
        ta.best_step[i] = ta.steps[i]
    if ta.stall_time <= 0:
        return False
    on_track = not abs(ta.track_out[i, _LAT]) > ta.max_lateral_error
    return on_track and (ta.steps[i] - ta.best_step[i]) * ta.control_period >= ta.stall_time


class EndCondition(NamedTuple):
    """One end condition: a row of :data:`TERMINATION_TERMS`."""

    name: str
    #: a failure pays the off-track penalty (``reward_weights["off_track"]``)
    failure: bool
    #: ``numba.njit`` function ``(ta, i) -> bool`` (see the module docstring)
    function: Callable
    doc: str


_E = EndCondition
#: the end conditions, in the order of ``ta.ended``'s columns and of the info keys
TERMINATION_TERMS: tuple[EndCondition, ...] = (
    _E("off_track", True, _end_off_track, "left the track: abs(e_lat) > max_lateral_error"),
    _E("finished", False, _end_finished, "finished the track (one lap of a closed one)"),
    _E("stalled", True, _end_stalled, "stall_time without stall_distance of progress (0: never)"),
)
del _E


def failure_flags(terms: tuple[EndCondition, ...] | None = None) -> np.ndarray:
    """(T,) bool: which conditions are failures."""
    return np.array([t.failure for t in (TERMINATION_TERMS if terms is None else terms)], dtype=np.bool_)


def termination_table() -> str:
    """The Markdown table of the end conditions (name, failure, condition) for the docs."""
    return markdown_table(("name", "penalised", "ends the episode when"),
                          [(t.name, "yes" if t.failure else "no", t.doc) for t in TERMINATION_TERMS])


def terminate_kernel(terms: tuple[EndCondition, ...] | None = None, jit: bool = True) -> Callable:
    """The termination stage of the pipeline, ``terminate(ta, rows, action)``, generated from the
    table (default: :data:`TERMINATION_TERMS` as it is now): each condition's flag of each robot of
    ``rows`` into ``ta.ended[i, j]``, and ``ta.failed[i]``: a failure among them."""
    terms = TERMINATION_TERMS if terms is None else terms
    check_table(terms, "end conditions", 2)
    body = ["failed = False"]
    for j, t in enumerate(terms):
        body += [f"ta.ended[i, {j}] = _end_{j}(ta, i)  # {t.name}"] + ([f"failed = failed or ta.ended[i, {j}]"]
                                                                     if t.failure else [])
    namespace = {f"_end_{j}": t.function for j, t in enumerate(terms)}
    return row_stage("_terminate", body + ["ta.failed[i] = failed"], namespace, __file__, __name__, jit)


@njit(cache=True)
def start_episode(ta, rows, action):
    """The termination's part of a reset: no condition holds, no reward yet, the best progress the
    start's (``ta.s`` after the track stage)."""
    for i in range(rows.shape[0]):
        if rows[i]:
            ta.ended[i] = False
            ta.failed[i] = False
            ta.reward[i] = 0.0
            ta.reward_terms[i] = 0.0
            ta.s_best[i] = ta.s[i]
            ta.best_step[i] = 0


def episode_step_limit(track: Track, time_limit_factor: float, control_period: float, geometry, limits) -> int:
    """The step limit ceil(factor · T / dt) of an episode on ``track``, T the ICR reference
    controller's nominal lap (:func:`~azimut_env.task.lap_time.reference_lap_time`); :data:`NO_LIMIT`
    for factor 0 (or a limit beyond any run)."""
    if time_limit_factor > 0:
        steps = time_limit_factor * reference_lap_time(track, geometry, limits) / control_period
    else:
        steps = 0.0
    return int(math.ceil(steps)) if 0 < steps < 9e18 else NO_LIMIT
