"""``azimut eval`` as a campaign: every (controller, track, seed) episode as a task of
:mod:`jobs.campaign.engine`, statistics over seeds, and one report to open.

An episode is defined by its key, ``(controller, track, seed, speed_scale, domain_randomization,
kicks, max_time)`` (``--speed-scales`` runs every episode at each scale, one key each, so
``--resume`` reuses the episodes of any scale run before, by ``--speed-scale`` or
``--speed-scales``), ``inputs`` (the content digests of the code and files it runs: the azimut
sources, a user controller's modules, a policy's files, a robot file; :mod:`jobs.eval.fingerprint`),
``track_file`` for a track read from a file (:mod:`jobs.eval.track_files`) and, when they are not
the default, the robot (``robot`` or ``robot_file``) and its ``imperfections`` preset: the env
is reset with ``seed`` (sensor and start noise, the ``random`` track, domain randomisation) and
the kick, if any, is drawn from ``seed`` too, so an episode's metrics are the same whichever
executor, worker or position in the queue runs it. The episodes of
one controller with the same options (all but track and seed) run as one batch on a vector env
(:func:`episode_batch`, one per worker), with the metrics each gets alone, bit for bit.

The report folder holds ``report.md`` (the summary table, mean and 95% bootstrap interval over
seeds per controller × track × metric; with several speed scales the fronts, :mod:`jobs.eval.fronts`;
then per track the plots that overlay the controllers,
and per controller × track its row with its plots embedded; then the per-seed rows),
``metrics.json`` (``campaign``, with ``speed_scales``; ``summary``, one cell per controller × track ×
speed scale; ``episodes``: the per-seed rows, each with its ``speed_scale``), ``plots/`` and
``episodes/`` (one record per finished episode, what ``--resume`` reads, and its trace
``<id>.npz``: :func:`jobs.eval.results.save_trace`).
"""

from __future__ import annotations

import argparse
import re
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from azimut_env.task.core import nominal_duration
from azimut_env.tracks import SCENARIO_NAMES
from control.episode import episode_metrics
from control.rollout import run_episode, run_episodes
from jobs.campaign.args import add_executor_arguments, arg_seeds, check_executor_args
from jobs.campaign.engine import CampaignInterrupted, Task, TaskStore, resolve_executor, run_tasks
from jobs.campaign.task import canonical, file_digest
from jobs.eval.controllers import build_controller, check_controllers
from jobs.eval.outputs import episode_label, is_own_plot, output_layout, speed_scales_of
from jobs.eval.plots import comparison_plots, write_plots
from jobs.eval.report import SUMMARY_COLUMNS, limits_text, write_campaign_report
from jobs.eval.track_files import episode_track, track_file_entry

__all__ = ["DEFAULT_DT", "add_arguments", "check_args", "seeds_of", "speed_scales_of", "reference_scale", "run_kwargs",
           "episode_task", "episode_batch",
           "draw_kick",
           "episode_tasks", "run_eval_campaign", "write_campaign_report", "comparison_plots"]

#: the env's default control period [s] (``AzimutEnv(control_period=0.02)``)
DEFAULT_DT = 0.02
def draw_kick(seed: int, track: str, speed_scale: float = 1.0, max_time: float | None = None,
              dt: float = DEFAULT_DT, n_wheels: int = 4, params=None, track_file: dict | None = None) -> dict:
    """The kick of episode ``seed`` (the env's ``kick`` reset option), drawn from the seed alone.

    1–``n_wheels`` random wheels (at most 4), an angular impulse of ±(0.2–1.0) N·m·s (as in
    :func:`jobs.eval.robustness.kick_trial`), at a random step between 20% and 60% of the nominal
    duration (or of ``max_time``, whichever is shorter).
    """
    rng = np.random.default_rng([int(seed), 0x6B1C])  # a stream of its own: not the env's
    horizon = nominal_duration(episode_track(track, params, seed, track_file), speed_scale)
    if max_time is not None:
        horizon = min(horizon, float(max_time))
    step = int(rng.uniform(0.2, 0.6) * horizon / dt)
    wheels = [int(w) for w in np.sort(rng.choice(n_wheels, size=int(rng.integers(1, min(n_wheels, 4) + 1)),
                                                 replace=False))]
    impulse = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.2, 1.0))
    return {"step": max(step, 1), "wheels": wheels, "impulse": impulse}


def _episode_setup(track: str, seed: int, speed_scale: float, domain_randomization: float, kicks: bool,
                   max_time: float | None, robot: str | None, robot_file: str | None,
                   imperfections: str | None = None, track_file: dict | None = None
                   ) -> tuple[dict | None, dict | None]:
    """An episode's kick (None: none) and env keyword arguments (None: the defaults)."""
    from jobs.args import robot_env_kwargs

    robot_kw = robot_env_kwargs(robot, robot_file, imperfections)
    params = _robot_params(robot_kw.get("robot"), imperfections) if robot_kw else None
    n_wheels = params.n if params is not None else 4
    kick = (draw_kick(seed, track, speed_scale, max_time, n_wheels=n_wheels, params=params, track_file=track_file)
            if kicks else None)
    env_kwargs = {"domain_randomization": float(domain_randomization)} if domain_randomization else None
    if robot_kw:
        env_kwargs = {**(env_kwargs or {}), **robot_kw}
    return kick, env_kwargs


def _episode_result(log, track: str, seed: int, kick: dict | None, return_log: bool) -> dict:
    """The campaign result of one episode's log: ``{"metrics": row}`` (and the log)."""
    row = episode_metrics(log)
    if track in SCENARIO_NAMES:
        from control.episode import scenario_metrics

        row.update(scenario_metrics(log))
    row["track"] = track  # the name asked for (a random track's Track may carry another)
    row["seed"] = int(seed)
    if kick is not None:
        row["kick"] = kick
    out: dict[str, Any] = {"metrics": row}
    if return_log:
        out["artifacts"] = {"log": log}
    return out


def episode_task(controller: str, track: str, seed: int, speed_scale: float = 1.0,
                 domain_randomization: float = 0.0, kicks: bool = False, max_time: float | None = None,
                 return_log: bool = False, robot: str | None = None, robot_file: str | None = None,
                 inputs: dict | None = None, imperfections: str | None = None,
                 track_file: dict | None = None) -> dict:
    """One campaign episode of the controller spec ``controller`` (:mod:`jobs.eval.controllers`):
    ``{"metrics": row}`` (plus ``artifacts.log``, the :class:`~control.episode.EpisodeLog`, with
    ``return_log``); the row's ``controller`` is the controller's name. ``robot`` (a preset's
    name) or ``robot_file`` (a description file) pick the robot (default: azimut3), ``imperfections``
    the preset put on it (default: the one its file names). ``inputs``:
    the content digests of the files the episode reads (:func:`episode_tasks`), in its key so
    that a changed file is a new episode; not read here. ``track_file``: the track is the file
    ``track_file["path"]`` (:func:`jobs.eval.track_files.episode_track`), named ``track``."""
    kick, env_kwargs = _episode_setup(track, seed, speed_scale, domain_randomization, kicks, max_time, robot,
                                      robot_file, imperfections, track_file)
    path = episode_track(track, None, seed, track_file) if track_file else track
    log = run_episode(build_controller(controller, speed_scale), path, seed=int(seed), kick=kick, max_time=max_time,
                      env_kwargs=env_kwargs)
    return _episode_result(log, track, seed, kick, return_log)


#: the key entries that every episode of one batch shares (all but the track and the seed)
_SHARED = ("controller", "speed_scale", "domain_randomization", "kicks", "max_time", "robot", "robot_file",
           "imperfections", "inputs")


def episode_batch(keys: list[dict], extras: list[dict]) -> list[dict]:
    """Several episodes of one controller (keys that differ only in ``track`` and ``seed``), stepped
    as one batch (:func:`control.rollout.run_episodes`, one vector env): each result is the one
    :func:`episode_task` returns for its key, bit for bit (the robots of a vector env do not
    interact, and the built-in controllers treat their robots independently)."""
    shared = {name: keys[0].get(name) for name in _SHARED}
    if any({name: k.get(name) for name in _SHARED} != shared for k in keys):
        raise ValueError("episode_batch: the episodes of a batch must differ only in track and seed")
    opts = {name: shared[name] for name in ("speed_scale", "domain_randomization", "kicks", "max_time", "robot",
                                             "robot_file", "imperfections")}
    opts["speed_scale"] = 1.0 if opts["speed_scale"] is None else opts["speed_scale"]
    opts["domain_randomization"] = opts["domain_randomization"] or 0.0
    opts["kicks"] = bool(opts["kicks"])
    setups = [_episode_setup(k["track"], int(k["seed"]), **opts, track_file=k.get("track_file")) for k in keys]
    paths = [episode_track(k["track"], None, int(k["seed"]), k["track_file"]) if k.get("track_file") else k["track"]
             for k in keys]
    logs = run_episodes(build_controller(shared["controller"], opts["speed_scale"]), paths,
                        [int(k["seed"]) for k in keys], kicks=[kick for kick, _ in setups],
                        max_time=opts["max_time"], env_kwargs=setups[0][1])
    return [_episode_result(log, k["track"], int(k["seed"]), kick, bool(e.get("return_log", False)))
            for log, k, e, (kick, _) in zip(logs, keys, extras, setups)]


def check_episode_result(result: Any, key: dict) -> None:
    """The schema of a saved :func:`episode_task` result, what the report reads back on
    ``--resume``: ``{"metrics": row}`` with a controller name, the episode's track and seed and every
    metric of :data:`SUMMARY_COLUMNS` a number (``completed`` a bool; NaN or None where undefined).
    Raises ``ValueError``/``TypeError`` naming what is wrong (the record is then recomputed)."""
    if not isinstance(result, dict) or not isinstance(result.get("metrics"), dict):
        raise TypeError("no 'metrics' dict")
    row = result["metrics"]
    if not isinstance(row.get("controller"), str):  # the controller's name (a policy's is not its spec)
        raise TypeError(f"metrics['controller'] = {row.get('controller')!r} is not a name")
    for name in ("track", "seed"):
        if row.get(name) != key[name] or type(row.get(name)) is not type(key[name]):
            raise ValueError(f"metrics[{name!r}] = {row.get(name)!r}, the episode's is {key[name]!r}")
    for name, *_ in SUMMARY_COLUMNS:
        if name not in row:
            raise KeyError(f"metrics[{name!r}] is missing")
        v = row[name]
        kinds = (bool,) if name == "completed" else (int, float, type(None))
        if not isinstance(v, kinds) or (name != "completed" and isinstance(v, bool)):
            raise TypeError(f"metrics[{name!r}] = {v!r} is not a {'bool' if name == 'completed' else 'number'}")


def _robot_params(robot: str | None, imperfections: str | None = None):
    """The RobotParams of the env's robot (a preset's name or a file's path, None: the default;
    with the preset ``imperfections``, None: the robot's own)."""
    from azimut_env.task.config import resolve_params

    return resolve_params(None, None, 1.0, robot, imperfections)


def episode_tasks(controllers: Sequence[str], tracks: Sequence[str], seeds: Sequence[int], *,
                  speed_scale: float = 1.0, domain_randomization: float = 0.0, kicks: bool = False,
                  max_time: float | None = None, plot_seed: int | None = None, robot: str | None = None,
                  robot_file: str | None = None, names: dict[str, str] | None = None,
                  all_logs: bool = False, imperfections: str | None = None,
                  speed_scales: Sequence[float] | None = None) -> list[Task]:
    """The campaign's tasks, track-major, then speed scale (``speed_scales``, else ``speed_scale``
    alone), controller and seed (the report's order); every episode returns its log with
    ``all_logs`` (``azimut eval``: each episode's trace, the export), else ``plot_seed``'s only;
    ``names`` (spec -> name) labels them. The robot (``robot``, ``robot_file``) and the
    ``imperfections`` preset are in each task's key only when they are given (``--resume`` never
    reuses an episode of another robot); ``inputs``, the digests of the code and files an episode
    runs, always (:func:`jobs.eval.fingerprint.controller_inputs`)."""
    from jobs.eval.fingerprint import controller_inputs

    names = names or {}
    tasks = []
    # the content of the code and of every file an episode reads, in its key: changed code (azimut's,
    # a user controller's modules) or a file changed at the same path (a retrained model, edited
    # statistics or robot file) is a new episode, not a stale record reused
    inputs = {c: controller_inputs(c) for c in controllers}
    robot_digest = {"robot_file": file_digest(robot_file)} if robot_file else {}
    scales = [float(s) for s in speed_scales] if speed_scales is not None else [float(speed_scale)]
    for track in tracks:
        params = _robot_params(str(Path(robot_file).resolve()) if robot_file else robot, imperfections)
        track_file = track_file_entry(track)
        path = episode_track(track, params, 0, track_file)
        for speed_scale, controller in ((s, c) for s in scales for c in controllers):
            nominal = nominal_duration(path, speed_scale)
            for seed in seeds:
                key = {"controller": controller, "track": track, "seed": int(seed), "speed_scale": float(speed_scale),
                       "domain_randomization": float(domain_randomization), "kicks": bool(kicks),
                       "max_time": None if max_time is None else float(max_time)}
                if robot_file:
                    key["robot_file"] = str(Path(robot_file).resolve())
                elif robot:
                    key["robot"] = robot
                if imperfections:
                    key["imperfections"] = imperfections
                if track_file:
                    key["track_file"] = track_file
                key["inputs"] = {**inputs[controller], **robot_digest}
                cost = min(nominal, max_time) if max_time else nominal
                # the ICR controller (and policies) cost more than the twist controllers
                cost *= 1.0 if controller in ("twist", "twist-setpoint") else 4.0
                group = {k: v for k, v in key.items() if k not in ("track", "seed", "track_file")}
                tasks.append(Task("jobs.eval.campaign:episode_task", key,
                                  extra={"return_log": all_logs or (plot_seed is not None and seed == plot_seed)},
                                  label=episode_label(names.get(controller, controller), track, seed, speed_scale),
                                  cost=cost,
                                  check="jobs.eval.campaign:check_episode_result",
                                  batch="jobs.eval.campaign:episode_batch", group=canonical(group)))
    return tasks


# ----------------------------------------------------------------------------- command line


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The campaign flags of ``azimut eval`` (seeds, options, executors; ``--max-time`` is
    ``azimut eval``'s own)."""
    from jobs.args import arg_float, arg_int

    parser.add_argument("--seeds", type=arg_seeds, default=None, metavar="SEEDS",
                        help="run every (controller, track) episode for each seed: a range 0-9, a list 0,3,5 or both "
                             "(default: --seed alone); the report gives mean and 95%% bootstrap intervals over them")
    parser.add_argument("--domain-randomization", type=arg_float(0.0, 0.5), default=0.0, metavar="D",
                        help="relative spread of friction, steering stiffness and mass drawn at each episode's "
                             "reset from its seed (the env's domain_randomization, 0..0.5; default 0)")
    parser.add_argument("--kicks", action="store_true",
                        help="kick 1-4 random wheels (±0.2-1 N·m·s) once per episode at 20-60%% of its duration, "
                             "drawn from the episode's seed")
    parser.add_argument("--bootstrap", type=arg_int(100, 1_000_000), default=10_000, metavar="N",
                        help="bootstrap resamples for the intervals (default 10000)")
    add_executor_arguments(parser, "episodes")


def check_args(args: argparse.Namespace) -> None:
    """The campaign flags together (``ValueError``, one line): --seed with --seeds, the executor,
    the output folder."""
    from jobs.args import check_output_layout, check_output_path

    if args.seeds is not None and args.seed not in (None, 0) and args.seeds != [args.seed]:
        raise ValueError("give --seed or --seeds, not both")
    if args.seed is not None and args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    check_executor_args(args)
    check_output_path(args.out, directory=True)
    check_output_layout(args.out, *output_layout(args, seeds_of(args)))


def run_kwargs(args: argparse.Namespace) -> dict:
    """The executor flags as keyword arguments of :func:`jobs.campaign.engine.run_tasks`."""
    return {"executor": resolve_executor(args.executor, args.workers, args.ray_address), "workers": args.workers,
            "threads": args.threads_per_task, "ray_address": args.ray_address, "retries": args.retries,
            "resume": args.resume}


def seeds_of(args: argparse.Namespace) -> list[int]:
    """The campaign's seeds: ``--seeds``, else ``[--seed]``."""
    return list(args.seeds) if args.seeds is not None else [int(args.seed or 0)]


def reference_scale(scales: Sequence[float]) -> float:
    """The speed scale of the per-run plots, comparisons, videos and the agents' table: the one
    nearest 1 (the tracks' nominal speed; of two as near, the slower)."""
    return min(scales, key=lambda s: (abs(s - 1.0), s))


# ------------------------------------------------------------------------------------- run


class _EnvPerRobot:
    """One env per robot (per distinct env keyword arguments), built on first use: its geometry
    and limits for the plots and the report."""

    def __init__(self, robots: dict, campaign_kw: dict):
        self.robots, self.campaign_kw = robots, campaign_kw
        self.envs: dict[str, Any] = {}

    def __call__(self, name: str):
        from azimut_env.env import AzimutEnv

        kw = self.robots[name]["env_kwargs"] if name in self.robots else self.campaign_kw
        if canonical(kw) not in self.envs:
            self.envs[canonical(kw)] = AzimutEnv(**kw)
        return self.envs[canonical(kw)]


def _remove_own_plots(plot_dir: Path) -> None:
    """The plots an earlier campaign wrote into ``plot_dir`` removed (not a resumed one's)."""
    for p in plot_dir.glob("*.png"):
        if is_own_plot(p.name):
            p.unlink()


def _artifact_writer(store: TaskStore, out: Path, first_seed: int, reference: float, export, robot_id,
                     video, plot_seed, names: dict, env_of):
    """The ``on_result`` hook of the campaign: every episode's trace saved (and exported with
    ``--export``, named by ``robot_id``: the robot file, else the preset); the video and the plots
    of the first seed at the reference scale."""
    from jobs.eval.results import export_episode, save_trace

    plot_dir, video_dir = out / "plots", out / "videos"

    def on_result(task: Task, rec: dict) -> None:
        art = (rec.get("result") or {}).get("artifacts")
        if not art or "log" not in art:
            return
        log = art["log"]
        first = task.key["seed"] == first_seed and task.key["speed_scale"] == reference
        store.folder.mkdir(parents=True, exist_ok=True)
        save_trace(store.folder / f"{task.id}.npz", log)  # every episode's, plots or not
        rec["result"]["trace"] = f"episodes/{task.id}.npz"
        if export:
            rec["result"]["export"] = export_episode(log, out / "exports", task.label, robot_id, export)
        if video and first:
            from jobs.eval.video import write_video

            name = re.sub(r"[^A-Za-z0-9_.-]+", "_", task.label)
            rec["result"]["video"] = f"videos/{write_video(log, video_dir / f'{name}.{video}', fmt=video).name}"
        if plot_seed is not None and first:
            plot_dir.mkdir(exist_ok=True)
            env = env_of(names.get(task.key["controller"], task.key["controller"]))
            rec["result"]["plots"] = [f"plots/{f}" for f in write_plots(log, plot_dir, env.geometry, env.limits)]

    return on_result


def _campaign_record(args: argparse.Namespace, scales, reference: float, env_of, robots: dict, env0, executor: str,
                     plot_seed, wall: float, computed: int, resumed: int) -> dict:
    """The campaign's settings and counts as ``results.json`` holds them; the limits once when
    every controller's robot has the same, else per controller."""
    by_controller = {name: limits_text(env_of(name).limits) for name in robots}  # each controller's robot's
    limits: str | dict = (next(iter(by_controller.values())) if len(set(by_controller.values())) == 1
                          else by_controller) if by_controller else limits_text(env0.limits)
    return {"speed_scale": scales[0] if len(scales) == 1 else None, "speed_scales": scales,
            "reference_scale": reference, "domain_randomization": args.domain_randomization,
            "kicks": bool(args.kicks), "max_time": args.max_time, "control_period": env0.control_period,
            "limits": limits, "executor": executor, "workers": args.workers, "level": 0.95,
            "n_resamples": args.bootstrap, "plot_seed": plot_seed, "wall_s": wall,
            "computed": computed, "resumed": resumed}


def run_eval_campaign(args: argparse.Namespace, controllers: Sequence[str], tracks: Sequence[str],
                      seeds: Sequence[int], stream=None) -> int:
    """Run the campaign ``args`` describes (``azimut eval``'s flags) and write the report.

    ``controllers`` are specs; the rows, cells and report carry their names
    (``args.controller_names``, else made here). Returns 0, or 1 when an episode failed (after
    its retries; the report lists it); 130 on Ctrl-C and 143 on SIGTERM, after saving the finished
    episodes (``--resume`` goes on from them)."""
    stream = stream if stream is not None else sys.stdout
    from jobs.args import robot_env_kwargs, robot_label
    from jobs.eval.console import EXIT_STATUS, progress_printer, say, signals_as_interrupts
    from jobs.eval.results import write_results
    from jobs.eval.robots import controller_robots

    scales = speed_scales_of(args)
    reference = reference_scale(scales)  # the per-run plots, comparisons and videos are of this scale
    names = getattr(args, "controller_names", None) or check_controllers(list(controllers), scales[0])

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plot_dir = out / "plots"
    store = TaskStore(out / "episodes")
    plot_seed = None if args.no_plots else seeds[0]
    video = getattr(args, "video", None)
    robot, robot_file = getattr(args, "robot", None), getattr(args, "robot_file", None)
    imperfections = getattr(args, "imperfections", None)
    campaign_kw = robot_env_kwargs(robot, robot_file, imperfections)
    robots = controller_robots(controllers, names, scales[0], campaign_kw, robot_label(args),
                               campaign_set=("domain_randomization",) if args.domain_randomization else ())
    tasks = episode_tasks(controllers, tracks, seeds, speed_scales=scales,
                          domain_randomization=args.domain_randomization, kicks=args.kicks, max_time=args.max_time,
                          plot_seed=seeds[0], robot=robot, robot_file=robot_file, names=names, all_logs=True,
                          imperfections=imperfections)
    executor = run_kwargs(args)["executor"]
    env_of = _EnvPerRobot(robots, campaign_kw)
    env0 = env_of("")
    if not args.resume and plot_dir.is_dir():
        _remove_own_plots(plot_dir)
    on_result = _artifact_writer(store, out, seeds[0], reference, getattr(args, "export", None), robot_file or robot,
                                 video, plot_seed, names, env_of)
    start = time.perf_counter()
    n_before = sum(1 for t in tasks if args.resume and (r := store.load(t)) is not None and r.get("status") == "ok")
    for path, problem in store.rejected:  # recomputed below: say so
        print(f"azimut eval: {path}: not a valid episode record ({problem}); recomputing it", file=sys.stderr)
    store.rejected.clear()
    with signals_as_interrupts() as caught:
        try:
            records = run_tasks(tasks, store, **run_kwargs(args), retry="transient", on_result=on_result,
                                progress=progress_printer(names, stream, store.folder, show_scale=len(scales) > 1))
        except CampaignInterrupted as exc:
            sig = caught["signal"]
            print(f"azimut eval: {'terminated (SIGTERM)' if sig == signal.SIGTERM else 'interrupted'}: {exc.done} of "
                  f"{exc.total} episodes saved in {store.folder}; run the same command with --resume to finish",
                  file=sys.stderr, flush=True)
            return EXIT_STATUS.get(sig, 130)
    wall = time.perf_counter() - start
    campaign = _campaign_record(args, scales, reference, env_of, robots, env0, executor, plot_seed, wall,
                                len(tasks) - n_before, n_before)
    n_ok, n_all = write_results(out, records, tasks, controllers, tracks, seeds, names, robots, campaign, store.folder,
                                n_resamples=args.bootstrap, video=bool(video), compare=plot_seed is not None)
    n_failed = n_all - n_ok
    say(f"{n_ok} of {n_all} episodes ok" + (f", {n_failed} failed" if n_failed else "")
        + f" in {wall:.1f} s ({executor}, {args.workers} worker(s)); report written to {out}/report.md", stream)
    return 0 if n_failed == 0 else 1
