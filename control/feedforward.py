"""The kinematic feed-forward driver (``azimut sim-paper --driver feedforward``).

β and φ̇ from the track's reference twist through the H representation (estimation paper
eq. (16)–(17) for β; the wheel speeds of ``docs/icr-controller.md`` eq. (W)), with proportional
pose correction. It ignores the actuator limits (steering jumps of up to 179°, flips across the
stops), which is why it exists: it shows what motor lag alone does to qua. The rate-aware driver
is the ICR reference controller (:func:`control.episode.run_episode`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from azimut_env.env import AzimutEnv
from azimut_env.task.core import nominal_duration
from azimut_env.tracks import make_track
from control.episode import EpisodeLog, record_step
from control.icr.config import Mode
from estimation import eta_from_twist, steering_from_lambda, wheel_speeds

__all__ = ["FeedForwardController", "run_feedforward"]


@dataclass
class FeedForwardController:
    """Kinematic feed-forward with proportional pose correction (no actuator limits).

    Attributes:
        k_pos: position gain [1/s]; k_head: heading gain [1/s]; speed_scale: multiplies the
        track's speed profile.
    """

    k_pos: float = 1.5
    k_head: float = 1.5
    speed_scale: float = 1.0

    def __post_init__(self) -> None:
        self._beta_prev = None

    def reset(self) -> None:
        self._beta_prev = None

    def __call__(self, env: AzimutEnv) -> tuple[np.ndarray, np.ndarray]:
        """Set-points (β_c [rad], φ̇_c [rad/s]) for the env's current state (uses the env's pose
        estimate, :attr:`AzimutEnv.estimated_pose`, the true pose unless ``pose_source="odometry"``)."""
        track, geom = env.track, env.geometry
        x, y, th = env.estimated_pose
        s = env.progress
        ref = track.sample(s)
        tw = track.reference_twist(s) * self.speed_scale
        vx = tw[0] + self.k_pos * (ref[0] - x)
        vy = tw[1] + self.k_pos * (ref[1] - y)
        w = tw[2] - self.k_head * math.remainder(th - ref[2], 2 * math.pi)
        c, sn = math.cos(th), math.sin(th)
        body = np.array([c * vx + sn * vy, -sn * vx + c * vy, w])
        dt = env.control_period
        if np.linalg.norm(body) < 1e-6:
            beta = env.measured_beta if self._beta_prev is None else self._beta_prev
            phidot = np.zeros(geom.n)
        else:
            lam, mu = eta_from_twist(body)
            beta = steering_from_lambda(lam, geom)
            rate = None if self._beta_prev is None else (beta - self._beta_prev) / dt
            if rate is not None:
                rate = np.where(np.abs(rate) > 5.0, 0.0, rate)  # a wheel flipping at its stop
            phidot = wheel_speeds(lam, mu, geom, beta_rate=rate, beta=beta)
        self._beta_prev = np.asarray(beta, dtype=float)
        return np.asarray(beta, dtype=float), np.asarray(phidot, dtype=float)


def run_feedforward(track: str = "paper", seed: int = 0, speed_scale: float = 1.0, max_time: float | None = None,
                    controller: FeedForwardController | None = None, env_kwargs: dict | None = None) -> EpisodeLog:
    """Drive ``track`` with the feed-forward until it finishes, leaves the track or ``max_time``
    [s] (default 3 × nominal + 10 s); the same :class:`~control.episode.EpisodeLog` as
    :func:`control.episode.run_episode` (mode always RUNNING, no limit check)."""
    env = AzimutEnv(track=make_track(track, rng=np.random.default_rng(seed)) if isinstance(track, str) else track,
                    **(env_kwargs or {}))
    ctrl = controller if controller is not None else FeedForwardController(speed_scale=speed_scale)
    ctrl.reset()
    _, info = env.reset(seed=seed)
    dt = env.control_period
    nominal = nominal_duration(env.track, ctrl.speed_scale)
    steps = int(math.ceil((max_time if max_time is not None else 3.0 * nominal + 10.0) / dt))
    rec: dict[str, list] = {}
    log = EpisodeLog("feedforward", env.track, dt)
    for _ in range(steps):
        lam_hat, _ = env.estimated_eta
        beta_c, phidot_c = ctrl(env)
        _, _, terminated, _, info = env.step(env.action_from_setpoints(beta_c, phidot_c))
        if "error" in info:
            log.error = info["error"]
            break
        record_step(rec, env, info, lam_hat, beta_c, phidot_c)
        if info.get("finished"):
            log.completed = True
            break
        if info.get("off_track"):
            log.error = "off track"
            break
    for key, values in rec.items():
        setattr(log, key, np.asarray(values))
    log.mode = np.full(log.qua.shape, int(Mode.RUNNING))
    log.violations = np.zeros(log.qua.shape, dtype=bool)
    log.t = dt * np.arange(1, log.qua.size + 1)
    env.close()
    return log
