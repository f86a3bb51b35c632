"""The paper's phenomenon in the simulator, measured and attributed: the departure of the steering
configuration from the constraining surface while the robot moves, and what each imperfection
contributes (``azimut sim-paper``'s library; the command line is :mod:`jobs.sim_paper`).

The paper (§4, Fig. 10–11) observes that the *measured* steering configuration of AZIMUT-3 leaves
the constraining surface S (the configurations whose propulsion axes concur, eq. 16–17) while it
moves, and names why: "geometric imperfections, actuators with finite stiffness, stiction and
limitations, as well as sensors with noise and quantification" (§1). A run drives a track with a
rate-aware controller (default: the ICR reference controller, whose commands are on S and within
the actuator limits by construction) and reports, **while moving** (:func:`control.episode.moving_mask`:
controller RUNNING and the true |μ| > 0.05 m/s; stops and in-place reconfigurations are left out):

* the **departure** of each wheel from S: |q_k − F_k(λ̂)| [°] with λ̂ the IT estimate of q (eq. 16–17
  give F; the difference wrapped to ]−90°, 90°], a wheel's axis being the same modulo π), its mean
  over wheels and steps and its 95th percentile per wheel, for the measured angles (what the
  robot's sensors see), the true angles (the propulsion axes themselves, with the steering-axis
  zero offsets of the robot's geometric imperfections) and the motor angles θ_m;
* qua (eq. 28–29) of the same, mean and min;
* the spring deflection β − θ_m and the motor lag θ_m − β_c (RMS, max, degrees);
* ``it_over_ns``: the share of the run's distinct measured configurations where IT's qua exceeds
  NS's by more than 0.1 point (of 100), the separation the paper's Fig. 11 shows on the real robot.

**Attribution** (:func:`run_phenomenon`): the same run with one cause removed at a time, each a
counterfactual robot:

* ``stiff x100`` (compliance): spring ×100, damper ×10 (same damping ratio), with the substeps the
  stability budget asks for;
* ``no friction``: no steering joint friction (stiction);
* ``no quantisation``: steering and wheel encoders without quantisation (noise kept);
* ``no imperfections``: no steering-axis zero offsets and rolling-radius errors;
* ``no motor lag``: the steering motors' position loop ×10 faster (same rate, acceleration and
  torque limits, so the controller's commands do not change).

The drop of the mean departure from the robot to each counterfactual is that cause's share; the
causes interact (friction's dead band is τ_s/k_s), so the shares need not add up.

``driver="feedforward"`` keeps the earlier kinematic feed-forward (β and φ̇ from the track's
reference twist with pose correction), which ignores the actuator limits (steering jumps of up to
179°): its departures are mostly motor lag.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from azimut_env.imperfections import DEFAULT_IMPERFECTIONS, with_imperfections
from azimut_env.params import ImperfectionParams, RobotParams
from azimut_env.physics.stability import check_stability
from azimut_env.tracks import TRACK_NAMES
from control.controller import make_controller
from control.episode import MOVING_MU, EpisodeLog, moving_mask
from control.rollout import run_episode
from estimation import estimate_icr, quality, steering_from_lambda
from jobs.bench_estimators import order_stats
from jobs.record_d2 import record_d2

__all__ = ["DRIVERS", "COUNTERFACTUALS", "SWEEPS", "default_robot", "stiff_params", "stable_substeps",
           "counterfactual", "departures_deg", "qua_of_angles", "it_over_ns", "d2_separation", "attribute",
           "run_phenomenon", "sweep"]

DRIVERS = ("icr", "feedforward")
#: the counterfactuals of :func:`run_phenomenon`, by the cause each removes
COUNTERFACTUALS = {"compliance": "stiff x100", "friction": "no friction", "quantisation": "no quantisation",
                   "imperfections": "no imperfections", "motor lag": "no motor lag"}
#: the parameters :func:`sweep` varies: stiffness k_s [N·m/rad] (damper ∝ √k_s), friction τ_c [N·m] (τ_s = 1.5 τ_c)
SWEEPS = ("stiffness", "friction")
#: the motor-lag counterfactual's position-loop factor
LAG_GAIN_FACTOR = 10.0


def default_robot() -> RobotParams:
    """The envs' default robot: ``RobotParams()`` with the default imperfections ("paper")."""
    return with_imperfections(RobotParams(), DEFAULT_IMPERFECTIONS)


def stiff_params(params: RobotParams | None = None, factor: float = 100.0) -> RobotParams:
    """``params`` with the steering spring ×``factor`` and the damper ×sqrt(``factor``) (the same
    damping ratio c_s / (2 sqrt(k_s I_mod)))."""
    if not (math.isfinite(factor) and factor >= 1.0):
        raise ValueError(f"stiffness factor must be finite and >= 1, got {factor!r}")
    p = params if params is not None else default_robot()
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


def counterfactual(params: RobotParams, cause: str, stiffness_factor: float = 100.0) -> RobotParams:
    """``params`` without ``cause`` (a key of :data:`COUNTERFACTUALS`; module docstring)."""
    st = params.steering
    if cause == "compliance":
        return stiff_params(params, stiffness_factor)
    if cause == "friction":
        return replace(params, steering=replace(st, friction_coulomb=0.0, friction_static=0.0))
    if cause == "quantisation":
        return replace(params, sensors=replace(params.sensors, steer_resolution=0.0, wheel_cpr=0))
    if cause == "imperfections":
        return replace(params, imperfections=ImperfectionParams())
    if cause == "motor lag":
        return replace(params, steering=replace(st, position_gain=st.position_gain * LAG_GAIN_FACTOR))
    raise ValueError(f"unknown cause {cause!r}; choose from {', '.join(COUNTERFACTUALS)}")


# ---------------------------------------------------------------------- measures


def _wrap_axis(x: np.ndarray) -> np.ndarray:
    """Angles wrapped to [−π/2, π/2[ (an axis is the same modulo π)."""
    return (x + math.pi / 2) % math.pi - math.pi / 2


def departures_deg(q: np.ndarray, geom) -> np.ndarray:
    """(T, n) |q_k − F_k(λ̂)| [°] of configurations q (T, n) [rad] from the constraining surface,
    λ̂ the IT estimate of q (a wheel whose axis holds λ̂ takes q_k: departure 0)."""
    q = geom.wrap_steering(np.asarray(q, dtype=np.float64))
    if q.shape[0] == 0:
        return np.zeros((0, geom.n))
    lam = estimate_icr(q, geom)
    return np.degrees(np.abs(_wrap_axis(q - steering_from_lambda(lam, geom, singular_fill=q))))


def qua_of_angles(q: np.ndarray, geom) -> np.ndarray:
    """qua (T,) of steering configurations q (T, n) [rad] against S(λ̂) of their own IT estimate
    (eq. 28–29), as the env computes it for the measured angles."""
    q = geom.wrap_steering(np.asarray(q, dtype=np.float64))
    if q.shape[0] == 0:
        return np.zeros(0)
    lam = estimate_icr(q, geom)
    return np.asarray(quality(steering_from_lambda(lam, geom, singular_fill=q), q), dtype=np.float64)


def it_over_ns(q: np.ndarray, geom, margin: float = 0.1) -> float:
    """Share of the distinct configurations of q (T, n) where IT's qua exceeds NS's by more than
    ``margin`` points of 100 (NaN without configurations)."""
    q = geom.wrap_steering(np.asarray(q, dtype=np.float64))
    if q.shape[0] == 0:
        return float("nan")
    _, first = np.unique(q, axis=0, return_index=True)
    q = q[np.sort(first)]
    qua = {m: 100 * np.asarray(quality(steering_from_lambda(estimate_icr(q, geom, m), geom, singular_fill=q), q))
           for m in ("IT", "NS")}
    return order_stats(qua["IT"], qua["NS"], margin)["a_over_b_margin"]


def d2_separation(q: np.ndarray, geom) -> dict:
    """The paper's Fig. 11 order on a D2 recording q (N, n) [rad] (:data:`~jobs.bench_estimators.FIG11_PAIRS`):
    ``d2_it_over_ns`` (share of points where IT's qua exceeds NS's by more than 0.1 point),
    ``d2_it_ge_ns`` and ``d2_ns_ge_ls`` (share of the points where the two differ at which the
    first is at least as good), ``d2_ns_ls_worst`` (min of NS − LS [points]) and the mean
    departure of the recorded configurations from the surface [°]."""
    q = geom.wrap_steering(np.asarray(q, dtype=np.float64))
    qua = {m: 100 * np.asarray(quality(steering_from_lambda(estimate_icr(q, geom, m), geom, singular_fill=q), q))
           for m in ("IT", "NS", "LS")}
    it_ns, ns_ls = order_stats(qua["IT"], qua["NS"]), order_stats(qua["NS"], qua["LS"])
    return {"d2_points": int(len(q)), "d2_it_over_ns": it_ns["a_over_b_margin"], "d2_it_ge_ns": it_ns["a_at_least_b"],
            "d2_ns_ge_ls": ns_ls["a_at_least_b"], "d2_ns_ls_worst": ns_ls["worst"],
            "d2_departure_mean_deg": float(departures_deg(q, geom).mean())}


def _stats(x: np.ndarray) -> tuple[float, float]:
    return (float(np.mean(x)), float(np.min(x))) if x.size else (float("nan"), float("nan"))


def _rms_max_deg(x: np.ndarray) -> tuple[float, float]:
    if not x.size:
        return float("nan"), float("nan")
    return float(np.degrees(np.sqrt(np.mean(x ** 2)))), float(np.degrees(np.max(np.abs(x))))


def attribute(log: EpisodeLog, geom, min_mu: float = MOVING_MU, steer_offset=None) -> dict:
    """The phenomenon's figures of one run over its moving steps (module docstring).
    ``steer_offset`` (n,) [rad]: the robot's steering-axis zero offsets (the true axes are at
    β + δ; default none)."""
    moving = moving_mask(log, min_mu)
    out: dict = {"steps": int(log.qua.size), "moving_steps": int(moving.sum()),
                 "standstill_share": float(1.0 - moving.mean()) if log.qua.size else float("nan"),
                 "completed": bool(log.completed), "error": log.error}
    offset = np.zeros(geom.n) if steer_offset is None else np.asarray(steer_offset, dtype=np.float64)
    configs = {"meas": log.beta_meas[moving], "true": log.beta_true[moving] + offset, "motor": log.motor_true[moving]}
    for name, q in configs.items():
        dep = departures_deg(q, geom)
        out[f"departure_{name}_mean_deg"] = float(dep.mean()) if dep.size else float("nan")
        out[f"departure_{name}_p95_deg"] = (np.percentile(dep, 95, axis=0).tolist() if dep.size
                                            else [float("nan")] * geom.n)
        out[f"qua_{name}_mean"], out[f"qua_{name}_min"] = _stats(qua_of_angles(q, geom))
    out["it_over_ns"] = it_over_ns(configs["meas"], geom)
    lag = (log.motor_true - log.beta_cmd)[moving] if log.beta_cmd.shape == log.motor_true.shape else np.zeros(0)
    out["deflection_rms_deg"], out["deflection_max_deg"] = _rms_max_deg((log.beta_true - log.motor_true)[moving])
    out["motor_lag_rms_deg"], out["motor_lag_max_deg"] = _rms_max_deg(lag)
    out["rms_lateral_m"] = float(np.sqrt(np.mean(log.lateral ** 2))) if log.lateral.size else float("nan")
    out["slip_energy_J"] = float(np.sum(log.slip_power) * log.dt)
    out["mean_nullspace_force_N"] = float(np.mean(log.nullspace_force)) if log.nullspace_force.size else float("nan")
    out["mean_antagonism_N"] = float(np.mean(log.antagonism)) if log.antagonism.size else float("nan")
    return out


# ---------------------------------------------------------------------- runs


def _drive(driver: str, track: str, seed: int, speed: float, params: RobotParams, substeps: int,
           sensors) -> EpisodeLog:
    env_kwargs = {"substeps": substeps, "params": params}
    if sensors is not None:
        env_kwargs["sensors"] = sensors
    if driver == "icr":  # the study's ICR driver is the controller without its look-ahead (measured on it)
        from control.path_controllers import ICRPathController

        controller = ICRPathController(speed, lookahead=None)
    else:
        controller = make_controller(driver, speed_scale=speed)
    return run_episode(controller, track, seed=seed, env_kwargs=env_kwargs)


def _check_run(driver: str, track: str) -> None:
    if driver not in DRIVERS:
        raise ValueError(f"unknown driver {driver!r}; choose from {', '.join(DRIVERS)}")
    if track not in TRACK_NAMES:
        raise ValueError(f"unknown track {track!r}; choose from {', '.join(TRACK_NAMES)}")


def run_phenomenon(driver: str = "icr", track: str = "paper", speeds=(0.5, 1.0, 1.4), seed: int = 0,
                   stiffness_factor: float = 100.0, sensors=None, substeps: int = 8, keep_logs: bool = False,
                   params: RobotParams | None = None, causes=tuple(COUNTERFACTUALS)) -> dict:
    """Drive ``track`` at each speed scale with the robot (``params``, default
    :func:`default_robot`) and each counterfactual of ``causes``; returns ``{"rows": [...],
    "substeps": {case: count}, "logs": {(speed, case): log}}`` (logs only with ``keep_logs``).
    Each row has ``case`` ("robot" or the counterfactual's name), ``cause`` and :func:`attribute`'s
    figures."""
    _check_run(driver, track)
    base = params if params is not None else default_robot()
    cases = [("robot", None, base, substeps)]
    for cause in causes:
        cf = counterfactual(base, cause, stiffness_factor)
        name = f"stiff x{stiffness_factor:g}" if cause == "compliance" else COUNTERFACTUALS[cause]
        cases.append((name, cause, cf, stable_substeps(cf, start=substeps)))
    rows, logs = [], {}
    for speed in speeds:
        for name, cause, run_params, sub in cases:
            log = _drive(driver, track, seed, float(speed), run_params, sub, sensors)
            offset = run_params.imperfections.offsets(run_params.n)
            row = {"driver": driver, "track": track, "speed_scale": float(speed), "case": name, "cause": cause,
                   "substeps": sub, **attribute(log, base.geometry, steer_offset=offset)}
            rows.append(row)
            if keep_logs:
                logs[(float(speed), name)] = log
    for row in rows:  # each cause's share: the drop of the mean measured departure without it
        ref = next(r for r in rows if r["speed_scale"] == row["speed_scale"] and r["case"] == "robot")
        row["departure_drop_deg"] = ref["departure_meas_mean_deg"] - row["departure_meas_mean_deg"]
    return {"rows": rows, "substeps": {name: sub for name, _, _, sub in cases}, "logs": logs}


def sweep(parameter: str, values, speeds=(0.5, 1.0), track: str = "paper", seed: int = 0,
          params: RobotParams | None = None, substeps: int = 8, d2: bool = False) -> list[dict]:
    """The ICR controller on ``track`` with one steering parameter of ``params`` (default
    :func:`default_robot`) set to each of ``values``: ``"stiffness"`` k_s [N·m/rad] (the damper
    keeps its damping ratio, c_s ∝ √k_s) or ``"friction"`` τ_c [N·m] (τ_s = 1.5 τ_c); one row of
    :func:`attribute` figures per value and speed. ``d2``: also record D2 with each value
    (:func:`~jobs.record_d2.record_d2`, seed ``seed``) and add :func:`d2_separation`'s figures to
    its rows."""
    _check_run("icr", track)
    if parameter not in SWEEPS:
        raise ValueError(f"unknown sweep {parameter!r}; choose from {', '.join(SWEEPS)}")
    base = params if params is not None else default_robot()
    st = base.steering
    rows = []
    for value in values:
        value = float(value)
        if parameter == "stiffness":
            run_params = replace(base, steering=replace(st, stiffness=value,
                                                        damping=st.damping * math.sqrt(value / st.stiffness)))
        else:
            run_params = replace(base, steering=replace(st, friction_coulomb=value, friction_static=1.5 * value))
        sub = stable_substeps(run_params, start=substeps)
        sep = d2_separation(record_d2(seed=seed, params=run_params, substeps=sub)[0], base.geometry) if d2 else {}
        for speed in speeds:
            log = _drive("icr", track, seed, float(speed), run_params, sub, None)
            rows.append({"parameter": parameter, "value": value, "speed_scale": float(speed), "substeps": sub,
                         **attribute(log, base.geometry, steer_offset=run_params.imperfections.offsets(base.n)), **sep})
    return rows
