"""``azimut sim-paper``: the paper's phenomenon in the simulator, measured and attributed.

Drives a track (default ``paper``) with the ICR reference controller at each speed scale, with
the robot (by default the envs' AZIMUT-3 with the ``"paper"`` imperfections) and with one
counterfactual per cause the paper names (compliance, friction, quantisation, geometric
imperfections, motor lag), and prints, while moving, the departure of the measured, true and
motor steering angles from the constraining surface (mean, p95 per wheel), the drop of the mean
departure without each cause, the share of configurations where IT beats NS by more than 0.1 point
of qua, qua, the spring deflection and the motor lag. ``--sweep stiffness|friction --values ...``
varies one steering parameter instead (``--d2``: and records D2 with each value, to show how the
estimators separate on it). The measures and the counterfactuals are defined in
:mod:`jobs.phenomenon`.
"""

from __future__ import annotations

import argparse
import json
import sys

from azimut_env.tracks import TRACK_NAMES
from control.episode import MOVING_MU
from control.feedforward import FeedForwardController  # re-exported
from jobs.args import add_robot_arguments, arg_float, arg_int, arg_output_path, robot_label, robot_params
from jobs.phenomenon import (
    COUNTERFACTUALS,
    DRIVERS,
    SWEEPS,
    attribute,
    departures_deg,
    qua_of_angles,
    run_phenomenon,
    stable_substeps,
    stiff_params,
    sweep,
)

__all__ = ["DRIVERS", "FeedForwardController", "stiff_params", "stable_substeps",
           "qua_of_angles", "departures_deg", "attribute", "run_phenomenon", "sweep", "table_markdown",
           "add_arguments", "check_args", "run"]

DEFAULT_SPEEDS = (0.5, 1.0, 1.4)


def _p95(v) -> str:
    return "/".join(f"{x:.2f}" for x in v)


_TABLE = (("speed_scale", "speed ×", "{:.2f}"), ("case", "case", "{}"), ("completed", "done", "{}"),
          ("standstill_share", "standstill", "{:.0%}"),
          ("departure_meas_mean_deg", "dep. β_meas mean [°]", "{:.3f}"),
          ("departure_meas_p95_deg", "p95 per wheel [°]", _p95),
          ("departure_true_mean_deg", "dep. true axes mean [°]", "{:.3f}"),
          ("departure_motor_mean_deg", "dep. θ_m mean [°]", "{:.3f}"),
          ("departure_drop_deg", "drop [°]", "{:+.3f}"), ("it_over_ns", "IT > NS+0.1", "{:.1%}"),
          ("qua_meas_mean", "qua β_meas mean", "{:.4f}"), ("qua_meas_min", "min", "{:.4f}"),
          ("deflection_rms_deg", "defl. RMS [°]", "{:.2f}"), ("motor_lag_rms_deg", "lag RMS [°]", "{:.2f}"),
          ("rms_lateral_m", "RMS lat [cm]", "{:.2f}"), ("mean_antagonism_N", "antagonism [N]", "{:.1f}"),
          ("mean_nullspace_force_N", "null-space force [N]", "{:.1f}"))
_SWEEP_TABLE = (("value", "value", "{:g}"),) + tuple(c for c in _TABLE if c[0] not in ("case", "departure_drop_deg"))
#: the columns ``--d2`` adds to the sweep: D2 recorded with each value (jobs.phenomenon.d2_separation)
_D2_TABLE = (("d2_departure_mean_deg", "D2 dep. mean [°]", "{:.3f}"), ("d2_it_over_ns", "D2 IT > NS+0.1", "{:.1%}"),
             ("d2_it_ge_ns", "D2 IT ≥ NS", "{:.2%}"), ("d2_ns_ge_ls", "D2 NS ≥ LS", "{:.1%}"),
             ("d2_ns_ls_worst", "worst NS − LS", "{:+.4f}"))


def table_markdown(rows: list[dict], columns=_TABLE) -> str:
    """The figures as a Markdown table (while moving; lateral error and force over the run)."""
    lines = ["| " + " | ".join(c[1] for c in columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    for row in rows:
        cells = []
        for key, _, fmt in columns:
            v = row.get(key)
            if key == "rms_lateral_m" and v is not None:
                v = 100 * v
            cells.append("-" if v is None else (fmt(v) if callable(fmt) else fmt.format(v)))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_phenomenon(logs: dict, geom, path: str) -> None:
    """Per speed: the mean measured departure over time of the robot and of each counterfactual
    (like Fig. 11, in degrees), with the robot's stopped and reconfiguring steps shaded (they are
    left out of the figures)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from control.episode import moving_mask

    speeds = sorted({k[0] for k in logs})
    fig, axes = plt.subplots(len(speeds), 1, figsize=(10, 2.6 * len(speeds)), squeeze=False)
    for ax, speed in zip(axes[:, 0], speeds):
        for (sp, case), log in logs.items():
            if sp != speed or not log.qua.size:
                continue
            if case == "robot":
                ax.fill_between(log.t, 0.0, 1.0, where=~moving_mask(log), color="0.88", step="mid", lw=0,
                                transform=ax.get_xaxis_transform(), label="not moving (excluded)")
            ax.plot(log.t, departures_deg(log.beta_meas, geom).mean(axis=1), lw=0.8 if case == "robot" else 0.6,
                    alpha=1.0 if case == "robot" else 0.7, label=case)
        ax.set_ylabel(f"departure [°], ×{speed:g}")
        ax.legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("t [s] (stops and reconfigurations included)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--driver", default="icr", choices=DRIVERS,
                        help="icr: the ICR reference controller (rate-aware; default); feedforward: the earlier "
                             "kinematic feed-forward (ignores the actuator limits)")
    parser.add_argument("--track", default="paper", choices=TRACK_NAMES, help="built-in track (default paper)")
    parser.add_argument("--speeds", type=arg_float(0.0, 3.0, lo_open=True), nargs="+", default=list(DEFAULT_SPEEDS),
                        help="speed scales of the track's profile (default 0.5 1 1.4)")
    parser.add_argument("--seed", type=arg_int(0), default=0)
    add_robot_arguments(parser, imperfections=True)
    parser.add_argument("--causes", nargs="+", default=list(COUNTERFACTUALS), metavar="CAUSE",
                        choices=[*COUNTERFACTUALS, "none"],
                        help=f"counterfactuals to run, among: {', '.join(COUNTERFACTUALS)} (default all; none: the "
                             "robot alone)")
    parser.add_argument("--sweep", choices=SWEEPS, default=None,
                        help="vary one steering parameter instead: stiffness k_s [N·m/rad] or friction τ_c [N·m] "
                             "(τ_s = 1.5 τ_c), over --values")
    parser.add_argument("--values", type=arg_float(0.0, 1e4), nargs="+", default=None,
                        help="the values of --sweep (stiffness > 0)")
    parser.add_argument("--d2", action="store_true",
                        help="with --sweep: also record D2 (azimut record-d2's run) with each value and report how it "
                             "separates the estimators (IT > NS + 0.1 point, IT ≥ NS, NS ≥ LS where they differ)")
    parser.add_argument("--stiffness-factor", type=arg_float(1.0, 1e4), default=100.0,
                        help="spring stiffness factor of the compliance counterfactual (default 100; damper ×sqrt)")
    parser.add_argument("--substeps", type=arg_int(1, 256), default=8, help="physics substeps of the robot's runs")
    parser.add_argument("--ideal-sensors", action="store_true", help="no sensor noise or quantisation")
    parser.add_argument("--json", type=arg_output_path(), default=None, help="write the figures as JSON here")
    parser.add_argument("--plot", type=arg_output_path(), default=None, help="write a PNG plot here (needs matplotlib)")


def _robot(args: argparse.Namespace):
    """The robot of ``--robot``/``--robot-file`` with ``--imperfections`` (the envs' rule)."""
    return robot_params(args)


def check_args(args: argparse.Namespace) -> None:
    from azimut_env.physics.stability import check_substeps

    check_substeps(args.substeps, _robot(args))  # the robot's physics, before any episode
    if (args.sweep is None) != (args.values is None):
        raise ValueError("--sweep and --values go together")
    if args.sweep == "stiffness" and min(args.values) <= 0:
        raise ValueError("--values of --sweep stiffness must be > 0 [N·m/rad]")
    if args.d2 and not args.sweep:
        raise ValueError("--d2 goes with --sweep")
    if args.sweep and args.driver != "icr":
        raise ValueError("--sweep drives the ICR controller (--driver icr)")
    if "none" in args.causes and len(args.causes) > 1:
        raise ValueError("--causes none runs the robot alone: give it alone")
    if args.plot:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            raise ValueError("--plot needs matplotlib (pip install -e '.[plot]')") from None


def _write_json(path: str, payload: dict) -> None:
    with open(path, "w") as fh:
        json.dump(payload, fh, indent=2, allow_nan=True)
    print(f"figures written to {path}")


def run(args: argparse.Namespace) -> int:
    params = _robot(args)
    head = f"on {args.track}, robot {robot_label(args)}, seed {args.seed}; while moving (controller RUNNING, " \
           f"true |μ| > {MOVING_MU} m/s)"
    if args.sweep:
        rows = sweep(args.sweep, args.values, args.speeds, args.track, seed=args.seed, params=params,
                     substeps=args.substeps, d2=args.d2)
        print(f"icr {head}; sweep of {args.sweep}" + ("; D2 recorded with each value" if args.d2 else ""))
        print(table_markdown(rows, _SWEEP_TABLE + (_D2_TABLE if args.d2 else ())), end="")
        if args.json:
            _write_json(args.json, {"track": args.track, "seed": args.seed, "sweep": args.sweep, "rows": rows})
    else:
        causes = () if args.causes == ["none"] else tuple(dict.fromkeys(args.causes))
        res = run_phenomenon(args.driver, args.track, args.speeds, seed=args.seed,
                             stiffness_factor=args.stiffness_factor, sensors="ideal" if args.ideal_sensors else None,
                             substeps=args.substeps, keep_logs=bool(args.plot), params=params, causes=causes)
        rows = res["rows"]
        subs = ", ".join(f"{k} {v}" for k, v in res["substeps"].items())
        print(f"{args.driver} {head}; substeps: {subs}")
        print(table_markdown(rows), end="")
        if args.json:
            _write_json(args.json, {"driver": args.driver, "track": args.track, "seed": args.seed,
                                    "moving_mu": MOVING_MU, "substeps": res["substeps"], "rows": rows})
        if args.plot:
            plot_phenomenon(res["logs"], params.geometry, args.plot)
            print(f"plot written to {args.plot}")
    failed = [r for r in rows if r["error"] is not None]
    for r in failed:
        print(f"speed ×{r['speed_scale']:g} {r.get('case', r.get('value'))}: {r['error']}", file=sys.stderr)
    return 0 if not failed else 1
