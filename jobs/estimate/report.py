"""The outputs of ``azimut estimate``: per-sample arrays (``samples.npz``, optional
``samples.csv``), ``summary.json``, ``report.md`` and the plots (:mod:`jobs.estimate.plots`).

``report.md`` opens with the diagnosis in plain words (:func:`diagnosis_lines`): the findings of
:func:`estimation.logs.diagnosis.diagnose`, each sentence stating the numbers it was drawn from;
the statistics while moving come next, standing set apart, then the whole log."""

from __future__ import annotations

import json
import math
import platform
import sys
from pathlib import Path

import numpy as np

from estimation.hrep import twist_from_eta
from estimation.logs import LogEstimate, LogSource, compare_estimators, odometry_drift
from estimation.logs.diagnosis import diagnose

#: every file ``azimut estimate`` may write in its folder (a plot only with the data it needs)
OUTPUT_NAMES = ("samples.npz", "samples.csv", "steer_space.png", "qua_time.png", "odometry.png", "motion.png",
                "summary.json", "report.md")

__all__ = ["OUTPUT_NAMES", "write_outputs", "sample_columns", "summary", "report_markdown", "diagnosis_lines"]


def _key(method: str) -> str:
    """A method's name in array keys and column names (``IT+`` -> ``ITplus``)."""
    return method.replace("+", "plus")


def sample_columns(result: LogEstimate, diag: dict | None = None) -> dict[str, np.ndarray]:
    """The per-sample arrays by name, as ``samples.npz`` holds them (see the docs for each); with
    the :func:`~estimation.logs.diagnosis.diagnose` of the log, the steering departure and the
    windowed yaw rates too."""
    cols: dict[str, np.ndarray] = {"t_s": result.t_s, "t_ns": result.t_ns, "beta": result.beta,
                                   "phidot": result.phidot, "out_of_range": result.out_of_range,
                                   "moving": result.moving, "rigid_twist": result.rigid_twist,
                                   "rigid_residual": result.rigid_residual, "contact_speed": result.contact_speed}
    for m in result.methods:
        k = _key(m)
        cols[f"lam_{k}"] = result.lam[m]
        cols[f"mu_{k}"] = result.mu[m]
        cols[f"twist_{k}"] = twist_from_eta(result.lam[m], result.mu[m])
        cols[f"qua_{k}"] = result.qua[m]
    cols["odom_twist"] = result.odom_twist
    cols["pose"] = result.pose
    if result.truth_at is not None:
        cols["truth_pose"] = result.truth_at
    if diag is not None:
        cols["steer_departure_deg"] = diag["departure_samples_deg"]
    if result.yaw_at is not None:
        cols["gyro_yaw"] = result.yaw_at
        if diag is not None and diag["rates"] is not None:
            cols.update({f"yaw_rate_{k}": v for k, v in diag["rates"].items()})
    return cols


def _write_csv(result: LogEstimate, modules, path: Path) -> None:
    """samples.csv: the columns of samples.npz flattened, one header name per column."""
    names = (["t_s"] + [f"beta_{m}" for m in modules] + [f"phidot_{m}" for m in modules]
             + ["out_of_range", "moving", "rigid_vx", "rigid_vy", "rigid_omega", "rigid_residual", "contact_speed"])
    blocks = [result.t_s[:, None], result.beta, result.phidot, result.out_of_range[:, None].astype(np.float64),
              result.moving[:, None].astype(np.float64), result.rigid_twist, result.rigid_residual[:, None],
              result.contact_speed[:, None]]
    for m in result.methods:
        k = _key(m)
        names += [f"lam_u_{k}", f"lam_v_{k}", f"lam_w_{k}", f"mu_{k}", f"twist_vx_{k}", f"twist_vy_{k}",
                  f"twist_omega_{k}", f"qua_{k}"]
        blocks += [result.lam[m], result.mu[m][:, None], twist_from_eta(result.lam[m], result.mu[m]),
                   result.qua[m][:, None]]
    names += ["odom_vx", "odom_vy", "odom_omega", "pose_x", "pose_y", "pose_theta"]
    blocks += [result.odom_twist, result.pose]
    if result.truth_at is not None:
        names += ["truth_x", "truth_y", "truth_theta"]
        blocks.append(result.truth_at)
    np.savetxt(path, np.hstack(blocks), fmt="%.17g", delimiter=",", header=",".join(names), comments="")


def summary(result: LogEstimate, source: LogSource, elapsed_s: float, diag: dict | None = None) -> dict:
    """The JSON summary: the diagnosis (sentences and findings), the log, the robot, the samples,
    the statistics while moving and standing, the gyro comparison, the estimators over the whole
    log, the odometry. ``diag``: the log's :func:`~estimation.logs.diagnosis.diagnose` (computed
    when not given)."""
    geom = source.geom
    diag = diagnose(result, geom, source.modules) if diag is None else diag
    dt = np.diff(result.t_ns) * 1e-9
    s = {
        "diagnosis": [],
        "findings": diag["findings"],
        "log": result.source,
        "robot": {"n": geom.n, "modules": list(source.modules), "alpha_deg": np.rad2deg(geom.alpha).tolist(),
                  "l_m": geom.l.tolist(), "b_m": geom.b.tolist(), "r_m": geom.r.tolist(),
                  "steer_range_rad": [geom.steer_min, geom.steer_max],
                  "unlimited_steering": bool(getattr(geom, "unlimited_steering", False))},
        "samples": {"read": result.n_read, "estimated": int(result.t_ns.size),
                    "skipped": dict(result.skipped), "skipped_total": int(sum(result.skipped.values())),
                    "out_of_range": int(result.out_of_range.sum()),
                    "duration_s": float(result.t_s[-1]) if result.t_ns.size else 0.0,
                    "median_period_s": float(np.median(dt)) if dt.size else float("nan"),
                    "max_period_s": float(dt.max()) if dt.size else float("nan")},
        "moving": {**diag["motion"], "quality": diag["quality"], "departure": diag["departure"]},
        "gyro": diag["gyro"],
        "signals": {"frozen": diag["frozen"], "standing_noise": diag["noise"]},
        "thresholds": diag["thresholds"],
        "estimators": compare_estimators(result),
        "odometry": {"method": result.odometry_method, "reference": result.truth.source if result.truth else None,
                     "drift": odometry_drift(result)},
        "elapsed_s": elapsed_s,
        "machine": platform.processor() or platform.machine(), "python": sys.version.split()[0],
    }
    s["diagnosis"] = diagnosis_lines(s)
    return s


def _fmt(v, spec: str) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def _span(st: dict) -> str:
    return f"{st['t0_s']:.1f}–{st['t1_s']:.1f} s"


def _list(items: list[str], most: int = 4) -> str:
    more = f" and {len(items) - most} more" if len(items) > most else ""
    return ", ".join(items[:most]) + more


_YAW_FLAGS = {"wpilog": "pass --yaw-entry NAME (the gyro's heading entry: a number with --yaw-unit, a "
                        "struct:Rotation2d or a Pose2d)",
              "ros": "pass --yaw-topic TOPIC (a sensor_msgs/Imu topic or a pose topic)"}


#: IT's mean qua while moving [%] below which the report suggests raw angles that need their offsets
_RAW_HINT_QUA = 90.0
#: a share of stale samples, and a gap between samples [s], worth a line of the diagnosis
_STALE_SHARE = 0.2
_GAP_S = 1.0


def _sampling_lines(sm: dict) -> list[str]:
    """Lines on samples the estimate did not see: skipped as stale, or a long gap."""
    out = []
    stale = next((c for why, c in sm["skipped"].items() if "older than the maximum age" in why), 0)
    if sm["read"] and stale > _STALE_SHARE * sm["read"]:
        out.append(f"{100 * stale / sm['read']:.0f}% of the samples read ({stale} of {sm['read']}) were skipped as "
                   "stale: a signal logged on change that stopped, or one logged far less often than the others "
                   "(--max-age sets how old a held value may be).")
    if sm["max_period_s"] == sm["max_period_s"] and sm["max_period_s"] > _GAP_S:
        out.append(f"The log has a gap of {sm['max_period_s']:.1f} s without a sample: what the robot did there is "
                   "not seen (a clock entry logged only on change?).")
    return out


def _finding_motion(f: dict, s: dict, th: dict) -> list[str]:
    """How long the robot moves and stands, or that it never moves; then the sampling findings."""
    out: list[str] = []
    if f["samples_moving"] == 0:
        out.append(f"The robot never moves in this log ({f['standing_s']:.0f} s standing: no wheel faster "
                   f"than {100 * f['moving_speed_m_s']:.0f} cm/s by the wheels' own odometry), so nothing "
                   "can be said about how the wheels work together.")
        return out
    qs = s["moving"]["quality"].get("IT", next(iter(s["moving"]["quality"].values())))["standing"]
    stand = (f" (IT's quality {qs['qua_mean']:.0f}% there, meaningless with the wheels at rest)"
             if qs["qua_mean"] is not None else "")
    out.append(f"Moving {100 * f['moving_fraction']:.0f}% of the log ({f['moving_s']:.0f} s); standing "
               f"{f['standing_s']:.0f} s{stand}, set apart below. Moving: a wheel faster than "
               f"{100 * f['moving_speed_m_s']:.0f} cm/s by the wheels' own odometry.")
    out += _sampling_lines(s["samples"])
    return out


def _finding_quality(f: dict, s: dict, th: dict) -> list[str]:
    """How well the wheels agree while moving, by the estimator's quality."""
    how = ("agree well" if f["qua_p5"] >= 97 else "mostly agree" if f["qua_mean"] >= th["fight_qua"] * 100
           else "often disagree")
    rms = s["moving"]["departure"]["median_rms_deg"]
    return [f"While moving, the wheels {how}: {f['method']}'s quality {f['qua_mean']:.1f}% on average, "
            f"at least {f['qua_p5']:.1f}% in 95% of the moving samples (lowest {f['qua_min']:.0f}%); "
            f"typically the steering is {rms:.1f}° RMS off one common turning centre."
            + (" If these are raw absolute-encoder angles (before your code's offsets), `azimut calibrate` "
               "fits the offsets." if f["qua_mean"] < _RAW_HINT_QUA else "")]


def _finding_module_offset(f: dict, s: dict, th: dict) -> list[str]:
    """One module's steering offset explains the departure."""
    return [f"Module {f['module']} reads {f['offset_deg']:+.1f}° off the others while moving (that one "
            f"offset explains the steering departure: {f['rms_deg']:.2f}° RMS → "
            f"{f['rms_without_deg']:.2f}°; "
            f"its own departure {f['mean_deg']:+.1f}° mean, {f['p95_abs_deg']:.1f}° p95): check its "
            "steering offset (`azimut calibrate` fits it)."]


def _finding_steering_disagree(f: dict, s: dict, th: dict) -> list[str]:
    """The modules disagree and no single offset explains it."""
    mods = _list([f"{m} {v:+.1f}°" for m, v in zip(f["modules"], f["median_deg"])])
    return [f"The modules' angles disagree while moving (median departure {mods}) and no single module's "
            "offset explains it: check the steering offsets and the module positions in the robot file."]


def _finding_fight(f: dict, s: dict, th: dict) -> list[str]:
    """The stretches where the wheels fight."""
    sts = _list([f"{_span(st)} (quality {st['qua_mean']:.0f}%)" for st in f["stretches"]])
    return [f"Stretches where the wheels fight while moving ({f['method']}'s quality below "
            f"{100 * th['fight_qua']:.0f}% for {th['stretch_min_s']} s or more): {sts}."]


def _finding_frozen(f: dict, s: dict, th: dict) -> list[str]:
    """A module's signal frozen while the robot moves."""
    what = "steering angle" if f["signal"] == "steering" else "wheel speed"
    return [f"Module {f['module']}'s {what} is frozen for {f['t1_s'] - f['t0_s']:.1f} s ({_span(f)}, "
            f"exactly {f['value']:.4g}) while the robot moves and the other modules' change: a stale or "
            "disconnected sensor, or a signal logged on change that stopped?"]


def _finding_noisy(f: dict, s: dict, th: dict) -> list[str]:
    """A module's steering angle noisy at rest."""
    return [f"Module {f['module']}'s steering angle is noisy at rest: {f['rms_deg']:.2f}° RMS from "
            f"sample to sample, against {f['others_median_deg']:.2f}° for the others: a loose encoder "
            "or magnet, or electrical noise?"]


def _finding_gyro_scale(f: dict, s: dict, th: dict) -> list[str]:
    """The wheel odometry turns more or less than the gyro."""
    more = "more" if f["slope"] > 1 else "less"
    return [f"Wheel odometry turns {100 * abs(f['slope'] - 1):.0f}% {more} than the gyro (slope "
            f"{f['slope']:.3f} over {f['turning_s']:.0f} s of turning): check the wheel radius and the "
            "module positions (track width) in the robot file, or the gyro's scale"
            + ("; fix the steering offsets first, they bias the odometry's turn rate too."
               if any(g["kind"] in ("module_offset", "steering_disagree") for g in s["findings"]) else ".")]


def _finding_gyro_agree(f: dict, s: dict, th: dict) -> list[str]:
    """The wheels and the gyro agree on the turn rate."""
    return [f"The wheels and the gyro agree on the turn rate while moving: slope {f['slope']:.3f}, "
            f"RMS difference {f['rms_diff_rad_s']:.3f} rad/s."]


def _finding_gyro_no_turn(f: dict, s: dict, th: dict) -> list[str]:
    """The gyro says the robot hardly turns: against the wheels that say it does (a check), or too
    little turning to check the odometry's scale."""
    out: list[str] = []
    if f["severity"] == "check":
        tot = (f" (heading change: gyro {math.degrees(f['gyro_rad']):.0f}°, wheels "
               f"{math.degrees(f['odometry_rad']):.0f}°)" if f["gyro_rad"] is not None else "")
        out.append(f"The wheels say the robot turns while the gyro says it hardly does{tot}; RMS difference "
                   f"{f['rms_diff_rad_s']:.2f} rad/s while moving: a drive motor inverted (a wheel speed of the "
                   "wrong sign), a gyro entry that is not the robot's heading, or the robot on blocks?")
    else:
        out.append(f"The robot hardly turns while moving ({f['turning_s']:.1f} s faster than "
                   f"{th['turn_rate_rad_s']} rad/s by the gyro): the gyro cannot check the odometry's turn "
                   f"scale (RMS difference {f['rms_diff_rad_s']:.3f} rad/s).")
    return out


def _finding_gyro_disagree(f: dict, s: dict, th: dict) -> list[str]:
    """The stretches where the gyro and the wheels disagree."""
    sts = _list([f"{_span(st)} (gyro {st['gyro_rad_s']:+.2f}, wheels {st['wheels_rad_s']:+.2f} rad/s)"
                 for st in f["stretches"]], 3)
    return [f"The gyro and the wheels disagree on the turn rate {sts}: slip, a skid, a push, or a "
            "wheel speed of the wrong sign?"]


def _finding_no_gyro(f: dict, s: dict, th: dict) -> list[str]:
    """The log has no gyro, and the flag that would read one."""
    fmt = str(f["format"]).lower()
    how = next((v for key, v in _YAW_FLAGS.items() if key in fmt or (key == "wpilog" and "wpilib" in fmt)),
               f"the {f['format']} reader reads no gyro")
    return [f"The log has no gyro here: {how} to check the wheel odometry against it."]


#: the sentence(s) of each kind of finding, by kind (:func:`diagnosis_lines`)
_FINDING_LINES = {
    "motion": _finding_motion,
    "quality": _finding_quality,
    "module_offset": _finding_module_offset,
    "steering_disagree": _finding_steering_disagree,
    "fight": _finding_fight,
    "frozen": _finding_frozen,
    "noisy": _finding_noisy,
    "gyro_scale": _finding_gyro_scale,
    "gyro_agree": _finding_gyro_agree,
    "gyro_no_turn": _finding_gyro_no_turn,
    "gyro_disagree": _finding_gyro_disagree,
    "no_gyro": _finding_no_gyro,
}


def diagnosis_lines(s: dict) -> list[str]:
    """The diagnosis in plain words, one sentence per finding of the :func:`summary` ``s``, in the
    findings' order; every number comes from the log."""
    th = s["thresholds"]
    out = []
    for f in s["findings"]:
        if f["kind"] in _FINDING_LINES:
            out += _FINDING_LINES[f["kind"]](f, s, th)
    if s["moving"]["samples_moving"] and not any(f["severity"] == "check" for f in s["findings"]):
        out.append("Nothing else stands out by the rules below.")
    return out


def _rules(th: dict) -> str:
    return (f"Rules: moving = the fastest wheel contact point of the wheels' rigid fit at least "
            f"{th['moving_speed_m_s']} m/s; fight = quality below {100 * th['fight_qua']:.0f}% for "
            f"{th['stretch_min_s']} s or more (gaps up to {th['bridge_s']} s bridged); a module offset is named when "
            f"it is at least {th['offset_min_deg']}°, leaves at most {100 * th['offset_explains']:.0f}% of the RMS "
            f"departure, and any other module's would leave {th['offset_stand_out']}× more; turn rates over "
            f"{th['rate_window_s']} s centred windows, slope over turns faster than {th['turn_rate_rad_s']} rad/s "
            f"(at least {th['turn_min_s']} s of them), reported beyond ±{100 * th['slope_tol']:.0f}%; gyro and wheels "
            f"disagree beyond {th['disagree_rate_rad_s']} rad/s + {100 * th['disagree_rel']:.0f}% of the gyro's rate; "
            f"frozen = exactly constant for {th['frozen_min_s']} s or more while moving, another module's angle "
            f"changing more than {th['frozen_others_deg']}° (wheel speed: {th['frozen_others_speed_m_s']} m/s); "
            f"noisy = standing sample-to-sample RMS at least {th['noisy_min_deg']}° and {th['noisy_ratio']:.0f}× "
            "the others' median.")


def _moving_sections(s: dict) -> list[str]:
    mv = s["moving"]
    lines = ["", f"## While moving ({mv['samples_moving']} samples, {mv['moving_s']:.1f} s), standing apart "
                 f"({mv['samples_standing']} samples, {mv['standing_s']:.1f} s)", "",
             "| method | moving: qua min % | qua mean % | qua p5 % | standing: qua min % | qua mean % | qua p5 % |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for m, q in mv["quality"].items():
        a, b = q["moving"], q["standing"]
        lines.append(f"| {m} | {_fmt(a['qua_min'], '.2f')} | {_fmt(a['qua_mean'], '.2f')} | {_fmt(a['qua_p5'], '.2f')} "
                     f"| {_fmt(b['qua_min'], '.2f')} | {_fmt(b['qua_mean'], '.2f')} | {_fmt(b['qua_p5'], '.2f')} |")
    dep = mv["departure"]
    lines += ["", f"Steering departure while moving: each module's measured angle minus the constraining surface's "
                  f"at {dep['method']}'s λ̂ [deg]. Offset alone: the one constant correction of that module alone "
                  "that best explains the departures, and the RMS departure it leaves"
                  + (f" (of {_fmt(dep['rms_deg'], '.3f')}° as measured), over the {dep['samples_offset_fit']} moving "
                     "samples" if dep["samples_offset_fit"] else ": not fitted, no moving sample")
                  + f" where the wheels do not fight (quality at least {100 * s['thresholds']['fight_qua']:.0f}%).", "",
              "| module | mean | median | mean abs | p95 abs | offset alone | RMS left |",
              "|---|---:|---:|---:|---:|---:|---:|"]
    for name, r in dep["modules"].items():
        lines.append(f"| {name} | {_fmt(r['mean_deg'], '+.3f')} | {_fmt(r['median_deg'], '+.3f')} | "
                     f"{_fmt(r['mean_abs_deg'], '.3f')} | "
                     f"{_fmt(r['p95_abs_deg'], '.3f')} | {_fmt(r['offset_deg'], '+.3f')} | "
                     f"{_fmt(r['rms_without_offset_deg'], '.3f')} |")
    g = s["gyro"]
    if g is not None:
        lines += ["", f"## Gyro against wheel odometry ({g['source']})", "",
                  f"Turn rates as the mean over a {g['window_s']} s window centred on each sample (the gyro's heading "
                  "and the odometry's, each interpolated linearly at the window's ends), over the "
                  f"{g['samples_moving']} moving samples the gyro covers; slope: least squares of ω_wheels = k "
                  f"ω_gyro over the turning samples ({g['odometry']['turning_s']:.1f} s).", "",
                  "| wheels | RMS difference [rad/s] | slope k | correlation |", "|---|---:|---:|---:|"]
        for key, label in (("odometry", f"dead reckoning ({g['odometry_method']})"), ("rigid", "rigid fit")):
            r = g[key]
            lines.append(f"| {label} | {_fmt(r['rms_diff_rad_s'], '.4f')} | {_fmt(r['slope'], '.4f')} | "
                         f"{_fmt(r['correlation'], '.4f')} |")
        tot = g["total"]
        if tot is not None:
            lines += ["", f"Heading change {tot['t0_s']:.1f}–{tot['t1_s']:.1f} s: gyro "
                          f"{math.degrees(tot['gyro_rad']):.1f}°, dead reckoning "
                          f"{math.degrees(tot['odometry_rad']):.1f}°, "
                          f"rigid fit {math.degrees(tot['rigid_rad']):.1f}°."]
        if g["disagree"]:
            lines += ["", "Disagreements: " + "; ".join(
                f"{_span(st)} gyro {st['gyro_rad_s']:+.3f}, wheels {st['wheels_rad_s']:+.3f} rad/s "
                f"(moving {100 * st['moving_fraction']:.0f}%)" for st in g["disagree"]) + "."]
    return lines


def _estimator_lines(est: dict, plots: list[str]) -> list[str]:
    """The estimators' table on the whole log (quality, valid λ̂, cost) and their plots."""
    lines: list[str] = []
    lines += ["", "## Estimators on this log, all samples (moving and standing)", "",
              "As `azimut bench-estimators` compares them on D2, over every sample: qua of eq. (28)–(29), the "
              "share of finite unit λ̂, and the cost of each method's `estimate_eta` calls (λ̂, μ̂ and qua) on this "
              "log, this machine.", "",
              "| method | qua min % | qua mean % | gap to ORACLE | valid unit λ̂ | µs/sample | samples/s | × NE |",
              "|---|---:|---:|---:|---:|---:|---:|---:|"]
    ne = est["methods"].get("NE", {}).get("us_per_sample")
    for m, r in est["methods"].items():
        ratio = r["us_per_sample"] / ne if ne else None
        lines.append(f"| {m} | {r['qua_min']:.2f} | {r['qua_mean']:.2f} | {_fmt(r.get('gap_to_oracle_mean'), '.3f')} "
                     f"| {100 * r['valid_unit']:.2f}% | {r['us_per_sample']:.2f} | {r['samples_per_s']:,.0f} | "
                     f"{_fmt(ratio, '.1f')} |")
    if est["IT_at_least_as_good_fraction"]:
        lines += ["", "IT's qua ≥ the other method's at a sample: " + ", ".join(
            f"{m} {100 * v:.2f}%" for m, v in est["IT_at_least_as_good_fraction"].items())]
    for name, title in (("steer_space.png", "Measured steering against the constraining surface (paper Fig. 10)"),
                        ("qua_time.png", "qua over time per estimator (paper Fig. 11)")):
        if name in plots:
            lines += ["", f"## {title}", "", f"![{title}]({name})"]
    return lines


def _odometry_lines(odo: dict, plots: list[str]) -> list[str]:
    """The dead reckoning against the reference pose, where the log has one, and its plot."""
    lines: list[str] = []
    lines += ["", f"## Odometry (dead reckoning with {odo['method']})", ""]
    d = odo["drift"]
    if d is None:
        lines.append("The log has no reference pose (CSV columns x, y, theta; ROS --truth-topic; wpilog "
                     "--truth-entry): the dead-reckoned pose starts at the origin and is not compared.")
    else:
        lines += [f"Against the reference pose ({odo['reference']}), from the first sample it covers:", "",
                  "| samples | duration [s] | distance [m] | final error [m] | RMS error [m] | max error [m] | "
                  "final heading error [deg] | drift [% of distance] |", "|---:|---:|---:|---:|---:|---:|---:|---:|",
                  f"| {d['samples']} | {d['duration_s']:.2f} | {d['distance_m']:.3f} | {d['final_error_m']:.4f} | "
                  f"{d['rms_error_m']:.4f} | {d['max_error_m']:.4f} | "
                  f"{math.degrees(d['final_heading_error_rad']):.2f} | {_fmt(100 * d['drift_per_m'], '.2f')} |"]
    if "odometry.png" in plots:
        lines += ["", "![odometry](odometry.png)"]
    return lines


def report_markdown(s: dict, plots: list[str]) -> str:
    """``report.md`` from the :func:`summary`."""
    log, sm, est, odo = s["log"], s["samples"], s["estimators"], s["odometry"]
    lines = [f"# azimut estimate: {log['path']}", "", "## Diagnosis", ""]
    lines += [f"- {x}" for x in s["diagnosis"]]
    lines += ["", _rules(s["thresholds"]), ""]
    lines.append(f"Log: {log['format']}; " + "; ".join(f"{k} {v}" for k, v in log.items()
                                                       if k not in ("format", "path") and v not in (None, [], "")))
    lines.append(f"Robot: {s['robot']['n']} modules ({', '.join(s['robot']['modules'])}), α = "
                 f"{', '.join(f'{a:.1f}' for a in s['robot']['alpha_deg'])} deg, l = "
                 f"{', '.join(f'{x:.3f}' for x in s['robot']['l_m'])} m, b = "
                 f"{', '.join(f'{x:.3f}' for x in s['robot']['b_m'])} m, r = "
                 f"{', '.join(f'{x:.4f}' for x in s['robot']['r_m'])} m")
    lines.append("")
    lines.append(f"Samples: {sm['read']} read, {sm['estimated']} estimated, {sm['skipped_total']} skipped; "
                 f"{sm['duration_s']:.2f} s, median period {1e3 * sm['median_period_s']:.2f} ms (longest "
                 f"{1e3 * sm['max_period_s']:.2f} ms). Estimated in {s['elapsed_s']:.1f} s (reading included).")
    if sm["skipped"]:
        lines += ["", "| skipped because | samples |", "|---|---:|"]
        lines += [f"| {why} | {count} |" for why, count in sm["skipped"].items()]
    if sm["out_of_range"]:
        lines += ["", f"{sm['out_of_range']} estimated samples have a steering angle outside the robot's range "
                      "]β_min, β_max] (a module with b ≠ 0 past its stop; samples.npz flags them in out_of_range): "
                      "the estimators wrap it (β and β + π are the same axis), exact for λ̂; μ̂ then uses the "
                      "wrapped angle, as the simulator's own estimate does."]
    lines += _moving_sections(s)
    if "motion.png" in plots:
        lines += ["", "![quality, steering departure and turn rates over time, moving shaded](motion.png)"]
    lines += _estimator_lines(est, plots)
    lines += _odometry_lines(odo, plots)
    lines += ["", f"Machine: {s['machine']}, Python {s['python']}.", ""]
    return "\n".join(lines)


def write_outputs(result: LogEstimate, source: LogSource, out: Path, *, elapsed_s: float, plots: bool = True,
                  csv: bool = False) -> list[str]:
    """Write everything to ``out`` (created); returns the file names."""
    out.mkdir(parents=True, exist_ok=True)
    for name in OUTPUT_NAMES:  # an earlier run's files go first: an interrupted write never mixes two runs
        if (out / name).is_file():
            (out / name).unlink()
    diag = diagnose(result, source.geom, source.modules)
    cols = sample_columns(result, diag)
    np.savez(out / "samples.npz", **cols)
    files = ["samples.npz"]
    if csv:
        _write_csv(result, source.modules, out / "samples.csv")
        files.append("samples.csv")
    pngs: list[str] = []
    if plots:
        from jobs.estimate.plots import write_plots

        pngs = write_plots(result, source.geom, source.modules, out, diag)
    s = summary(result, source, elapsed_s, diag)
    (out / "summary.json").write_text(json.dumps(s, indent=2, allow_nan=True))
    (out / "report.md").write_text(report_markdown(s, pngs))
    return files + pngs + ["summary.json", "report.md"]
