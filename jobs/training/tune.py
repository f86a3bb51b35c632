"""``azimut tune``: search ``azimut train``'s hyperparameters with Optuna (:mod:`train.tuning`; the
``tune`` and ``rl`` extras).

``--trials`` trials of ``--steps`` environment steps each, evaluated ``--evals`` times on the
held-out ``--eval-tracks`` (the median pruner's reports). The study lives in ``--storage`` (default
``sqlite:///OUT/study.db``): the same command run in other processes or on other machines with the
same storage and ``--study-name`` adds its trials to the same study. ``OUT`` gets ``trials/trial_<n>/``
(each trial's run folder), ``study.json`` (the study's name, storage and defining arguments:
one study per ``OUT``, and a resume keeps those arguments, :func:`check_args`), ``trials.json``
(every trial: state, value, hyperparameters, why it failed; rewritten at the start, after each
trial and on an interruption) and ``best_hyperparams.json``, the versioned file ``azimut train
--hyperparams`` reads. Trials left running by a dead process are failed at the start
(:func:`train.tuning.fail_dead_trials`); Ctrl-C or SIGTERM ends with one line, exit 130/143.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from azimut_env.tracks import TRACK_NAMES
from jobs.args import add_robot_arguments, arg_choice_list, arg_int, arg_output_path, require_module
from train.envs import ACTIONS, canonical_action
from train.trainer import DEFAULT_EVAL_TRACKS

__all__ = ["add_arguments", "check_args", "run", "default_storage"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--algo", choices=("ppo", "sac"), default="ppo", help="algorithm (default ppo)")
    parser.add_argument("--action", type=canonical_action, choices=tuple(ACTIONS), default="residual",
                        help="action space (default residual)")
    parser.add_argument("--track", choices=TRACK_NAMES, default="random",
                        help="training track (default random: the evaluation tracks are held out)")
    parser.add_argument("--trials", type=arg_int(1, 100_000), default=20,
                        help="trials this process runs (default 20); other processes on the same storage add theirs")
    parser.add_argument("--steps", type=arg_int(1), default=100_000,
                        help="environment steps per trial (default 100000)")
    parser.add_argument("--evals", type=arg_int(1, 1000), default=4,
                        help="periodic evaluations per trial, the pruner's reports (default 4)")
    parser.add_argument("--eval-tracks", type=arg_choice_list(TRACK_NAMES), default=list(DEFAULT_EVAL_TRACKS),
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


#: the file in --out that names its study and the arguments that define it
STUDY_FILE = "study.json"
#: the study's user attribute with the same record (the storage's copy, seen by every process)
STUDY_ATTR = "azimut_study_args"


def study_args(args: argparse.Namespace) -> dict:
    """The arguments that define a study: its trials are comparable only if they share them (the
    value is a mean return on the same evaluation tracks after the same budget on the same robot).
    ``--seed`` (varied on purpose), ``--trials`` and ``--torch-threads`` are not among them."""
    from jobs.args import robot_args_kwargs

    return {"--algo": args.algo, "--action": args.action, "--track": args.track, "--steps": args.steps,
            "--evals": args.evals, "--eval-tracks": ",".join(args.eval_tracks), "--num-robots": args.num_robots,
            "robot": robot_args_kwargs(args)}


def _flags(rec: dict, keys) -> str:
    from azimut_env.task.config import robot_label

    return " ".join(f"--robot {robot_label(rec[k])}" if k == "robot" else f"{k} {rec[k]}" for k in keys)


def _differing(old: dict, new: dict) -> list[str]:
    """The keys of :func:`study_args` whose values differ (the robot: as the envs build it)."""
    keys = [k for k in new if old.get(k) != new[k]]
    if "robot" in keys and isinstance(old.get("robot"), dict):
        from azimut_env.task.config import robot_of

        try:
            if robot_of(old["robot"]) == robot_of(new["robot"]):
                keys.remove("robot")
        except (ValueError, TypeError, OSError):
            pass
    return keys


def _refuse_other_args(where: str, name: str, old: dict, new: dict) -> None:
    keys = _differing(old, new)
    if keys:
        raise ValueError(f"{where}: the study {name!r} was run with {_flags(old, keys)}, not {_flags(new, keys)}; "
                         "its trials would not compare (a resume keeps them: give another --out and --study-name "
                         "for a new study)")


def _read_study_file(out: Path) -> dict | None:
    """OUT's study record: study.json, or what an earlier version's trials.json says (its study's
    name and storage); None when OUT holds no study."""
    for name in (STUDY_FILE, "trials.json"):
        f = out / name
        if not f.exists():
            continue
        try:
            rec = json.loads(f.read_text())
        except (OSError, ValueError) as exc:
            raise ValueError(f"--out {out}: {name} is not a study record ({exc})") from None
        if not isinstance(rec, dict) or not isinstance(rec.get("study"), str):
            raise ValueError(f"--out {out}: {name} is not a study record (no 'study' name)")
        return rec
    trials = out / "trials"
    if (trials.is_dir() and any(trials.iterdir())) or (out / "best_hyperparams.json").exists():
        raise ValueError(f"--out {out}: holds trial folders of a study it does not name (no {STUDY_FILE} or "
                         "trials.json): give another --out")
    return None


def _check_sqlite(storage: str, flag: str) -> bool:
    """An ``sqlite:///FILE`` storage: refused when FILE is a folder, or does not exist in a writable
    folder; True when the file exists (to be opened), False when it is to be created."""
    import os

    path = Path(storage[len("sqlite:///"):].split("?")[0])
    if path.is_dir() or storage.endswith("/"):
        raise ValueError(f"{flag}: {path} is a folder, not an SQLite file")
    if path.exists():
        return True
    if not path.parent.is_dir() or not os.access(path.parent, os.W_OK):
        raise ValueError(f"{flag}: cannot create the SQLite file (no writable folder {str(path.parent)!r})")
    return False


def _stored_args(storage_url: str, flag: str, study_name: str) -> tuple[bool, dict | None]:
    """Whether ``storage_url`` holds the study, and its :data:`STUDY_ATTR` (None if it has none);
    a storage that cannot be opened is refused in one line."""
    import logging

    import optuna

    optuna.logging.set_verbosity(logging.WARNING)
    storage = None
    try:  # open it now: a storage that cannot be opened is refused before any training
        storage = optuna.storages.RDBStorage(storage_url)
        try:
            study_id = storage.get_study_id_from_name(study_name)
        except KeyError:
            return False, None
        return True, storage.get_study_user_attrs(study_id).get(STUDY_ATTR)
    except Exception as exc:  # noqa: BLE001 (SQLAlchemy/Optuna raise many kinds: one line)
        msg = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise ValueError(f"{flag}: cannot open the Optuna storage ({msg})") from None
    finally:
        if storage is not None:
            storage.engine.dispose()


def check_args(args: argparse.Namespace) -> None:
    """Refuse what cannot run, creating nothing: a storage that cannot be opened or created (an
    SQLite file that is a folder, the default ``OUT/study.db`` included); an ``--out`` that holds
    another study (another ``--study-name``, ``--algo``/``--action`` with the default name, or
    another storage: its trial folders and best_hyperparams.json would be overwritten); a resume
    with other arguments that define the study (:func:`study_args`)."""
    require_module("optuna", "azimut tune (the [tune] extra)")
    require_module("stable_baselines3", "azimut tune (the [rl] extra)")
    require_module("torch", "azimut tune (the [rl] extra)")
    from jobs.args import check_output_layout

    out = Path(args.out)
    check_output_layout(out, [STUDY_FILE, "trials.json", "best_hyperparams.json"], {"trials": ()})
    given_name = args.study_name is not None
    args.study_name = args.study_name or f"tune-{args.algo}-{args.action}"
    given = args.storage
    flag = f"--storage {given}" if given else f"--out {args.out}: the default storage {out / 'study.db'}"
    args.storage = given or default_storage(out)
    current = study_args(args)
    rec = _read_study_file(out) if out.is_dir() else None
    if rec is not None:
        if rec["study"] != args.study_name:
            old = rec.get("args") if isinstance(rec.get("args"), dict) else {}
            keys = [k for k in ("--algo", "--action") if k in old and old[k] != current[k]]
            what = (f"its {_flags(old, keys)}, not {_flags(current, keys)}" if keys and not given_name
                    else "--study-name")
            raise ValueError(f"--out {args.out} holds the study {rec['study']!r}, not {args.study_name!r} ({what}): "
                             "its trial folders and best_hyperparams.json would be overwritten; give another --out "
                             "(one study per folder), or that study's arguments to resume it")
        if rec.get("storage", args.storage) not in (args.storage, None) and (given or rec.get("storage_given")):
            raise ValueError(f"--out {args.out} holds the study {rec['study']!r} of the storage {rec['storage']}, "
                             f"not {args.storage} (--storage): give another --out, or that --storage")
        if isinstance(rec.get("args"), dict):
            _refuse_other_args(f"--out {args.out}", rec["study"], rec["args"], current)
    exists = True
    if not given and not out.is_dir():
        exists = False  # OUT/study.db, created with OUT (which --out's own check has vetted)
    elif args.storage.startswith("sqlite:///"):
        exists = _check_sqlite(args.storage, flag)
    has_study, stored = _stored_args(args.storage, flag, args.study_name) if exists else (False, None)
    if isinstance(stored, dict):
        _refuse_other_args(f"--storage {args.storage}", args.study_name, stored, current)
    if rec is not None and not has_study and (out / "trials").is_dir() and any((out / "trials").iterdir()):
        raise ValueError(f"--out {args.out} holds the trials of the study {rec['study']!r}, which {args.storage} "
                         "does not have (deleted or moved?): give another --out, or the --storage that has it")


def _trial_entry(t) -> dict:
    entry = {"number": t.number, "state": t.state.name, "value": t.value, "params": t.params,
             "hyperparams": t.user_attrs.get("hyperparams"), "num_timesteps": t.user_attrs.get("num_timesteps"),
             "intermediate": {str(k): v for k, v in t.intermediate_values.items()}}
    for key in ("fail_reason", "interrupted", "process"):
        if key in t.user_attrs:
            entry[key] = t.user_attrs[key]
    return entry


def write_trials(out: Path, study, args: argparse.Namespace, prov: dict, interrupted: str | None = None) -> None:
    """``OUT/trials.json``: every trial of the study (state, value, hyperparameters, why it failed),
    rewritten at the start, after each trial and on an interruption."""
    from jobs.records import write_json

    data = {"study": args.study_name, "storage": args.storage, "args": study_args(args), "provenance": prov,
            "trials": [_trial_entry(t) for t in study.get_trials(deepcopy=False)]}
    if interrupted:
        data["interrupted"] = interrupted
    write_json(out / "trials.json", data)


def run(args: argparse.Namespace) -> int:
    """Tune (see the module docstring). SIGINT (Ctrl-C) or SIGTERM: the running trial's folder is
    saved, it is marked failed (``interrupted``), ``trials.json`` is written, one line says so, exit
    130 (SIGTERM: 143)."""
    from train.interrupts import exit_code, signal_name, signals_as_interrupts

    state: dict = {}
    try:
        with signals_as_interrupts():
            return _run(args, state)
    except KeyboardInterrupt as exc:
        name = signal_name(getattr(exc, "signum", 2))
        if "study" not in state:
            print(f"azimut tune: interrupted ({name}) before the first trial; nothing saved", file=sys.stderr)
            return exit_code(exc)
        write_trials(Path(args.out), state["study"], args, state["provenance"], interrupted=name)
        running = [t.number for t in state["study"].get_trials(deepcopy=False)
                   if t.user_attrs.get("interrupted") and t.user_attrs.get("process", {}).get("pid") == os.getpid()]
        which = (f"trial {running[-1]} marked failed (interrupted), its run folder saved; " if running
                 else "after a finished trial; ")
        print(f"azimut tune: interrupted ({name}); {which}{args.out}/trials.json written; the same command adds "
              f"--trials more trials to the study", file=sys.stderr, flush=True)
        return exit_code(exc)


def _run(args: argparse.Namespace, state: dict) -> int:
    import torch

    torch.set_num_threads(args.torch_threads)
    import logging

    import optuna

    optuna.logging.set_verbosity(logging.WARNING)
    logger = logging.getLogger("optuna.study._optimize")
    quiet_interrupt = _QuietInterrupt()
    logger.addFilter(quiet_interrupt)
    try:
        return _tune(args, state, optuna)
    finally:
        logger.removeFilter(quiet_interrupt)


class _QuietInterrupt:
    """A logging filter: Optuna's two warnings of a trial failed by ``KeyboardInterrupt`` (the
    first with its traceback) are left out; :func:`run` says it in one line."""

    def __init__(self) -> None:
        self.interrupted = False

    def filter(self, record) -> bool:
        if record.exc_info and isinstance(record.exc_info[1], KeyboardInterrupt):
            self.interrupted = True
            return False
        return not (self.interrupted and "failed with value" in record.getMessage())


def _tune(args: argparse.Namespace, state: dict, optuna) -> int:
    from jobs.args import robot_args_kwargs
    from jobs.records import provenance, write_json
    from train.interrupts import raise_if_requested, requested
    from train.tuning import best_hyperparams_file, fail_dead_trials, make_objective, open_study

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    eval_every = max(args.steps // args.evals, 1)
    study = open_study(args.storage, args.study_name, args.seed, n_startup_trials=min(5, args.trials),
                       n_warmup_steps=eval_every)
    current = study_args(args)
    if STUDY_ATTR not in study.user_attrs:
        study.set_user_attr(STUDY_ATTR, current)
    write_json(out / STUDY_FILE, {"study": args.study_name, "storage": args.storage,
                                  "storage_given": args.storage != default_storage(out), "args": current})
    prov = provenance()
    state.update(study=study, provenance=prov)
    for number, reason in fail_dead_trials(study):
        print(f"azimut tune: trial {number} was left running by a process that is gone; marked failed ({reason})",
              file=sys.stderr, flush=True)
    write_trials(out, study, args, prov)
    env_kwargs = robot_args_kwargs(args) or None
    objective = make_objective(args.algo, args.action, args.track, args.seed, args.steps, out, args.num_robots,
                               tuple(args.eval_tracks), eval_every, env_kwargs=env_kwargs,
                               record_extra={"provenance": prov})

    def said(study, trial) -> None:
        value = "-" if trial.value is None else f"{trial.value:.1f}"
        print(f"trial {trial.number}: {trial.state.name.lower()}, value {value}, "
              f"{trial.user_attrs.get('num_timesteps', '?')} steps", flush=True)
        write_trials(out, study, args, prov)
        if requested() is not None:  # a signal after the trial's learning: no new trial
            study.stop()

    study.optimize(objective, n_trials=args.trials, callbacks=[said], catch=())
    raise_if_requested()
    write_trials(out, study, args, prov)
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
