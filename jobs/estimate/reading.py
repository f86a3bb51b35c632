"""The flags that say how to read a robot log, shared by the commands that read one (``azimut
estimate``, ``azimut calibrate``): the log, the robot, the format and each format's own flags.

:func:`add_reading_arguments` adds them to a parser; :func:`open_source` opens the log they name
(every check that needs no sample), raising ``ValueError`` (one line) for a flag that does not fit
or a log that cannot be used (:class:`~estimation.logs.LogError` is a ``ValueError``).
"""

from __future__ import annotations

import argparse
import sys
import time

from jobs.args import add_robot_arguments, robot_description

__all__ = ["LogProgress", "run_on_log", "add_reading_arguments", "open_source", "robot_geometry", "reader_options",
           "ROS_OPTIONS", "WPILOG_OPTIONS", "WPILOG_MODULE_OPTIONS"]

#: flags that only a ROS 2 bag takes (dest -> flag), and only a .wpilog; of those, the ones of
#: per-module entries (--steer-entry, --wheel-entry) only, and the one of state arrays only
ROS_OPTIONS = {"topic": "--topic", "steer_joint": "--steer-joint", "drive_joint": "--drive-joint",
               "truth_topic": "--truth-topic", "time": "--time", "yaw_topic": "--yaw-topic", "max_age_s": "--max-age"}
WPILOG_OPTIONS = {"states_entry": "--states-entry", "truth_entry": "--truth-entry", "angle_unit": "--angle-unit",
                  "steer_entry": "--steer-entry", "wheel_entry": "--wheel-entry", "wheel_scale": "--wheel-scale",
                  "max_age_s": "--max-age", "yaw_entry": "--yaw-entry", "yaw_unit": "--yaw-unit"}
WPILOG_MODULE_OPTIONS = ("steer_entry", "wheel_entry", "wheel_scale", "max_age_s")


def _finite(what: str, positive: bool):
    def convert(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if x != x or x in (float("inf"), float("-inf")):
            raise argparse.ArgumentTypeError(f"{what} must be finite, got {text}")
        if positive and x <= 0:
            raise argparse.ArgumentTypeError(f"{what} must be > 0, got {text}")
        if not positive and x == 0:
            raise argparse.ArgumentTypeError(f"{what} must not be 0, got {text}")
        return x
    convert.__name__ = what
    return convert


def _module_names(text: str) -> list[str]:
    names = [s.strip() for s in text.split(",")]
    if not all(names):
        raise argparse.ArgumentTypeError(f"empty module name in {text!r}")
    return names


def add_reading_arguments(parser: argparse.ArgumentParser) -> None:
    """LOG, --robot/--robot-file, --module-names, --format, --steer-convention, the ROS 2 bag flags,
    the WPILib data log flags and --threads (the estimators' blocks of samples)."""
    from estimation.logs import FORMATS, STEER_CONVENTIONS
    from jobs.args import add_threads_argument

    add_threads_argument(parser, "the estimators (blocks of samples)")
    from estimation.logs.ros import TIME_SOURCES
    from estimation.logs.wpilog import ANGLE_UNITS, YAW_UNITS

    parser.add_argument("log", metavar="LOG", help="the log: a .csv file, a .wpilog, a ROS 2 bag directory or a bare "
                                                   ".mcap / .db3 file")
    add_robot_arguments(parser)  # --robot NAME / --robot-file PATH: the geometry and the module names
    parser.add_argument("--module-names", type=_module_names, default=None, metavar="A,B,...",
                        help="the modules' names in the robot's order, in place of the robot file's (the CSV columns' "
                             "<module>, the ROS joints' and the wpilog entries' {module})")
    parser.add_argument("--format", choices=FORMATS, default=None, help="the log's format (default: from its "
                                                                         "content, then its suffix)")
    parser.add_argument("--steer-convention", choices=STEER_CONVENTIONS, default=None,
                        help="CSV, ROS and wpilog per-module entries: the steering angles are the paper's β (beta; "
                             "the default for CSV and ROS) or the module's rolling direction from the chassis x axis "
                             "(heading: WPILib's convention, the default for wpilog entries; a URDF steering joint "
                             "whose zero points the wheel forward); wpilog state arrays are always headings")
    ros = parser.add_argument_group("ROS 2 bags")
    ros.add_argument("--topic", action="append", default=None,
                     help="the JointState topic (default /joint_states); given more than once, joint groups "
                          "published on several topics")
    ros.add_argument("--steer-joint", default=None, metavar="TEMPLATE",
                     help="a module's steering joint name, {module} standing for the module's name in the robot "
                          "file (default '{module}_steer')")
    ros.add_argument("--drive-joint", default=None, metavar="TEMPLATE",
                     help="a module's drive (wheel) joint name (default '{module}_drive')")
    ros.add_argument("--truth-topic", default=None, help="a reference pose: nav_msgs/Odometry, geometry_msgs/"
                                                         "PoseStamped or PoseWithCovarianceStamped topic")
    ros.add_argument("--time", choices=TIME_SOURCES, default=None,
                     help="a message's time: its header stamp (header, the default) or when the bag logged it (log)")
    ros.add_argument("--yaw-topic", default=None, metavar="TOPIC",
                     help="the gyro heading: a sensor_msgs/Imu topic or a pose topic (its orientation's yaw)")
    parser.add_argument("--max-age", dest="max_age_s", type=_finite("--max-age", positive=True), default=None,
                        metavar="SECONDS", help="signals logged apart (wpilog per-module entries, ROS joint groups in "
                                                "separate messages) are held onto one clock: a sample where some "
                                                "value is older than this is skipped as stale (default 0.5)")
    wpi = parser.add_argument_group("WPILib data logs")
    wpi.add_argument("--states-entry", default=None, metavar="NAME",
                     help="the module-states entry (default: the one struct:SwerveModuleState[] entry, or the "
                          "one whose name ends with Measured)")
    wpi.add_argument("--steer-entry", default=None, metavar="PATTERN",
                     help="per-module entries instead of a state array: each module's steering angle entry, {i} "
                          "standing for its index from 0 and {module} for its name (a number or struct:Rotation2d; "
                          "e.g. 'NT:/SmartDashboard/Mod {i} Cancoder'); needs --wheel-entry")
    wpi.add_argument("--wheel-entry", default=None, metavar="PATTERN",
                     help="each module's wheel speed entry (a number; e.g. '/Drive/Module{i}/DriveVelocityRadPerSec'"
                          "); needs --steer-entry")
    wpi.add_argument("--angle-unit", choices=ANGLE_UNITS, default=None,
                     help="the unit of steering angles logged as numbers: a double[] module-state entry's or "
                          "--steer-entry's")
    wpi.add_argument("--wheel-scale", type=_finite("--wheel-scale", positive=False), default=None, metavar="X",
                     help="--wheel-entry values times X are the wheel's speed in m/s (default 1: m/s; the wheel "
                          "radius for rad/s; negative for an inverted motor)")
    wpi.add_argument("--truth-entry", default=None, metavar="NAME", help="a reference pose: a struct:Pose2d or "
                                                                         "double[3] entry")
    wpi.add_argument("--yaw-entry", default=None, metavar="NAME",
                     help="the gyro heading: a number (with --yaw-unit), a struct:Rotation2d, a struct:Pose2d or a "
                          "double[3] pose")
    wpi.add_argument("--yaw-unit", choices=YAW_UNITS, default=None, help="the unit of a --yaw-entry number")


def robot_geometry(args: argparse.Namespace):
    """The geometry and module names of ``--robot-file`` or ``--robot`` (default: the azimut3 preset),
    the names replaced by ``--module-names`` when given."""
    from estimation.logs.source import check_module_names

    robot = robot_description(args)
    geom = robot.geometry
    names = getattr(args, "module_names", None)
    if names is not None:
        try:
            return geom, check_module_names(names, geom)
        except ValueError as exc:
            raise ValueError(f"argument --module-names: {exc}") from None
    return geom, robot.module_names


def reader_options(args: argparse.Namespace, fmt: str) -> dict:
    """The reader's options from the flags; a flag of another format, or of the other wpilog layout,
    is refused."""
    own = {"ros": ROS_OPTIONS, "wpilog": WPILOG_OPTIONS, "csv": {}}[fmt]
    for dest, flag in {**ROS_OPTIONS, **WPILOG_OPTIONS}.items():
        if getattr(args, dest, None) is not None and dest not in own:
            raise ValueError(f"argument {flag}: does not apply to a {fmt} log")
    options = {dest: getattr(args, dest) for dest in own if getattr(args, dest, None) is not None}
    modules = fmt == "wpilog" and ("steer_entry" in options or "wheel_entry" in options)
    if modules:
        for dest in ("steer_entry", "wheel_entry"):
            if dest not in options:
                other = "--wheel-entry" if dest == "steer_entry" else "--steer-entry"
                raise ValueError(f"argument {other}: needs {WPILOG_OPTIONS[dest]} too (per-module entries)")
        if "states_entry" in options:
            raise ValueError("argument --states-entry: does not apply with per-module entries (--steer-entry, "
                             "--wheel-entry)")
    elif fmt == "wpilog":
        for dest in WPILOG_MODULE_OPTIONS:
            if dest in options:
                raise ValueError(f"argument {WPILOG_OPTIONS[dest]}: applies to per-module entries only (--steer-entry"
                                 ", --wheel-entry)")
    if "yaw_unit" in options and "yaw_entry" not in options:
        raise ValueError("argument --yaw-unit: needs --yaw-entry")
    if getattr(args, "steer_convention", None) is not None:
        if fmt == "wpilog" and not modules:
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


def open_source(args: argparse.Namespace):
    """The :class:`~estimation.logs.LogSource` the reading flags name (every check that needs no
    sample: format, topics, entries, columns, joint names, the flags against the format).
    ``ValueError`` with a one-line message when a flag does not fit or the log cannot be used."""
    from estimation.logs import detect_format, open_log

    geom, modules = robot_geometry(args)
    fmt = args.format or detect_format(args.log)
    options = reader_options(args, fmt)
    if fmt == "ros":
        _check_recorded_robot(args, geom)
    return open_log(args.log, geom, modules, fmt=fmt, **options)


class LogProgress:
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


def run_on_log(command: str, args: argparse.Namespace, check_args, work, errors=(ValueError,)):
    """The start of a command that reads a log: ``check_args(args)`` unless the CLI ran it (it opens
    ``args.source``), then ``work(source, progress)`` with a progress bar on a terminal. Returns
    (its result, seconds), or 2 after one line ``azimut COMMAND: error: ...`` on stderr when a check
    or the work raises one of ``errors`` (a log found unusable while read, or a fit refused)."""
    if getattr(args, "source", None) is None:
        try:
            check_args(args)
        except ValueError as exc:
            print(f"azimut {command}: error: {exc}", file=sys.stderr)
            return 2
    from estimation.threads import set_default_threads

    set_default_threads(getattr(args, "threads", None))  # None: the cores this process may use
    progress = LogProgress(command)
    t0 = time.perf_counter()
    try:
        result = work(args.source, progress)
    except errors as exc:
        progress.close()
        print(f"azimut {command}: error: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    progress.close()
    return result, time.perf_counter() - t0
