"""Synthetic wheel logs for the log tests: a smooth chassis motion, its exact steering angles and
wheel speeds (``steering_from_lambda``, ``wheel_speeds``), optional steering noise, and the true
pose integrated with ``integrate_pose``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimation import RobotGeometry, eta_from_twist, integrate_pose, steering_from_lambda, wheel_speeds

MODULES4 = ("front_left", "rear_left", "rear_right", "front_right")


@dataclass
class Motion:
    t_s: np.ndarray  # (N,)
    beta: np.ndarray  # (N, n) the paper's β, in range
    phidot: np.ndarray  # (N, n)
    pose: np.ndarray  # (N, 3) true pose
    twist: np.ndarray  # (N, 3)

    @property
    def t_ns(self) -> np.ndarray:
        return np.rint(self.t_s * 1e9).astype(np.int64)


def motion(geom: RobotGeometry, n: int = 400, dt: float = 0.01, noise: float = 0.0, seed: int = 0,
           start=(1.0, -2.0, 0.4)) -> Motion:
    """n samples every dt [s] of a curving, crabbing motion; the twist of sample k acts over
    (t_{k-1}, t_k], so that pose k = integrate_pose(pose k-1, twist k, dt); the wheel speeds
    include the steer-to-drive coupling of the finite-difference β̇ (r φ̇ = μ c − b β̇)."""
    t = np.arange(n) * dt
    twist = np.column_stack([0.6 + 0.3 * np.sin(0.7 * t), 0.2 * np.cos(0.4 * t), 0.5 * np.sin(0.3 * t + 0.2)])
    lam, mu = eta_from_twist(twist)
    beta = steering_from_lambda(lam, geom)
    beta_rate = np.vstack([np.zeros((1, geom.n)), np.diff(beta, axis=0) / dt])  # what dead reckoning assumes
    phidot = wheel_speeds(lam, mu, geom, beta_rate=beta_rate, beta=beta)
    if noise:
        beta = geom.wrap_steering(beta + noise * np.random.default_rng(seed).standard_normal(beta.shape))
    pose = np.empty((n, 3))
    pose[0] = start
    for k in range(1, n):
        pose[k] = integrate_pose(pose[k - 1], twist[k], dt)
    return Motion(t, beta, phidot, pose, twist)


def heading_of(beta: np.ndarray, geom: RobotGeometry) -> np.ndarray:
    """The module heading [rad] (rolling direction from X_R) of steering angles β (the inverse of
    ``beta_from_heading``)."""
    return beta + geom.alpha - np.pi / 2
