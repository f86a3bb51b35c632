"""``azimut calibrate LOG --out DIR``: each module's steering offset and wheel-speed factor fitted
to a log of ordinary driving (:mod:`estimation.calibration`), with the figures before and after.

Reads the log as ``azimut estimate`` does (the same reading flags: :mod:`jobs.estimate.reading`),
keeps the samples where the robot moves, fits, and writes to DIR:

* ``calibration.json``: per module ``steer_offset_deg`` (what to **add** to the logged angle) and
  ``wheel_scale`` (the factor to apply to the logged wheel speed), their uncertainties, what the log
  could and could not tell, and the figures before and after; ``azimut estimate ... --calibration
  DIR/calibration.json`` applies it;
* ``report.md``: the same for a reader, with the offsets in the forms robot code takes them.

A log that cannot be read, or has too few moving samples, is refused with one line and exit
status 2 before anything is written.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from jobs.args import arg_output_path

__all__ = ["add_arguments", "check_args", "run"]


def _degrees_list(text: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers of degrees, got {text!r}") from None
    if not all(math.isfinite(v) and abs(v) <= 720.0 for v in values):
        raise argparse.ArgumentTypeError(f"offsets must be finite degrees within ±720, got {text!r}")
    return values


def _speed(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a speed in m/s, got {text!r}") from None
    if not (math.isfinite(v) and 0.0 < v <= 5.0):
        raise argparse.ArgumentTypeError(f"must be in ]0, 5] m/s, got {text!r}")
    return v


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from estimation.calibration import MOVING_SPEED
    from jobs.estimate.reading import add_reading_arguments

    add_reading_arguments(parser)
    parser.add_argument("--out", required=True, type=arg_output_path(directory=True), help="report folder")
    parser.add_argument("--current-offsets", type=_degrees_list, default=None, metavar="DEG,...",
                        help="the offsets the robot's code applies now, as degrees to ADD to the logged angle, one "
                             "per module in the robot file's order (code that subtracts an angleOffset: its "
                             "negatives; write --current-offsets=-12,... when the first is negative); the report "
                             "compares them with the fit")
    parser.add_argument("--moving-speed", type=_speed, default=MOVING_SPEED, metavar="M_PER_S",
                        help=f"a sample is moving when the wheels' rigid fit moves a steering axis at least this fast "
                             f"(default {MOVING_SPEED})")


def check_args(args: argparse.Namespace) -> None:
    from jobs.estimate.reading import open_source

    args.source = open_source(args)
    cur = args.current_offsets
    if cur is not None and len(cur) != args.source.geom.n:
        raise ValueError(f"argument --current-offsets: {len(cur)} values for a robot of {args.source.geom.n} modules "
                         f"({', '.join(args.source.modules)})")


def run(args: argparse.Namespace) -> int:
    from estimation.logs.calibrate import calibrate_source
    from jobs.calibrate.report import write_outputs
    from jobs.estimate.reading import run_on_log

    done = run_on_log("calibrate", args, check_args, lambda source, progress: calibrate_source(
        source, moving_speed=args.moving_speed, current_offsets_deg=args.current_offsets, progress=progress))
    if isinstance(done, int):
        return done
    result, elapsed = done
    out = Path(args.out)
    files = write_outputs(result, args.source, out, elapsed_s=elapsed)
    before, after = result["before"]["qua_IT_mean"], result["after"]["qua_IT_mean"]
    print(f"calibrated {len(args.source.modules)} modules on {result['samples']['moving']} moving samples of "
          f"{result['samples']['read']} in {elapsed:.1f} s: IT's qua while moving {100 * before:.2f}% as logged, "
          f"{100 * after:.2f}% calibrated; wrote {', '.join(files)} to {out}")
    return 0
