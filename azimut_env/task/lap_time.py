"""Lap times of a track: the time of its speed profile, and the nominal lap of the ICR reference
controller, which also stops to turn wheels in place where their steering angle must cross the
steering stops (the env's per-track time limit is a multiple of it, ``time_limit_factor``).
"""

from __future__ import annotations

import numpy as np

from azimut_env.params import ActuatorLimits
from azimut_env.tracks import Track
from estimation import eta_from_twist, steering_from_lambda
from estimation.geometry import RobotGeometry

__all__ = ["nominal_duration", "steering_wraps", "reference_lap_time", "REFERENCE_TURN_FRACTIONS"]


def nominal_duration(track: Track, speed_scale: float = 1.0) -> float:
    """The time [s] to drive ``track`` at its reference speed profile (speeds below 5 cm/s count as
    5 cm/s, so a profile that starts or ends at rest has a finite duration), plus its holds."""
    drive = float(np.sum(np.diff(track.s) / np.maximum(track.speed[:-1] * speed_scale, 0.05)))
    return drive + track.hold_time if track.holds else drive


#: Fractions of the steering rate and acceleration limits at which the reference ICR controller
#: turns its wheels in place (``control.icr.controller.ICRControllerConfig.reconfig_rate_fraction``
#: and ``reconfig_accel_fraction``; a test keeps them equal).
REFERENCE_TURN_FRACTIONS = (0.5, 0.3)


def steering_wraps(track: Track, geometry: RobotGeometry) -> np.ndarray:
    """The swings [rad] of the wheels whose steering angle β_k = F_k(λ) (eq. (16)–(17)) wraps
    across the steering stops (jumps by more than π/2 between consecutive samples) along the ICR
    path of ``track``'s reference motion (λ from the reference twist in the chassis frame,
    ``eta_from_twist``), one entry per wheel and crossing: where the ICR reference controller must
    stop and turn that wheel in place, by the swing, from one side of its range to the other.
    None without steering stops (unlimited steering)."""
    if geometry.unlimited_steering:
        return np.zeros(0)
    tw = track.reference_twist(track.s, speed=np.ones_like(track.s))
    c, s = np.cos(track.heading), np.sin(track.heading)
    body = np.stack([c * tw[:, 0] + s * tw[:, 1], -s * tw[:, 0] + c * tw[:, 1], tw[:, 2]], axis=1)
    moving = np.linalg.norm(body, axis=1) > 1e-9
    if np.count_nonzero(moving) < 2:
        return np.zeros(0)
    lam, _ = eta_from_twist(body[moving])
    swing = np.abs(np.diff(steering_from_lambda(lam, geometry), axis=0))
    return swing[swing > 0.5 * np.pi]


def reference_lap_time(track: Track, geometry: RobotGeometry, limits: ActuatorLimits,
                       speed_scale: float = 1.0) -> float:
    """The nominal lap [s] of the ICR reference controller on ``track``: the time of the speed
    profile (:func:`nominal_duration`) plus, for each wheel that wraps across its steering stops
    along the reference ICR path (:func:`steering_wraps`), the time to turn it in place by its
    swing on a trapezoidal profile at the reference controller's fractions
    (:data:`REFERENCE_TURN_FRACTIONS`) of the steering rate and acceleration limits of ``limits``
    (1.79 s for a swing of π with the default limits). How it compares with the reference
    controller's measured laps: ``docs/results/eval.md``, "Time limit"."""
    rate = REFERENCE_TURN_FRACTIONS[0] * limits.steer_rate_max
    accel = REFERENCE_TURN_FRACTIONS[1] * limits.steer_accel_max
    swing = steering_wraps(track, geometry)
    turn = np.where(swing < rate * rate / accel, 2.0 * np.sqrt(swing / accel), swing / rate + rate / accel)
    return nominal_duration(track, speed_scale) + float(np.sum(turn))
