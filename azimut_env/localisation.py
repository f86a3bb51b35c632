"""Where the task's pose comes from: the true pose, or odometry corrected by a noisy absolute fix.

With ``pose_source="true"`` (the default) the tracking errors and look-ahead points of the
observation are computed from the simulator's true chassis pose: privileged information, a
legitimate design for RL in simulation, but not what a real robot has. With
``pose_source="odometry"`` they are computed from a pose estimate that a real robot could have:

* **dead reckoning** every control step from the estimated H state and the wheel encoders
  (``estimation.odometry_twist``: λ̂ of the IT estimate, μ fitted to r φ̇ + b β̇ with β̇ the finite
  difference of the measured steering angles; ``estimation.integrate_pose``: the SE(2)
  exponential over the control period). It drifts: tire slip, compliance and sensor noise all
  enter it, and nothing corrects the heading;
* a **localisation fix** (a marker, beacon or lidar map system) every ``fix_period_s``: the
  estimate is replaced by the true pose plus Gaussian noise (σ ``fix_noise_xy_m`` on x and y,
  ``fix_noise_theta_rad`` on θ), with no latency. A fix is also taken at each reset.

The noise is drawn from a generator that each robot's reset spawns from the robot's own
generator (only when ``pose_source="odometry"``), so the same seed gives the same episode and a
robot of the vector env replays the single env bit for bit.

The reward, the termination (off track, finished), the progress and ``info`` stay computed from
the true pose in both modes: they are the task's judge, not the robot's perception.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .validation import check_nonnegative, check_range

__all__ = ["POSE_SOURCES", "LocalisationParams", "check_pose_source"]

#: the values of the envs' ``pose_source`` argument
POSE_SOURCES = ("true", "odometry")


def check_pose_source(value) -> str:
    """``value`` if it is one of :data:`POSE_SOURCES`, else ``ValueError``."""
    if not isinstance(value, str) or value not in POSE_SOURCES:
        raise ValueError(f"pose_source must be one of {POSE_SOURCES}, got {value!r}")
    return value


@dataclass(frozen=True)
class LocalisationParams:
    """The absolute localisation fixes that correct the odometry (``pose_source="odometry"``).

    Attributes:
        fix_period_s: time between fixes [s] (rounded to a whole number of control periods, at
            least one); ``math.inf``: no fix after the one at reset (pure dead reckoning).
        fix_noise_xy_m: standard deviation of a fix's x and y [m].
        fix_noise_theta_rad: standard deviation of a fix's heading [rad].
    """

    fix_period_s: float = 1.0
    fix_noise_xy_m: float = 0.02
    fix_noise_theta_rad: float = 0.01

    def __post_init__(self) -> None:
        fp = self.fix_period_s
        if not (isinstance(fp, (int, float)) and not isinstance(fp, bool) and (fp == math.inf or
                                                                                 (math.isfinite(fp) and fp > 0))):
            raise ValueError(f"LocalisationParams.fix_period_s must be > 0 (or math.inf), got {fp!r}")
        object.__setattr__(self, "fix_period_s", float(fp))
        for name in ("fix_noise_xy_m", "fix_noise_theta_rad"):
            object.__setattr__(self, name, check_nonnegative(f"LocalisationParams.{name}", getattr(self, name)))
        check_range("LocalisationParams.fix_noise_theta_rad", self.fix_noise_theta_rad, 0.0, math.pi)

    def fix_every(self, control_period: float) -> int:
        """Control steps between fixes (0: never)."""
        if self.fix_period_s == math.inf:
            return 0
        return max(1, int(round(self.fix_period_s / control_period)))
