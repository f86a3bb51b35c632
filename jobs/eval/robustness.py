"""Robustness study: wheels knocked to random angles mid-track (the paper's D3 situation).

Each trial starts the robot at rest at a random progress on a track, lets the controller bring it
up to speed, then kicks random wheels with a random angular impulse (the env's ``kick`` reset
option: an impulsive torque about the steering axes, like a collision), and follows it for a while.
A trial *recovers* if the run neither fails nor leaves the track, no commanded limit is exceeded,
and the lateral error is back (and stays) under ``recover_tol`` within ``recover_time`` of the kick.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from azimut_env.tracks import make_track
from control.rollout import run_episode
from jobs.eval.controllers import build_controller

__all__ = ["KickTrial", "kick_trial", "kick_study", "kick_trial_task", "kick_study_campaign", "summarize_kicks"]


@dataclass(frozen=True)
class KickTrial:
    """Outcome of one kick trial.

    Attributes:
        seed: the trial's seed; wheels: the kicked wheels; impulse: [N·m·s] (signed).
        kick_time: [s] after the start; peak_beta_error: largest |β_meas − β_cmd| (mod π) after
            the kick [rad]; max_lateral_after: [m]; recovery_time: [s] from the kick until the
            lateral error is under the tolerance for good (NaN if never); settle_time: [s] from
            the kick until every measured wheel angle is within 5° of its command (mod π) for
            good (NaN if never); limit_violation_steps;
            reconfigure_events; error: the run's failure, if any; recovered: see the module doc.
    """

    seed: int
    wheels: tuple[int, ...]
    impulse: float
    kick_time: float
    peak_beta_error: float
    max_lateral_after: float
    recovery_time: float
    settle_time: float
    limit_violation_steps: int
    reconfigure_events: int
    error: str | None
    recovered: bool


def kick_trial(seed: int, controller: str = "icr", track: str = "paper", kick_step: int = 100,
               after: float = 6.0, recover_tol: float = 0.05, recover_time: float = 3.0) -> KickTrial:
    """One trial (see the module docstring) of the controller spec ``controller``
    (:mod:`jobs.eval.controllers`); everything random is drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    tr = make_track(track, rng=np.random.default_rng(seed))
    start = float(rng.uniform(0.1, 0.8) * tr.length)
    wheels = tuple(int(w) for w in np.sort(rng.choice(4, size=int(rng.integers(1, 5)), replace=False)))
    impulse = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.2, 1.0))
    dt = 0.02
    log = run_episode(build_controller(controller), tr, seed=seed,
                      kick={"step": kick_step, "wheels": list(wheels), "impulse": impulse},
                      max_time=kick_step * dt + after, start_progress=start)
    k0 = kick_step
    lat = np.abs(log.lateral[k0:]) if log.lateral.size > k0 else np.zeros(0)
    dbeta = np.abs(np.mod(log.beta_meas[k0:] - log.beta_cmd[k0:] + np.pi / 2, np.pi) - np.pi / 2)
    bad = np.flatnonzero(lat >= recover_tol)
    rec_t = 0.0 if bad.size == 0 else (float((bad[-1] + 1) * dt) if bad[-1] + 1 < lat.size else float("nan"))
    unsettled = np.flatnonzero(np.max(dbeta, axis=1) >= np.deg2rad(5.0)) if dbeta.size else np.zeros(0, int)
    settle_t = 0.0 if unsettled.size == 0 else (float((unsettled[-1] + 1) * dt) if unsettled[-1] + 1 < len(dbeta)
                                                  else float("nan"))
    viol = int(np.sum(log.violations))
    recovered = (log.error is None and viol == 0 and np.isfinite(rec_t) and rec_t <= recover_time)
    return KickTrial(seed=seed, wheels=wheels, impulse=impulse, kick_time=k0 * dt,
                     peak_beta_error=float(dbeta.max()) if dbeta.size else 0.0,
                     max_lateral_after=float(lat.max()) if lat.size else float("nan"), recovery_time=rec_t,
                     settle_time=settle_t,
                     limit_violation_steps=viol, reconfigure_events=log.events, error=log.error,
                     recovered=bool(recovered))


def kick_study(n_runs: int = 200, controller: str = "icr", track: str = "paper", seed0: int = 1000,
               progress=None) -> list[KickTrial]:
    """``n_runs`` trials with seeds seed0, seed0 + 1, ... (``progress(i, n)`` called after each)."""
    trials = []
    for i in range(n_runs):
        trials.append(kick_trial(seed0 + i, controller, track))
        if progress is not None:
            progress(i + 1, n_runs)
    return trials


def kick_trial_task(seed: int, controller: str = "icr", track: str = "paper") -> dict:
    """:func:`kick_trial` as a campaign task (:mod:`jobs.campaign.engine`): ``{"trial": dict}``."""
    return {"trial": asdict(kick_trial(seed, controller, track))}


def check_kick_trial_result(result, key: dict) -> None:
    """The schema of a saved :func:`kick_trial_task` result read back on ``--resume``: ``{"trial":
    the KickTrial's fields}`` of this seed (``TypeError``/``ValueError`` otherwise: recomputed)."""
    trial = result.get("trial") if isinstance(result, dict) else None
    if not isinstance(trial, dict) or not isinstance(trial.get("wheels"), list):
        raise TypeError("no 'trial' dict with a 'wheels' list")
    KickTrial(**{**trial, "wheels": tuple(trial["wheels"])})  # every field, no other
    if trial["seed"] != key["seed"]:
        raise ValueError(f"trial seed {trial['seed']!r}, the task's is {key['seed']!r}")


def kick_study_campaign(n_runs: int, controller: str = "icr", track: str = "paper", seed0: int = 1000,
                        store=None, **run_kwargs) -> list[KickTrial]:
    """:func:`kick_study` run by :func:`jobs.campaign.engine.run_tasks` (``run_kwargs``: executor,
    workers, resume, progress, ...), with each trial saved in ``store`` as it finishes. The same
    trials as the serial study, whatever the executor; a trial whose task failed (after its retry)
    is a failed, unrecovered trial."""
    import tempfile

    from jobs.campaign.engine import Task, run_tasks

    tasks = [Task("jobs.eval.robustness:kick_trial_task", {"seed": seed0 + i, "controller": controller, "track": track},
                  label=f"kick-{controller}-{track}-{seed0 + i}", check="jobs.eval.robustness:check_kick_trial_result")
             for i in range(n_runs)]
    if store is None:
        with tempfile.TemporaryDirectory(prefix="azimut-kicks-") as tmp:
            records = run_tasks(tasks, tmp, **run_kwargs)
    else:
        records = run_tasks(tasks, store, **run_kwargs)
    trials = []
    for task, rec in zip(tasks, records):
        if rec["status"] == "ok":
            d = dict(rec["result"]["trial"])
            d["wheels"] = tuple(d["wheels"])
            trials.append(KickTrial(**d))
        else:
            nan = float("nan")
            trials.append(KickTrial(seed=task.key["seed"], wheels=(), impulse=nan, kick_time=nan, peak_beta_error=nan,
                                    max_lateral_after=nan, recovery_time=nan, settle_time=nan,
                                    limit_violation_steps=0, reconfigure_events=0,
                                    error=f"task failed: {rec.get('error')}", recovered=False))
    return trials


def summarize_kicks(trials: list[KickTrial]) -> dict:
    """The distribution: recovered fraction, percentiles of recovery time, peak β error and
    lateral error after the kick, totals of limit violations and failures."""
    rec = np.array([t.recovery_time for t in trials])
    lat = np.array([t.max_lateral_after for t in trials])
    peak = np.array([t.peak_beta_error for t in trials])
    pct = (0, 50, 90, 99, 100)

    def p(x):
        x = x[np.isfinite(x)]
        return {f"p{q}": float(np.percentile(x, q)) for q in pct} if x.size else {}

    return {
        "runs": len(trials),
        "recovered": int(sum(t.recovered for t in trials)),
        "failed_runs": int(sum(t.error is not None for t in trials)),
        "never_recovered": int(np.sum(~np.isfinite(rec))),
        "limit_violation_steps": int(sum(t.limit_violation_steps for t in trials)),
        "reconfigure_events_mean": float(np.mean([t.reconfigure_events for t in trials])),
        "recovery_time_s": p(rec),
        "settle_time_s": p(np.array([t.settle_time for t in trials])),
        "max_lateral_after_m": p(lat),
        "peak_beta_error_rad": p(peak),
        "trials": [asdict(t) for t in trials],
    }
