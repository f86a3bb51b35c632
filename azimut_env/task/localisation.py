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

import numpy as np

from azimut_env.physics.layout import RS_POSE
from azimut_env.task.track_state import AHEAD, BACK
from azimut_env.tracks import TQ, query_batch_kernel
from azimut_env.validation import check_fields, check_nonnegative, check_range
from estimation import integrate_pose, odometry_twist

__all__ = ["POSE_SOURCES", "LocalisationParams", "check_pose_source", "OdometryPoses"]

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
        check_fields(self)
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


class OdometryPoses:
    """The pose estimates of N robots with ``pose_source="odometry"``, and the track state seen
    from them (filled by the task's track query).

    Attributes (leading axis N): ``pose`` (N, 3) the estimates (x, y, θ); ``vel`` (N, 2) the
    world velocity of the odometry twist at mid-period; ``beta_prev`` (N, n) the measured steering
    angles of the previous step (for β̇); ``track_state`` (N, 5) (columns
    :class:`~azimut_env.tracks.TQ`) and ``look`` (N, K, 3): the track state and look-ahead
    points of the estimates.
    """

    def __init__(self, params: LocalisationParams, control_period: float, geometry, n_robots: int, n: int,
                 lookahead_count: int) -> None:
        self.dt = float(control_period)
        self.geometry = geometry
        self.fix_every = params.fix_every(control_period)
        self.fix_sigma = np.array([params.fix_noise_xy_m, params.fix_noise_xy_m, params.fix_noise_theta_rad])
        self.pose = np.zeros((n_robots, 3))
        self.vel = np.zeros((n_robots, 2))
        self.beta_prev = np.zeros((n_robots, n))
        self.track_state = np.zeros((n_robots, len(TQ)))
        self.look = np.zeros((n_robots, lookahead_count, 3))
        self._rngs: list[np.random.Generator | None] = [None] * n_robots

    def fix(self, i: int, true_pose: np.ndarray) -> np.ndarray:
        """A localisation fix of robot i: its true pose plus Gaussian noise (draws 3 normals)."""
        return true_pose + self.fix_sigma * self._rngs[i].standard_normal(3)

    def spawn(self, i: int, rng: np.random.Generator) -> None:
        """Robot i's new episode: its localisation generator, spawned from ``rng`` (one draw)."""
        self._rngs[i] = np.random.default_rng(int(rng.integers(0, 2**63 - 1)))

    def start_stage(self, ns, rows: np.ndarray, action: np.ndarray) -> None:
        """The odometry stage of a reset (:mod:`azimut_env.task.pipeline`): the first fix of the
        robots of ``rows``, at rest, and the track state seen from it (from the start progress
        ``ns.s``). ``ns``: the task's arrays by name (:func:`azimut_env.task.arrays.task_arrays`)."""
        idx = np.flatnonzero(rows)
        for i in idx:
            self.beta_prev[i] = ns.beta_m[i]
            self.pose[i] = self.fix(int(i), ns.summary[i, RS_POSE])
            self.vel[i] = 0.0
        self._query(ns, idx, ns.s)

    def step_stage(self, ns, rows: np.ndarray, action: np.ndarray) -> None:
        """The odometry stage of a step: :meth:`advance` the robots of ``rows``, then the track
        state seen from their estimates (from the progress of the last one)."""
        idx = np.flatnonzero(rows)
        self.advance(idx, ns.lam_hat, ns.phidot_m, ns.beta_m, ns.steps, ns.summary[:, RS_POSE])
        self._query(ns, idx, self.track_state[:, TQ.S])

    def _query(self, ns, idx: np.ndarray, hints: np.ndarray) -> None:
        out = np.empty((idx.shape[0], len(TQ)))
        look = np.empty((idx.shape[0],) + self.look.shape[1:])
        query_batch_kernel(ns.packs, idx, ns.track_closed, ns.track_length, ns.track_rho, self.pose[idx], hints[idx],
                           BACK, AHEAD, ns.lookahead_spacing, out, look)
        self.track_state[idx] = out
        self.look[idx] = look

    def advance(self, idx: np.ndarray, lam_hat: np.ndarray, phidot: np.ndarray, beta: np.ndarray,
                steps: np.ndarray, true_poses: np.ndarray) -> None:
        """One control period of dead reckoning for the robots ``idx`` from their IT estimate λ̂
        (N, 3), measured φ̇ and β (N, n); then a fix where one is due (``steps`` (N,) since the
        reset a multiple of ``fix_every``), from ``true_poses`` (N, 3)."""
        dt = self.dt
        beta_rate = (beta[idx] - self.beta_prev[idx]) / dt
        twist = odometry_twist(lam_hat[idx], phidot[idx], beta[idx], beta_rate, self.geometry)
        pose = integrate_pose(self.pose[idx], twist, dt)
        self.beta_prev[idx] = beta[idx]
        th = pose[:, 2] - 0.5 * twist[:, 2] * dt  # the heading at mid-period
        c, sn = np.cos(th), np.sin(th)
        self.vel[idx, 0] = c * twist[:, 0] - sn * twist[:, 1]
        self.vel[idx, 1] = sn * twist[:, 0] + c * twist[:, 1]
        self.pose[idx] = pose
        if self.fix_every > 0:
            for i in idx[steps[idx] % self.fix_every == 0]:
                self.pose[i] = self.fix(int(i), true_poses[i])
