"""Where the actions enter: check, clip, action → set-points, and the command latency.

:class:`CommandPath` turns the normalised actions of N robots (N, 2n) into the motors'
set-points (β_cmd, φ̇_cmd) (``params.setpoints_from_action``, compiled), refusing NaN or inf
before anything changes, and with ``TaskConfig.action_latency`` = k > 0 delays them by k control
periods through a per-robot FIFO (emptied at each reset: the motors hold the reset set-points for
the first k steps). The set-points go to the physics through ``AzimutPhysics.set_setpoints``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from azimut_env.action_map import ActuatorLimits, setpoints_row
from azimut_env.physics.layout import CMD

__all__ = ["CommandPath", "float32_copy", "remember_action"]


@njit(cache=True)
def _apply_actions_kernel(a, cmd, rows, steer_min, steer_max, wheel_speed_max):
    """Actions a (N, 2n) float32 for the robots where ``rows`` is True: return the first row with
    NaN/inf (writing nothing), else clip them to [−1, 1] in place and write the set-points of
    ``params.setpoints_from_action`` into cmd (N, n, 2) and return −1."""
    n = cmd.shape[1]
    for i in range(a.shape[0]):
        if rows[i]:
            for j in range(a.shape[1]):
                if not math.isfinite(a[i, j]):
                    return i
    for i in range(a.shape[0]):
        if rows[i]:
            for j in range(a.shape[1]):
                a[i, j] = min(max(a[i, j], -1.0), 1.0)
            setpoints_row(a, i, n, steer_min, steer_max, wheel_speed_max, cmd)
    return -1


@njit(cache=True)
def _shift_fifo_kernel(fifo, new, cmd, rows):
    """Command latency, for the robots where ``rows`` is True: the oldest set-points fifo[i, 0]
    go to cmd[i], the queue (N, k, n, 2) moves up by one and new[i] enters at its end."""
    k = fifo.shape[1]
    for i in range(fifo.shape[0]):
        if rows[i]:
            cmd[i] = fifo[i, 0]
            for j in range(k - 1):
                fifo[i, j] = fifo[i, j + 1]
            fifo[i, k - 1] = new[i]


def float32_copy(a: np.ndarray) -> np.ndarray:
    """A float32 copy of the real array ``a``; values beyond float32 become ±inf silently (the
    callers refuse them). The overflow guard (``np.errstate``, costly next to the copy) is entered
    only for wider floats: integers and float16/32 cannot overflow float32."""
    if a.dtype.kind == "f" and a.dtype.itemsize > 4:
        with np.errstate(over="ignore"):
            return np.array(a, dtype=np.float32)
    return np.array(a, dtype=np.float32)


class CommandPath:
    """Actions → set-points of N robots with n wheels, with a latency of ``latency`` control periods."""

    def __init__(self, limits: ActuatorLimits, n_robots: int, n: int, latency: int) -> None:
        self.n_robots, self.n = n_robots, n
        self._lim = (*limits.steer_action_range, float(limits.wheel_speed_max))
        # command latency: set-points waiting to be applied, oldest first (N, k, n, len(CMD))
        self.fifo = np.zeros((n_robots, latency, n, len(CMD)))
        self._new = np.zeros((n_robots, n, len(CMD)))
        self._out = np.zeros((n_robots, n, len(CMD)))  # the set-points leaving the FIFOs
        self._all = np.ones(n_robots, dtype=np.bool_)

    def reset_robot(self, i: int, setpoints: np.ndarray) -> None:
        """Robot i's queue holds ``setpoints`` (n, len(CMD)) (its motors' set-points at reset)."""
        self.fifo[i] = setpoints

    def apply(self, actions: np.ndarray, physics, rows: np.ndarray | None = None, owned: bool = False) -> np.ndarray:
        """Check, clip and write the set-points of ``actions`` (N, 2n) for ``rows`` (default all)
        to ``physics``. With latency k > 0 the set-points enter the rows' FIFOs and the ones given
        k calls earlier go to the motors. Returns the clipped float32 copy (``owned``: ``actions``
        is already a float32 (N, 2n) copy of the caller's, clipped in place). Raises
        ``ValueError`` (changing nothing) on NaN or inf."""
        a = actions
        if not owned:
            a = np.asarray(actions)
            if a.dtype.kind not in "biuf":
                raise TypeError(f"actions must hold real numbers, got dtype {a.dtype}")
            a = float32_copy(a)
        if a.shape != (self.n_robots, 2 * self.n) or a.dtype != np.float32:
            raise ValueError(f"actions must have shape {(self.n_robots, 2 * self.n)}, got {np.shape(actions)}")
        rows = self._all if rows is None else rows
        bad = _apply_actions_kernel(a, self._new, rows, *self._lim)
        if bad >= 0:
            raise ValueError(f"action contains NaN or inf (robot {bad}): {np.asarray(actions)[bad]}")
        cmd = self._new
        if self.fifo.shape[1] > 0:
            cmd = self._out
            _shift_fifo_kernel(self.fifo, self._new, cmd, rows)
        physics.set_setpoints(cmd, None if rows is self._all else rows)
        return a


@njit(cache=True)
def remember_action(ta, rows, action):
    """The last stage of the pipeline's reward: ``ta.prev_action`` takes the step's clipped
    ``action`` (N, 2n) float32 for the robots of ``rows`` (the reward's action rate reads the
    previous one, the observation this one)."""
    for i in range(rows.shape[0]):
        if rows[i]:
            for j in range(action.shape[1]):  # element by element: no array view per robot
                ta.prev_action[i, j] = action[i, j]
