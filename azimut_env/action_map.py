"""The actuator limits and the map between the envs' normalised actions and the actuator
set-points.

Everything a controller needs to know about the actuators is in :class:`ActuatorLimits`
(``env.unwrapped.limits``). The normalised action of :class:`~azimut_env.env.AzimutEnv` is

* ``action[:n]``  steering set-points: ``β_cmd = action · β_max`` [rad] (β_max = π/2, the stop);
* ``action[n:]``  propulsion set-points: ``φ̇_cmd = action · φ̇_max`` [rad/s].

:func:`setpoints_from_action` and :func:`action_from_setpoints` convert both ways. They are pure
functions of arrays (batched over leading axes) and are the single definition of that map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numba import njit

from azimut_env.validation import check_fields
from azimut_env.validation import check_positive_fields as _check_positive

__all__ = ["CMD", "ActuatorLimits", "setpoints_from_action", "action_from_setpoints", "setpoints_row"]


class CMD(IntEnum):
    """Columns of the per-wheel set-points ``commands`` (N, n, len(CMD)) this map writes and the
    physics reads: the steering angle β_cmd [rad] and the wheel spin rate φ̇_cmd [rad/s]
    (:mod:`azimut_env.physics.layout` names it with the physics' own columns)."""

    BETA, PHIDOT = range(2)


@dataclass(frozen=True)
class ActuatorLimits:
    """Limits of the steering and propulsion actuators (identical for every wheel).

    Attributes:
        steer_rate_max: steering motor speed limit |θ̇_m| [rad/s].
        steer_accel_max: steering motor acceleration limit |θ̈_m| [rad/s²].
        steer_torque_max: torque the steering motor can put through the spring [N·m]; beyond it the
            motor stalls (its angle stays within ``steer_torque_max / stiffness`` of β).
        wheel_speed_max: propulsion speed limit |φ̇| [rad/s], also the scale of the propulsion action.
        wheel_accel_max: propulsion set-point acceleration limit |φ̈_ref| [rad/s²].
        wheel_torque_max: propulsion motor torque limit [N·m].
        steer_min, steer_max: steering range ]β_min, β_max] [rad] (hard stops); β_max scales the
            steering action. ``−inf``, ``+inf``: unlimited steering (no stops; the steering action
            then scales by π, :attr:`steer_action_scale`).
    """

    steer_rate_max: float = 4.0
    steer_accel_max: float = 30.0
    steer_torque_max: float = 15.0
    wheel_speed_max: float = 20.0
    wheel_accel_max: float = 40.0
    wheel_torque_max: float = 5.0
    steer_min: float = -math.pi / 2
    steer_max: float = math.pi / 2

    def __post_init__(self) -> None:
        check_fields(self)
        _check_positive(self, "steer_rate_max", "steer_accel_max", "steer_torque_max", "wheel_speed_max",
                        "wheel_accel_max", "wheel_torque_max")
        if self.unlimited_steering:
            return
        if not (math.isfinite(self.steer_min) and math.isfinite(self.steer_max)
                and self.steer_min < 0 < self.steer_max):
            raise ValueError(f"ActuatorLimits steering range must satisfy steer_min < 0 < steer_max (or be −inf, "
                             f"+inf: unlimited), got ]{self.steer_min}, {self.steer_max}]")

    @property
    def unlimited_steering(self) -> bool:
        """No steering stops (``steer_min = −inf``, ``steer_max = +inf``)."""
        return self.steer_min == -math.inf and self.steer_max == math.inf

    @property
    def steer_action_range(self) -> tuple[float, float]:
        """(β_lo, β_hi) [rad] of the steering action: β_cmd = max(a · β_hi, β_lo), a ∈ [−1, 1]; the
        steering range, or (−π, π) for unlimited steering (every angle once, ±π the same)."""
        if self.unlimited_steering:
            return -math.pi, math.pi
        return float(self.steer_min), float(self.steer_max)


@njit(cache=True)
def setpoints_row(a, i, n, steer_min, steer_max, wheel_speed_max, cmd):
    """Set-points of the clipped action row a[i] (2n,) into cmd[i] (n, 2): β_cmd = a·β_max (not
    below β_min) [rad], φ̇_cmd = a·φ̇_max [rad/s]. The one implementation of the action map; the
    task's compiled step calls it too."""
    for k in range(n):
        cmd[i, k, CMD.BETA] = max(a[i, k] * steer_max, steer_min)
        cmd[i, k, CMD.PHIDOT] = a[i, n + k] * wheel_speed_max


@njit(cache=True)
def _setpoints_batch(a, n, steer_min, steer_max, wheel_speed_max, cmd):
    for i in range(a.shape[0]):
        setpoints_row(a, i, n, steer_min, steer_max, wheel_speed_max, cmd)


def setpoints_from_action(action, limits: ActuatorLimits, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised action (..., 2n) in [−1, 1] -> (β_cmd [rad], φ̇_cmd [rad/s]), each (..., n).

    Values outside [−1, 1] are clipped first (the Gymnasium convention for Box actions). NaN or inf
    raise ``ValueError``.
    """
    a = np.asarray(action, dtype=np.float64)
    if a.ndim == 0 or a.shape[-1] != 2 * n:
        raise ValueError(f"action must have shape (..., {2 * n}) for {n} wheels, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action contains NaN or inf: {a}")
    flat = np.ascontiguousarray(np.clip(a, -1.0, 1.0).reshape(-1, 2 * n))
    cmd = np.empty((flat.shape[0], n, 2))
    lo, hi = limits.steer_action_range
    _setpoints_batch(flat, n, lo, hi, float(limits.wheel_speed_max), cmd)
    batch = a.shape[:-1]
    return cmd[..., 0].reshape(batch + (n,)), cmd[..., 1].reshape(batch + (n,))


def action_from_setpoints(beta_cmd, phidot_cmd, limits: ActuatorLimits) -> np.ndarray:
    """(β_cmd [rad], φ̇_cmd [rad/s]), each (..., n) -> normalised float32 action (..., 2n).

    The inverse of :func:`setpoints_from_action`; set-points beyond the limits are clipped to
    [−1, 1]. Steering angles are used as given (wrap them into the steering range first); with
    unlimited steering they are taken modulo 2π into ]−π, π] (the module turns the short way to
    its set-point).
    """
    beta = np.asarray(beta_cmd, dtype=np.float64)
    phidot = np.asarray(phidot_cmd, dtype=np.float64)
    if beta.shape != phidot.shape:
        raise ValueError(f"beta_cmd and phidot_cmd must have the same shape, got {beta.shape} and {phidot.shape}")
    if not (np.all(np.isfinite(beta)) and np.all(np.isfinite(phidot))):
        raise ValueError("set-points contain NaN or inf")
    if limits.unlimited_steering:
        beta = math.pi - np.mod(math.pi - beta, 2 * math.pi)
    a = np.concatenate([beta / limits.steer_action_range[1], phidot / limits.wheel_speed_max], axis=-1)
    return np.clip(a, -1.0, 1.0).astype(np.float32)
