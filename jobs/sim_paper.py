"""``azimut sim-paper``: the paper's phenomenon in the simulator, measured and attributed.

The paper (§4, Fig. 10–11) observes that the *measured* steering configuration of AZIMUT-3 leaves
the constraining surface S (the configurations whose propulsion axes concur, eq. 16–17) while it
moves, and measures how far with qua (eq. 28–29). In the simulator two things can put the wheels
off S even when every command is on it:

* **motor lag**: the steering motors are position-controlled with rate, acceleration and torque
  limits, so the motor angles θ_m trail the commands β_c; the four motors do not trail by amounts
  that keep the axes concurrent;
* **compliance**: the series-elastic steering (spring k_s, damper c_s between motor and module)
  lets tire forces and moments deflect the module, β = θ_m + δ.

This module drives a track with a rate-aware controller (default: the ICR reference controller of
:mod:`control.icr.controller`, whose commands are on S and within the actuator limits by
construction) and reports, **while moving** (:func:`control.episode.moving_mask`: controller
RUNNING and the true |μ| > 0.05 m/s; stops and in-place reconfigurations are left out):

* ``qua(β_meas)``: qua of the measured steering angles (what the robot's sensors see; noise and
  quantisation included), each against S(λ̂) of its own IT estimate;
* ``qua(β)``: the same on the true angles (the physics alone);
* ``qua(θ_m)``: the same on the motor angles: the **motor-lag part** (what the actuators alone do);
* the **compliance part**: the spring deflection δ = β − θ_m (RMS and max, degrees) and the
  drop of qua from θ_m to β;
* the same run with a **stiff steering counterfactual** (spring ×``stiffness_factor``, damper
  ×sqrt(``stiffness_factor``) so the damping ratio stays the same), with as many physics substeps
  as the physics' stability check asks for (the compliant run uses the default substeps; the
  substep counts are printed).

``--driver feedforward`` keeps the earlier kinematic feed-forward (β and φ̇ from the track's
reference twist, eq. 16–17, with proportional pose correction), which ignores the actuator
limits: it commands steering jumps of up to 179° and flips across the stops, so its qua is mostly
motor lag. It reproduces the earlier ``sim-paper`` figures.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace

import numpy as np

from azimut_env.params import RobotParams
from azimut_env.physics.stability import check_stability
from azimut_env.tracks import TRACK_NAMES
from control.controller import make_controller
from control.episode import MOVING_MU, EpisodeLog, moving_mask
from control.feedforward import FeedForwardController  # re-exported
from control.rollout import run_episode
from estimation import estimate_icr, quality, steering_from_lambda
from jobs.args import add_robot_arguments, arg_float, arg_int, arg_output_path, robot_label, robot_params

__all__ = ["DRIVERS", "FeedForwardController", "stiff_params", "stable_substeps",
           "qua_of_angles", "attribute", "run_phenomenon", "add_arguments", "check_args", "run"]

DRIVERS = ("icr", "feedforward")
DEFAULT_SPEEDS = (0.5, 1.0, 1.4)


# ---------------------------------------------------------------------- the stiff counterfactual


def stiff_params(params: RobotParams | None = None, factor: float = 100.0) -> RobotParams:
    """``params`` with the steering spring ×``factor`` and the damper ×sqrt(``factor``) (the same
    damping ratio c_s / (2 sqrt(k_s I_mod)))."""
    if not (math.isfinite(factor) and factor >= 1.0):
        raise ValueError(f"stiffness factor must be finite and >= 1, got {factor!r}")
    p = params if params is not None else RobotParams()
    st = p.steering
    return replace(p, steering=replace(st, stiffness=st.stiffness * factor, damping=st.damping * math.sqrt(factor)))


def stable_substeps(params: RobotParams, control_period: float = 0.02, start: int = 8, most: int = 256) -> int:
    """The smallest substep count (``start`` doubled) that the physics' stability check accepts
    for ``params``; ``ValueError`` if none up to ``most``."""
    k = start
    while k <= most:
        try:
            check_stability(params, control_period / k)
            return k
        except ValueError:
            k *= 2
    raise ValueError(f"no substep count up to {most} is stable for these steering parameters")


# ---------------------------------------------------------------------- attribution


def qua_of_angles(q: np.ndarray, geom) -> np.ndarray:
    """qua (T,) of steering configurations q (T, n) [rad] against S(λ̂) of their own IT estimate
    (eq. 28–29), as the env computes it for the measured angles."""
    q = geom.wrap_steering(np.asarray(q, dtype=np.float64))
    if q.shape[0] == 0:
        return np.zeros(0)
    lam = estimate_icr(q, geom)
    return np.asarray(quality(steering_from_lambda(lam, geom, singular_fill=q), q), dtype=np.float64)


def _stats(x: np.ndarray) -> tuple[float, float]:
    return (float(np.mean(x)), float(np.min(x))) if x.size else (float("nan"), float("nan"))


def attribute(log: EpisodeLog, geom, min_mu: float = MOVING_MU) -> dict:
    """The phenomenon's figures of one run over its moving steps (see the module docstring)."""
    moving = moving_mask(log, min_mu)
    out: dict = {"steps": int(log.qua.size), "moving_steps": int(moving.sum()),
                 "standstill_share": float(1.0 - moving.mean()) if log.qua.size else float("nan"),
                 "completed": bool(log.completed), "error": log.error}
    q_meas = log.qua[moving]
    q_true = qua_of_angles(log.beta_true[moving], geom) if moving.any() else np.zeros(0)
    q_motor = qua_of_angles(log.motor_true[moving], geom) if moving.any() else np.zeros(0)
    for name, q in (("qua_meas", q_meas), ("qua_true", q_true), ("qua_motor", q_motor)):
        out[f"{name}_mean"], out[f"{name}_min"] = _stats(q)
    defl = (log.beta_true - log.motor_true)[moving]
    lag = (log.motor_true - log.beta_cmd)[moving] if log.beta_cmd.shape == log.motor_true.shape else np.zeros((0,))
    out["deflection_rms_deg"] = float(np.degrees(np.sqrt(np.mean(defl**2)))) if defl.size else float("nan")
    out["deflection_max_deg"] = float(np.degrees(np.max(np.abs(defl)))) if defl.size else float("nan")
    out["motor_lag_rms_deg"] = float(np.degrees(np.sqrt(np.mean(lag**2)))) if lag.size else float("nan")
    out["motor_lag_max_deg"] = float(np.degrees(np.max(np.abs(lag)))) if lag.size else float("nan")
    out["rms_lateral_m"] = float(np.sqrt(np.mean(log.lateral**2))) if log.lateral.size else float("nan")
    out["slip_energy_J"] = float(np.sum(log.slip_power) * log.dt)
    out["mean_internal_force_N"] = float(np.mean(log.internal_force)) if log.internal_force.size else float("nan")
    return out


def _drive(driver: str, track: str, seed: int, speed: float, params: RobotParams | None, substeps: int,
           sensors) -> EpisodeLog:
    env_kwargs = {"substeps": substeps}
    if params is not None:
        env_kwargs["params"] = params
    if sensors is not None:
        env_kwargs["sensors"] = sensors
    return run_episode(make_controller(driver, speed_scale=speed), track, seed=seed, env_kwargs=env_kwargs)


def run_phenomenon(driver: str = "icr", track: str = "paper", speeds=DEFAULT_SPEEDS, seed: int = 0,
                   stiffness_factor: float = 100.0, sensors=None, substeps: int = 8,
                   keep_logs: bool = False, params: RobotParams | None = None) -> dict:
    """Drive ``track`` at each speed scale with the robot's own steering (``params``, default
    ``RobotParams()``) and the stiff one; returns ``{"rows": [...], "substeps": {...}, "logs":
    {...}}`` (logs only with ``keep_logs``)."""
    if driver not in DRIVERS:
        raise ValueError(f"unknown driver {driver!r}; choose from {', '.join(DRIVERS)}")
    if track not in TRACK_NAMES:
        raise ValueError(f"unknown track {track!r}; choose from {', '.join(TRACK_NAMES)}")
    base = params if params is not None else RobotParams()
    geom = base.geometry
    stiff = stiff_params(base, stiffness_factor)
    stiff_sub = stable_substeps(stiff, start=substeps)
    rows, logs = [], {}
    for speed in speeds:
        for steering, run_params, sub in (("compliant", params, substeps),
                                          (f"stiff x{stiffness_factor:g}", stiff, stiff_sub)):
            log = _drive(driver, track, seed, float(speed), run_params, sub, sensors)
            row = {"driver": driver, "track": track, "speed_scale": float(speed), "steering": steering,
                   "substeps": sub, **attribute(log, geom)}
            rows.append(row)
            if keep_logs:
                logs[(float(speed), steering)] = log
    return {"rows": rows, "substeps": {"compliant": substeps, "stiff": stiff_sub}, "logs": logs}


_TABLE = (("speed_scale", "speed ×", "{:.2f}"), ("steering", "steering", "{}"), ("completed", "done", "{}"),
          ("standstill_share", "standstill", "{:.0%}"), ("qua_meas_mean", "qua β_meas mean", "{:.4f}"),
          ("qua_meas_min", "min", "{:.4f}"), ("qua_true_mean", "qua β mean", "{:.4f}"),
          ("qua_true_min", "min", "{:.4f}"), ("qua_motor_mean", "qua θ_m mean", "{:.4f}"),
          ("qua_motor_min", "min", "{:.4f}"), ("motor_lag_rms_deg", "lag θ_m−β_c RMS [°]", "{:.2f}"),
          ("deflection_rms_deg", "defl. β−θ_m RMS [°]", "{:.2f}"), ("deflection_max_deg", "max [°]", "{:.2f}"),
          ("rms_lateral_m", "RMS lat [cm]", "{:.2f}"), ("slip_energy_J", "slip [J]", "{:.1f}"),
          ("mean_internal_force_N", "int. force [N]", "{:.2f}"))


def table_markdown(rows: list[dict]) -> str:
    """The figures as a Markdown table (while moving; lateral error, slip and force over the run)."""
    lines = ["| " + " | ".join(c[1] for c in _TABLE) + " |", "|" + "|".join("---" for _ in _TABLE) + "|"]
    for row in rows:
        cells = []
        for key, _, fmt in _TABLE:
            v = row[key]
            if key == "rms_lateral_m":
                v = 100 * v
            cells.append(fmt.format(v) if v is not None else "-")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_phenomenon(logs: dict, geom, path: str) -> None:
    """Per speed: qua over time of β (compliant), θ_m (compliant) and β (stiff) (like Fig. 11), with
    the compliant run's stopped and reconfiguring steps shaded (they are left out of the figures)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    speeds = sorted({k[0] for k in logs})
    fig, axes = plt.subplots(len(speeds), 1, figsize=(10, 2.6 * len(speeds)), squeeze=False)
    for ax, speed in zip(axes[:, 0], speeds):
        for (sp, steering), log in sorted(logs.items()):
            if sp != speed or not log.qua.size:
                continue
            if steering == "compliant":
                ax.fill_between(log.t, 0.0, 1.02, where=~moving_mask(log), color="0.88", step="mid", lw=0,
                                label="not moving (excluded)")
                ax.plot(log.t, qua_of_angles(log.beta_true, geom), lw=0.8, label="qua β (compliant)")
                ax.plot(log.t, qua_of_angles(log.motor_true, geom), lw=0.8, alpha=0.8, label="qua θ_m (compliant)")
            else:
                ax.plot(log.t, qua_of_angles(log.beta_true, geom), lw=0.8, alpha=0.8, label=f"qua β ({steering})")
        ax.set_ylabel(f"qua, speed ×{speed:g}")
        ax.set_ylim(0, 1.02)
        ax.legend(loc="lower left", fontsize=7)
    axes[-1, 0].set_xlabel("t [s] (stops and reconfigurations included)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--driver", default="icr", choices=DRIVERS,
                        help="icr: the ICR reference controller (rate-aware; default); feedforward: the earlier "
                             "kinematic feed-forward (ignores the actuator limits; reproduces earlier figures)")
    parser.add_argument("--track", default="paper", choices=TRACK_NAMES, help="built-in track (default paper)")
    parser.add_argument("--speeds", type=arg_float(0.0, 3.0, lo_open=True), nargs="+", default=list(DEFAULT_SPEEDS),
                        help="speed scales of the track's profile (default 0.5 1 1.4)")
    parser.add_argument("--seed", type=arg_int(0), default=0)
    add_robot_arguments(parser)
    parser.add_argument("--stiffness-factor", type=arg_float(1.0, 1e4), default=100.0,
                        help="spring stiffness factor of the stiff counterfactual (default 100; damper ×sqrt)")
    parser.add_argument("--substeps", type=arg_int(1, 256), default=8, help="physics substeps of the compliant run")
    parser.add_argument("--ideal-sensors", action="store_true", help="no sensor noise or quantisation")
    parser.add_argument("--json", type=arg_output_path(), default=None, help="write the figures as JSON here")
    parser.add_argument("--plot", type=arg_output_path(), default=None, help="write a PNG plot here (needs matplotlib)")


def check_args(args: argparse.Namespace) -> None:
    from azimut_env.physics.stability import check_substeps

    check_substeps(args.substeps, robot_params(args))  # the compliant run's physics, before any episode
    if args.plot:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            raise ValueError("--plot needs matplotlib (pip install -e '.[plot]')") from None


def run(args: argparse.Namespace) -> int:
    res = run_phenomenon(args.driver, args.track, args.speeds, seed=args.seed, stiffness_factor=args.stiffness_factor,
                         sensors="ideal" if args.ideal_sensors else None, substeps=args.substeps,
                         keep_logs=bool(args.plot), params=robot_params(args))
    rows = res["rows"]
    print(f"{args.driver} on {args.track}, robot {robot_label(args)}, seed {args.seed}; qua while moving (controller "
          f"RUNNING, true |μ| > {MOVING_MU} m/s); substeps: compliant {res['substeps']['compliant']}, "
          f"stiff {res['substeps']['stiff']}")
    print(table_markdown(rows), end="")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"driver": args.driver, "track": args.track, "seed": args.seed, "moving_mu": MOVING_MU,
                       "substeps": res["substeps"], "rows": rows}, fh, indent=2, allow_nan=True)
        print(f"figures written to {args.json}")
    if args.plot:
        plot_phenomenon(res["logs"], (robot_params(args) or RobotParams()).geometry, args.plot)
        print(f"plot written to {args.plot}")
    failed = [r for r in rows if r["error"] is not None]
    for r in failed:
        print(f"speed ×{r['speed_scale']:g} {r['steering']}: {r['error']}", file=sys.stderr)
    return 0 if not failed else 1
