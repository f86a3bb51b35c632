"""Run a trained policy on a track and record the same per-step log as ``azimut eval``.

:func:`run_policy_episode` is one episode of the one episode loop
(:func:`control.rollout.run_episode`) with the policy as its controller
(:class:`train.policy.PolicyController`), so :func:`control.episode.episode_metrics` gives the
same metrics as for the controllers, the episode's return (sum of ``Azimut-v2`` rewards) with
them.
"""

from __future__ import annotations

import numpy as np

from azimut_env.tracks import Track
from control.episode import EpisodeLog, episode_metrics
from control.rollout import run_episode
from train.policy import PolicyController, TrainedPolicy

__all__ = ["run_policy_episode", "policy_metrics"]


def run_policy_episode(policy: TrainedPolicy, track: str | Track, seed: int = 0, label: str | None = None,
                       deterministic: bool = True, kick: dict | None = None, max_time: float | None = None,
                       env_kwargs: dict | None = None) -> tuple[EpisodeLog, float]:
    """(EpisodeLog, return) of ``policy`` on ``track`` (named ``label``, default ``ALGO-ACTION``).

    The episode ends as every episode of :mod:`control.rollout` does (the track finished, off the
    track, a stall, an env error, or ``max_time`` [s], default 3 × the track's nominal duration
    + 10 s, the env's own time limit being off); ``kick`` is the env's reset option;
    ``env_kwargs`` are added to the policy's training env arguments (e.g. ``domain_randomization``)."""
    controller = PolicyController(policy, label or f"{policy.algo}-{policy.action}", deterministic=deterministic)
    log = run_episode(controller, track, seed=seed, kick=kick, max_time=max_time, env_kwargs=env_kwargs)
    return log, log.ret


class _ActionRecorder:
    """A :class:`TrainedPolicy` that also sums the squares of its clipped actions (for
    ``mean_sq_action``)."""

    def __init__(self, policy: TrainedPolicy) -> None:
        self._policy, self.sum_sq, self.count = policy, 0.0, 0

    def __getattr__(self, name):
        return getattr(self._policy, name)

    def act(self, obs, deterministic: bool = True):
        action = self._policy.act(obs, deterministic=deterministic)
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        self.sum_sq += float(np.sum(np.mean(a ** 2, axis=-1)))
        self.count += a.shape[0]
        return action


def policy_metrics(policy: TrainedPolicy, track: str | Track, seed: int = 0, label: str | None = None,
                   max_time: float | None = None) -> tuple[dict, EpisodeLog]:
    """(``azimut eval`` metrics row, with its ``return``, EpisodeLog) of one episode of ``policy``;
    the row also holds ``mean_sq_action``, the mean over the episode's steps of mean_k(a_k²) of
    the clipped action a ∈ [−1, 1] (for a residual policy: how far it corrects the reference)."""
    recorder = _ActionRecorder(policy)
    log, _ = run_policy_episode(recorder, track, seed=seed, label=label, max_time=max_time)
    row = episode_metrics(log)
    row["mean_sq_action"] = recorder.sum_sq / recorder.count if recorder.count else float("nan")
    return row, log
