"""``azimut eval``: run controllers on tracks in the simulator and write a report folder.

Controllers (``--controllers``, specs of :mod:`control.controller`, made by
:mod:`jobs.eval.controllers`):

* ``icr``: :class:`~control.icr.controller.ICRController` on the IT-estimated (λ̂, μ̂), fed by a
  :class:`~control.follow.path_follower.PathFollower` (:class:`~control.path_controllers.ICRPathController`);
* ``twist``: :class:`~control.twist.wpilib.SwerveController`, the WPILib-style baseline, fed by the
  same follower (:class:`~control.path_controllers.TwistPathController`);
* ``twist-setpoint``: :class:`~control.twist.setpoint.SetpointController`, a setpoint generator in
  the manner of Team 254's ``SwerveSetpointGenerator`` (never beyond the actuator limits), fed by the
  same follower (:class:`~control.path_controllers.SetpointPathController`);
* ``feedforward``: the kinematic feed-forward of ``azimut sim-paper`` (no actuator limits);
* ``ppo:PATH``, ``sac:PATH`` (or ``ppo:NAME=PATH``): a policy ``azimut train`` wrote;
* ``package.module:Class``: a controller of yours (a :class:`~control.controller.Controller`).

All run with the same actuator limits and control period, through the one episode loop
(:func:`control.rollout.run_episode`).

Per controller and track (and seed: ``azimut eval`` runs a campaign of (controller, track, seed)
episodes, see :mod:`jobs.eval.campaign`, whose ``report.md`` and ``metrics.json`` give the
mean and a bootstrap interval over seeds of each metric) the report has: RMS and max lateral
error, RMS heading error, completion time, slip energy ∫ Σ|F·v_slip| dt and per metre travelled,
mean antagonism (and weighted by distance, ∫ A|v| dt / ∫ |v| dt) and mean null-space force of the
tire forces (:mod:`azimut_env.physics.antagonism`), slip and antagonism at standstill
(:func:`control.episode.distance_metrics`), mean
and min qua of the measured steering configuration (eq. 28–29) over all steps and **while moving**
(see :func:`moving_mask`: the controller in its RUNNING mode and the true |μ| above
:data:`MOVING_MU`; stops and in-place reconfigurations, where the wheels turn with the chassis at
rest, are left out), the standstill share (the other steps), the number of steps where a
commanded limit was exceeded, and the number of stop-and-reconfigure events; and PNG plots: the
trajectory over the track (the paper's Fig. 9), pairwise β projections against the constraining
surface (Fig. 10), qua over time (Fig. 11), the ICR's path on the sphere, and the wheel commands
against their limits. ``--speed-scales`` runs every controller at several speed scales and adds the
fronts, lap time against slip per metre per track (:mod:`jobs.eval.fronts`). ``--video`` adds a
video (GIF, or MP4 with ffmpeg) of each (controller, track) episode of the first seed, the env's
top-down view redrawn from the episode's log (:mod:`jobs.eval.video`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from azimut_env.tracks import ALL_TRACK_NAMES, SCENARIO_NAMES, TRACK_NAMES
from control.episode import MOVING_MU, EpisodeLog, episode_metrics, moving_mask, progress_bar
from jobs.args import add_robot_arguments, arg_choice_list, arg_float, arg_int, arg_output_path, require_module
from jobs.eval import campaign
from jobs.eval.controllers import POLICY_PREFIXES, arg_controllers, check_controllers, is_policy
from jobs.eval.plots import write_plots  # re-exported
from jobs.eval.video import VIDEO_FORMATS, check_video_format

__all__ = ["DEFAULT_CONTROLLERS", "POLICY_PREFIXES", "MOVING_MU", "EpisodeLog", "moving_mask", "episode_metrics",
           "is_policy", "arg_controllers", "write_plots", "write_report", "add_arguments", "run"]

#: the controllers ``azimut eval`` compares by default: the ICR controller and both twist
#: baselines (the plain WPILib-style one and the setpoint generator, the strongest)
DEFAULT_CONTROLLERS = ("icr", "twist", "twist-setpoint")
#: Default evaluation order: the paper track first.
DEFAULT_TRACKS = TRACK_NAMES  #: the built-in tracks (azimut_env.tracks), paper first


def arg_tracks(text: str) -> list[str]:
    """``type=`` of ``--tracks``: built-in tracks and scenarios (``suite``: every scenario, in
    :data:`SCENARIO_NAMES` order) and waypoint files of the user's (a path:
    :func:`jobs.eval.track_files.read_track_file`, read and checked here), order kept, no repeats."""
    from jobs.eval.track_files import looks_like_a_file, read_track_file

    items = [t.strip() for t in text.split(",") if t.strip()]
    expanded = []
    for item in items:
        expanded += list(SCENARIO_NAMES) if item == "suite" else [item]
    files = [t for t in expanded if t not in ALL_TRACK_NAMES and looks_like_a_file(t)]
    for path in files:
        try:
            read_track_file(path)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc).splitlines()[0]) from None
    names: list[str] = []
    if len(files) < len(expanded) or not expanded:
        try:
            names = arg_choice_list(ALL_TRACK_NAMES)(",".join(t for t in expanded if t not in files))
        except argparse.ArgumentTypeError as exc:
            raise argparse.ArgumentTypeError(f"{exc}; or suite (every scenario); or the path of a waypoint file "
                                             "(x,y per line, .csv)") from None
    if len(set(expanded)) != len(expanded):
        raise argparse.ArgumentTypeError(f"repeated entries in {text!r}")
    return [t for t in expanded if t in files or t in names]


def arg_speed_scales(text: str) -> list[float]:
    """``type=`` of ``--speed-scales``: comma-separated speed scales, each what ``--speed-scale``
    takes (a number in ]0, 10]), order kept, no repeats (1 and 1.0 are one), at least one."""
    items = [t.strip() for t in text.split(",")]
    if not any(items):
        raise argparse.ArgumentTypeError(f"give at least one speed scale, got {text!r}")
    if not all(items):
        raise argparse.ArgumentTypeError(f"an empty entry in {text!r}")
    one = arg_float(0.0, 10.0, lo_open=True)
    scales = []
    for item in items:
        try:
            scales.append(one(item))
        except argparse.ArgumentTypeError as exc:
            raise argparse.ArgumentTypeError(f"{exc} (in {text!r})") from None
    if len(set(scales)) != len(scales):
        raise argparse.ArgumentTypeError(f"repeated speed scales in {text!r}")
    return scales


arg_speed_scales.__name__ = "speed scales"


_COLUMNS = [("controller", "controller", "{}"), ("track", "track", "{}"), ("completed", "done", "{}"),
            ("rms_lateral_m", "RMS lat [cm]", "{:.2f}", 100), ("max_lateral_m", "max lat [cm]", "{:.2f}", 100),
            ("rms_heading_rad", "RMS head [deg]", "{:.2f}", 180 / math.pi),
            ("completion_time_s", "time [s]", "{:.1f}"), ("slip_energy_J", "slip energy [J]", "{:.2f}"),
            ("slip_energy_per_m", "slip per m [J/m]", "{:.2f}"), ("mean_antagonism_N", "mean antagonism [N]", "{:.2f}"),
            ("antagonism_distance_weighted_N", "antagonism over distance [N]", "{:.2f}"),
            ("mean_nullspace_force_N", "mean null-space force [N]", "{:.2f}"), ("mean_qua", "mean qua (all)", "{:.4f}"),
            ("min_qua", "min qua (all)", "{:.4f}"), ("mean_qua_moving", "mean qua moving", "{:.4f}"),
            ("min_qua_moving", "min qua moving", "{:.4f}"), ("standstill_share", "standstill share", "{:.2f}"),
            ("limit_violation_steps", "limit-exceeded steps", "{}"),
            ("reconfigure_events", "stop+reconfig", "{}"), ("return", "return", "{:.1f}")]


def metrics_markdown(rows: list[dict]) -> str:
    """The metrics table in Markdown."""
    head = "| " + " | ".join(c[1] for c in _COLUMNS) + " |"
    sep = "|" + "|".join("---" for _ in _COLUMNS) + "|"
    lines = [head, sep]
    for row in rows:
        cells = []
        for col in _COLUMNS:
            v = row[col[0]]
            if len(col) > 3 and isinstance(v, float):
                v = v * col[3]
            cells.append(col[2].format(v) if v is not None else "-")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_report(rows: list[dict], out: Path, header: str = "") -> None:
    """metrics.md and metrics.json in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "metrics.json").write_text(json.dumps(rows, indent=2, allow_nan=True))
    (out / "metrics.md").write_text(f"# azimut eval\n\n{header}\n\n" + metrics_markdown(rows))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--controllers", default=",".join(DEFAULT_CONTROLLERS), type=arg_controllers,
                        help="comma-separated controllers: icr, twist, twist-setpoint, feedforward, trained policies "
                             "ppo:PATH or sac:PATH (the model.zip azimut train wrote; ppo:NAME=PATH names it, default "
                             "the run folder's name), or package.module:Class, a controller of yours (default: "
                             f"{','.join(DEFAULT_CONTROLLERS)})")
    parser.add_argument("--tracks", default=",".join(DEFAULT_TRACKS), type=arg_tracks,
                        help=f"comma-separated tracks among {', '.join(TRACK_NAMES)} (default: these, paper first), "
                             f"scenarios among {', '.join(SCENARIO_NAMES)}, scaled to the robot ('suite': all six "
                             "scenarios; docs/robots.md), and paths of your own: a CSV file of waypoints x,y[,heading"
                             "[,speed]] in m, rad, m/s (docs/control.md)")
    parser.add_argument("--seed", type=arg_int(0, 2**32 - 1), default=0,
                        help="env seed (noise, start, random track); default 0")
    add_robot_arguments(parser, imperfections=True)
    speed = parser.add_mutually_exclusive_group()
    speed.add_argument("--speed-scale", type=arg_float(0.0, 10.0, lo_open=True), default=1.0,
                       help="multiply every track's speed profile (default 1: the track's nominal speed)")
    speed.add_argument("--speed-scales", type=arg_speed_scales, default=None, metavar="SCALES",
                       help="run each controller at each of these speed scales (comma-separated, e.g. "
                            "0.6,0.8,1.0,1.2,1.4; each as --speed-scale): the report adds the fronts, lap time "
                            "against slip per metre per track; not with --speed-scale")
    parser.add_argument("--max-time", type=arg_float(0.0, 3600.0, lo_open=True), default=None, metavar="SECONDS",
                        help="end each episode after this simulated time (default: 3 x the track's nominal "
                             "duration + 10 s); a short value gives a quick smoke run")
    parser.add_argument("--out", default="reports/eval", type=arg_output_path(directory=True),
                        help="report folder (default reports/eval)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--video", nargs="?", const="gif", default=None, choices=VIDEO_FORMATS, metavar="FORMAT",
                        help="also write a video of each (controller, track) episode of the first seed to "
                             "OUT/videos/ (gif, the default, or mp4 with an ffmpeg executable; needs pygame, the "
                             "render extra), listed in report.md")
    parser.add_argument("--export", choices=("mcap", "sqlite3"), default=None, metavar="FORMAT",
                        help="also write every episode as a ROS 2 bag to OUT/exports/ (mcap, which Foxglove "
                             "opens, or sqlite3): joint states, the estimated ICR, the true pose, odometry; azimut "
                             "estimate reads it back (docs/logs.md; needs rosbags, the logs extra)")
    parser.add_argument("--kick-runs", type=arg_int(0, 100_000), default=0,
                        help="also run the robustness study: N trials per controller on 'paper' with random "
                             "wheels kicked to random angles mid-track (default 0: skip; the study uses 200)")
    campaign.add_arguments(parser)  # --seeds, --workers, --executor, --ray-address, --resume, ...


def check_args(args: argparse.Namespace) -> None:
    """What ``type=`` cannot see: plots need matplotlib (the [plot] extra); every controller made
    once (trained policies loaded, user classes checked against the protocol, names distinct;
    ``args.controller_names`` keeps spec -> name); the campaign flags together (see
    :func:`jobs.eval.campaign.check_args`)."""
    if not args.no_plots:
        require_module("matplotlib", "writing plots (pass --no-plots to skip them)")
    if getattr(args, "video", None):
        check_video_format(args.video)
    if getattr(args, "export", None):
        require_module("rosbags", "--export (the logs extra: pip install 'azimut[logs]')")
    for item in args.controllers:
        if is_policy(item):
            from train.policy import model_file, policy_name

            if model_file(policy_name(item.split(":", 1)[1])[1]).suffix != ".pt":  # RLlib's export: torch only
                require_module("stable_baselines3", f"--controllers {item} (the [rl] extra)")
            require_module("torch", f"--controllers {item} (the [rl] extra)")
    other_robot = (getattr(args, "robot", None) not in (None, "azimut3") or getattr(args, "robot_file", None)
                   or getattr(args, "imperfections", None) not in (None, "paper"))
    if args.kick_runs > 0 and other_robot:
        raise ValueError("--kick-runs: the robustness study runs on the default robot (azimut3, paper imperfections) "
                         "only")
    scales = campaign.speed_scales_of(args)
    args.controller_names = check_controllers(list(args.controllers), scales[0])
    # a controller is made with speed_scale only when it is not 1 (controller_options): try the other kind too
    for other in [s for s in scales[1:] if (s == 1.0) != (scales[0] == 1.0)][:1]:
        check_controllers(list(args.controllers), other)
    _check_policy_robots(args)
    campaign.check_args(args)


def _check_policy_robots(args: argparse.Namespace) -> None:
    """``ValueError`` (one line) if a trained policy is evaluated on another robot than the one it
    learned (its run's ``env_kwargs``: robot and imperfections; a policy acts on the geometry,
    limits and imperfections it was trained with, and elsewhere it drives a robot it never saw
    without a word)."""
    policies = [spec for spec in args.controllers if is_policy(spec)]
    if not policies:
        return
    from azimut_env.task.config import robot_label, robot_of
    from jobs.args import robot_env_kwargs
    from jobs.eval.controllers import build_controller

    want = robot_env_kwargs(getattr(args, "robot", None), getattr(args, "robot_file", None),
                            getattr(args, "imperfections", None))
    evaluated = robot_of(want)
    for spec in policies:
        trained = dict(getattr(build_controller(spec, campaign.speed_scales_of(args)[0]), "env_kwargs", None) or {})
        if robot_of(trained) != evaluated:
            raise ValueError(f"argument --controllers: {spec}: trained on the robot {robot_label(trained)}, not on "
                             f"the evaluated {robot_label(want)}; evaluate it with the "
                             "--robot/--robot-file/--imperfections it learned")


def _kick_section(controllers: list[str], n_runs: int, seed: int, out: Path, run_kwargs: dict | None = None,
                  names: dict[str, str] | None = None) -> str:
    """Run the robustness study per controller (on the campaign's executor, ``run_kwargs`` of
    :func:`jobs.campaign.engine.run_tasks`; trials saved under ``out/kicks/``); write
    kicks_<controller>.json; return Markdown."""
    from jobs.eval.robustness import kick_study_campaign, summarize_kicks
    from jobs.records import write_json

    lines = ["## Robustness: random wheels kicked to random angles mid-track (paper track)", "",
             "| controller | runs | recovered | failed | limit-exceeded steps | recovery time p50/p90/max [s] "
             "| wheels settled p50/p90/max [s] | max lateral after kick p50/p90/max [cm] "
             "| peak β error p50/max [deg] |",
             "|---|---|---|---|---|---|---|---|---|"]
    names = names or {}
    for spec in [c for c in controllers if not is_policy(c)]:  # trained policies: not in this study yet
        controller = names.get(spec, spec)
        start = time.time()

        def progress(i, n, *_, label=f"kicks/{controller}", t0=start):  # this iteration's label and start
            return progress_bar(label, i / n, t0)

        trials = kick_study_campaign(n_runs, spec, seed0=1000 + 1000 * seed,
                                     store=out / "kicks" / controller, **(run_kwargs or {}), progress=progress)
        if sys.stderr.isatty():
            sys.stderr.write("\n")
        summ = summarize_kicks(trials)
        write_json(out / f"kicks_{controller}.json", summ)
        rt, lat, pb = summ["recovery_time_s"], summ["max_lateral_after_m"], summ["peak_beta_error_rad"]
        st = summ["settle_time_s"]
        lines.append(f"| {controller} | {summ['runs']} | {summ['recovered']} | {summ['failed_runs']} | "
                     f"{summ['limit_violation_steps']} | {rt.get('p50', float('nan')):.2f}/"
                     f"{rt.get('p90', float('nan')):.2f}/"
                     f"{rt.get('p100', float('nan')):.2f} | {st.get('p50', float('nan')):.2f}/"
                     f"{st.get('p90', float('nan')):.2f}/{st.get('p100', float('nan')):.2f} | "
                     f"{100 * lat['p50']:.2f}/{100 * lat['p90']:.2f}/"
                     f"{100 * lat['p100']:.2f} | {math.degrees(pb['p50']):.0f}/{math.degrees(pb['p100']):.0f} |")
        print(f"kicks {controller}: {summ['recovered']}/{summ['runs']} recovered", flush=True)
    from jobs.glossary import KICK_GLOSSARY, glossary_lines

    return "\n".join(lines + [""] + glossary_lines(KICK_GLOSSARY, KICK_GLOSSARY, "### Columns of the kick study"))


def run(args: argparse.Namespace) -> int:
    try:
        controllers = (list(args.controllers) if isinstance(args.controllers, list)
                       else arg_controllers(args.controllers))
        tracks = list(args.tracks) if isinstance(args.tracks, list) else arg_tracks(args.tracks)
        if not (math.isfinite(args.speed_scale) and args.speed_scale > 0):
            raise ValueError(f"--speed-scale must be > 0, got {args.speed_scale}")
        scales = campaign.speed_scales_of(args)
        if getattr(args, "speed_scales", None) is not None:
            bad = [s for s in scales if not (isinstance(s, (int, float)) and math.isfinite(s) and 0 < s <= 10)]
            if bad or not scales or len(set(scales)) != len(scales):
                raise ValueError(f"--speed-scales must be distinct numbers in ]0, 10], got {args.speed_scales}")
        if args.kick_runs < 0:
            raise ValueError(f"--kick-runs must be >= 0, got {args.kick_runs}")
        names = getattr(args, "controller_names", None) or check_controllers(controllers, scales[0])
    except (ValueError, argparse.ArgumentTypeError) as exc:
        print(f"azimut eval: error: {exc}", file=sys.stderr)
        return 2
    args.controller_names = names
    out = Path(args.out)
    seeds = campaign.seeds_of(args)
    rc = campaign.run_eval_campaign(args, controllers, tracks, seeds)
    if rc in (0, 1) and args.kick_runs > 0:
        with open(out / "report.md", "a") as fh:
            fh.write("\n" + _kick_section(controllers, args.kick_runs, seeds[0], out, campaign.run_kwargs(args),
                                           names) + "\n")
    return rc
