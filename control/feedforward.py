"""The kinematic feed-forward driver (``azimut sim-paper --driver feedforward``; controller name
``feedforward``).

β and φ̇ from the track's reference twist through the H representation (estimation paper
eq. (16)–(17) for β; the wheel speeds of ``docs/icr-controller.md`` eq. (W)), with proportional
pose correction. It ignores the actuator limits (its steering set-points jump and flip across
the stops), which is why it exists: it shows what motor lag alone does to qua. The rate-aware driver
is the ICR reference controller (:class:`control.path_controllers.ICRPathController`). It declares
no β̇, β̈ or φ̈; the commanded-limit check of an episode differences its set-points
(:class:`control.limits.SetpointLimitCheck`): on ``paper`` they exceed a limit on about 95 steps.
"""

from __future__ import annotations

import math

import numpy as np

from control.commands import WheelCommand
from estimation import eta_from_twist, steering_from_lambda, wheel_speeds

__all__ = ["FeedForwardController"]


class FeedForwardController:
    """Kinematic feed-forward with proportional pose correction (no actuator limits), for the N
    robots of an env (a :class:`control.controller.Controller`; each robot computed on its own).

    Args:
        speed_scale: multiplies the track's speed profile. k_pos: position gain [1/s];
        k_head: heading gain [1/s].
    """

    name = "feedforward"

    def __init__(self, speed_scale: float = 1.0, *, k_pos: float = 1.5, k_head: float = 1.5) -> None:
        for key, value in (("speed_scale", speed_scale), ("k_pos", k_pos), ("k_head", k_head)):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(value) or value < 0 or (key == "speed_scale" and value == 0):
                raise ValueError(f"{key} must be a finite number {'> 0' if key == 'speed_scale' else '>= 0'}, "
                                 f"got {value!r}")
        self.speed_scale, self.k_pos, self.k_head = float(speed_scale), float(k_pos), float(k_head)
        self._beta_prev: list[np.ndarray | None] = []

    def reset(self, env, rows) -> None:
        num = int(np.shape(env.measured_beta)[0])
        if len(self._beta_prev) != num:
            self._beta_prev = [None] * num
        for i in np.asarray(rows, dtype=np.intp):
            self._beta_prev[i] = None

    def _robot(self, track, s: float, pose: np.ndarray, beta_meas: np.ndarray, geom, dt: float, i: int):
        """Set-points (β_c [rad], φ̇_c [rad/s]) of robot i at progress s and pose (x, y, θ)."""
        x, y, th = pose
        ref = track.sample(s)
        tw = track.reference_twist(s) * self.speed_scale
        vx = tw[0] + self.k_pos * (ref[0] - x)
        vy = tw[1] + self.k_pos * (ref[1] - y)
        w = tw[2] - self.k_head * math.remainder(th - ref[2], 2 * math.pi)
        c, sn = math.cos(th), math.sin(th)
        body = np.array([c * vx + sn * vy, -sn * vx + c * vy, w])
        prev = self._beta_prev[i]
        if np.linalg.norm(body) < 1e-6:
            beta = beta_meas if prev is None else prev
            phidot = np.zeros(geom.n)
        else:
            lam, mu = eta_from_twist(body)
            beta = steering_from_lambda(lam, geom)
            if prev is not None:  # unlimited steering: the nearer angle of each axis
                beta = geom.nearest_steering(beta, prev)
            rate = None if prev is None else (beta - prev) / dt
            if rate is not None:
                rate = np.where(np.abs(rate) > 5.0, 0.0, rate)  # a wheel flipping at its stop
            phidot = wheel_speeds(lam, mu, geom, beta_rate=rate, beta=beta)
        self._beta_prev[i] = np.asarray(beta, dtype=float)
        return np.asarray(beta, dtype=float), np.asarray(phidot, dtype=float)

    def act(self, env, obs) -> WheelCommand:
        """Set-points for the env's current state (from its pose estimate,
        ``estimated_pose``: the true pose unless ``pose_source="odometry"``)."""
        poses, progress, beta_meas = env.estimated_pose, np.atleast_1d(env.progress), env.measured_beta
        geom, dt, tracks = env.geometry, env.control_period, env.tracks
        out = [self._robot(tracks[i], float(progress[i]), poses[i], beta_meas[i], geom, dt, i)
               for i in range(len(self._beta_prev))]
        return WheelCommand(beta=np.array([b for b, _ in out]), phidot=np.array([p for _, p in out]))
