"""Train a PPO or SAC agent on ``Azimut-v2`` and save its run folder (``azimut train``'s library).

:func:`train` is what ``azimut train`` (:mod:`jobs.training.command`) and its several-seeds
campaign (:mod:`jobs.training.seeds`) run; both import it from here. The run folder ``out``
gets ``model.zip`` + ``vecnormalize.pkl`` (the final policy and its observation/reward
normalisation), ``best_model.zip`` + ``best_vecnormalize.pkl`` (highest mean return on the
evaluation tracks), ``checkpoints/`` (every ``checkpoint_every`` steps; absent if none was due),
``evaluations.json`` (the periodic evaluations, with the ``azimut eval`` metrics),
``progress.csv`` and TensorBoard logs (``tb/``, if ``tensorboard`` is installed) and ``run.json``
(arguments, hyperparameters and their file version, wall time and steps/s inside ``learn``).
Defaults come from the versioned hyperparameter files (``train/hyperparams/{ppo,sac}.json``, one
entry per action space). Needs the ``rl`` extra.
"""

from __future__ import annotations

import json
import math
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from azimut_env import ENV_ID
from train.envs import action_key

__all__ = ["DEFAULT_EVAL_TRACKS", "RUN_ARGS", "check_resume", "checkpoint_steps", "latest_checkpoint", "run_steps",
           "train", "was_interrupted"]

#: the tracks of a run's periodic evaluations by default (any of ``azimut_env.tracks.TRACK_NAMES``
#: may be chosen: that tuple is the one list of the built-in tracks)
DEFAULT_EVAL_TRACKS = ("circle", "figure8")

#: the file a new run writes in its folder before learning: what ``--resume`` must match
RUN_ARGS = "train_args.json"


def latest_checkpoint(out: Path) -> Path | None:
    """The newest ``checkpoints/model_<steps>_steps.zip`` of a run folder, None if there is none."""
    ckpts = sorted((Path(out) / "checkpoints").glob("model_*_steps.zip"), key=checkpoint_steps)
    return ckpts[-1] if ckpts else None


def checkpoint_steps(ckpt: Path) -> int:
    """The environment steps of a checkpoint ``model_<steps>_steps.zip`` (SB3's
    ``CheckpointCallback`` name); −1 if the name holds no number there."""
    steps = Path(ckpt).stem.split("_")[1]
    return int(steps) if steps.isdigit() else -1


def _trained_with(out: Path, ckpt: Path) -> dict:
    """What the run in ``out`` was trained with: its :data:`RUN_ARGS` file, else its ``run.json``
    (runs of earlier versions), else what the checkpoint's own ``data`` says (the algorithm from its
    policy class; the action space only as raw (8 actions) or not (3))."""
    import zipfile

    for name in (RUN_ARGS, "run.json"):
        try:
            rec = json.loads((out / name).read_text())
        except (OSError, ValueError):
            continue
        if isinstance(rec, dict) and {"algo", "action"} <= set(rec):
            return {"algo": rec["algo"], "action": action_key(rec["action"]), "env_kwargs": rec.get("env_kwargs") or {}}
    data = json.loads(zipfile.ZipFile(ckpt).read("data"))
    algo = "sac" if ".sac." in str(data.get("policy_class", {}).get("__module__", "")) else "ppo"
    shape = list(data.get("action_space", {}).get("_shape") or [])
    return {"algo": algo, "action": "raw" if shape == [8] else None, "env_kwargs": None}


def _check_trained_with(out: Path, ckpt: Path, algo: str, action: str, env_kwargs: dict | None) -> None:
    """``ValueError`` (one line) unless the run in ``out`` was trained with this ``algo``,
    ``action`` and robot (what :func:`_trained_with` knows of them)."""
    from azimut_env.task.config import robot_label, robot_of

    rec = _trained_with(out, ckpt)
    if rec["algo"] != algo:
        raise ValueError(f"--resume: {out} was trained with --algo {rec['algo']}, not {algo}")
    if rec["action"] is not None and rec["action"] != action_key(action):
        raise ValueError(f"--resume: {out} was trained with --action {rec['action'].replace('_', '-')}, not {action}")
    if rec["env_kwargs"] is not None and robot_of(rec["env_kwargs"]) != robot_of(env_kwargs or {}):
        raise ValueError(f"--resume: {out} was trained with the robot {robot_label(rec['env_kwargs'])}, not "
                         f"{robot_label(env_kwargs or {})} (--robot, --robot-file, --imperfections)")


def check_resume(out: Path, algo: str, action: str, env_kwargs: dict | None, steps: int | None = None) -> Path:
    """The checkpoint ``train(..., resume=True)`` continues from, checked before any work
    (``ValueError``, one line starting ``--resume:``): there is one and it is readable, and the run
    was trained with the same algorithm, action space and robot (``env_kwargs``: ``--robot``,
    ``--imperfections``). With ``steps`` (a single run that has its final model): refused when the
    checkpoint already reached the budget (``steps`` is the run's total, not steps to add)."""
    from train.saved_files import check_checkpoint

    out = Path(out)
    ckpt = latest_checkpoint(out)
    if ckpt is None:
        raise ValueError(f"--resume: no checkpoint in {out}/checkpoints")
    check_checkpoint(ckpt)
    _check_trained_with(out, ckpt, algo, action, env_kwargs)
    if steps is not None:
        done = run_steps(out, ckpt)
        finished = (out / "model.zip").exists() and not was_interrupted(out)
        if done > int(steps) or (finished and done >= int(steps)):
            raise ValueError(f"--resume: the run in {out} has {done} steps already, --steps {steps} is the run's "
                             f"total, not steps to add (give one above {done} to train on)")
    return ckpt


def run_steps(out: Path, ckpt: Path | None = None) -> int:
    """The environment steps the run in ``out`` has done: those of its newest checkpoint, or of its
    ``run.json`` when it has its final model and says more (a run finished after its last checkpoint)."""
    ckpt = latest_checkpoint(out) if ckpt is None else ckpt
    done = checkpoint_steps(ckpt) if ckpt is not None else 0
    if (Path(out) / "model.zip").exists():
        try:
            rec = json.loads((Path(out) / "run.json").read_text())
            n = rec.get("num_timesteps") if isinstance(rec, dict) else None
            if isinstance(n, int) and not isinstance(n, bool):
                done = max(done, n)
        except (OSError, ValueError):
            pass
    return done


def was_interrupted(out: Path) -> bool:
    """Whether the run in ``out`` was stopped by a signal (its ``run.json`` says ``"interrupted"``):
    its ``model.zip`` is then the interrupted model, not a final one, and ``--resume`` continues it."""
    try:
        rec = json.loads((Path(out) / "run.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(rec, dict) and bool(rec.get("interrupted"))


def _fused_adam(hp: dict) -> dict:
    """``hp`` with Adam's fused kernel asked for (unless ``policy_kwargs.optimizer_kwargs`` says
    otherwise): the same update as the per-parameter loop PyTorch runs on CPU by default, in one
    call per step; an implementation choice, not a hyperparameter (``run.json`` records ``hp``)."""
    kw = dict(hp.get("policy_kwargs") or {})
    kw["optimizer_kwargs"] = {"fused": True, **(kw.get("optimizer_kwargs") or {})}
    return {**hp, "policy_kwargs": kw}


def _new_or_resumed_model(cls, ckpt: Path | None, out: Path, steps: int, seed: int, hp: dict, env,
                          run_args: dict):
    """The normalised vector env and the model: loaded from ``ckpt`` (never more steps than
    ``steps``), or new, with ``run_args`` written to :data:`RUN_ARGS`."""
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    venv = VecMonitor(env)
    venv.seed(seed)
    gamma = float(hp.get("gamma", 0.99))
    if ckpt is not None:
        from train.policy import vecnormalize_path

        venv = VecNormalize.load(str(vecnormalize_path(ckpt)), venv)
        model = cls.load(str(ckpt), env=venv, device="cpu")
        if model.num_timesteps > int(steps):  # never a record of more steps than its budget (check_resume first)
            venv.close()
            raise ValueError(f"--resume: the run in {out} has {model.num_timesteps} steps already, --steps {steps} "
                             f"is the run's total, not steps to add (give one above {model.num_timesteps})")
        print(f"resuming from {ckpt} ({model.num_timesteps} steps)", flush=True)
    else:
        venv = VecNormalize(venv, norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=gamma)
        model = cls("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **_fused_adam(hp))
        (out / RUN_ARGS).write_text(json.dumps(run_args, indent=1, default=str))
    return venv, model


def _set_logger(model, out: Path, quiet: bool) -> None:
    """SB3's logger: CSV, stdout unless ``quiet``, and TensorBoard where it is installed."""
    from stable_baselines3.common.logger import configure

    formats = ["csv"] + ([] if quiet else ["stdout"])
    try:
        import tensorboard  # noqa: F401

        formats.append("tensorboard")
    except ImportError:
        pass
    model.set_logger(configure(str(out / ("tb" if "tensorboard" in formats else "logs")), formats))


def _callbacks(out: Path, algo: str, action: str, env_kwargs: dict, seed: int, num_robots: int, eval_tracks,
               eval_every: int, checkpoint_every: int, time_limit_min: float, eval_max_time, on_evaluation):
    """The learning callbacks: signals, info statistics, the wall-clock guard (returned, None
    without a time limit), the held-out evaluator (returned) and the checkpoints."""
    from stable_baselines3.common.callbacks import CheckpointCallback

    from train.callbacks import HeldOutEvalCallback, InfoStatsCallback, StopOnSignal, WallClockLimit

    callbacks = [StopOnSignal(), InfoStatsCallback()]
    guard = None
    if time_limit_min > 0:
        guard = WallClockLimit(60.0 * time_limit_min)
        callbacks.append(guard)
    evaluator = HeldOutEvalCallback(list(eval_tracks), eval_every if eval_every > 0 else 10**15, out, algo, action,
                                    env_kwargs, seed=seed, max_time=eval_max_time, on_evaluation=on_evaluation)
    callbacks.append(evaluator)
    if checkpoint_every > 0:
        callbacks.append(CheckpointCallback(max(checkpoint_every // num_robots, 1), str(out / "checkpoints"),
                                            name_prefix="model", save_vecnormalize=True))
    return callbacks, evaluator, guard


def _save_final(model, venv, out: Path) -> None:
    """The learnt model and its normalisation statistics saved; an empty checkpoints folder (a run
    shorter than checkpoint_every) removed."""
    ckpt_dir = out / "checkpoints"
    if ckpt_dir.is_dir() and not any(ckpt_dir.iterdir()):
        ckpt_dir.rmdir()  # a run shorter than checkpoint_every: no empty folder left behind
    model.save(str(out / "model.zip"))
    venv.save(str(out / "vecnormalize.pkl"))


def train(algo: str, action: str, track: str, seed: int, steps: int, out: Path, num_robots: int = 16,
          eval_tracks: tuple[str, ...] = DEFAULT_EVAL_TRACKS, eval_every: int = 200_000,
          checkpoint_every: int = 200_000,
          resume: bool = False, overrides: dict | None = None, progress_bar: bool = False, quiet: bool = False,
          env_kwargs: dict | None = None, time_limit_min: float = 0.0, eval_max_time: float | None = None,
          record_extra: dict[str, Any] | None = None, correction_cost: float = 0.0,
          on_evaluation: Callable[[dict], bool] | None = None) -> dict:
    """Train and save (see the module docstring); returns the run record (``run.json``), to which
    ``record_extra`` (e.g. the caller's provenance: package version, commit) is added.

    The budget is ``steps`` environment steps (all robots together; PPO rounds up to whole
    rollouts). ``time_limit_min`` > 0 is a safety guard only: learning stops after that many
    minutes of wall time and the record says ``"complete": false`` (a run that did not reach its
    step budget, which reports leave out) and ``"stopped": "time_limit"``. ``correction_cost`` is
    the residual action space's cost on the correction's size
    (:class:`~control.action_spaces.vector.VectorControllerAction`).
    ``on_evaluation(entry)`` is called after each periodic evaluation (its ``evaluations.json``
    entry); returning False stops learning there (``azimut tune``'s pruner): the record then says
    ``"stopped": "on_evaluation"`` and ``"complete": false``.

    ``track`` is the training track (``random``: a new track per episode); ``eval_tracks`` the
    tracks of the periodic deterministic evaluations (every ``eval_every`` steps, and at the end);
    ``resume`` continues from :func:`latest_checkpoint` (SAC starts a new replay buffer) up to
    ``steps`` in all, the checkpoint's included; the run must have been trained with the same
    ``algo``, ``action`` and ``env_kwargs`` and have done at most ``steps`` (:func:`check_resume`,
    ``ValueError``).

    A ``KeyboardInterrupt`` (Ctrl-C) in learning or the final evaluation, or a SIGINT/SIGTERM
    under :func:`train.interrupts.signals_as_interrupts` (learning stops at the next step), saves
    the run as it stands (a checkpoint at its steps, ``model.zip``, ``run.json`` with
    ``"complete": false`` and ``"interrupted"``) and raises
    :class:`~train.interrupts.Interrupted` carrying that record."""
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import CallbackList

    from train.envs import make_sb3_env
    from train.hyperparams import load_hyperparams
    from train.interrupts import raise_if_requested

    env_kwargs = dict(env_kwargs or {})
    ckpt = latest_checkpoint(out) if resume else None
    if ckpt is not None:  # the files themselves: check_resume, before (the CLI), or SB3 while loading
        _check_trained_with(out, ckpt, algo, action, env_kwargs)
    out.mkdir(parents=True, exist_ok=True)
    key = action_key(action)
    hp, hp_version = load_hyperparams(algo, key)
    hp.update(overrides or {})
    cls = PPO if algo == "ppo" else SAC
    venv, model = _new_or_resumed_model(cls, ckpt, out, steps, seed, hp, make_sb3_env(
        action, num_robots, track, env_kwargs, correction_cost),
        {"algo": algo, "action": action, "track": track, "seed": seed, "steps": steps, "num_robots": num_robots,
         "env_kwargs": env_kwargs, "correction_cost": float(correction_cost)})
    _set_logger(model, out, quiet)
    callbacks, evaluator, guard = _callbacks(out, algo, action, env_kwargs, seed, num_robots, eval_tracks, eval_every,
                                             checkpoint_every, time_limit_min, eval_max_time, on_evaluation)
    start_steps = model.num_timesteps
    t0 = time.perf_counter()
    # SB3 adds the steps a resumed model has done to total_timesteps: give it what is left
    todo = max(int(steps) - start_steps, 0) if ckpt is not None else steps
    rollout = int(hp["n_steps"]) * int(num_robots) if algo == "ppo" else 1  # SB3's PPO learns whole rollouts
    if not quiet and int(todo) % rollout:  # say what --steps becomes
        print(f"azimut train: PPO learns in rollouts of n_steps x robots = {hp['n_steps']} x {num_robots} = "
              f"{rollout} steps, so {todo} steps {'to go ' if ckpt is not None else ''}become "
              f"{-(-int(todo) // rollout) * rollout} (run.json keeps both: 'steps' and 'num_timesteps')", flush=True)

    def record_of(final_rows: list, complete: bool, stopped: str | None, learn_s: float) -> dict:
        done_steps = model.num_timesteps - start_steps
        return {"complete": complete, "stopped": stopped,
                "time_limit_min": time_limit_min, "algo": algo, "action": action,
                "track": track, "seed": seed,
                "steps": steps, "num_timesteps": int(model.num_timesteps), "num_robots": num_robots,
                "correction_cost": float(correction_cost), "eval_tracks": list(eval_tracks),
                "hyperparams": hp, "hyperparams_version": hp_version, "env_id": ENV_ID, "env_kwargs": env_kwargs,
                "learn_wall_s": learn_s, "steps_per_s_in_learn": done_steps / learn_s if learn_s > 0 else math.nan,
                "torch_threads": torch.get_num_threads(), "resumed_from": str(ckpt) if ckpt else None,
                "machine": f"{platform.node()} ({os.cpu_count()} CPUs, shared)", "final_eval": final_rows,
                **(record_extra or {})}

    learn_s = math.nan
    try:
        model.learn(total_timesteps=todo, callback=CallbackList(callbacks), reset_num_timesteps=ckpt is None,
                    progress_bar=progress_bar, log_interval=1 if algo == "ppo" else 10)
        learn_s = time.perf_counter() - t0
        raise_if_requested()  # StopOnSignal ended learn: an interrupted run, not a finished one
        _save_final(model, venv, out)
        final = evaluator.evaluate()
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM through train.interrupts: save what there is
        learn_s = time.perf_counter() - t0 if math.isnan(learn_s) else learn_s
        raise _interrupted(exc, model, venv, out, record_of([], False, "interrupted", learn_s)) from None
    final["final"] = True
    evaluator.history.append(final)
    (out / "evaluations.json").write_text(json.dumps(evaluator.history, indent=1, allow_nan=True))
    complete = int(model.num_timesteps) >= int(steps) and not evaluator.stopped
    stopped = "on_evaluation" if evaluator.stopped else "time_limit" if guard is not None and guard.fired else None
    record = record_of(final["rows"], complete, stopped, learn_s)
    (out / "run.json").write_text(json.dumps(record, indent=1, allow_nan=True, default=str))
    venv.close()
    return record


def _interrupted(exc: KeyboardInterrupt, model, venv, out: Path, record: dict):
    """Save an interrupted run (see :func:`train`): a checkpoint at its steps (what ``--resume``
    continues from), ``model.zip`` + ``vecnormalize.pkl`` and ``run.json`` (``"complete": false``,
    ``"interrupted"``: the signal, ``"saved"``: the files); returns the
    :class:`~train.interrupts.Interrupted` to raise. SB3 and the env are between two Python
    operations, so the networks and the statistics are whole (a checkpoint torn by the signal is
    rewritten under the same name)."""
    from train.interrupts import Interrupted, signal_name

    signum = int(getattr(exc, "signum", 2))
    n = int(model.num_timesteps)
    ckpt_dir = out / "checkpoints"
    ckpt_dir.mkdir(exist_ok=True)
    saved = [ckpt_dir / f"model_{n}_steps.zip", ckpt_dir / f"model_vecnormalize_{n}_steps.pkl",
             out / "model.zip", out / "vecnormalize.pkl"]
    model.save(str(saved[0]))
    venv.save(str(saved[1]))
    model.save(str(saved[2]))
    venv.save(str(saved[3]))
    record = {**record, "interrupted": signal_name(signum), "saved": [str(p) for p in saved]}
    (out / "run.json").write_text(json.dumps(record, indent=1, allow_nan=True, default=str))
    for close in (model.logger.close, venv.close):
        try:
            close()
        except Exception:  # noqa: BLE001,S110 (an env or logger torn by the signal: its files are saved above)
            pass
    return Interrupted(signum, record)
