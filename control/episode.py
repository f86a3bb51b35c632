"""One episode of a built-in controller on a track: :func:`run_episode`, its per-step
:class:`EpisodeLog`, and the metrics row of a log (:func:`episode_metrics`).

The runner behind ``azimut eval`` (:mod:`jobs.eval.command`), the kick study
(:mod:`jobs.eval.robustness`), ``azimut sim-paper`` (:mod:`jobs.sim_paper`, whose feed-forward
driver fills the same log through :func:`record_step`) and the trained-policy rollout
(:mod:`train.rollout`). It imports none of them, so none of them imports another through it.
"""

from __future__ import annotations

import functools
import math
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from azimut_env.env import AzimutEnv
from azimut_env.task.core import nominal_duration
from azimut_env.tracks import TRACK_NAMES, Track, make_track
from control.follow.path_follower import PathFollower, PathFollowerConfig
from control.icr.controller import ICRController, ICRControllerConfig, Mode, reference_stop_mask
from control.limits import limit_violations
from control.twist.wpilib import SwerveConfig, SwerveController

__all__ = ["CONTROLLERS", "MOVING_MU", "EpisodeLog", "run_episode", "record_step", "moving_mask", "episode_metrics",
           "progress_bar"]

#: the built-in controllers :func:`run_episode` drives (trained policies: :mod:`train.rollout`)
CONTROLLERS = ("icr", "twist")
#: |μ| [m/s] of the true chassis motion above which a step counts as moving (5% of the paper
#: track's nominal 1 m/s; μ = ‖ξ̇‖ of the twist, ξ̇ = μ (v, −u, w)).
MOVING_MU = 0.05


@dataclass
class EpisodeLog:
    """Per-step records of one run (arrays of length T) and its outcome."""

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
    beta_true: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    motor_true: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    beta_cmd: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    phidot_cmd: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    beta_rate: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    phiddot: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    lam_hat: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    mu_true: np.ndarray = field(default_factory=lambda: np.zeros(0))
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


def run_episode(controller: str, track: str | Track = "paper", seed: int = 0, speed_scale: float = 1.0,
                kick: dict | None = None, max_time: float | None = None, progress: bool = False,
                icr_config: ICRControllerConfig | None = None, swerve_config: SwerveConfig | None = None,
                follower_config: PathFollowerConfig | None = None, env_kwargs: dict | None = None,
                start_progress: float | None = None) -> EpisodeLog:
    """Drive one track with one controller until the track is done (or ``max_time`` [s]).

    Args:
        controller: ``"icr"`` or ``"twist"``.
        track: a built-in name (``random`` is drawn from ``seed``) or a Track.
        seed: env seed (sensor noise, start noise, random track).
        speed_scale: multiplies the track's speed profile.
        kick: ``{"step": int, "wheels": [...], "impulse": N·m·s}`` (the env's reset option).
        max_time: time limit [s]; default 3 × the nominal duration + 10 s.
        start_progress: start at rest at this progress [m] (the env's reset option).
    """
    if controller not in CONTROLLERS:
        raise ValueError(f"unknown controller {controller!r}; choose from {CONTROLLERS}")
    if isinstance(track, str):
        if track not in TRACK_NAMES:
            raise ValueError(f"unknown track {track!r}; choose from {TRACK_NAMES}")
        track = make_track(track, rng=np.random.default_rng(seed))
    env = AzimutEnv(track=track, **(env_kwargs or {}))
    options = {}
    if kick:
        options["kick"] = kick
    if start_progress is not None:
        options["start_progress"] = float(start_progress)
    _, info = env.reset(seed=seed, options=options or None)
    geom, limits, dt = env.geometry, env.limits, env.control_period
    fcfg = follower_config or PathFollowerConfig(speed_scale=speed_scale)
    stop_mask = None
    if controller == "icr":
        axis_margin = (icr_config or ICRControllerConfig()).axis_margin
        stop_mask = functools.partial(reference_stop_mask, geom=geom, axis_margin=axis_margin)
    follower = PathFollower(env.track, fcfg, stop_mask=stop_mask, dt=dt)
    follower.reset(info["progress"])
    if controller == "icr":
        ctl = ICRController(geom, limits, dt, icr_config)
    else:
        ctl = SwerveController(geom, limits, dt, swerve_config)
        ctl.reset(env.measured_beta, env.measured_phidot)
    nominal = nominal_duration(env.track, fcfg.speed_scale)
    max_time = max_time if max_time is not None else 3.0 * nominal + 10.0
    steps = int(math.ceil(max_time / dt))
    rec: dict[str, list] = {}
    log = EpisodeLog(controller, env.track, dt)
    start = time.time()
    label = f"{controller}/{env.track.name}"
    for k in range(steps):
        lam_hat, mu_hat = env.estimated_eta
        beta_m, phidot_m = env.measured_beta, env.measured_phidot
        target = follower.step(env.estimated_pose)  # the true pose unless pose_source="odometry"
        if controller == "icr":
            cmd = ctl.step(lam_hat, mu_hat, beta_m, phidot_m, target.lam, target.mu)
            mode = int(cmd.info["mode"])
        else:
            cmd = ctl.step(target.twist, beta_m)
            mode = int(Mode.RUNNING)
        viol = bool(limit_violations(cmd.beta_rate, cmd.beta_accel, cmd.phidot, cmd.phiddot, limits).any())
        _, reward, terminated, truncated, info = env.step(env.action_from_setpoints(cmd.beta, cmd.phidot))
        log.ret = reward if k == 0 else log.ret + reward
        if "error" in info:
            log.error = info["error"]
            break
        record_step(rec, env, info, lam_hat, cmd.beta, cmd.phidot, beta_rate=cmd.beta_rate, phiddot=cmd.phiddot,
                    mode=mode, violations=viol)
        done = info["progress"] >= env.track.length - 0.01 or info.get("finished", False)
        if progress and k % 50 == 0:
            progress_bar(label, min(1.0, info["progress"] / env.track.length), start)
        if done:
            log.completed = True
            break
        if info.get("off_track"):
            log.error = "off track"
            break
    if progress and sys.stderr.isatty():
        sys.stderr.write("\n")
    for key, values in rec.items():
        setattr(log, key, np.asarray(values))
    log.t = dt * np.arange(1, log.lateral.size + 1)
    log.events = int(ctl.state.events) if controller == "icr" and ctl.state is not None else 0
    env.close()
    return log


def record_step(rec: dict[str, list], env: AzimutEnv, info: dict, lam_hat, beta_cmd, phidot_cmd, **extra) -> None:
    """Append one control step's log entries to ``rec`` (key -> list; the keys of
    :class:`EpisodeLog`): the env's info and measurements after the step, the commands, and the
    driver's own ``extra`` entries (e.g. ``mode``, ``violations``)."""
    for key, value in (("pose", info["pose"]), ("lateral", info["lateral_error"]),
                       ("heading", info["heading_error"]), ("slip_power", info["slip_power"]),
                       ("internal_force", info["internal_force"]), ("qua", info["qua"]),
                       ("beta_meas", env.measured_beta), ("beta_true", info["beta_true"]),
                       ("motor_true", env.physics.motor_angles()[0]), ("beta_cmd", beta_cmd),
                       ("phidot_cmd", phidot_cmd), ("lam_hat", lam_hat),
                       ("mu_true", abs(float(info["eta_true"][1]))), *extra.items()):
        rec.setdefault(key, []).append(value)


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
