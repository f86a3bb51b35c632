"""``azimut estimate LOG --out DIR``: the ICR, the H state and odometry from a robot's recorded log.

Reads steering angles and wheel speeds over time from a CSV file, a ROS 2 bag (MCAP or SQLite3,
``sensor_msgs/msg/JointState``) or a WPILib ``.wpilog`` (swerve module states), runs every
estimator on every sample (:func:`estimation.logs.estimate_log`), and writes to DIR:

* ``samples.npz`` (and ``samples.csv`` with ``--csv``): per good sample its time, β and φ̇, and
  per estimator λ̂, μ̂, the twist μ̂ (v, −u, w) and qua; the dead-reckoned pose and its twist;
* ``report.md`` and ``summary.json``: the estimators compared on this log as ``azimut
  bench-estimators`` compares them on D2, the skipped samples by reason, and the odometry
  against the log's reference pose (drift per metre travelled) where it has one;
* ``steer_space.png`` (the paper's Fig. 10), ``qua_time.png`` (Fig. 11), ``odometry.png``.

``docs/logs.md`` gives each format's layout and an example. A log that cannot be used (missing
topic, entry or column, joint names not matching the robot, unsorted or duplicated timestamps, a
truncated file) is refused with one line and exit status 2, before any output is written.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from jobs.args import add_robot_arguments, arg_choice_list, arg_int, arg_output_path, require_module

__all__ = ["add_arguments", "check_args", "run", "robot_geometry", "ROS_OPTIONS", "WPILOG_OPTIONS"]

#: flags that only a ROS 2 bag takes (dest -> flag), and only a .wpilog
ROS_OPTIONS = {"topic": "--topic", "steer_joint": "--steer-joint", "drive_joint": "--drive-joint",
               "truth_topic": "--truth-topic", "time": "--time"}
WPILOG_OPTIONS = {"states_entry": "--states-entry", "truth_entry": "--truth-entry", "angle_unit": "--angle-unit"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from estimation.estimate import METHODS
    from estimation.logs import DEFAULT_METHODS, FORMATS, STEER_CONVENTIONS
    from estimation.logs.ros import TIME_SOURCES
    from estimation.logs.wpilog import ANGLE_UNITS

    parser.add_argument("log", metavar="LOG", help="the log: a .csv file, a .wpilog, a ROS 2 bag directory or a bare "
                                                   ".mcap / .db3 file")
    parser.add_argument("--out", required=True, type=arg_output_path(directory=True), help="report folder")
    add_robot_arguments(parser)  # --robot NAME / --robot-file PATH: the geometry and the module names
    parser.add_argument("--format", choices=FORMATS, default=None, help="the log's format (default: from its "
                                                                         "content, then its suffix)")
    parser.add_argument("--methods", type=arg_choice_list(METHODS), default=list(DEFAULT_METHODS),
                        help=f"estimators among {','.join(METHODS)} (default {','.join(DEFAULT_METHODS)}; ORACLE, "
                             "the exhaustive yardstick, costs about 100× IT)")
    parser.add_argument("--odometry-method", choices=METHODS, default=None,
                        help="the estimator whose λ̂ the dead reckoning uses (default: the first of --methods)")
    parser.add_argument("--steer-convention", choices=STEER_CONVENTIONS, default=None,
                        help="CSV and ROS: the steering angles are the paper's β (beta, the default) or the "
                             "module's rolling direction from the chassis x axis (heading: WPILib's convention, "
                             "a URDF steering joint whose zero points the wheel forward); .wpilog is always heading")
    ros = parser.add_argument_group("ROS 2 bags")
    ros.add_argument("--topic", default=None, help="the JointState topic (default /joint_states)")
    ros.add_argument("--steer-joint", default=None, metavar="TEMPLATE",
                     help="a module's steering joint name, {module} standing for the module's name in the robot "
                          "file (default '{module}_steer')")
    ros.add_argument("--drive-joint", default=None, metavar="TEMPLATE",
                     help="a module's drive (wheel) joint name (default '{module}_drive')")
    ros.add_argument("--truth-topic", default=None, help="a reference pose: nav_msgs/Odometry, geometry_msgs/"
                                                         "PoseStamped or PoseWithCovarianceStamped topic")
    ros.add_argument("--time", choices=TIME_SOURCES, default=None,
                     help="a message's time: its header stamp (header, the default) or when the bag logged it (log)")
    wpi = parser.add_argument_group("WPILib data logs")
    wpi.add_argument("--states-entry", default=None, metavar="NAME",
                     help="the module-states entry (default: the one struct:SwerveModuleState[] entry, or the "
                          "one whose name ends with Measured)")
    wpi.add_argument("--truth-entry", default=None, metavar="NAME", help="a reference pose: a struct:Pose2d or "
                                                                         "double[3] entry")
    wpi.add_argument("--angle-unit", choices=ANGLE_UNITS, default=None,
                     help="the angle unit of a double[] module-state entry ([angle, speed] pairs)")
    parser.add_argument("--chunk", type=arg_int(1, 10_000_000), default=50_000,
                        help="samples estimated at a time (memory; results do not depend on it)")
    parser.add_argument("--csv", action="store_true", help="also write samples.csv (slower and larger than .npz)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")


def robot_geometry(args: argparse.Namespace):
    """The geometry and module names of ``--robot-file`` or ``--robot`` (default: the azimut3 preset)."""
    from azimut_env.robot_file import DEFAULT_PRESET, preset_source
    from estimation.geometry import RobotGeometry
    from estimation.robot_file import module_names, parse_robot_text, read_robot_file

    if getattr(args, "robot_file", None):
        data = read_robot_file(args.robot_file)
    else:
        name = getattr(args, "robot", None) or DEFAULT_PRESET
        data = parse_robot_text(preset_source(name), f"preset {name!r}")
    return RobotGeometry.from_description(data), module_names(data)


def _reader_options(args: argparse.Namespace, fmt: str) -> dict:
    """The reader's options from the flags; a flag of another format is refused."""
    own = {"ros": ROS_OPTIONS, "wpilog": WPILOG_OPTIONS, "csv": {}}[fmt]
    for dest, flag in {**ROS_OPTIONS, **WPILOG_OPTIONS}.items():
        if getattr(args, dest) is not None and dest not in own:
            raise ValueError(f"argument {flag}: does not apply to a {fmt} log")
    options = {dest: getattr(args, dest) for dest in own if getattr(args, dest) is not None}
    if args.steer_convention is not None:
        if fmt == "wpilog":
            raise ValueError("argument --steer-convention: a .wpilog's module states are always headings")
        options["steer_convention"] = args.steer_convention
    return options


def _check_recorded_robot(args: argparse.Namespace, geom) -> None:
    """``ValueError`` (one line) when a bag of ``azimut eval --export`` records another robot than
    the one given (``--robot``/``--robot-file``, default azimut3): its steering angles read with
    another geometry give a wrong ICR and odometry without a word."""
    import numpy as np

    from control.export import geometry_record
    from estimation.logs.ros import recorded_robot

    rec = recorded_robot(args.log)
    if rec is None:
        return
    robot, recorded = rec
    given = geometry_record(geom)
    same = recorded.get("n") == given["n"] and all(
        np.allclose(np.asarray(recorded.get(k, []), float), given[k], rtol=0.0, atol=1e-12)
        for k in ("alpha", "l", "b"))
    if not same:
        flag = f"--robot-file {robot}" if robot.endswith(".toml") else f"--robot {robot}"
        raise ValueError(f"{args.log}: exported from the robot {robot} (its metadata.yaml), whose geometry is not "
                         f"the one given; pass {flag}")


def check_args(args: argparse.Namespace) -> None:
    """Open the log (every check that needs no sample: format, topics, entries, columns, joint
    names) and keep it on ``args`` for :func:`run`; refuse flags that do not fit."""
    from estimation.logs import detect_format, open_log

    if not args.no_plots:
        require_module("matplotlib", "writing plots (pass --no-plots to skip them)")
    odo = args.odometry_method
    if odo is not None and odo not in args.methods:
        raise ValueError(f"argument --odometry-method: {odo} is not among --methods {','.join(args.methods)}")
    geom, modules = robot_geometry(args)
    fmt = args.format or detect_format(args.log)
    options = _reader_options(args, fmt)
    if fmt == "ros":
        _check_recorded_robot(args, geom)
    args.source = open_log(args.log, geom, modules, fmt=fmt, **options)


class _Progress:
    """A progress line on a terminal: tqdm's bar when installed, else ``control.episode.progress_bar``."""

    def __init__(self, label: str) -> None:
        self.label, self.start, self.bar, self.tqdm = label, time.time(), None, None
        if sys.stderr.isatty():
            try:
                from tqdm import tqdm
            except ImportError:
                tqdm = None
            self.tqdm = tqdm

    def __call__(self, done: int, total: int | None) -> None:
        if not sys.stderr.isatty():
            return
        if self.tqdm is not None:
            if self.bar is None:
                self.bar = self.tqdm(total=total, desc=self.label, unit="sample", file=sys.stderr)
            self.bar.update(done - self.bar.n)
            return
        from control.episode import progress_bar

        progress_bar(self.label, min(1.0, done / total) if total else 0.0, self.start)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        elif sys.stderr.isatty():
            sys.stderr.write("\n")


def run(args: argparse.Namespace) -> int:
    from estimation.logs import LogError, estimate_log
    from jobs.estimate.report import write_outputs

    if getattr(args, "source", None) is None:
        try:
            check_args(args)
        except ValueError as exc:
            print(f"azimut estimate: error: {exc}", file=sys.stderr)
            return 2
    source = args.source
    progress = _Progress("estimate")
    t0 = time.perf_counter()
    try:
        result = estimate_log(source, args.methods, odometry_method=args.odometry_method, chunk_size=args.chunk,
                              progress=progress)
    except LogError as exc:
        progress.close()
        print(f"azimut estimate: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    progress.close()
    elapsed = time.perf_counter() - t0
    out = Path(args.out)
    files = write_outputs(result, source, out, elapsed_s=elapsed, plots=not args.no_plots, csv=args.csv)
    skipped = sum(result.skipped.values())
    print(f"estimated {result.t_ns.size} samples of {result.n_read} ({skipped} skipped) in {elapsed:.1f} s; "
          f"wrote {', '.join(files)} to {out}")
    return 0
