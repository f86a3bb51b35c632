"""Run a trained policy on a track and record the same per-step log as ``azimut eval``.

:func:`run_policy_episode` drives one robot (an ``AzimutVectorEnv`` of one, behind the policy's
action space, no autoreset) until the track is finished, the robot leaves it, or the env's time
limit, and fills a :class:`control.episode.EpisodeLog`, so :func:`control.episode.episode_metrics`
gives the same metrics as for the controllers; the episode's return (sum of ``Azimut-v1``
rewards) comes with it.
"""

from __future__ import annotations

import numpy as np
from gymnasium.vector import AutoresetMode

from azimut_env.tracks import TRACK_NAMES, Track, make_track
from train.envs import make_vector_env

__all__ = ["run_policy_episode", "policy_metrics"]


def run_policy_episode(policy, track: str | Track, seed: int = 0, label: str | None = None,
                       deterministic: bool = True, kick: dict | None = None, max_time: float | None = None,
                       env_kwargs: dict | None = None):
    """(EpisodeLog, return) of ``policy`` (a :class:`train.policy.TrainedPolicy`) on ``track``.

    As :func:`control.episode.run_episode`: the episode ends when the track is finished, off
    track, or after ``max_time`` [s] (default 3 × the track's nominal duration + 10 s, the env's
    own time limit being off); ``kick`` is the env's reset option; ``env_kwargs`` are added to the
    policy's training env arguments (e.g. ``domain_randomization``)."""
    from azimut_env.task.core import nominal_duration
    from control.episode import EpisodeLog, record_step
    from control.icr.controller import Mode
    from control.limits import limit_violations

    if isinstance(track, str):
        if track not in TRACK_NAMES:
            raise ValueError(f"unknown track {track!r}; choose from {', '.join(TRACK_NAMES)}")
        track = make_track(track, rng=np.random.default_rng(seed))
    kwargs = {**policy.env_kwargs, **(env_kwargs or {}), "time_limit_factor": 0.0}
    venv = make_vector_env(policy.action, 1, track=track, autoreset_mode=AutoresetMode.DISABLED, env_kwargs=kwargs)
    base = venv.unwrapped
    obs, info = venv.reset(seed=seed, options={"kick": kick} if kick else None)
    max_time = max_time if max_time is not None else 3.0 * nominal_duration(base.tracks[0]) + 10.0
    dt, limits = base.control_period, base.limits
    log = EpisodeLog(label or f"{policy.algo}-{policy.action}", base.tracks[0], dt)
    rec: dict[str, list] = {}
    ret = 0.0
    beta_prev, phidot_prev = base.setpoints_from_action(base.task.prev_action)
    beta_prev, phidot_prev = beta_prev[0], phidot_prev[0]
    rate_prev = np.zeros_like(beta_prev)
    events = 0
    for _ in range(int(np.ceil(max_time / base.control_period))):
        action = policy.act(obs, deterministic=deterministic)
        obs, reward, terminated, truncated, info = venv.step(action)
        ret += float(reward[0])
        if "error" in info and info["_error"][0]:
            log.error = str(info["error"][0])
            break
        sub = base.sub_env_info(0)
        beta_c, phidot_c = base.setpoints_from_action(base.task.prev_action)
        beta_c, phidot_c = beta_c[0], phidot_c[0]
        rate = (beta_c - beta_prev) / dt
        accel, phiddot = (rate - rate_prev) / dt, (phidot_c - phidot_prev) / dt
        if "limit_exceeded" in info:  # the controller's own commands (float64), as azimut eval checks them
            viol = bool(info["limit_exceeded"][0])
        else:  # raw set-points: finite differences of what the env applied
            viol = bool(limit_violations(rate, accel, phidot_c, phiddot, limits).any())
        beta_prev, rate_prev, phidot_prev = beta_c, rate, phidot_c
        mode = int(info["controller_mode"][0]) if "controller_mode" in info else int(Mode.RUNNING)
        if rec.get("mode") and mode == int(Mode.STOPPING) and rec["mode"][-1] == int(Mode.RUNNING):
            events += 1
        lam_hat, _ = base.estimated_eta
        record_step(rec, _SubEnv(base), sub, lam_hat[0], beta_c, phidot_c, beta_rate=rate, phiddot=phiddot,
                    mode=mode, violations=viol)
        if info["finished"][0]:
            log.completed = True
            break
        if info["off_track"][0]:
            log.error = "off track"
            break
        if info.get("stalled", np.zeros(1, bool))[0]:
            log.error = "stalled"
            break
        if truncated[0] or terminated[0]:
            log.error = "time limit"
            break
    for key, values in rec.items():
        setattr(log, key, np.asarray(values))
    log.t = dt * np.arange(1, log.lateral.size + 1)
    log.events = events
    log.ret = ret
    venv.close()
    return log, ret


class _SubEnv:
    """Sub-env 0 of a one-robot vector env, seen as :func:`control.episode.record_step` reads a
    single env (``measured_beta`` of that robot, ``physics``)."""

    def __init__(self, base):
        self.measured_beta = base.measured_beta[0]
        self.physics = base.physics


def policy_metrics(policy, track: str | Track, seed: int = 0, label: str | None = None,
                   max_time: float | None = None) -> tuple[dict, object]:
    """(``azimut eval`` metrics row plus ``return``, EpisodeLog) of one episode of ``policy``."""
    from control.episode import episode_metrics

    log, ret = run_policy_episode(policy, track, seed=seed, label=label, max_time=max_time)
    row = episode_metrics(log)
    row["return"] = ret
    return row, log
