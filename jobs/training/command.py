"""``azimut train``: train a PPO or SAC agent on ``Azimut-v2`` (Stable-Baselines3, the ``rl`` extra).

The training is :func:`train.trainer.train` (library code); this job adds the command line, the
provenance in ``run.json`` (package version and git commit, :func:`jobs.records.provenance`) and
``learning_curve.png`` labelled from the run's own arguments. Defaults come from the versioned
hyperparameter files (``train/hyperparams/{ppo,sac}.json``, one entry per action space);
``--hyperparams FILE`` (JSON) overrides keys. The run folder ``--out`` gets ``model.zip`` +
``vecnormalize.pkl`` (the final policy and its observation/reward normalisation),
``best_model.zip`` + ``best_vecnormalize.pkl`` (highest mean return on the evaluation
tracks, ``--eval-tracks``),
``checkpoints/``, ``evaluations.json`` (the periodic evaluations, with the ``azimut eval``
metrics), ``progress.csv`` and TensorBoard logs (``tb/``, if ``tensorboard`` is installed),
``learning_curve.png`` (if matplotlib is) and ``run.json`` (arguments, hyperparameters and their
file version, wall time and steps/s inside ``learn``). ``--resume`` continues from the newest
checkpoint in ``--out`` (SAC starts a new replay buffer). Trained policies go into ``azimut eval
--controllers ppo:OUT/model.zip``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from azimut_env.tracks import TRACK_NAMES
from jobs.args import (
    add_robot_arguments,
    arg_choice_list,
    arg_int,
    arg_output_path,
    arg_threads,
    require_module,
)
from train.envs import ACTIONS, canonical_action
from train.trainer import DEFAULT_EVAL_TRACKS, RUN_ARGS

__all__ = ["add_arguments", "check_args", "run", "hyperparams_overrides", "ENGINES"]

#: training engines of --engine
ENGINES = ("sb3", "rllib")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--engine", choices=ENGINES, default="sb3",
                        help="sb3 (default): Stable-Baselines3 in this process; rllib: Ray RLlib's PPO, experience "
                             "collected by --env-runners env runners on a local Ray instance or, with --ray-address, "
                             "a cluster (the [rllib] extra)")
    parser.add_argument("--env-runners", type=arg_int(0, 4096), default=1,
                        help="--engine rllib: remote env runners of --num-robots robots each (default 1; 0: sample "
                             "in the driver)")
    parser.add_argument("--algo", choices=("ppo", "sac"), default="ppo", help="algorithm (default ppo)")
    parser.add_argument("--action", type=canonical_action, choices=tuple(ACTIONS), default="raw",
                        help="action space: raw set-points, residual on the ICR controller, or ICR rates (default raw)")
    parser.add_argument("--track", choices=TRACK_NAMES, default="random",
                        help="training track (default random: a new track per episode, so that the built-ins are "
                             "held out)")
    parser.add_argument("--seed", type=arg_int(0, 2**31 - 1), default=0, help="seed (default 0)")
    add_robot_arguments(parser, imperfections=True)
    parser.add_argument("--steps", type=arg_int(1), default=1_000_000, help="environment steps (default 1000000)")
    parser.add_argument("--out", type=arg_output_path(directory=True), required=True, help="run folder")
    parser.add_argument("--num-robots", type=arg_int(1, 4096), default=16, help="robots in the vector env (default 16)")
    parser.add_argument("--eval-tracks", type=arg_choice_list(TRACK_NAMES), default=list(DEFAULT_EVAL_TRACKS),
                        help="tracks of the periodic evaluation (default circle,figure8)")
    parser.add_argument("--eval-every", type=arg_int(0), default=200_000,
                        help="environment steps between evaluations (default 200000; 0: only at the end)")
    parser.add_argument("--checkpoint-every", type=arg_int(0), default=200_000,
                        help="environment steps between checkpoints (default 200000; 0: none)")
    parser.add_argument("--time-limit", type=float, default=0.0,
                        help="safety guard: stop learning after this many minutes of wall time and mark the run "
                             "incomplete (run.json 'complete': false; reports leave it out); the budget is --steps "
                             "(default 0: no guard)")
    parser.add_argument("--correction-cost", type=float, default=0.0, metavar="W",
                        help="residual action space only: subtract W x mean(action^2) from each step's reward, a "
                             "cost on the correction's size that keeps the agent near the reference controller "
                             "(default 0: none)")
    parser.add_argument("--resume", action="store_true", help="continue from the newest checkpoint in --out")
    parser.add_argument("--hyperparams", default=None,
                        help="JSON file of hyperparameters overriding the defaults: an object of keyword arguments, "
                             "or the versioned best_hyperparams.json azimut tune writes")
    parser.add_argument("--torch-threads", type=arg_int(1, 256), default=1, help="torch CPU threads (default 1)")
    parser.add_argument("--threads", type=arg_threads, default=None, metavar="N",
                        help="threads of the vector env and its controllers, blocks of robots (default: the cores "
                             "this process may use less torch's extra threads, so that the two do not oversubscribe "
                             "the cores; the results do not depend on it)")
    parser.add_argument("--progress-bar", action="store_true",
                        help="SB3's progress bar (needs tqdm and rich; otherwise a line per evaluation)")
    parser.add_argument("--quiet", action="store_true", help="no SB3 log table on stdout")
    from jobs.campaign.args import add_executor_arguments, arg_seeds

    parser.add_argument("--seeds", type=arg_seeds, default=None, metavar="SEEDS",
                        help="train one agent per seed (0-4, 0,3,5) into OUT/seed_N, with --workers at a time; "
                             "OUT/report.md gives learning curves and final metrics as mean and 95%% interval "
                             "over seeds (--resume then keeps the finished seeds)")
    add_executor_arguments(parser, "seeds", threads=False, resume=False)


def check_args(args: argparse.Namespace) -> None:
    if not (math.isfinite(args.time_limit) and args.time_limit >= 0):
        raise ValueError(f"--time-limit must be a finite number of minutes >= 0, got {args.time_limit}")
    cost = args.correction_cost
    if not (math.isfinite(cost) and cost >= 0):
        raise ValueError(f"--correction-cost must be a finite number >= 0, got {cost}")
    if cost and args.action != "residual":
        raise ValueError(f"--correction-cost applies to --action residual only, not {args.action}")
    if args.engine == "rllib":
        _check_rllib_args(args)
    else:
        if args.env_runners != 1:
            raise ValueError("--env-runners applies to --engine rllib only")
        require_module("stable_baselines3", "azimut train")
    require_module("torch", "azimut train")
    if args.progress_bar:
        require_module("rich", "--progress-bar")
        require_module("tqdm", "--progress-bar")
    data = None
    if args.hyperparams is not None:
        p = Path(args.hyperparams)
        if not p.is_file():
            what = "a folder, not a file" if p.is_dir() else "no such file"
            raise ValueError(f"--hyperparams {args.hyperparams}: {what}")
        try:
            data = json.loads(p.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f"--hyperparams {args.hyperparams}: not valid JSON ({exc})") from None
        from train.tuning import read_hyperparams_file

        try:  # a plain object of overrides, or the versioned file azimut tune writes
            data = read_hyperparams_file(data, args.algo, args.action)
        except ValueError as exc:
            raise ValueError(f"--hyperparams {args.hyperparams}: {exc}") from None
    from jobs.args import check_output_layout

    check_output_layout(args.out, *output_layout(args))
    if getattr(args, "seeds", None) is None:  # the executor flags drive the seeds campaign only
        given = [flag for flag, value, default in (("--workers", args.workers, 1),
                                                   ("--executor", args.executor, "auto"),
                                                   ("--ray-address", None if args.engine == "rllib"
                                                    else args.ray_address, None),
                                                   ("--retries", args.retries, 1))
                 if value != default]
        if given:
            raise ValueError(f"{', '.join(given)} only apply with --seeds (one agent trains in this process)")
        if args.resume:
            from train.trainer import check_resume

            check_resume(Path(args.out), args.algo, args.action, _robot_kwargs(args), steps=args.steps)
        if not args.resume and (Path(args.out) / "model.zip").exists():
            raise ValueError(f"--out {args.out} already holds a trained model (use --resume or another folder)")
    else:
        from jobs.training.seeds import check_seed_args

        check_seed_args(args)
    if data is not None:  # last, as it imports SB3 and builds the algorithm (seconds): the cheap refusals first
        from train.envs import action_key
        from train.hyperparams import check_hyperparams

        try:  # before --out is created: unknown keys, wrong types and ranges, the constructor's refusals
            check_hyperparams(args.algo, action_key(args.action), data)
        except ValueError as exc:
            raise ValueError(f"--hyperparams {args.hyperparams}: {exc}") from None


def _check_rllib_args(args: argparse.Namespace) -> None:
    """``--engine rllib`` with the other flags, and RLlib importable (``ValueError``, one line)."""
    if args.algo != "ppo":
        raise ValueError(f"--engine rllib trains PPO only, not --algo {args.algo}")
    for flag, given in (("--seeds", getattr(args, "seeds", None) is not None), ("--resume", args.resume),
                        ("--correction-cost", bool(args.correction_cost)), ("--progress-bar", args.progress_bar)):
        if given:
            raise ValueError(f"{flag} is not available with --engine rllib")
    try:
        import ray.rllib  # noqa: F401
    except Exception as exc:  # noqa: BLE001 (a missing dependency of RLlib raises ImportError or others)
        raise ValueError(f"--engine rllib needs Ray RLlib (pip install 'azimut[rllib]'), which cannot be imported "
                         f"here ({type(exc).__name__}: {exc})") from None


def hyperparams_overrides(args: argparse.Namespace) -> dict | None:
    """The overrides of ``--hyperparams`` (None without it): the file's object, or the
    ``hyperparams`` of a versioned file that ``azimut tune`` wrote (checked in :func:`check_args`)."""
    from train.tuning import hyperparams_overrides as read_overrides

    return read_overrides(args.hyperparams, args.algo, args.action)


def output_layout(args: argparse.Namespace) -> tuple[list[str], dict[str, tuple[str, ...]]]:
    """What ``azimut train`` writes in ``--out``, for :func:`jobs.args.check_output_layout`: one
    run (the model, its statistics, the best model, run.json, evaluations.json, the learning
    curve; checkpoints/ and the logger's tb/ or logs/), or with ``--seeds`` one run folder per
    seed plus the campaign's records (seeds/), seeds.json, report.md and learning_curves.png."""
    run_files = ["model.zip", "vecnormalize.pkl", "best_model.zip", "best_vecnormalize.pkl", "run.json",
                 RUN_ARGS, "evaluations.json", "learning_curve.png"]
    run_dirs = {"checkpoints": (".zip", ".pkl"), "tb": (), "logs": (".csv",)}
    if getattr(args, "seeds", None) is None:
        return run_files, run_dirs
    files = ["seeds.json", "report.md", "learning_curves.png"]
    dirs: dict[str, tuple[str, ...]] = {"seeds": (".json",)}
    for seed in args.seeds:
        files += [f"seed_{seed}/{f}" for f in run_files]
        dirs.update({f"seed_{seed}/{d}": suffixes for d, suffixes in run_dirs.items()})
    return files, dirs


def _robot_kwargs(args: argparse.Namespace) -> dict:
    """The env keyword arguments of ``--robot``/``--robot-file`` and ``--imperfections`` (kept in
    run.json's env_kwargs, so the trained policy is evaluated on its robot)."""
    from jobs.args import robot_args_kwargs

    return robot_args_kwargs(args)


def _print_final(record: dict) -> None:
    for r in record["final_eval"]:
        lap = ("lap " + format(r["completion_time_s"], ".1f") + " s" if r["completed"]
               else (r["error"] or "lap not finished in the evaluation time"))
        print(f"  {r['track']:<8} return {r['return']:.1f}, RMS lat {100 * r['rms_lateral_m']:.2f} cm, "
              f"antagonism {r['mean_antagonism_N']:.2f} N, null-space force {r['mean_nullspace_force_N']:.2f} N, "
              f"slip {r['slip_energy_J']:.2f} J, "
              f"{lap}")


def _run_rllib(args: argparse.Namespace) -> int:
    from jobs.records import provenance
    from jobs.training.plots import write_learning_curve
    from train.rllib_engine import train_rllib

    record = train_rllib(args.action, args.track, args.seed, args.steps, Path(args.out), args.num_robots,
                         tuple(args.eval_tracks), args.eval_every, hyperparams_overrides(args),
                         env_kwargs=_robot_kwargs(args) or None, ray_address=args.ray_address,
                         env_runners=args.env_runners, time_limit_min=args.time_limit, quiet=args.quiet,
                         record_extra={"provenance": provenance()})
    write_learning_curve(Path(args.out), record)
    if not record["complete"]:
        print(f"INCOMPLETE: the --time-limit guard stopped learning at {record['num_timesteps']} of {args.steps} "
              "steps (run.json 'complete': false)", flush=True)
    print(f"trained {record['num_timesteps']} steps with RLlib ({args.env_runners} env runner(s)) in "
          f"{record['learn_wall_s']:.0f} s; policy: {args.out}/model.pt (azimut eval --controllers "
          f"ppo:{args.out})", flush=True)
    _print_final(record)
    return 0


def run(args: argparse.Namespace) -> int:
    """Train (see the module docstring). SIGINT (Ctrl-C) or SIGTERM: the run is saved as it stands
    (:func:`train.trainer.train`), one line says what and how to continue, exit 130 (SIGTERM: 143)."""
    from train.interrupts import exit_code, signals_as_interrupts

    if getattr(args, "seeds", None) is not None:  # the campaign's own Ctrl-C handling (its workers' too)
        return _run(args)
    try:
        with signals_as_interrupts():
            return _run(args)
    except KeyboardInterrupt as exc:
        print(interrupted_line(exc, args), file=sys.stderr, flush=True)
        return exit_code(exc)


def interrupted_line(exc: KeyboardInterrupt, args: argparse.Namespace) -> str:
    """The one line of an interrupted ``azimut train``: the signal, the steps done, what was saved
    and the command that continues."""
    from train.interrupts import signal_name

    name = signal_name(getattr(exc, "signum", 2))
    record = getattr(exc, "record", None)
    if record is None:
        return f"azimut train: interrupted ({name}) before learning started; nothing saved"
    ckpt = Path(record["saved"][0]).name
    return (f"azimut train: interrupted ({name}) at {record['num_timesteps']} of {record['steps']} steps; saved "
            f"{args.out}/checkpoints/{ckpt}, model.zip and run.json ('complete': false, 'interrupted': "
            f"'{name}'); the same command with --resume continues")


def env_threads(args: argparse.Namespace) -> int:
    """The vector env's threads: ``--threads``, else the cores this process may use less torch's
    threads beyond the main one (PPO alternates the env's steps and torch's update, and torch's
    worker threads keep spinning after their work: measured on 2 cores, 16 robots, env/torch
    threads 1/1 8,014 env steps/s, 2/1 8,343, 2/2 8,666, 1/2 9,089; docs/results/bench-env.md)."""
    from estimation.threads import default_threads

    if args.threads is not None:
        return args.threads
    return max(1, default_threads() - (args.torch_threads - 1))


def _run(args: argparse.Namespace) -> int:
    if getattr(args, "seeds", None) is not None:  # one agent per seed, as campaign tasks (jobs.training.seeds)
        from jobs.training.seeds import run_seeds

        return run_seeds(args, args.seeds, _robot_kwargs(args) or None)
    import torch

    from estimation.threads import set_default_threads

    torch.set_num_threads(args.torch_threads)
    threads = env_threads(args)
    set_default_threads(threads)
    if args.engine == "rllib":
        return _run_rllib(args)
    from jobs.records import provenance
    from jobs.training.plots import write_learning_curve
    from train.trainer import train

    overrides = hyperparams_overrides(args)
    record = train(args.algo, args.action, args.track, args.seed, args.steps, Path(args.out), args.num_robots,
                   tuple(args.eval_tracks), args.eval_every, args.checkpoint_every, args.resume, overrides,
                   args.progress_bar, args.quiet, env_kwargs=_robot_kwargs(args) or None,
                   time_limit_min=args.time_limit,
                   record_extra={"provenance": provenance(),
                                 "threads": {"env": threads, "torch": args.torch_threads}},
                   correction_cost=args.correction_cost)
    write_learning_curve(Path(args.out), record)
    if not record["complete"]:
        print(f"INCOMPLETE: the --time-limit guard stopped learning at {record['num_timesteps']} of {args.steps} "
              "steps (run.json 'complete': false)", flush=True)
    print(f"trained {record['num_timesteps']} steps in {record['learn_wall_s']:.0f} s "
          f"({record['steps_per_s_in_learn']:.0f} steps/s inside learn); model: {args.out}/model.zip", flush=True)
    _print_final(record)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(run(argparse.ArgumentParser().parse_args()))
