"""``azimut tune``: search ``azimut train``'s hyperparameters with Optuna (:mod:`train.tuning`; the
``tune`` and ``rl`` extras).

``--trials`` trials of ``--steps`` environment steps each, evaluated ``--evals`` times on the
held-out ``--eval-tracks`` (the median pruner's reports). The study lives in ``--storage`` (default
``sqlite:///OUT/study.db``): the same command run in other processes or on other machines with the
same storage and ``--study-name`` adds its trials to the same study. ``OUT`` gets ``trials/trial_<n>/``
(each trial's run folder), ``trials.json`` (every trial: state, value, hyperparameters) and
``best_hyperparams.json``, the versioned file ``azimut train --hyperparams`` reads.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from azimut_env.tracks import TRACK_NAMES
from jobs.args import add_robot_arguments, arg_choice_list, arg_int, arg_output_path, require_module
from train.envs import ACTIONS
from train.trainer import EVAL_TRACKS

__all__ = ["add_arguments", "check_args", "run", "default_storage"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--algo", choices=("ppo", "sac"), default="ppo", help="algorithm (default ppo)")
    parser.add_argument("--action", choices=tuple(ACTIONS), default="residual",
                        help="action space (default residual)")
    parser.add_argument("--track", choices=TRACK_NAMES, default="random",
                        help="training track (default random: the evaluation tracks are held out)")
    parser.add_argument("--trials", type=arg_int(1, 100_000), default=20,
                        help="trials this process runs (default 20); other processes on the same storage add theirs")
    parser.add_argument("--steps", type=arg_int(1), default=100_000,
                        help="environment steps per trial (default 100000)")
    parser.add_argument("--evals", type=arg_int(1, 1000), default=4,
                        help="periodic evaluations per trial, the pruner's reports (default 4)")
    parser.add_argument("--eval-tracks", type=arg_choice_list(TRACK_NAMES), default=list(EVAL_TRACKS[:2]),
                        help="held-out tracks of the evaluations (default circle,figure8)")
    parser.add_argument("--num-robots", type=arg_int(1, 4096), default=16, help="robots in the vector env (default 16)")
    parser.add_argument("--seed", type=arg_int(0, 2**31 - 1), default=0,
                        help="seed of the sampler and of every trial's training (default 0)")
    parser.add_argument("--out", type=arg_output_path(directory=True), required=True, help="study folder")
    parser.add_argument("--storage", default=None,
                        help="Optuna storage URL shared by the processes of one study (default sqlite:///OUT/study.db)")
    parser.add_argument("--study-name", default=None, help="study name (default: tune-ALGO-ACTION)")
    parser.add_argument("--torch-threads", type=arg_int(1, 256), default=1, help="torch CPU threads (default 1)")
    add_robot_arguments(parser, imperfections=True)


def default_storage(out: str | Path) -> str:
    return f"sqlite:///{Path(out).resolve() / 'study.db'}"


def check_args(args: argparse.Namespace) -> None:
    """Refuse what cannot run, creating nothing: the default storage (``OUT/study.db``) is the
    output folder's, which ``--out``'s own check has vetted; an SQLite file that does not exist yet
    needs an existing, writable folder; any other storage is opened (and closed) here."""
    require_module("optuna", "azimut tune (the [tune] extra)")
    require_module("stable_baselines3", "azimut tune (the [rl] extra)")
    require_module("torch", "azimut tune (the [rl] extra)")
    args.study_name = args.study_name or f"tune-{args.algo}-{args.action}"
    if args.storage is None:
        args.storage = default_storage(args.out)
        return
    if args.storage.startswith("sqlite:///"):
        path = Path(args.storage[len("sqlite:///"):])
        if path.is_dir():
            raise ValueError(f"--storage {args.storage}: is a folder, not an SQLite file")
        if not path.exists():
            import os

            if not path.parent.is_dir() or not os.access(path.parent, os.W_OK):
                raise ValueError(f"--storage {args.storage}: cannot create the SQLite file (no writable folder "
                                 f"{str(path.parent)!r})")
            return
    import logging

    import optuna

    optuna.logging.set_verbosity(logging.WARNING)
    try:  # open it now: a storage that cannot be opened is refused before any training
        storage = optuna.storages.RDBStorage(args.storage)
        storage.get_all_studies()
        storage.engine.dispose()
    except Exception as exc:  # noqa: BLE001 (SQLAlchemy/Optuna raise many kinds: one line)
        msg = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise ValueError(f"--storage {args.storage}: cannot open the Optuna storage ({msg})") from None


def run(args: argparse.Namespace) -> int:
    import torch

    torch.set_num_threads(args.torch_threads)
    import optuna

    from jobs.args import robot_args_kwargs
    from jobs.records import provenance, write_json
    from train.tuning import best_hyperparams_file, make_objective, open_study

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    eval_every = max(args.steps // args.evals, 1)
    study = open_study(args.storage, args.study_name, args.seed, n_startup_trials=min(5, args.trials),
                       n_warmup_steps=eval_every)
    env_kwargs = robot_args_kwargs(args) or None
    prov = provenance()
    objective = make_objective(args.algo, args.action, args.track, args.seed, args.steps, out, args.num_robots,
                               tuple(args.eval_tracks), eval_every, env_kwargs=env_kwargs,
                               record_extra={"provenance": prov})

    def said(study, trial) -> None:
        value = "-" if trial.value is None else f"{trial.value:.1f}"
        print(f"trial {trial.number}: {trial.state.name.lower()}, value {value}, "
              f"{trial.user_attrs.get('num_timesteps', '?')} steps", flush=True)

    study.optimize(objective, n_trials=args.trials, callbacks=[said], catch=())
    trials = [{"number": t.number, "state": t.state.name, "value": t.value, "params": t.params,
               "hyperparams": t.user_attrs.get("hyperparams"), "num_timesteps": t.user_attrs.get("num_timesteps"),
               "intermediate": {str(k): v for k, v in t.intermediate_values.items()}} for t in study.trials]
    write_json(out / "trials.json", {"study": args.study_name, "storage": args.storage, "provenance": prov,
                                     "trials": trials})
    complete = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    if not complete:
        print("azimut tune: no trial completed (all pruned or failed); no best_hyperparams.json", file=sys.stderr)
        return 1
    data = best_hyperparams_file(study, args.algo, args.action, out / "best_hyperparams.json",
                                 extra={"steps_per_trial": args.steps, "eval_tracks": list(args.eval_tracks),
                                        "track": args.track, "provenance": prov})
    print(f"best trial {data['trial']} (mean evaluation return {data['value']:.1f}) of {len(study.trials)}: "
          f"{json.dumps(data['hyperparams'])}", flush=True)
    print(f"written {out}/best_hyperparams.json: azimut train --algo {args.algo} --action {args.action} "
          f"--hyperparams {out}/best_hyperparams.json ...", flush=True)
    return 0
