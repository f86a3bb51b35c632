"""The start of an episode: the robot's starting pose and steering angles.

At a reset (:meth:`~azimut_env.task.core.AzimutTask.reset_robot`) a robot draws, from its own
generator and in this order: its parameters
(:func:`~azimut_env.physics.wheel_params.randomized_wheel_params`, only with domain
randomisation), its steering encoder biases (the sensors), then its starting pose and steering
angles (:func:`start_configuration`). The draws are the same whatever the number of robots, so
robot i of a batch starts as a single env seeded the same way.
"""

from __future__ import annotations

import numpy as np

from azimut_env.tracks import Track
from estimation import eta_from_twist, steering_from_lambda
from estimation.geometry import RobotGeometry

__all__ = ["reference_steering", "start_configuration"]


def reference_steering(track: Track, s: float, theta: float, geometry: RobotGeometry) -> np.ndarray:
    """(n,) steering angles [rad] of the track's reference motion at progress s [m] with the chassis
    heading θ [rad] (direction only; zeros where the reference stands still)."""
    tw = track.reference_twist_body(s, theta, speed=1.0)
    if np.linalg.norm(tw) < 1e-9:
        return np.zeros(geometry.n)
    lam, _ = eta_from_twist(tw)
    return steering_from_lambda(lam, geometry)


def start_configuration(track: Track, s0: float, noise: float, geometry: RobotGeometry,
                        rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The starting pose (x, y, θ) [m, m, rad] and steering angles (n,) [rad] at progress ``s0``:
    the track's reference pose plus uniform noise of ±``noise`` (``start_noise``), then the
    reference steering angles at that heading plus the same noise, within the steering stops (no
    stops with unlimited steering)."""
    pose = track.sample(s0)[:3] + rng.uniform(-noise, noise, size=3)
    beta = reference_steering(track, s0, pose[2], geometry) + rng.uniform(-noise, noise, size=geometry.n)
    if geometry.unlimited_steering:
        return pose, beta
    return pose, np.clip(beta, geometry.steer_min + 1e-6, geometry.steer_max)
