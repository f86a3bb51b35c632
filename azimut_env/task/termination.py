"""When an episode of ``Azimut-v2`` ends: termination (off the track, finished, stalled) and the
time limit (truncation).

Per step, after the track query (:meth:`~azimut_env.task.core.AzimutTask.observe`):
:func:`check_track_limits` flags the robots whose lateral error exceeds ``max_lateral_error``
(off the track) or whose progress reached the end of the track (finished; one lap of a closed
track); the reward then charges the off-track penalty; :func:`check_stalls` flags the robots
without ``stall_distance`` of new progress for ``stall_time`` (which pay the penalty too). A
physics blow-up ends the episode as well (``AzimutTask.end_blown_up``).

Truncation: each episode's step limit is ``time_limit_factor`` × the reference controller's
nominal lap on its track (:mod:`azimut_env.task.lap_time`) / the control period (:func:`episode_step_limit`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from azimut_env.task.lap_time import reference_lap_time
from azimut_env.tracks import TQ, Track

__all__ = ["check_track_limits", "check_stalls", "episode_step_limit", "NO_LIMIT"]

#: the step limit of an episode without one
NO_LIMIT = int(np.iinfo(np.int64).max)


@njit(cache=True)
def check_track_limits(rows, track_state, lengths, max_lateral_error, off_track, finished):
    """For the robots where ``rows`` is True, from the true track state (N, 5) (columns
    :class:`~azimut_env.tracks.TQ`) and each track's length (N,) [m]: ``off_track`` (|e_lat| >
    ``max_lateral_error``) and ``finished`` (s at the end of the track, to 1 µm)."""
    for i in range(rows.shape[0]):
        if rows[i]:
            off_track[i] = abs(track_state[i, TQ.LATERAL]) > max_lateral_error
            finished[i] = track_state[i, TQ.S] >= lengths[i] - 1e-6


def check_stalls(rows: np.ndarray, s: np.ndarray, s_best: np.ndarray, best_step: np.ndarray, steps: np.ndarray,
                 off_track: np.ndarray, stall_time: float, stall_distance: float, dt: float) -> np.ndarray | None:
    """Stall detection for the robots where ``rows`` is True: a robot that got ``stall_distance``
    [m] past its best progress ``s_best`` records it (``s_best``, ``best_step``, updated in place);
    with ``stall_time`` > 0 [s], returns the (N,) mask of robots (not off the track) without such
    progress for ``stall_time``; None when stalls are off."""
    better = rows & (s > s_best + stall_distance)
    s_best[better] = s[better]
    best_step[better] = steps[better]
    if stall_time <= 0:
        return None
    return rows & ~off_track & ((steps - best_step) * dt >= stall_time)


def episode_step_limit(track: Track, time_limit_factor: float, control_period: float, geometry, limits) -> int:
    """The step limit ceil(factor · T / dt) of an episode on ``track``, T the ICR reference
    controller's nominal lap (:func:`~azimut_env.task.lap_time.reference_lap_time`); :data:`NO_LIMIT`
    for factor 0 (or a limit beyond any run)."""
    if time_limit_factor > 0:
        steps = time_limit_factor * reference_lap_time(track, geometry, limits) / control_period
    else:
        steps = 0.0
    return int(math.ceil(steps)) if 0 < steps < 9e18 else NO_LIMIT
