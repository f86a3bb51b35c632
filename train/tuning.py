"""Hyperparameter search for ``azimut train`` with Optuna (``azimut tune``; the ``tune`` extra).

As RL Baselines3 Zoo does it (Raffin, *RL Baselines3 Zoo*, GitHub 2020, ``rl_zoo3/exp_manager.py``
and ``hyperparams_opt.py``): a TPE sampler (Bergstra et al., *Algorithms for Hyper-Parameter
Optimization*, NeurIPS 2011; Akiba et al., *Optuna*, KDD 2019), a median pruner fed by the periodic
evaluations of each trial (a trial stops when its evaluation return falls below the median of the
earlier trials' at the same step), and a study in an RDB storage (``sqlite:///FILE`` or any
SQLAlchemy URL) so that several processes or machines running the same command share one study.

Each trial trains with :func:`train.trainer.train` into ``OUT/trials/trial_<n>/`` with the
hyperparameters it samples (:func:`sample_hyperparams`) over the defaults of
``train/hyperparams/*.json``; its value is the mean return of the final evaluation on the held-out
evaluation tracks (higher is better). :func:`best_hyperparams_file` writes the best trial as a
versioned file that ``azimut train --hyperparams`` reads (:func:`read_hyperparams_file`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["HYPERPARAMS_FORMAT", "HYPERPARAMS_FILE_VERSION", "sample_hyperparams", "open_study", "make_objective",
           "best_hyperparams_file", "read_hyperparams_file", "trial_seed", "trial_seeded_sampler",
           "fail_dead_trials", "process_tag"]

#: the ``format`` of a hyperparameter file that carries its provenance
HYPERPARAMS_FORMAT = "azimut-hyperparams"
#: its version (bump when the file's layout changes)
HYPERPARAMS_FILE_VERSION = 1

_NET = {"small": [64, 64], "medium": [128, 128], "large": [256, 256]}


def sample_hyperparams(trial, algo: str, num_robots: int) -> dict[str, Any]:
    """The keyword arguments of a trial, sampled from RL Zoo's search spaces (narrowed to this
    env's scale: rollouts of ``n_steps`` × ``num_robots``, ``log_std_init`` around the defaults)."""
    if algo == "ppo":
        n_steps = trial.suggest_categorical("n_steps", [64, 128, 256, 512])
        batch = trial.suggest_categorical("batch_size", [128, 256, 512, 1024])
        hp = {"n_steps": n_steps, "batch_size": min(batch, n_steps * num_robots),
              "n_epochs": trial.suggest_categorical("n_epochs", [5, 10, 20]),
              "learning_rate": trial.suggest_float("learning_rate", 1e-5, 1e-3, log=True),
              "gamma": trial.suggest_categorical("gamma", [0.98, 0.99, 0.995]),
              "gae_lambda": trial.suggest_categorical("gae_lambda", [0.9, 0.95, 0.98]),
              "clip_range": trial.suggest_categorical("clip_range", [0.1, 0.2, 0.3]),
              "ent_coef": trial.suggest_float("ent_coef", 1e-8, 1e-2, log=True),
              "max_grad_norm": trial.suggest_categorical("max_grad_norm", [0.3, 0.5, 1.0]),
              "policy_kwargs": {"net_arch": _NET[trial.suggest_categorical("net_arch", list(_NET))],
                                "log_std_init": trial.suggest_float("log_std_init", -3.0, -0.5)}}
        return hp
    if algo == "sac":
        return {"learning_rate": trial.suggest_float("learning_rate", 1e-5, 1e-3, log=True),
                "batch_size": trial.suggest_categorical("batch_size", [128, 256, 512]),
                "tau": trial.suggest_categorical("tau", [0.005, 0.01, 0.02]),
                "gamma": trial.suggest_categorical("gamma", [0.98, 0.99, 0.995]),
                "gradient_steps": trial.suggest_categorical("gradient_steps", [1, 2, 4]),
                "learning_starts": trial.suggest_categorical("learning_starts", [1000, 5000]),
                "policy_kwargs": {"net_arch": _NET[trial.suggest_categorical("net_arch", list(_NET))],
                                  "log_std_init": trial.suggest_float("log_std_init", -3.0, -1.0)}}
    raise ValueError(f"unknown algorithm {algo!r}")


def trial_seed(seed: int, number: int) -> int:
    """The sampler seed of trial ``number`` of a study run with ``--seed seed``: 32 bits of NumPy's
    ``SeedSequence([seed, number])``, so that every trial, whichever process runs it, draws from its
    own stream, and the same trial number with the same finished trials before it draws the same."""
    import numpy as np

    return int(np.random.SeedSequence([int(seed), int(number)]).generate_state(1)[0])


def trial_seeded_sampler(seed: int, n_startup_trials: int):
    """A TPE sampler seeded per trial (:func:`trial_seed`): one ``TPESampler(seed=trial_seed(seed,
    n))`` for trial ``n``. One ``TPESampler(seed=seed)`` per process made the processes of a
    parallel study propose the same hyperparameters (each its own copy of the same random stream);
    trial numbers are unique in a study, so these differ. ``constant_liar``: a trial running in
    another process counts as a poor one, so TPE does not propose beside it."""
    import optuna

    class TrialSeededTPESampler(optuna.samplers.BaseSampler):
        def __init__(self) -> None:
            self._samplers: dict[int, optuna.samplers.TPESampler] = {}

        def _of(self, trial) -> optuna.samplers.TPESampler:
            if trial.number not in self._samplers:
                self._samplers[trial.number] = optuna.samplers.TPESampler(
                    seed=trial_seed(seed, trial.number), n_startup_trials=n_startup_trials, constant_liar=True)
            return self._samplers[trial.number]

        def infer_relative_search_space(self, study, trial):
            return self._of(trial).infer_relative_search_space(study, trial)

        def sample_relative(self, study, trial, search_space):
            return self._of(trial).sample_relative(study, trial, search_space)

        def sample_independent(self, study, trial, param_name, param_distribution):
            return self._of(trial).sample_independent(study, trial, param_name, param_distribution)

        def before_trial(self, study, trial) -> None:
            self._of(trial).before_trial(study, trial)

        def after_trial(self, study, trial, state, values) -> None:
            self._samplers.pop(trial.number, self._of(trial)).after_trial(study, trial, state, values)

        def reseed_rng(self) -> None:  # the seeds are the trials': nothing to reseed
            pass

    return TrialSeededTPESampler()


#: seconds between a running trial's heartbeats in an RDB storage, and without one for how long a
#: trial counts as abandoned (its process killed) and is failed
HEARTBEAT_S, GRACE_S = 30, 120


def open_study(storage: str, study_name: str, seed: int, n_startup_trials: int, n_warmup_steps: int):
    """The study ``study_name`` in ``storage`` (created, or loaded if another process made it):
    maximise, TPE sampler seeded per trial from ``seed`` (:func:`trial_seeded_sampler`), median
    pruner that waits ``n_startup_trials`` trials and ``n_warmup_steps`` environment steps within a
    trial before it prunes. An RDB storage URL gets Optuna's heartbeat (:data:`HEARTBEAT_S`,
    :data:`GRACE_S`), with which a trial whose process died is failed (:func:`fail_dead_trials`)."""
    import optuna

    if isinstance(storage, str) and "://" in storage:
        import warnings

        with warnings.catch_warnings():  # heartbeat_interval is "experimental" (since Optuna 2.9): not the user's
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            storage = optuna.storages.RDBStorage(storage, heartbeat_interval=HEARTBEAT_S, grace_period=GRACE_S)
    sampler = trial_seeded_sampler(seed, n_startup_trials)
    pruner = optuna.pruners.MedianPruner(n_startup_trials=n_startup_trials, n_warmup_steps=n_warmup_steps)
    return optuna.create_study(storage=storage, study_name=study_name, direction="maximize", sampler=sampler,
                               pruner=pruner, load_if_exists=True)


def process_tag() -> dict:
    """This process as a running trial records it (user attribute ``process``): host, pid and, on
    Linux, its start time in clock ticks since boot (a later process with the same pid differs)."""
    import os
    import socket

    return {"host": socket.gethostname(), "pid": os.getpid(), "start": _start_ticks(os.getpid())}


def _start_ticks(pid: int) -> int | None:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return int(stat[stat.rindex(")") + 2:].split()[19])


def _process_gone(tag) -> bool:
    """Whether the process of a trial's ``process`` tag is known to be gone: on this host, no
    process with its pid, or one started at another time."""
    import os
    import socket

    if not isinstance(tag, dict) or tag.get("host") != socket.gethostname() or not isinstance(tag.get("pid"), int):
        return False
    if tag["pid"] == os.getpid():
        return False
    try:
        os.kill(tag["pid"], 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        pass
    start = _start_ticks(tag["pid"])
    return tag.get("start") is not None and start is not None and start != tag["start"]


def fail_dead_trials(study) -> list[tuple[int, str]]:
    """Fail the trials of ``study`` left RUNNING by a process that is gone (SIGKILL, a crash, a
    lost machine), each with the user attribute ``fail_reason``: on this host, its process (the
    ``process`` tag of :func:`process_tag`) no longer runs; on any host, its heartbeat stopped
    more than :data:`GRACE_S` s ago. Returns ``[(trial number, reason), ...]``. A trial running
    in a live process, or one of an earlier version without either record, is left alone."""
    import optuna
    from optuna.trial import TrialState

    storage = study._storage
    stale = set()
    if getattr(storage, "get_heartbeat_interval", lambda: None)() is not None and \
            hasattr(storage, "_get_stale_trial_ids"):
        stale = set(storage._get_stale_trial_ids(study._study_id))
    failed = []
    for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        tag = t.user_attrs.get("process")
        if _process_gone(tag):
            reason = f"its process (pid {tag['pid']} on {tag['host']}) is gone: killed or crashed"
        elif t._trial_id in stale:
            reason = f"no heartbeat for more than {GRACE_S} s: its process was killed or its machine lost"
        else:
            continue
        try:
            storage.set_trial_user_attr(t._trial_id, "fail_reason", reason)
            if storage.set_trial_state_values(t._trial_id, state=TrialState.FAIL):
                failed.append((t.number, reason))
        except (optuna.exceptions.UpdateFinishedTrialError, RuntimeError):
            pass  # another process failed it first
    return failed


def make_objective(algo: str, action: str, track: str, seed: int, steps: int, out: Path, num_robots: int,
                   eval_tracks: tuple[str, ...], eval_every: int, env_kwargs: dict | None = None,
                   record_extra: dict | None = None, quiet: bool = True):
    """The objective of a trial: train (see the module docstring) and return the final evaluation's
    mean return; a pruned trial raises ``optuna.TrialPruned`` after its run folder is written."""
    import optuna

    from train.interrupts import raise_if_requested, signal_name
    from train.trainer import train

    def objective(trial) -> float:
        trial.set_user_attr("process", process_tag())
        hp = sample_hyperparams(trial, algo, num_robots)
        trial.set_user_attr("hyperparams", hp)

        def report(entry: dict) -> bool:
            trial.report(float(entry["mean_return"]), int(entry["timesteps"]))
            return not trial.should_prune()

        folder = Path(out) / "trials" / f"trial_{trial.number}"
        try:
            raise_if_requested()  # a signal between two trials: this one does not start
            record = train(algo, action, track, seed, steps, folder, num_robots, tuple(eval_tracks), eval_every, 0,
                           overrides=hp, quiet=quiet, env_kwargs=env_kwargs, on_evaluation=report,
                           record_extra={**(record_extra or {}), "optuna_trial": trial.number})
        except KeyboardInterrupt as exc:  # Optuna marks it FAIL: say why in the trial
            name = signal_name(getattr(exc, "signum", 2))
            trial.set_user_attr("interrupted", name)
            trial.set_user_attr("fail_reason", f"interrupted ({name})")
            raise
        value = float(sum(r["return"] for r in record["final_eval"]) / len(record["final_eval"]))
        trial.set_user_attr("num_timesteps", int(record["num_timesteps"]))
        if record.get("stopped"):
            raise optuna.TrialPruned()
        return value

    return objective


def best_hyperparams_file(study, algo: str, action: str, path: Path, extra: dict | None = None) -> dict:
    """Write the study's best trial as a versioned hyperparameter file (see
    :func:`read_hyperparams_file`); returns its content."""
    best = study.best_trial
    data = {"format": HYPERPARAMS_FORMAT, "version": HYPERPARAMS_FILE_VERSION, "algo": algo, "action": action,
            "study": study.study_name, "trial": best.number, "value": best.value,
            "trials_complete": sum(1 for t in study.trials if t.state.name == "COMPLETE"),
            "trials_pruned": sum(1 for t in study.trials if t.state.name == "PRUNED"),
            **(extra or {}), "hyperparams": best.user_attrs["hyperparams"]}
    Path(path).write_text(json.dumps(data, indent=1) + "\n")
    return data


def hyperparams_overrides(path: str | None, algo: str, action: str) -> dict | None:
    """The overrides of the ``--hyperparams`` file ``path`` (None without one), read by
    :func:`read_hyperparams_file`; ``azimut train`` and its seeds campaign both read them here."""
    if not path:
        return None
    return read_hyperparams_file(json.loads(Path(path).read_text()), algo, action)


def read_hyperparams_file(data: Any, algo: str, action: str) -> dict:
    """The overrides in a ``--hyperparams`` file's JSON ``data``: a plain object of keyword
    arguments, or a versioned file of :func:`best_hyperparams_file` (``format``
    ``azimut-hyperparams``), whose algorithm and action space must match (``ValueError``)."""
    if not isinstance(data, dict):
        raise ValueError("expected a JSON object")
    if data.get("format") != HYPERPARAMS_FORMAT:
        return data
    if data.get("version") != HYPERPARAMS_FILE_VERSION:
        raise ValueError(f"hyperparameter file version {data.get('version')!r} is not "
                         f"{HYPERPARAMS_FILE_VERSION} (the one this azimut reads)")
    if data.get("algo") != algo or data.get("action") != action:
        raise ValueError(f"tuned for --algo {data.get('algo')} --action {data.get('action')}, not --algo {algo} "
                         f"--action {action}")
    if not isinstance(data.get("hyperparams"), dict):
        raise ValueError("'hyperparams' must be a JSON object")
    return data["hyperparams"]
