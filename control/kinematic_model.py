"""A rigid, kinematic stand-in for the robot: a test bench for controllers without the physics.

The wheels follow their set-points exactly (β = β_c, φ̇ = φ̇_c). The chassis twist is the least-
squares solution of every wheel's rolling and no-side-slip constraints; the residual is the slip
the wheels would need, a proxy for scrub when the propulsion axes do not concur. With contact
point P_k = A_k + b_k e_k, e_k = (cos γ_k, sin γ_k), rolling direction d_k = (sin γ_k, −cos γ_k)
(kinematics module conventions)::

    v(P_k) · e_k = 0                        (no side slip)
    v(P_k) · d_k = r_k φ̇_k + b_k β̇_k        (rolling, with the steer-to-drive coupling)

where v(P) = (ẋ − θ̇ P_y, ẏ + θ̇ P_x) in the chassis frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimation.geometry import RobotGeometry

__all__ = ["twist_from_wheels", "KinematicRobot"]


def twist_from_wheels(beta, beta_rate, phidot, geom: RobotGeometry) -> tuple[np.ndarray, float]:
    """Least-squares chassis twist (ẋ, ẏ, θ̇) in R and the slip residual ‖A ξ̇ − y‖ [m/s]."""
    beta = np.asarray(beta, dtype=np.float64)
    gamma = geom.alpha + beta
    e = np.stack([np.cos(gamma), np.sin(gamma)], axis=1)
    d = np.stack([np.sin(gamma), -np.cos(gamma)], axis=1)
    p = geom.axis_xy + geom.b[:, None] * e
    rows, rhs = [], []
    for dirs, target in ((e, np.zeros(geom.n)), (d, geom.r * np.asarray(phidot) + geom.b * np.asarray(beta_rate))):
        # v(P)·u = u_x ẋ + u_y ẏ + θ̇ (P_x u_y − P_y u_x)
        rows.append(np.stack([dirs[:, 0], dirs[:, 1], p[:, 0] * dirs[:, 1] - p[:, 1] * dirs[:, 0]], axis=1))
        rhs.append(target)
    a, y = np.concatenate(rows), np.concatenate(rhs)
    twist, *_ = np.linalg.lstsq(a, y, rcond=None)
    return twist, float(np.linalg.norm(a @ twist - y))


@dataclass
class KinematicRobot:
    """Pose (x, y, θ) in the world [m, m, rad] integrated from the wheels' least-squares twist.

    ``step(beta_c, phidot_c, dt)`` applies commands (wheels follow exactly) and returns the twist
    in R and the slip residual. Attributes ``beta`` and ``phidot`` are the wheel state.
    """

    geom: RobotGeometry
    pose: np.ndarray
    beta: np.ndarray
    phidot: np.ndarray

    @classmethod
    def at_rest(cls, geom: RobotGeometry, pose=(0.0, 0.0, 0.0), beta=None) -> "KinematicRobot":
        beta = np.zeros(geom.n) if beta is None else np.asarray(beta, dtype=np.float64).copy()
        return cls(geom, np.asarray(pose, dtype=np.float64).copy(), beta, np.zeros(geom.n))

    def step(self, beta_c, phidot_c, dt: float) -> tuple[np.ndarray, float]:
        beta_c = np.asarray(beta_c, dtype=np.float64)
        rate = (beta_c - self.beta) / dt
        twist, slip = twist_from_wheels(beta_c, rate, phidot_c, self.geom)
        c, s = np.cos(self.pose[2] + 0.5 * twist[2] * dt), np.sin(self.pose[2] + 0.5 * twist[2] * dt)
        self.pose = self.pose + dt * np.array([c * twist[0] - s * twist[1], s * twist[0] + c * twist[1], twist[2]])
        self.beta = beta_c.copy()
        self.phidot = np.asarray(phidot_c, dtype=np.float64).copy()
        return twist, slip
