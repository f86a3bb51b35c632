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
from estimation.libm import hypot

__all__ = ["MOVING_MU", "MIN_DISTANCE_M", "EpisodeLog", "moving_mask", "chassis_speed", "distance_metrics",
           "episode_metrics", "scenario_metrics", "SCENARIO_METRICS", "progress_bar"]

#: |μ| [m/s] of the true chassis motion above which a step counts as moving (5% of the paper
#: track's nominal 1 m/s; μ = ‖ξ̇‖ of the twist, ξ̇ = μ (v, −u, w)).
MOVING_MU = 0.05
#: [m] the least distance the chassis centre must travel for the per-metre metrics
#: (:func:`distance_metrics`) to be defined: below it they are None, with the reason
MIN_DISTANCE_M = 0.01


@dataclass
class EpisodeLog:
    """Per-step records of one run (arrays of length T, one row per control step, after the step)
    and its outcome.

    Attributes:
        controller: the controller's name; track: the episode's track; dt: control period [s].
        t: [s] the time at the end of each step; pose: (T, 3) true pose (x, y, θ) [m, m, rad];
        lateral, heading: the track errors [m], [rad]; slip_power [W], nullspace_force [N],
        antagonism [N], qua: as the env's info; beta_meas, beta_true, motor_true: (T, n) measured and true steering
        angles and the true motor angles [rad]; phidot_meas: (T, n) the measured wheel spin
        rates [rad/s]; beta_cmd, phidot_cmd: (T, n) the commands
        [rad], [rad/s]; beta_rate, phiddot: (T, n) their rates where the controller gave them
        (else empty); lam_hat, mu_hat: (T, 3), (T,) the estimate (λ̂, μ̂ [m/s]) the controller read
        (made from the previous row's measurements; the first from the reset's); mu_true: (T,) |μ| of
        the true motion [m/s]; twist_true: (T, 3) the true chassis-frame twist (ẋ, ẏ, θ̇);
        mode: (T,) the controller's :class:`~control.icr.config.Mode`; violations: (T,) a
        commanded limit exceeded (any of ``limit_flags``); limit_flags: (T, 5) which: steering
        rate, steering acceleration, wheel speed, wheel acceleration, steering range
        (:data:`control.limits.LIMIT_KINDS`; of the set-points themselves, differenced over the
        period, the first against the measured state at the reset, or a rate the controller
        declares: :class:`control.limits.SetpointLimitCheck`); events: the stop-and-reconfigure
        sequences; completed: the track was finished; error: why the episode ended early (the env's error, ``"off
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
    nullspace_force: np.ndarray = field(default_factory=lambda: np.zeros(0))
    antagonism: np.ndarray = field(default_factory=lambda: np.zeros(0))
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
    limit_flags: np.ndarray = field(default_factory=lambda: np.zeros((0, 5), dtype=bool))
    #: (T,) bool: the step's command was a hold (the track held the robot still: exactly zero)
    hold: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    events: int = 0
    completed: bool = False
    error: str | None = None
    ret: float = float("nan")  #: the episode's return (sum of the ``Azimut-v2`` rewards)


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


def chassis_speed(log: EpisodeLog) -> np.ndarray | None:
    """(T,) the speed |v| = ‖(ẋ, ẏ)‖ [m/s] of the true chassis centre at each logged step (the
    linear part of ``twist_true``, whichever frame it is written in); None when the log has no
    true twist."""
    if log.twist_true.ndim != 2 or log.twist_true.shape[0] != log.slip_power.shape[0] \
            or log.twist_true.shape[1] < 2:
        return None
    return hypot(log.twist_true[:, 0], log.twist_true[:, 1])  # the C library's: the same bits on every CPU


def distance_metrics(log: EpisodeLog) -> dict:
    """The metrics that weigh slip and antagonism by the distance travelled, and those of the
    standstill apart (keys of :func:`episode_metrics`'s row):

    * ``distance_m`` [m]: the path length of the true chassis centre, ∫ |v| dt = Σ_k |v_k| dt with
      |v_k| its speed at the end of control step k (:func:`chassis_speed`), the same samples and
      rectangle rule as the slip energy Σ_k P_k dt; None when the log has no true twist;
    * ``slip_energy_per_m`` [J/m]: the slip energy (all steps) divided by ``distance_m``;
    * ``antagonism_distance_weighted_N`` [N]: ∫ A |v| dt / ∫ |v| dt = Σ A_k |v_k| / Σ |v_k|, the
      antagonism A averaged over the distance instead of the time (a step at rest weighs nothing);
    * ``per_m_reason``: None, or why the two above are None: the chassis travelled less than
      :data:`MIN_DISTANCE_M` (a standstill-only episode), the log has no true twist, or a value
      is not finite; they are never NaN or infinity;
    * ``standstill_slip_energy_J`` [J] and ``standstill_mean_antagonism_N`` [N]: the slip energy
      and the mean antagonism over the standstill steps, those that are not moving steps
      (:func:`moving_mask`, the same steps as ``standstill_share``); 0 J and None without
      standstill steps.
    """
    dt = log.dt
    standstill = ~moving_mask(log)
    out: dict = {}
    speed = chassis_speed(log)
    distance = float(np.sum(speed) * dt) if speed is not None else None
    out["distance_m"] = distance
    if distance is None:
        reason = "the log has no true chassis twist to measure the distance travelled"
    elif not (np.isfinite(distance) and np.all(np.isfinite(log.slip_power))):
        reason = "the distance or the slip power is not finite"
    elif not distance >= MIN_DISTANCE_M:
        reason = f"the chassis travelled {distance:.4f} m, less than {MIN_DISTANCE_M} m"
    else:
        reason = None
    if reason is None:
        out["slip_energy_per_m"] = float(np.sum(log.slip_power) * dt) / distance
        weighted = (float(np.sum(log.antagonism * speed) / np.sum(speed))
                    if log.antagonism.shape == speed.shape else float("nan"))
        out["antagonism_distance_weighted_N"] = weighted if np.isfinite(weighted) else None
    else:
        out["slip_energy_per_m"] = out["antagonism_distance_weighted_N"] = None
    out["per_m_reason"] = reason
    still = standstill if standstill.shape == log.slip_power.shape else np.zeros(log.slip_power.shape, dtype=bool)
    out["standstill_slip_energy_J"] = float(np.sum(log.slip_power[still]) * dt)
    still = standstill if standstill.shape == log.antagonism.shape else np.zeros(log.antagonism.shape, dtype=bool)
    out["standstill_mean_antagonism_N"] = float(np.mean(log.antagonism[still])) if still.any() else None
    return out


def episode_metrics(log: EpisodeLog) -> dict:
    """The metrics table row of one run (see the module docstring); NaN where undefined, but
    None for the per-metre and standstill metrics (:func:`distance_metrics`)."""
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
        "mean_nullspace_force_N": float(np.mean(log.nullspace_force)) if log.nullspace_force.size else float("nan"),
        "mean_antagonism_N": float(np.mean(log.antagonism)) if log.antagonism.size else float("nan"),
        "mean_qua": float(np.mean(log.qua)) if log.qua.size else float("nan"),
        "min_qua": float(np.min(log.qua)) if log.qua.size else float("nan"),
        "mean_qua_moving": float(np.mean(log.qua[moving])) if moving.any() else float("nan"),
        "min_qua_moving": float(np.min(log.qua[moving])) if moving.any() else float("nan"),
        "standstill_share": float(1.0 - np.mean(moving)) if log.qua.size else float("nan"),
        **distance_metrics(log),
        "limit_violation_steps": int(np.sum(log.violations)),
        "reconfigure_events": int(log.events),
        "return": float(log.ret),
    }


#: the keys :func:`scenario_metrics` adds to a row, with their units
SCENARIO_METRICS = ("peak_steer_rate_cmd", "peak_steer_rate", "setpoint_flips", "travel_reversals", "hold_steps",
                    "hold_chassis_m", "hold_yaw_rad", "hold_steer_rad", "hold_steer_cmd_rad")


def _angle_steps(x: np.ndarray) -> np.ndarray:
    """Differences of angles (T, n) between consecutive steps, modulo 2π into [−π, π[ (a
    module's motion, whichever turn its angle is written in)."""
    return np.mod(np.diff(x, axis=0) + np.pi, 2 * np.pi) - np.pi if x.shape[0] > 1 else np.zeros((0,) + x.shape[1:])


def scenario_metrics(log: EpisodeLog, moving_fraction: float = 0.05) -> dict:
    """The per-scenario metrics of a run (added to :func:`episode_metrics`'s row for the
    scenarios, ``azimut_env.tracks.SCENARIO_NAMES``; NaN where undefined):

    * ``peak_steer_rate_cmd``, ``peak_steer_rate`` [rad/s]: the largest |β̇| over the modules
      and steps, of the commands (the controller's β̇_c) and of the wheels (the true β's
      differences over a period, modulo 2π);
    * ``setpoint_flips``: module set-points that jump by more than π/2 in one period (a flip of
      the wheel about its axis; modulo 2π, so a module winding past ±π does not count);
    * ``travel_reversals``: the times a module's commanded travel direction turns by more than
      π/2 between consecutive steps where it is commanded to roll (|φ̇_c| above
      ``moving_fraction`` of the run's largest |φ̇_c|) and the chassis moves (:func:`moving_mask`:
      not a module turned in place): β's change plus π when φ̇_c changes sign (a ``reverse``
      command reverses every module by design; elsewhere it is a flip);
    * the ``hold`` complaint, over the steps whose command was a hold (exactly zero,
      ``EpisodeLog.hold``): ``hold_steps``; ``hold_chassis_m`` and ``hold_yaw_rad``, the chassis
      path length [m] and heading travel [rad] during them; ``hold_steer_rad`` and
      ``hold_steer_cmd_rad``, the largest steering travel of a module [rad] (Σ|Δβ|, true and
      commanded) during them.
    """
    dt = log.dt
    out: dict = {}
    rate = np.abs(log.beta_rate) if log.beta_rate.size else np.zeros((0,))
    out["peak_steer_rate_cmd"] = float(np.max(rate)) if rate.size else float("nan")
    true_steps = _angle_steps(log.beta_true)
    out["peak_steer_rate"] = float(np.max(np.abs(true_steps)) / dt) if true_steps.size else float("nan")
    cmd_steps = _angle_steps(log.beta_cmd)
    out["setpoint_flips"] = int(np.sum(np.abs(cmd_steps) > 0.5 * np.pi))
    reversals = 0
    if log.phidot_cmd.size:
        ph = log.phidot_cmd
        rolling = np.abs(ph) > moving_fraction * max(float(np.max(np.abs(ph))), 1e-12)
        rolling &= moving_mask(log)[:, None]  # the chassis moving (not a module turned in place)
        travel = log.beta_cmd + np.where(ph < 0, np.pi, 0.0)  # the direction the module rolls, up to α
        for k in range(ph.shape[1]):
            idx = np.flatnonzero(rolling[:, k])
            if idx.size > 1:
                turn = np.mod(np.diff(travel[idx, k]) + np.pi, 2 * np.pi) - np.pi
                reversals += int(np.sum(np.abs(turn) > 0.5 * np.pi))
    out["travel_reversals"] = reversals
    hold = log.hold if log.hold.shape == log.lateral.shape else np.zeros(log.lateral.shape, dtype=bool)
    steps = hold[1:] if hold.size > 1 else np.zeros(0, dtype=bool)  # the motion into step k under its command
    out["hold_steps"] = int(np.sum(hold))
    if steps.any():
        dxy = np.diff(log.pose[:, :2], axis=0)[steps]
        out["hold_chassis_m"] = float(np.sum(np.hypot(dxy[:, 0], dxy[:, 1])))
        out["hold_yaw_rad"] = float(np.sum(np.abs(np.diff(log.pose[:, 2])[steps])))
        out["hold_steer_rad"] = float(np.max(np.sum(np.abs(true_steps[steps]), axis=0)))
        out["hold_steer_cmd_rad"] = float(np.max(np.sum(np.abs(cmd_steps[steps]), axis=0)))
    else:
        for key in ("hold_chassis_m", "hold_yaw_rad", "hold_steer_rad", "hold_steer_cmd_rad"):
            out[key] = float("nan")
    return out
