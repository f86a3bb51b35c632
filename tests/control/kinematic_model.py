"""A rigid, kinematic stand-in for the robot: a test bench for controllers without the physics
(the tests' own: ``from kinematic_model import KinematicRobot`` in ``tests/control``).

The wheels follow their set-points exactly (β = β_c, φ̇ = φ̇_c). The chassis twist is the least-
squares solution of every wheel's rolling and no-side-slip constraints; the residual is the slip
the wheels would need, a proxy for scrub when the propulsion axes do not concur
(:func:`estimation.kinematics.twist_from_wheels`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimation.geometry import RobotGeometry
from estimation.kinematics import twist_from_wheels

__all__ = ["KinematicRobot", "twist_from_wheels"]  # twist_from_wheels: re-exported from estimation


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
    def at_rest(cls, geom: RobotGeometry, pose=(0.0, 0.0, 0.0), beta=None) -> KinematicRobot:
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
