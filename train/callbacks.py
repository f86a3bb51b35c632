"""SB3 callbacks of ``azimut train``: env diagnostics from the infos, and periodic evaluation on
held-out tracks with the ``azimut eval`` metrics."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from train.policy import TrainedPolicy
from train.rollout import policy_metrics

__all__ = ["InfoStatsCallback", "HeldOutEvalCallback", "WallClockLimit", "StopOnSignal"]

_INFO_KEYS = ("slip_power", "antagonism", "nullspace_force", "heading_error", "lateral_error")


class InfoStatsCallback(BaseCallback):
    """Mean |value| over the last ``every`` env steps of the infos' slip power [W], antagonism and
    null-space force [N], heading and lateral errors, logged as ``env/<key>`` (TensorBoard and progress.csv)."""

    def __init__(self, every: int = 256) -> None:
        super().__init__()
        self.every = int(every)
        self._sums = dict.fromkeys(_INFO_KEYS, 0.0)
        self._count = 0

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", ()):
            for key in _INFO_KEYS:
                if key in info:
                    self._sums[key] += abs(float(info[key]))
            self._count += 1
        if self.n_calls % self.every == 0 and self._count:
            for key, total in self._sums.items():
                self.logger.record(f"env/{key}", total / self._count)
            self._sums = dict.fromkeys(_INFO_KEYS, 0.0)
            self._count = 0
        return True


class HeldOutEvalCallback(BaseCallback):
    """Every ``eval_every`` timesteps: one deterministic episode per held-out track with the
    current policy and the training VecNormalize statistics; logs ``eval/<track>/...`` and the
    mean return, appends the rows to ``out/evaluations.json``, and saves the best policy (highest
    mean return) as ``best_model.zip`` + ``best_vecnormalize.pkl``; ``on_evaluation(entry)``
    returning False stops learning (``stopped`` is then True)."""

    def __init__(self, tracks: list[str], eval_every: int, out: Path, algo: str, action: str, env_kwargs: dict,
                 seed: int = 0, max_time: float | None = None, on_evaluation=None) -> None:
        super().__init__()
        self.on_evaluation, self.stopped = on_evaluation, False
        self.max_time = max_time
        self.tracks, self.eval_every, self.out = list(tracks), int(eval_every), Path(out)
        self.algo, self.action, self.env_kwargs, self.seed = algo, action, dict(env_kwargs), int(seed)
        self.best = -np.inf
        self._next = int(eval_every)
        self.history: list[dict] = []
        f = self.out / "evaluations.json"
        if f.is_file():
            self.history = json.loads(f.read_text())
            if self.history:
                self.best = max(h["mean_return"] for h in self.history)

    def _on_training_start(self) -> None:
        self._next = (self.num_timesteps // self.eval_every + 1) * self.eval_every

    def evaluate(self) -> dict:
        vn = self.model.get_vec_normalize_env()
        policy = TrainedPolicy(model=self.model, algo=self.algo, action=self.action, env_kwargs=self.env_kwargs,
                               obs_rms=None if vn is None else vn.obs_rms,
                               clip_obs=10.0 if vn is None else vn.clip_obs, epsilon=1e-8 if vn is None else vn.epsilon)
        start = time.perf_counter()
        rows = [policy_metrics(policy, track, seed=self.seed, label=f"{self.algo}-{self.action}",
                               max_time=self.max_time)[0] for track in self.tracks]
        entry = {"timesteps": int(self.num_timesteps), "eval_wall_s": time.perf_counter() - start, "rows": rows,
                 "mean_return": float(np.mean([r["return"] for r in rows]))}
        for r in rows:
            t = r["track"]
            self.logger.record(f"eval/{t}/return", r["return"])
            self.logger.record(f"eval/{t}/rms_lateral_cm", 100 * r["rms_lateral_m"])
            self.logger.record(f"eval/{t}/antagonism_N", r["mean_antagonism_N"])
            self.logger.record(f"eval/{t}/nullspace_force_N", r["mean_nullspace_force_N"])
            self.logger.record(f"eval/{t}/slip_energy_J", r["slip_energy_J"])
            self.logger.record(f"eval/{t}/completed", float(r["completed"]))
        self.logger.record("eval/mean_return", entry["mean_return"])
        return entry

    def _on_step(self) -> bool:
        if self.eval_every <= 0 or self.num_timesteps < self._next:
            return True
        self._next += self.eval_every
        entry = self.evaluate()
        self.history.append(entry)
        (self.out / "evaluations.json").write_text(json.dumps(self.history, indent=1, allow_nan=True))
        if entry["mean_return"] > self.best:
            self.best = entry["mean_return"]
            self.model.save(str(self.out / "best_model.zip"))
            vn = self.model.get_vec_normalize_env()
            if vn is not None:
                vn.save(str(self.out / "best_vecnormalize.pkl"))
        summary = ", ".join(f"{r['track']} ret {r['return']:.0f} lat {100 * r['rms_lateral_m']:.2f} cm "
                            f"antagonism {r['mean_antagonism_N']:.1f} N"
                            f"{'' if r['completed'] else ' (' + (r['error'] or 'not finished') + ')'}"
                            for r in entry["rows"])
        print(f"[eval @ {self.num_timesteps}] {summary}", flush=True)
        if self.on_evaluation is not None and self.on_evaluation(entry) is False:
            self.stopped = True
            return False
        return True


class WallClockLimit(BaseCallback):
    """Stop ``learn`` after ``seconds`` of wall time (a guard; ``fired`` says it stopped it)."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = float(seconds)
        self._start = 0.0
        self.fired = False

    def _on_training_start(self) -> None:
        self._start = time.perf_counter()

    def _on_step(self) -> bool:
        self.fired = time.perf_counter() - self._start >= self.seconds
        return not self.fired


class StopOnSignal(BaseCallback):
    """Stop ``learn`` at the step after a SIGINT or SIGTERM (:func:`train.interrupts.requested`);
    :func:`train.trainer.train` then saves the run as interrupted."""

    def _on_step(self) -> bool:
        from train.interrupts import requested

        return requested() is None
