"""The episode loop: :func:`run_episodes` steps N episodes of one controller as one batch, and
:func:`run_episode` is its N = 1 case. Every job that drives the simulated robot with a
controller uses it (``azimut eval``, the kick study, ``azimut sim-paper``, ``azimut record-d2``,
a trained policy's evaluation).

Per robot i: an :class:`~azimut_env.vector_env.AzimutVectorEnv` sub-env on ``tracks[i]``, reset
with ``seeds[i]`` (sensor and start noise, domain randomisation; a built-in track name is made
from the seed too, so ``random`` is drawn from it) and the robot's ``kick`` and
``start_progress`` reset options. Each control period the controller's
:meth:`~control.controller.Controller.act` gives the commands of all robots, the env steps them
(the command's ``action`` if it has one, else the set-points through
``env.action_from_setpoints``), and each running robot's :class:`~control.episode.EpisodeLog`
gets a row. A robot's episode ends, and its log with it, at the first of:

* an env error (a physics blow-up; the step is not logged; ``log.error`` is the env's message);
* the end of the track: the env's ``finished``, or progress within 1 cm of the track's length
  (``log.completed``);
* off the track (``"off track"``), a stall (``"stalled"``, only with the env's ``stall_time``),
  the env's time limit (``"time limit"``; off unless ``env_kwargs`` sets ``time_limit_factor``);
* ``max_time`` [s] (default 3 × the track's nominal duration at the controller's
  ``speed_scale`` + 10 s; not an error).

The others go on: a robot the env ended (terminated or truncated) is reset in place (its seed's
generator goes on) and its controller restarted, so every robot the controller sees is in a
running episode; what it does after its own episode ended is not logged. Sub-env i behaves as a
single env seeded with ``seeds[i]`` and the robots' physics do not interact, so a batch gives
each robot the episode it gets alone, as long as the controller treats its robots independently
(the built-ins do; a policy's network may round a batch differently;
``tests/control/test_controller_api.py`` checks it bit for bit; a controller of yours:
:func:`control.checks.check_batch_independence`).

What ``act`` returns is checked first (:func:`control.commands.checked_command`: shapes, real
numbers, no NaN; the message names the controller and the field). Each period's commanded-limit
check (``EpisodeLog.violations`` and ``limit_flags``, ``azimut eval``'s
``limit_violation_steps``) reads the set-points the env gets: the command's β and φ̇, or those
read back from its action (``env.setpoints_from_action``), differenced over the period, the
first period against the measured state at the reset (:class:`control.limits.SetpointLimitCheck`);
a rate the command declares over its limit counts too.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence

import numpy as np
from gymnasium.vector import AutoresetMode

from azimut_env.task.core import nominal_duration
from azimut_env.tracks import SCENARIO_NAMES, TRACK_NAMES, Track, make_track
from azimut_env.vector_env import AzimutVectorEnv
from control.commands import WheelCommand, checked_command
from control.controller import Controller, make_controller
from control.episode import EpisodeLog, progress_bar
from control.icr.config import Mode
from control.limits import SetpointLimitCheck, limit_violations

__all__ = ["run_episodes", "run_episode", "END_TOLERANCE"]

#: progress [m] short of the track's length at which an episode counts as completed
END_TOLERANCE = 0.01


def _per_robot(value, num: int, what: str) -> list:
    """``value`` for each of ``num`` robots: a sequence of ``num`` entries, or one for all."""
    if isinstance(value, (list, tuple)):
        if len(value) != num:
            raise ValueError(f"{what} must have one entry per seed ({num}), got {len(value)}")
        return list(value)
    return [value] * num


def _track(spec, seed: int) -> Track | str:
    """A Track, or a scenario's name (the env builds it for its robot)."""
    if isinstance(spec, Track) or (isinstance(spec, str) and spec in SCENARIO_NAMES):
        return spec
    if not isinstance(spec, str) or spec not in TRACK_NAMES:
        raise ValueError(f"unknown track {spec!r}; choose from {', '.join(TRACK_NAMES + SCENARIO_NAMES)}")
    return make_track(spec, rng=np.random.default_rng(seed))


def _declared(cmd: WheelCommand, limits) -> np.ndarray:
    """(N, 4) bool: the declared rates over their limits (:func:`control.limits.limit_violations`
    of β̇, β̈, φ̇, φ̈; the rates the command leaves None are not checked)."""
    zero = np.zeros(np.shape(cmd.phidot))
    vals = [zero if v is None else v for v in (cmd.beta_rate, cmd.beta_accel, cmd.phidot, cmd.phiddot)]
    return limit_violations(*vals, limits)


def _applied(cmd: WheelCommand, env) -> tuple[np.ndarray, np.ndarray]:
    """(β, φ̇) (N, n) the set-points the env applies: the command's, or those read back from its
    action when it gives one (what the limits are counted on and the episode records)."""
    if cmd.action is None:
        return cmd.beta, cmd.phidot
    return env.setpoints_from_action(cmd.action)


def _limit_flags(cmd: WheelCommand, env, check: SetpointLimitCheck, applied) -> np.ndarray:
    """(N, 5) bool, the :data:`~control.limits.LIMIT_KINDS` exceeded this period: by the set-points
    themselves (``applied``: :func:`_applied`; :class:`~control.limits.SetpointLimitCheck`), or by a
    rate the controller declares."""
    flags = check.step(*applied, from_action=cmd.action is not None)
    flags[:, :4] |= _declared(cmd, env.limits)
    return flags


def _record(rec: dict, info: dict, i: int, cmd: WheelCommand, applied, eta_hat: tuple, beta_meas: np.ndarray,
            phidot_meas: np.ndarray, motor: np.ndarray, flags: np.ndarray) -> None:
    """Append robot i's row (the keys of :class:`EpisodeLog`) after a step, from the env's info
    (the vector env's batched info, whose row i is the single env's info of that robot)."""
    row = [("pose", info["pose"][i]), ("lateral", info["lateral_error"][i]), ("heading", info["heading_error"][i]),
           ("slip_power", info["slip_power"][i]), ("nullspace_force", info["nullspace_force"][i]),
           ("antagonism", info["antagonism"][i]), ("qua", info["qua"][i]), ("beta_meas", beta_meas[i]),
           ("phidot_meas", phidot_meas[i]),
           ("beta_true", info["beta_true"][i]), ("motor_true", motor[i]),
           ("beta_cmd", np.array(applied[0][i], dtype=np.float64)),
           ("phidot_cmd", np.array(applied[1][i], dtype=np.float64)),
           ("lam_hat", eta_hat[0][i]), ("mu_hat", float(eta_hat[1][i])),
           ("mu_true", abs(float(info["eta_true"][1][i]))),
           ("twist_true", np.array(info["twist"][i], dtype=np.float64)),
           ("mode", int(cmd.mode[i]) if cmd.mode is not None else int(Mode.RUNNING)),
           ("violations", bool(flags.any())), ("limit_flags", flags.copy())]
    if "hold" in cmd.info:  # the path followers' holds (Track.holds): the command was exactly zero
        row.append(("hold", bool(cmd.info["hold"][i])))
    if cmd.beta_rate is not None:
        row.append(("beta_rate", np.array(cmd.beta_rate[i], dtype=np.float64)))
    if cmd.phiddot is not None:
        row.append(("phiddot", np.array(cmd.phiddot[i], dtype=np.float64)))
    for key, value in row:
        rec.setdefault(key, []).append(value)


def _end_of(info: dict, i: int, length: float, terminated, truncated) -> tuple[bool, str | None] | None:
    """(completed, error) if robot i's episode ended with this (logged) step, else None."""
    if info["finished"][i] or info["progress"][i] >= length - END_TOLERANCE:
        return True, None
    if info["off_track"][i]:
        return False, "off track"
    if info["stalled"][i]:
        return False, "stalled"
    if truncated[i]:
        return False, "time limit"
    if terminated[i]:
        return False, "terminated"
    return None


def run_episodes(controller: Controller, tracks: str | Track | Sequence[str | Track], seeds: Sequence[int], *,
                 kicks: dict | Sequence[dict | None] | None = None,
                 start_progress: float | Sequence[float | None] | None = None, max_time: float | None = None,
                 env_kwargs: dict | None = None, progress: bool = False) -> list[EpisodeLog]:
    """One episode per seed, all stepped as one batch (see the module docstring).

    Args:
        controller: a :class:`~control.controller.Controller` (``make_controller(spec)`` makes one).
        tracks: one track (a built-in name or a :class:`~azimut_env.tracks.Track`) for every
            robot, or one per seed.
        seeds: the robots' env seeds (N = len(seeds)).
        kicks: the env's ``kick`` reset option (``{"step", "wheels", "impulse"}``), one for all or
            one per robot (None: no kick).
        start_progress: start at rest at this progress [m] (the env's reset option), one for all or
            one per robot (None: the start of the track).
        max_time: each episode's time limit [s] (default: 3 × its track's nominal duration at the
            controller's ``speed_scale`` + 10 s).
        env_kwargs: ``AzimutVectorEnv`` keyword arguments, over the controller's ``env_kwargs``
            (``time_limit_factor`` is 0 unless given here).
        progress: draw a progress bar on a terminal.

    Returns:
        the N logs, in the order of ``seeds``.
    """
    if not isinstance(controller, Controller):
        raise TypeError(f"controller must implement control.controller.Controller (name, reset, act), got "
                        f"{type(controller).__name__}")
    seeds = [int(s) for s in seeds]
    num = len(seeds)
    if num == 0:
        raise ValueError("give at least one seed")
    tracks = [_track(t, s) for t, s in zip(_per_robot(tracks, num, "tracks"), seeds)]
    kicks = _per_robot(kicks, num, "kicks")
    starts = _per_robot(start_progress, num, "start_progress")
    if max_time is not None and not (math.isfinite(max_time) and max_time > 0):
        raise ValueError(f"max_time must be finite and > 0, got {max_time!r}")
    options = []
    for track, kick, start in zip(tracks, kicks, starts):
        opt: dict = {"track": track}
        if kick:
            opt["kick"] = kick
        if start is not None:
            opt["start_progress"] = float(start)
        options.append(opt)
    kw = {**dict(getattr(controller, "env_kwargs", None) or {}), "time_limit_factor": 0.0, **(env_kwargs or {})}
    env = AzimutVectorEnv(num_envs=num, track=tracks[0], autoreset_mode=AutoresetMode.DISABLED, **kw)
    try:
        return _loop(controller, env, seeds, options, max_time, progress)
    finally:
        env.close()


def _horizons(controller: Controller, tracks, max_time: float | None, dt: float) -> list[int]:
    """Each robot's step limit: ``max_time``, else three times the track's nominal duration at the
    controller's ``speed_scale`` (checked) plus 10 s."""
    scale = getattr(controller, "speed_scale", 1.0)
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"controller {controller.name!r}: speed_scale must be a finite number > 0, got {scale!r}")
    return [int(math.ceil((max_time if max_time is not None else 3.0 * nominal_duration(t, scale) + 10.0) / dt))
            for t in tracks]


def _restart(controller: Controller, env: AzimutVectorEnv, check: SetpointLimitCheck, over: np.ndarray):
    """The robots ``over`` that the env ended while others run: reset, one by one on their track,
    with the limit check and the controller reset for them; returns the new observation."""
    num = env.num_envs
    for i in over:
        mask = np.zeros(num, dtype=np.bool_)
        mask[i] = True
        obs, _ = env.reset(options={"reset_mask": mask, "track": env.tracks[i]})
    check.reset(over, env.geometry.measured_steering(env.measured_beta), env.measured_phidot)
    controller.reset(env, over)
    return obs


def _loop(controller: Controller, env: AzimutVectorEnv, seeds: list[int], options: list[dict],
          max_time: float | None, progress: bool) -> list[EpisodeLog]:
    num, n, dt, name = len(seeds), env.n, env.control_period, controller.name
    obs, _ = env.reset(seed=seeds, options=options)
    check = SetpointLimitCheck(env.limits, dt, num, n)  # the first period differenced against the reset's
    # from the measured state, the angles where the controllers start (a wheel past a stop at it)
    check.reset(np.arange(num), env.geometry.measured_steering(env.measured_beta), env.measured_phidot)
    controller.reset(env, np.arange(num))
    lengths = [t.length for t in env.tracks]
    horizons = _horizons(controller, env.tracks, max_time, dt)
    logs = [EpisodeLog(name, t, dt) for t in env.tracks]
    recs: list[dict] = [{} for _ in range(num)]
    ret: list[float | None] = [None] * num
    events = np.zeros(num, dtype=np.int64)
    alive = np.ones(num, dtype=np.bool_)
    label, start = f"{name}/{env.tracks[0].name}" + (f" x{num}" if num > 1 else ""), time.time()
    k = 0
    while alive.any():
        eta_hat = env.estimated_eta  # (λ̂, μ̂) the controller reads
        cmd = checked_command(controller.act(env, obs), name, num, n)
        action = cmd.action if cmd.action is not None else env.action_from_setpoints(cmd.beta, cmd.phidot)
        applied = _applied(cmd, env)
        flags = _limit_flags(cmd, env, check, applied)
        obs, reward, terminated, truncated, info = env.step(action)
        if cmd.events is not None:
            events = np.asarray(cmd.events, dtype=np.int64)
        beta_meas, phidot_meas, motor = env.measured_beta, env.measured_phidot, env.physics.motor_angles()
        errors = info.get("error")
        ended = []
        for i in np.flatnonzero(alive):
            r = float(reward[i])
            ret[i] = r if ret[i] is None else ret[i] + r
            if errors is not None and info["_error"][i]:
                logs[i].error = str(errors[i])
                ended.append(i)
                continue
            _record(recs[i], info, i, cmd, applied, eta_hat, beta_meas, phidot_meas, motor, flags[i])
            end = _end_of(info, i, lengths[i], terminated, truncated)
            if end is None and k + 1 >= horizons[i]:
                end = (False, None)
            if end is not None:
                logs[i].completed, logs[i].error = end
                ended.append(i)
        if progress and k % 50 == 0:
            frac = np.mean([min(1.0, float(info["progress"][i]) / lengths[i]) if alive[i] else 1.0 for i in range(num)])
            progress_bar(label, float(frac), start)
        for i in ended:
            _finish(logs[i], recs[i], dt, int(events[i]), ret[i])
        alive[ended] = False
        over = np.flatnonzero(terminated | truncated)
        if over.size and alive.any():  # the env ended these: on, unlogged, in fresh episodes (module docstring)
            obs = _restart(controller, env, check, over)
        k += 1
    if progress and sys.stderr.isatty():
        sys.stderr.write("\n")
    return logs


def _finish(log: EpisodeLog, rec: dict, dt: float, events: int, ret: float | None) -> None:
    for key, values in rec.items():
        setattr(log, key, np.asarray(values))
    log.t = dt * np.arange(1, log.qua.size + 1)
    log.events = events
    log.ret = float("nan") if ret is None else ret


def run_episode(controller: Controller | str, track: str | Track = "paper", seed: int = 0, *,
                kick: dict | None = None, start_progress: float | None = None, max_time: float | None = None,
                env_kwargs: dict | None = None, progress: bool = False, **controller_options) -> EpisodeLog:
    """One episode of ``controller`` (a :class:`~control.controller.Controller`, or a spec made
    with :func:`~control.controller.make_controller` and ``controller_options``, e.g. ``"icr"``
    with ``speed_scale=0.5``) on ``track`` with ``seed``: :func:`run_episodes` for one robot."""
    if isinstance(controller, str):
        controller = make_controller(controller, **controller_options)
    elif controller_options:
        raise TypeError(f"options {sorted(controller_options)} are for a controller spec; this controller is "
                        "already made")
    return run_episodes(controller, [track], [seed], kicks=[kick], start_progress=[start_progress],
                        max_time=max_time, env_kwargs=env_kwargs, progress=progress)[0]
