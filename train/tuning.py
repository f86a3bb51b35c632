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
           "best_hyperparams_file", "read_hyperparams_file"]

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


def open_study(storage: str, study_name: str, seed: int, n_startup_trials: int, n_warmup_steps: int):
    """The study ``study_name`` in ``storage`` (created, or loaded if another process made it):
    maximise, TPE sampler seeded with ``seed``, median pruner that waits ``n_startup_trials``
    trials and ``n_warmup_steps`` environment steps within a trial before it prunes."""
    import optuna

    sampler = optuna.samplers.TPESampler(seed=seed, n_startup_trials=n_startup_trials)
    pruner = optuna.pruners.MedianPruner(n_startup_trials=n_startup_trials, n_warmup_steps=n_warmup_steps)
    return optuna.create_study(storage=storage, study_name=study_name, direction="maximize", sampler=sampler,
                               pruner=pruner, load_if_exists=True)


def make_objective(algo: str, action: str, track: str, seed: int, steps: int, out: Path, num_robots: int,
                   eval_tracks: tuple[str, ...], eval_every: int, env_kwargs: dict | None = None,
                   record_extra: dict | None = None, quiet: bool = True):
    """The objective of a trial: train (see the module docstring) and return the final evaluation's
    mean return; a pruned trial raises ``optuna.TrialPruned`` after its run folder is written."""
    import optuna

    from train.trainer import train

    def objective(trial) -> float:
        hp = sample_hyperparams(trial, algo, num_robots)
        trial.set_user_attr("hyperparams", hp)

        def report(entry: dict) -> bool:
            trial.report(float(entry["mean_return"]), int(entry["timesteps"]))
            return not trial.should_prune()

        folder = Path(out) / "trials" / f"trial_{trial.number}"
        record = train(algo, action, track, seed, steps, folder, num_robots, tuple(eval_tracks), eval_every, 0,
                       overrides=hp, quiet=quiet, env_kwargs=env_kwargs, on_evaluation=report,
                       record_extra={**(record_extra or {}), "optuna_trial": trial.number})
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
