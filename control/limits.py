"""Actuator limits as ``control/`` uses them.

The limits themselves are :class:`azimut_env.params.ActuatorLimits` (one definition, shared with the
env). The controllers compute *commanded* set-points (β_c, φ̇_c) once per control period; the
limits bound the commands and their finite differences over a period: |β̇_c| ≤ steer_rate_max
[rad/s], |β̈_c| ≤ steer_accel_max [rad/s²], |φ̇_c| ≤ wheel_speed_max [rad/s] and
|φ̈_c| ≤ wheel_accel_max [rad/s²]. Every controller gets the same ones, so comparisons are fair.

:class:`SetpointLimitCheck` is the commanded-limit check of the episode loop (``azimut eval``'s
``limit_violation_steps``): it reads the set-points themselves, whatever rates a controller
declares. Per robot and control period k (period dt):

* β̇_k = (β_k − β_{k−1}) / dt, β̈_k = (β̇_k − β̇_{k−1}) / dt, φ̈_k = (φ̇_k − φ̇_{k−1}) / dt; with
  unlimited steering β_k − β_{k−1} is taken modulo 2π into [−π, π[ (the module turns the short
  way, as the env's action map does);
* the first period of an episode is differenced against the measured state at its reset
  (β_{−1} = the measured steering angles, φ̇_{−1} = the measured wheel speeds, β̇_{−1} = 0: the
  robot starts at rest), what a controller reads when it starts;
* with steering stops, β_k outside [steer_min, steer_max] (the env would clip it to the stop);
* |φ̇_k| > wheel_speed_max.

A value counts as over its limit L only above L·(1 + ``RTOL``) (1e-6: floating rounding of the
differences; the built-in controllers that keep the limits reach them to 1e-14 relative), plus,
for set-points read back from a float32 action, the action's own rounding (2^-24 of the
steering and wheel-speed scales, through the differences: 2δ/dt on a rate, 4δ/dt² on an
acceleration).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from azimut_env.params import ActuatorLimits

__all__ = ["ActuatorLimits", "limit_array", "limit_violations", "limit_exceeded", "SetpointLimitCheck", "LIMIT_KINDS",
           "RTOL", "ACTION_QUANTUM"]

#: relative slack of every limit (floating rounding)
RTOL = 1e-6
#: the rounding of a float32 action in [−1, 1], relative to its scale (β_max, φ̇_max): 2^-24
ACTION_QUANTUM = 2.0**-24
#: the columns of :meth:`SetpointLimitCheck.step`'s flags
LIMIT_KINDS = ("steer_rate", "steer_accel", "wheel_speed", "wheel_accel", "steer_range")


def limit_array(limits: ActuatorLimits) -> np.ndarray:
    """(steer_rate_max, steer_accel_max, wheel_speed_max, wheel_accel_max) as a float array."""
    return np.array([limits.steer_rate_max, limits.steer_accel_max, limits.wheel_speed_max,
                     limits.wheel_accel_max])


def limit_violations(beta_rate, beta_accel, phidot, phiddot, limits: ActuatorLimits,
                     rtol: float = 1e-6) -> np.ndarray:
    """Which limits a command exceeds: bool (4,) for (β̇, β̈, φ̇, φ̈) of (n,) inputs, or (N, 4).

    A value counts as exceeding only above ``limit · (1 + rtol)`` (floating-point slack).
    """
    vals = [np.asarray(x, dtype=np.float64) for x in (beta_rate, beta_accel, phidot, phiddot)]
    lim = limit_array(limits) * (1.0 + rtol)
    return np.stack([np.any(np.abs(v) > m, axis=-1) for v, m in zip(vals, lim)], axis=-1)


@njit(cache=True)
def _exceeded_kernel(beta_rate, beta_accel, phidot, phiddot, lim, out) -> None:
    for i in range(out.shape[0]):
        hit = False
        for k in range(phidot.shape[1]):
            hit = hit or (abs(beta_rate[i, k]) > lim[0] or abs(beta_accel[i, k]) > lim[1] or abs(phidot[i, k]) > lim[2]
                          or abs(phiddot[i, k]) > lim[3])
        out[i] = hit


def limit_exceeded(beta_rate, beta_accel, phidot, phiddot, limits: ActuatorLimits, rtol: float = 1e-6) -> np.ndarray:
    """(N,) bool: robot i's command exceeds some limit, ``limit_violations(...).any(axis=-1)`` of
    (N, n) arrays in one compiled call (the same comparisons)."""
    vals = [np.ascontiguousarray(x, dtype=np.float64) for x in (beta_rate, beta_accel, phidot, phiddot)]
    if vals[0].ndim != 2 or any(v.shape != vals[0].shape for v in vals):
        raise ValueError(f"the commands must be (N, n) arrays of one shape, got {[v.shape for v in vals]}")
    out = np.empty(vals[0].shape[0], dtype=np.bool_)
    _exceeded_kernel(*vals, limit_array(limits) * (1.0 + rtol), out)
    return out


class SetpointLimitCheck:
    """The commanded-limit check of N robots' set-points, period after period (see the module
    docstring for the definitions).

    Args:
        limits: the robots' actuator limits; dt: the control period [s]; num: robots N;
        n: wheels per robot.
    """

    def __init__(self, limits: ActuatorLimits, dt: float, num: int, n: int) -> None:
        self.limits, self.dt = limits, float(dt)
        self.beta, self.phidot = np.zeros((num, n)), np.zeros((num, n))
        self.rate = np.zeros((num, n))
        lo, hi = limits.steer_action_range
        self._scales = (max(abs(lo), abs(hi)), float(limits.wheel_speed_max))

    def reset(self, rows, beta, phidot) -> None:
        """Restart the robots ``rows`` from β, φ̇ ((M, n) or (N, n) of all robots, read at
        ``rows``), at rest: the angles the controllers start from
        (:meth:`~estimation.geometry.RobotGeometry.measured_steering` of the measured ones)."""
        rows = np.asarray(rows, dtype=np.intp)
        beta, phidot = np.asarray(beta, dtype=np.float64), np.asarray(phidot, dtype=np.float64)
        if beta.shape[0] != rows.size:
            beta, phidot = beta[rows], phidot[rows]
        self.beta[rows], self.phidot[rows], self.rate[rows] = beta, phidot, 0.0

    def step(self, beta, phidot, *, from_action: bool = False) -> np.ndarray:
        """(N, 5) bool, the :data:`LIMIT_KINDS` each robot's set-points (N, n) exceed this period;
        then they become the previous ones. ``from_action``: the set-points were read back from a
        float32 action (its rounding is added to the slack)."""
        lim, dt = self.limits, self.dt
        beta, phidot = np.asarray(beta, dtype=np.float64), np.asarray(phidot, dtype=np.float64)
        dbeta = beta - self.beta
        if lim.unlimited_steering:
            dbeta = np.mod(dbeta + np.pi, 2 * np.pi) - np.pi
        with np.errstate(over="ignore", invalid="ignore"):  # set-points near 1e308: inf rates, counted as over
            rate = dbeta / dt
            accel = (rate - self.rate) / dt
            phiddot = (phidot - self.phidot) / dt
        q_beta, q_phi = (ACTION_QUANTUM * s for s in self._scales) if from_action else (0.0, 0.0)
        slack = 1.0 + RTOL
        flags = np.stack([
            np.any(np.abs(rate) > lim.steer_rate_max * slack + 2 * q_beta / dt, axis=-1),
            np.any(np.abs(accel) > lim.steer_accel_max * slack + 4 * q_beta / dt**2, axis=-1),
            np.any(np.abs(phidot) > lim.wheel_speed_max * slack + q_phi, axis=-1),
            np.any(np.abs(phiddot) > lim.wheel_accel_max * slack + 2 * q_phi / dt, axis=-1),
            np.zeros(beta.shape[0], dtype=bool) if lim.unlimited_steering else
            np.any((beta > lim.steer_max + abs(lim.steer_max) * RTOL + q_beta)
                   | (beta < lim.steer_min - abs(lim.steer_min) * RTOL - q_beta), axis=-1),
        ], axis=-1)
        self.beta, self.phidot, self.rate = beta.copy(), phidot.copy(), rate
        return flags
