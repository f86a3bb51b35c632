"""Actuator limits shared by every controller in ``control/`` (ICR-based and twist baseline alike).

The controllers compute *commanded* set-points (β_c, φ̇_c) per control period; these limits bound
the commands and their finite differences, so that the comparison between controllers is fair.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ActuatorLimits", "limit_violations"]


@dataclass(frozen=True)
class ActuatorLimits:
    """Per-wheel actuator limits (the same for every wheel).

    Attributes:
        steer_rate: max |β̇| of the steering set-point [rad/s].
        steer_accel: max |β̈| of the steering set-point [rad/s²].
        wheel_speed: max |φ̇| of the propulsion set-point [rad/s].
        wheel_accel: max |φ̈| of the propulsion set-point [rad/s²].

    Defaults are assumptions for an AZIMUT-3-sized robot (r = 0.08 m): 1.6 m/s wheel surface
    speed, 2.4 m/s² wheel surface acceleration, 3 rad/s and 15 rad/s² steering.
    """

    steer_rate: float = 3.0
    steer_accel: float = 15.0
    wheel_speed: float = 20.0
    wheel_accel: float = 30.0

    def __post_init__(self) -> None:
        for name in ("steer_rate", "steer_accel", "wheel_speed", "wheel_accel"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float, np.floating)) and np.isfinite(value) and value > 0):
                raise ValueError(f"ActuatorLimits.{name} must be a finite number > 0, got {value!r}")

    def as_array(self) -> np.ndarray:
        """(steer_rate, steer_accel, wheel_speed, wheel_accel) as a float array."""
        return np.array([self.steer_rate, self.steer_accel, self.wheel_speed, self.wheel_accel])


def limit_violations(beta_rate, beta_accel, phidot, phiddot, limits: ActuatorLimits,
                     rtol: float = 1e-6) -> np.ndarray:
    """Which limits a command exceeds: bool (4,) for (β̇, β̈, φ̇, φ̈), or (N, 4) for (N, n) inputs.

    A value counts as exceeding only above ``limit · (1 + rtol)`` (floating-point slack).
    """
    vals = [np.asarray(x, dtype=np.float64) for x in (beta_rate, beta_accel, phidot, phiddot)]
    lim = limits.as_array() * (1.0 + rtol)
    return np.stack([np.any(np.abs(v) > m, axis=-1) for v, m in zip(vals, lim)], axis=-1)
