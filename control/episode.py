"""The record of one episode, :class:`EpisodeLog` (per-step arrays and the outcome), and its
metrics row (:func:`episode_metrics`).

The episode loop (:func:`control.rollout.run_episodes`) fills one log per robot, whatever the
controller; ``azimut eval`` (:mod:`jobs.eval.command`), the kick study
(:mod:`jobs.eval.robustness`), ``azimut sim-paper`` (:mod:`jobs.sim_paper`) and ``azimut
record-d2`` read it. It imports none of them, so none of them imports another through it.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np

from azimut_env.tracks import Track
from control.icr.config import Mode

__all__ = ["MOVING_MU", "EpisodeLog", "moving_mask", "episode_metrics", "progress_bar"]

#: |μ| [m/s] of the true chassis motion above which a step counts as moving (5% of the paper
#: track's nominal 1 m/s; μ = ‖ξ̇‖ of the twist, ξ̇ = μ (v, −u, w)).
MOVING_MU = 0.05


@dataclass
class EpisodeLog:
    """Per-step records of one run (arrays of length T, one row per control step, after the step)
    and its outcome.

    Attributes:
        controller: the controller's name; track: the episode's track; dt: control period [s].
        t: [s] the time at the end of each step; pose: (T, 3) true pose (x, y, θ) [m, m, rad];
        lateral, heading: the track errors [m], [rad]; slip_power [W], internal_force [N], qua:
        as the env's info; beta_meas, beta_true, motor_true: (T, n) measured and true steering
        angles and the true motor angles [rad]; phidot_meas: (T, n) the measured wheel spin
        rates [rad/s]; beta_cmd, phidot_cmd: (T, n) the commands
        [rad], [rad/s]; beta_rate, phiddot: (T, n) their rates where the controller gave them
        (else empty); lam_hat, mu_hat: (T, 3), (T,) the estimate (λ̂, μ̂ [m/s]) the controller read
        (made from the previous row's measurements; the first from the reset's); mu_true: (T,) |μ| of
        the true motion [m/s]; twist_true: (T, 3) the true chassis-frame twist (ẋ, ẏ, θ̇);
        mode: (T,) the controller's :class:`~control.icr.config.Mode`; violations: (T,) a
        commanded limit exceeded; events: the stop-and-reconfigure sequences; completed: the
        track was finished; error: why the episode ended early (the env's error, ``"off
        track"``, ``"stalled"``, ``"time limit"``), None otherwise; ret: the return.
    """

    controller: str
    track: Track
    dt: float
    t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pose: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    lateral: np.ndarray = field(default_factory=lambda: np.zeros(0))
    heading: np.ndarray = field(default_factory=lambda: np.zeros(0))
    slip_power: np.ndarray = field(default_factory=lambda: np.zeros(0))
    internal_force: np.ndarray = field(default_factory=lambda: np.zeros(0))
    qua: np.ndarray = field(default_factory=lambda: np.zeros(0))
    beta_meas: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    phidot_meas: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    beta_true: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    motor_true: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    beta_cmd: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    phidot_cmd: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    beta_rate: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    phiddot: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    lam_hat: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    mu_hat: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mu_true: np.ndarray = field(default_factory=lambda: np.zeros(0))
    twist_true: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    mode: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    violations: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    events: int = 0
    completed: bool = False
    error: str | None = None
    ret: float = float("nan")  #: the episode's return (sum of the ``Azimut-v1`` rewards)


def progress_bar(label: str, frac: float, start: float, stream=sys.stderr) -> None:
    """One ``label [####....] pct% seconds`` line on ``stream`` (rewritten in place; only on a terminal)."""
    if not stream.isatty():
        return
    width = 30
    k = int(round(frac * width))
    stream.write(f"\r{label:<24} [{'#' * k}{'.' * (width - k)}] {100 * frac:5.1f}% {time.time() - start:6.1f}s")
    stream.flush()


def moving_mask(log: EpisodeLog, min_mu: float = MOVING_MU) -> np.ndarray:
    """(T,) bool: the steps where the robot moves: the controller is RUNNING (not stopping or
    reconfiguring in place; the twist baseline always is) and the true |μ| > ``min_mu`` [m/s]."""
    if log.mu_true.shape != log.qua.shape:
        return np.zeros(log.qua.shape, dtype=bool)
    return (log.mode == int(Mode.RUNNING)) & (log.mu_true > min_mu)


def episode_metrics(log: EpisodeLog) -> dict:
    """The metrics table row of one run (see the module docstring); NaN where undefined."""
    t_end = float(log.t[-1]) if log.t.size else float("nan")
    lat = log.lateral if log.lateral.size else np.array([np.nan])
    head = log.heading if log.heading.size else np.array([np.nan])
    moving = moving_mask(log)
    return {
        "controller": log.controller,
        "track": log.track.name,
        "completed": bool(log.completed),
        "error": log.error,
        "rms_lateral_m": float(np.sqrt(np.mean(lat**2))),
        "max_lateral_m": float(np.max(np.abs(lat))),
        "rms_heading_rad": float(np.sqrt(np.mean(head**2))),
        "completion_time_s": t_end if log.completed else float("nan"),
        "slip_energy_J": float(np.sum(log.slip_power) * log.dt),
        "mean_internal_force_N": float(np.mean(log.internal_force)) if log.internal_force.size else float("nan"),
        "mean_qua": float(np.mean(log.qua)) if log.qua.size else float("nan"),
        "min_qua": float(np.min(log.qua)) if log.qua.size else float("nan"),
        "mean_qua_moving": float(np.mean(log.qua[moving])) if moving.any() else float("nan"),
        "min_qua_moving": float(np.min(log.qua[moving])) if moving.any() else float("nan"),
        "standstill_share": float(1.0 - np.mean(moving)) if log.qua.size else float("nan"),
        "limit_violation_steps": int(np.sum(log.violations)),
        "reconfigure_events": int(log.events),
        "return": float(log.ret),
    }
