"""What an estimated log says about the robot: statistics while moving (standing set apart), the
wheels' yaw rate against a gyro's, and findings by fixed rules, each computed from the data.

The rules (thresholds are the module's constants, recorded with the findings):

* **moving**: ``LogEstimate.moving`` (the wheels' rigid fit, :mod:`estimation.logs.motion`);
  times are the sums of the sample periods (each sample counts the period before it).
* **steering departure** of module k: ``steering_difference(β_k, F_k(λ̂))`` with λ̂ IT's estimate
  (the measured angle minus the angle the constraining surface gives at IT's ICR) [deg].
* **module offset**: for each module k alone, the constant offset δ_k that best explains the
  departures while moving (:func:`module_offsets`: the δ_k that minimises the squared departures
  of the corrected angles; over the moving samples where the wheels do not fight, qua ≥
  :data:`FIGHT_QUA`, at most :data:`OFFSET_SAMPLES` of them, evenly spaced). One
  module off by δ makes the others depart too (IT spreads the disagreement over the wheels),
  but only the odd one out, corrected, brings the departures down to the noise. A module is named
  when |δ_k| ≥ :data:`OFFSET_MIN_DEG`, its correction leaves at most :data:`OFFSET_EXPLAINS` of the
  RMS departure, and any other module's leaves :data:`OFFSET_STAND_OUT` times more. Otherwise,
  where a module's median departure is at least :data:`OFFSET_MIN_DEG`, the finding is that the
  modules disagree (several offsets, or wrong module positions).
* **wheels fight**: stretches (:func:`stretches`: at least :data:`STRETCH_MIN_S`, gaps up to
  :data:`BRIDGE_S` bridged) of moving samples with IT's qua below :data:`FIGHT_QUA` (an RMS
  steering departure of about 5°).
* **gyro**: the yaw rates over a centred window (:func:`~estimation.logs.motion.window_rate`):
  the gyro's, the dead reckoning's (the odometry estimator's λ̂), the rigid fit's. While moving:
  RMS difference, correlation, and the least-squares slope k of ω_wheels ≈ k ω_gyro over the
  samples turning faster than :data:`TURN_RATE` (at least :data:`TURN_MIN_S` of them); |k − 1| >
  :data:`SLOPE_TOL` is a finding (a wrong track width or wheel radius, or a gyro's scale).
  Disagreement: |ω_wheels − ω_gyro| > :data:`DISAGREE_RATE` + :data:`DISAGREE_REL` |ω_gyro| for
  :data:`STRETCH_MIN_S` or more (slip, a skid, a push, a wrong geometry).
* **frozen signal**: a module's steering angle (or wheel speed) exactly constant for at least
  :data:`FROZEN_MIN_S` while the robot moves (half the run's samples or more) and another
  module's angle changes by more than :data:`FROZEN_OTHERS_DEG` (wheel speed: more than
  :data:`FROZEN_OTHERS_SPEED` m/s) during it.
* **noisy signal**: standing, the RMS sample-to-sample change of a module's angle (over the pairs
  where every other module's changes by less than 2°, i.e. no deliberate steering) at least
  :data:`NOISY_MIN_DEG` and :data:`NOISY_RATIO` times the median of the other modules'; at
  least 1 s of such standing pairs.
"""

from __future__ import annotations

import math

import numpy as np

from estimation.estimate import estimate_icr
from estimation.geometry import RobotGeometry
from estimation.kinematics import steering_from_lambda
from estimation.logs.motion import RATE_WINDOW_S, integrated_heading, window_rate
from estimation.logs.pipeline import LogEstimate

__all__ = ["THRESHOLDS", "sample_periods", "stretches", "motion_split", "quality_split", "steering_departure",
           "module_offsets", "departure_stats", "gyro_comparison", "frozen_signals", "noisy_signals", "diagnose"]

FIGHT_QUA = 0.95
STRETCH_MIN_S = 0.5
BRIDGE_S = 0.2
OFFSET_MIN_DEG = 1.0
OFFSET_STAND_OUT = 1.5
OFFSET_EXPLAINS = 0.7
OFFSET_SAMPLES = 20_000
TURN_RATE = 0.1
TURN_MIN_S = 1.0
SLOPE_TOL = 0.02
DISAGREE_RATE = 0.2
DISAGREE_REL = 0.1
FROZEN_MIN_S = 1.0
FROZEN_OTHERS_DEG = 1.0
FROZEN_OTHERS_SPEED = 0.05
NOISY_MIN_DEG = 0.2
NOISY_RATIO = 5.0
_CALM_DEG = 2.0

#: every threshold of the rules, by name, as the summary records them
THRESHOLDS = {"fight_qua": FIGHT_QUA, "stretch_min_s": STRETCH_MIN_S, "bridge_s": BRIDGE_S,
              "offset_min_deg": OFFSET_MIN_DEG, "offset_stand_out": OFFSET_STAND_OUT,
              "offset_explains": OFFSET_EXPLAINS, "turn_rate_rad_s": TURN_RATE,
              "turn_min_s": TURN_MIN_S, "slope_tol": SLOPE_TOL, "disagree_rate_rad_s": DISAGREE_RATE,
              "disagree_rel": DISAGREE_REL, "rate_window_s": RATE_WINDOW_S, "frozen_min_s": FROZEN_MIN_S,
              "frozen_others_deg": FROZEN_OTHERS_DEG, "frozen_others_speed_m_s": FROZEN_OTHERS_SPEED,
              "noisy_min_deg": NOISY_MIN_DEG, "noisy_ratio": NOISY_RATIO}


def _main_method(result: LogEstimate) -> str:
    return "IT" if "IT" in result.methods else result.odometry_method


def sample_periods(t_ns: np.ndarray) -> np.ndarray:
    """(K,) the period [s] before each sample (the first gets the median period)."""
    dt = np.diff(np.asarray(t_ns, dtype=np.int64)) * 1e-9
    return np.concatenate([[float(np.median(dt)) if dt.size else 0.0], dt])


def stretches(mask: np.ndarray, t_s: np.ndarray, min_s: float = STRETCH_MIN_S,
              bridge_s: float = BRIDGE_S) -> list[tuple[int, int]]:
    """The runs of ``mask`` as inclusive (first, last) sample indices, runs less than ``bridge_s``
    apart joined, those lasting at least ``min_s`` kept (a run lasts from its first sample's time
    minus one period to its last sample's time)."""
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        return []
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    runs = [[int(starts[0]), int(ends[0])]]
    for a, b in zip(starts[1:], ends[1:]):
        if t_s[a] - t_s[runs[-1][1]] <= bridge_s:
            runs[-1][1] = int(b)
        else:
            runs.append([int(a), int(b)])
    period = sample_periods(np.rint(np.asarray(t_s) * 1e9).astype(np.int64))
    return [(a, b) for a, b in runs if t_s[b] - t_s[a] + period[a] >= min_s - 1e-9]


def motion_split(result: LogEstimate) -> dict:
    """Time and samples moving and standing."""
    dt = sample_periods(result.t_ns)
    mv = result.moving
    total = float(dt.sum())
    return {"moving_speed_m_s": result.moving_speed, "samples_moving": int(mv.sum()),
            "samples_standing": int((~mv).sum()), "moving_s": float(dt[mv].sum()), "standing_s": float(dt[~mv].sum()),
            "moving_fraction": float(dt[mv].sum() / total) if total > 0 else float(mv.mean())}


def _qua_stats(q: np.ndarray) -> dict:
    if q.size == 0:
        return {"samples": 0, "qua_min": None, "qua_mean": None, "qua_p5": None}
    return {"samples": int(q.size), "qua_min": float(100 * q.min()), "qua_mean": float(100 * q.mean()),
            "qua_p5": float(100 * np.percentile(q, 5))}


def quality_split(result: LogEstimate) -> dict:
    """Per estimator, qua min, mean and 5th percentile [%] over the moving and the standing samples."""
    return {m: {"moving": _qua_stats(result.qua[m][result.moving]),
                "standing": _qua_stats(result.qua[m][~result.moving])} for m in result.methods}


def _surface_difference(q: np.ndarray, lam: np.ndarray, geom: RobotGeometry) -> np.ndarray:
    q = geom.wrap_steering(q)
    return geom.steering_difference(q, steering_from_lambda(lam, geom, singular_fill=q))


def steering_departure(result: LogEstimate, geom: RobotGeometry, method: str | None = None) -> np.ndarray:
    """(K, n) [rad] each measured angle minus the constraining surface's at the estimator's λ̂
    (default IT): ``geom.steering_difference(β, steering_from_lambda(λ̂))`` (a wheel whose axis
    holds the ICR: 0)."""
    return _surface_difference(result.beta, result.lam[method or _main_method(result)], geom)


def _departure_of(q: np.ndarray, geom: RobotGeometry) -> np.ndarray:
    return _surface_difference(q, estimate_icr(q, geom, "IT"), geom)


def module_offsets(beta: np.ndarray, geom: RobotGeometry, max_samples: int = OFFSET_SAMPLES) -> dict | None:
    """The best constant steering offset of each module alone, over the (K, n) samples ``beta``
    (at most ``max_samples`` of them, evenly spaced): δ_k minimises Σ_t ‖q_t − δ_k e_k − F(λ̂_t)‖²
    with λ̂_t IT's estimate of the corrected angles, i.e. makes module k's mean departure zero
    (solved by the secant method, three IT passes). Returns ``offset_deg`` (n,) the δ_k [deg],
    ``rms_deg`` (n,) the RMS departure [deg] left with δ_k removed, and ``rms0_deg`` the RMS
    departure of the angles as measured; None without samples."""
    if beta.shape[0] == 0:
        return None
    step = max(1, -(-beta.shape[0] // max_samples))
    q = geom.wrap_steering(beta[::step])
    dep0 = _departure_of(q, geom)
    offset, rms = np.zeros(geom.n), np.zeros(geom.n)
    for k in range(geom.n):
        def mean_departure(delta, k=k):
            qk = q.copy()
            qk[:, k] = geom.wrap_steering(qk[:, k] - delta)
            dep = _departure_of(qk, geom)
            return float(dep[:, k].mean()), dep

        x0, f0, dep = 0.0, float(dep0[:, k].mean()), dep0
        x1 = 2.0 * f0  # a wheel's own share of its offset in its departure is about a half
        for _ in range(3):
            if x1 == x0:
                break
            f1, dep = mean_departure(x1)
            if abs(f1) < 1e-7 or f1 == f0:
                x0 = x1
                break
            x0, f0, x1 = x1, f1, x1 - f1 * (x1 - x0) / (f1 - f0)
        offset[k] = x0
        rms[k] = float(np.sqrt(np.mean(dep**2)))
    return {"offset_deg": np.degrees(offset), "rms_deg": np.degrees(rms),
            "rms0_deg": float(np.degrees(np.sqrt(np.mean(dep0**2))))}


def departure_stats(result: LogEstimate, geom: RobotGeometry, modules, departure_deg: np.ndarray | None = None) -> dict:
    """Per module, while moving: IT's departure [deg] (signed mean, mean |·|, 95th percentile |·|;
    ``departure_deg`` (K, n) when already computed) and the one-module offset of
    :func:`module_offsets` with the RMS departure it leaves [deg]; ``rms_deg``: the RMS departure
    as measured (over the samples of :func:`module_offsets`)."""
    mv = result.moving
    if departure_deg is None:
        departure_deg = np.degrees(steering_departure(result, geom))
    dep = departure_deg[mv]
    calm = mv & (result.qua[_main_method(result)] >= FIGHT_QUA)  # not the stretches where the wheels fight
    off = module_offsets(result.beta[calm], geom)
    table = {}
    for k, name in enumerate(modules):
        row = {"mean_deg": None, "median_deg": None, "mean_abs_deg": None, "p95_abs_deg": None, "offset_deg": None,
               "rms_without_offset_deg": None}
        if dep.shape[0]:
            row.update(mean_deg=float(dep[:, k].mean()), median_deg=float(np.median(dep[:, k])),
                       mean_abs_deg=float(np.abs(dep[:, k]).mean()),
                       p95_abs_deg=float(np.percentile(np.abs(dep[:, k]), 95)))
        if off is not None:
            row.update(offset_deg=float(off["offset_deg"][k]), rms_without_offset_deg=float(off["rms_deg"][k]))
        table[name] = row
    rms = np.sqrt(np.mean(dep**2, axis=1))
    return {"method": _main_method(result), "samples": int(mv.sum()), "samples_offset_fit": int(calm.sum()),
            "modules": table, "rms_deg": None if off is None else off["rms0_deg"],
            "median_rms_deg": float(np.median(rms)) if rms.size else None}


def _rate_stats(wheel: np.ndarray, gyro: np.ndarray, dt: np.ndarray) -> dict:
    out = {"samples": int(wheel.size), "rms_diff_rad_s": None, "correlation": None, "slope": None,
           "turning_s": float(dt[np.abs(gyro) > TURN_RATE].sum())}
    if wheel.size == 0:
        return out
    out["rms_diff_rad_s"] = float(np.sqrt(np.mean((wheel - gyro) ** 2)))
    if wheel.size > 2 and wheel.std() > 0 and gyro.std() > 0:
        out["correlation"] = float(np.corrcoef(wheel, gyro)[0, 1])
    turn = np.abs(gyro) > TURN_RATE
    if out["turning_s"] >= TURN_MIN_S:
        out["slope"] = float(np.sum(wheel[turn] * gyro[turn]) / np.sum(gyro[turn] ** 2))
    return out


def gyro_rates(result: LogEstimate) -> dict[str, np.ndarray] | None:
    """The windowed yaw rates [rad/s] at the samples: ``gyro``, ``odometry`` (the dead reckoning's
    heading) and ``rigid`` (the rigid fit's θ̇ integrated); None without a gyro."""
    if result.yaw is None:
        return None
    t = result.t_ns
    return {"gyro": window_rate(t, result.yaw.t_ns, result.yaw.yaw),
            "odometry": window_rate(t, t, result.pose[:, 2]),
            "rigid": window_rate(t, t, integrated_heading(t, result.rigid_twist[:, 2]))}


def gyro_comparison(result: LogEstimate, rates: dict | None = None) -> dict | None:
    """The wheels' yaw rate against the gyro's (see the module docstring); None without a gyro."""
    rates = gyro_rates(result) if rates is None else rates
    if rates is None:
        return None
    g, w = rates["gyro"], rates["odometry"]
    ok = np.isfinite(g) & np.isfinite(w)
    mv = ok & result.moving
    dt = sample_periods(result.t_ns)
    out = {"source": result.yaw.source, "window_s": RATE_WINDOW_S, "samples": int(ok.sum()),
           "samples_moving": int(mv.sum()), "odometry_method": result.odometry_method,
           "odometry": _rate_stats(w[mv], g[mv], dt[mv]), "rigid": _rate_stats(rates["rigid"][mv], g[mv], dt[mv])}
    cover = np.flatnonzero(np.isfinite(result.yaw_at))
    if cover.size > 1:
        a, b = int(cover[0]), int(cover[-1])
        rigid_heading = integrated_heading(result.t_ns, result.rigid_twist[:, 2])
        out["total"] = {"t0_s": float(result.t_s[a]), "t1_s": float(result.t_s[b]),
                        "gyro_rad": float(result.yaw_at[b] - result.yaw_at[a]),
                        "odometry_rad": float(result.pose[b, 2] - result.pose[a, 2]),
                        "rigid_rad": float(rigid_heading[b] - rigid_heading[a])}
    else:
        out["total"] = None
    gap = np.where(ok, np.abs(w - g), 0.0)
    bad = ok & (gap > DISAGREE_RATE + DISAGREE_REL * np.abs(np.where(ok, g, 0.0)))
    out["disagree"] = [{"t0_s": float(result.t_s[a]), "t1_s": float(result.t_s[b]),
                        "gyro_rad_s": float(np.mean(g[a:b + 1][ok[a:b + 1]])),
                        "wheels_rad_s": float(np.mean(w[a:b + 1][ok[a:b + 1]])),
                        "moving_fraction": float(result.moving[a:b + 1].mean())}
                       for a, b in stretches(bad, result.t_s)]
    return out


def _constant_runs(x: np.ndarray, t_s: np.ndarray, min_s: float) -> list[tuple[int, int]]:
    """Inclusive (first, last) index runs where ``x`` keeps exactly one value for ``min_s`` or more."""
    same = np.concatenate([[0], (x[1:] == x[:-1]).astype(np.int8), [0]])
    edges = np.diff(same)
    first, last = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)  # x[first..last] all equal
    keep = t_s[last] - t_s[first] >= min_s - 1e-9
    return list(zip(first[keep].tolist(), last[keep].tolist()))


def frozen_signals(result: LogEstimate, geom: RobotGeometry) -> list[dict]:
    """Steering angles and wheel speeds that stay exactly constant while the robot moves and the
    others change (see the module docstring)."""
    found = []
    t = result.t_s
    for signal, values, others_change in (
            ("steering", result.beta, lambda j, a, b: np.degrees(np.abs(geom.steering_difference(
                result.beta[a:b + 1, j], result.beta[a, j]))).max() > FROZEN_OTHERS_DEG),
            ("wheel speed", result.phidot, lambda j, a, b: geom.r[j] * np.ptp(result.phidot[a:b + 1, j])
             > FROZEN_OTHERS_SPEED)):
        for k in range(geom.n):
            for a, b in _constant_runs(values[:, k], t, FROZEN_MIN_S):
                if result.moving[a:b + 1].mean() < 0.5:
                    continue
                if not any(others_change(j, a, b) for j in range(geom.n) if j != k):
                    continue
                found.append({"signal": signal, "module": k, "t0_s": float(t[a]), "t1_s": float(t[b]),
                              "value": float(values[a, k])})
    return found


def noisy_signals(result: LogEstimate, geom: RobotGeometry) -> dict:
    """Standing steering noise per module [deg] (RMS sample-to-sample change) and the modules far
    noisier than the others (see the module docstring)."""
    pairs = ~result.moving[1:] & ~result.moving[:-1]
    step = np.degrees(np.abs(geom.steering_difference(result.beta[1:], result.beta[:-1])))
    dt = np.diff(result.t_ns) * 1e-9
    rms = np.full(geom.n, np.nan)
    for k in range(geom.n):
        others = np.delete(step, k, axis=1)
        calm = pairs & (others < _CALM_DEG).all(axis=1)
        if dt[calm].sum() >= 1.0:
            rms[k] = float(np.sqrt(np.mean(step[calm, k] ** 2)))
    noisy = []
    for k in range(geom.n):
        ref = np.delete(rms, k)
        ref = ref[np.isfinite(ref)]
        if np.isfinite(rms[k]) and ref.size and rms[k] >= NOISY_MIN_DEG and rms[k] >= NOISY_RATIO * np.median(ref):
            noisy.append({"module": k, "rms_deg": float(rms[k]), "others_median_deg": float(np.median(ref))})
    return {"standing_rms_deg": [None if math.isnan(v) else float(v) for v in rms], "noisy": noisy}


def _offset_finding(departure: dict, modules: list) -> dict | None:
    """``module_offset`` when one module's offset explains the departure, else ``steering_disagree``
    when a module's mean departure reaches :data:`OFFSET_MIN_DEG`, else None."""
    rows = departure["modules"]
    if departure["rms_deg"] is not None and departure["rms_deg"] > 0:
        rms = np.array([rows[m]["rms_without_offset_deg"] for m in modules])
        k = int(np.argmin(rms))
        row = rows[modules[k]]
        if abs(row["offset_deg"]) >= OFFSET_MIN_DEG and rms[k] <= OFFSET_EXPLAINS * departure["rms_deg"] \
                and OFFSET_STAND_OUT * rms[k] <= np.delete(rms, k).min():
            return _finding("module_offset", "check", module=modules[k], offset_deg=row["offset_deg"],
                            mean_deg=row["mean_deg"], p95_abs_deg=row["p95_abs_deg"],
                            rms_deg=departure["rms_deg"], rms_without_deg=float(rms[k]))
    off = [(m, rows[m]["median_deg"]) for m in modules if abs(rows[m]["median_deg"]) >= OFFSET_MIN_DEG]
    if off:
        return _finding("steering_disagree", "check", modules=[m for m, _ in off], median_deg=[v for _, v in off],
                        rms_deg=departure["rms_deg"])
    return None


def _finding(kind: str, severity: str, **data) -> dict:
    return {"kind": kind, "severity": severity, **data}


def diagnose(result: LogEstimate, geom: RobotGeometry, modules) -> dict:
    """Every statistic of this module and the findings, in the order a report gives them: a list
    of dicts with ``kind``, ``severity`` (``"info"``: a fact; ``"check"``: something to look at)
    and the numbers they state. Kinds: ``motion``, ``quality``, ``module_offset``,
    ``steering_disagree``, ``fight``, ``frozen``, ``noisy``, ``gyro_scale``, ``gyro_agree``,
    ``gyro_no_turn``, ``gyro_disagree``, ``no_gyro``. Also the arrays ``rates`` (:func:`gyro_rates`)
    and ``departure_samples_deg`` (K, n) (:func:`steering_departure` in degrees)."""
    modules = list(modules)
    motion = motion_split(result)
    quality = quality_split(result)
    departure_deg = np.degrees(steering_departure(result, geom))
    departure = departure_stats(result, geom, modules, departure_deg)
    rates = gyro_rates(result)
    gyro = gyro_comparison(result, rates)
    frozen = frozen_signals(result, geom)
    noise = noisy_signals(result, geom)
    method = _main_method(result)
    f = [_finding("motion", "info", **motion)]
    qm = quality[method]["moving"]
    if qm["samples"]:
        f.append(_finding("quality", "info", method=method, qua_mean=qm["qua_mean"], qua_p5=qm["qua_p5"],
                          qua_min=qm["qua_min"], standing_qua_mean=quality[method]["standing"]["qua_mean"]))
        offset = _offset_finding(departure, modules)
        if offset is not None:
            f.append(offset)
        fight = stretches(result.moving & (result.qua[method] < FIGHT_QUA), result.t_s)
        if fight:
            f.append(_finding("fight", "check", method=method, stretches=[
                {"t0_s": float(result.t_s[a]), "t1_s": float(result.t_s[b]),
                 "qua_mean": float(100 * result.qua[method][a:b + 1][result.moving[a:b + 1]].mean()),
                 "qua_min": float(100 * result.qua[method][a:b + 1].min())} for a, b in fight]))
    for fr in frozen:
        f.append(_finding("frozen", "check", **{**fr, "module": modules[fr["module"]]}))
    for nz in noise["noisy"]:
        f.append(_finding("noisy", "check", **{**nz, "module": modules[nz["module"]]}))
    if gyro is None:
        f.append(_finding("no_gyro", "info", format=result.source.get("format")))
    elif gyro["samples_moving"]:
        o = gyro["odometry"]
        if o["slope"] is None:  # a check when the wheels turn where the gyro does not
            wheels_turn = o["rms_diff_rad_s"] > DISAGREE_RATE
            tot = gyro["total"] or {}
            f.append(_finding("gyro_no_turn", "check" if wheels_turn else "info", turning_s=o["turning_s"],
                              rms_diff_rad_s=o["rms_diff_rad_s"], source=gyro["source"],
                              gyro_rad=tot.get("gyro_rad"), odometry_rad=tot.get("odometry_rad")))
        elif abs(o["slope"] - 1) > SLOPE_TOL:
            f.append(_finding("gyro_scale", "check", slope=o["slope"], correlation=o["correlation"],
                              turning_s=o["turning_s"], rigid_slope=gyro["rigid"]["slope"], source=gyro["source"]))
        else:
            f.append(_finding("gyro_agree", "info", slope=o["slope"], rms_diff_rad_s=o["rms_diff_rad_s"],
                              correlation=o["correlation"], source=gyro["source"]))
        if gyro["disagree"]:
            f.append(_finding("gyro_disagree", "check", stretches=gyro["disagree"]))
    return {"thresholds": dict(THRESHOLDS, moving_speed_m_s=result.moving_speed), "motion": motion,
            "quality": quality, "departure": departure, "gyro": gyro, "frozen": frozen, "noise": noise,
            "findings": f, "rates": rates, "departure_samples_deg": departure_deg}
