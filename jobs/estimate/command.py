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

``docs/logs.md`` gives each format's layout and an example; the reading flags are
:mod:`jobs.estimate.reading`'s, shared with ``azimut calibrate``. A log that cannot be used (missing
topic, entry or column, joint names not matching the robot, unsorted or duplicated timestamps, a
truncated file) is refused with one line and exit status 2, before any output is written.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from jobs.args import arg_choice_list, arg_int, arg_output_path, require_module
from jobs.estimate.reading import ROS_OPTIONS, WPILOG_OPTIONS, add_reading_arguments, open_source, robot_geometry

__all__ = ["add_arguments", "check_args", "run", "robot_geometry", "ROS_OPTIONS", "WPILOG_OPTIONS"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from estimation.estimate import METHODS
    from estimation.logs import DEFAULT_METHODS

    add_reading_arguments(parser)  # LOG, the robot, --format, --steer-convention, the ROS and wpilog flags
    parser.add_argument("--out", required=True, type=arg_output_path(directory=True), help="report folder")
    parser.add_argument("--methods", type=arg_choice_list(METHODS), default=list(DEFAULT_METHODS),
                        help=f"estimators among {','.join(METHODS)} (default {','.join(DEFAULT_METHODS)}; ORACLE, "
                             "the exhaustive yardstick, costs about 100× IT)")
    parser.add_argument("--odometry-method", choices=METHODS, default=None,
                        help="the estimator whose λ̂ the dead reckoning uses (default: the first of --methods)")
    parser.add_argument("--chunk", type=arg_int(1, 10_000_000), default=50_000,
                        help="samples estimated at a time (memory; results do not depend on it)")
    parser.add_argument("--csv", action="store_true", help="also write samples.csv (slower and larger than .npz)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--calibration", default=None, metavar="FILE",
                        help="a calibration.json of azimut calibrate (for this robot): its steering offsets are added "
                             "to the logged angles and its wheel factors applied to the wheel speeds")


def check_args(args: argparse.Namespace) -> None:
    """Open the log (every check that needs no sample: format, topics, entries, columns, joint
    names; :func:`jobs.estimate.reading.open_source`) and keep it on ``args`` for :func:`run`; refuse
    flags that do not fit."""
    if not args.no_plots:
        require_module("matplotlib", "writing plots (pass --no-plots to skip them)")
    odo = args.odometry_method
    if odo is not None and odo not in args.methods:
        raise ValueError(f"argument --odometry-method: {odo} is not among --methods {','.join(args.methods)}")
    args.source = open_source(args)
    if args.calibration is not None:
        from estimation.logs.calibrated import CalibratedLog, read_calibration

        offset, scale = read_calibration(args.calibration, args.source.geom, args.source.modules)
        args.source = CalibratedLog(args.source, offset, scale, label=str(args.calibration))


def run(args: argparse.Namespace) -> int:
    from estimation.logs import LogError, estimate_log
    from jobs.estimate.reading import run_on_log
    from jobs.estimate.report import write_outputs

    done = run_on_log("estimate", args, check_args, lambda source, progress: estimate_log(
        source, args.methods, odometry_method=args.odometry_method, chunk_size=args.chunk, progress=progress),
        errors=(LogError,))
    if isinstance(done, int):
        return done
    result, elapsed = done
    source = args.source
    out = Path(args.out)
    files = write_outputs(result, source, out, elapsed_s=elapsed, plots=not args.no_plots, csv=args.csv)
    skipped = sum(result.skipped.values())
    print(f"estimated {result.t_ns.size} samples of {result.n_read} ({skipped} skipped) in {elapsed:.1f} s; "
          f"wrote {', '.join(files)} to {out}")
    return 0
