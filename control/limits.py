"""Actuator limits as ``control/`` uses them.

The limits themselves are :class:`azimut_env.params.ActuatorLimits` (one definition, shared with the
env). The controllers compute *commanded* set-points (β_c, φ̇_c) once per control period; the
limits bound the commands and their finite differences over a period: |β̇_c| ≤ steer_rate_max
[rad/s], |β̈_c| ≤ steer_accel_max [rad/s²], |φ̇_c| ≤ wheel_speed_max [rad/s] and
|φ̈_c| ≤ wheel_accel_max [rad/s²]. Every controller gets the same ones, so comparisons are fair.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from azimut_env.params import ActuatorLimits

__all__ = ["ActuatorLimits", "limit_array", "limit_violations", "limit_exceeded"]


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
