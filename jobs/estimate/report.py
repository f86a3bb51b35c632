"""The outputs of ``azimut estimate``: per-sample arrays (``samples.npz``, optional
``samples.csv``), ``summary.json``, ``report.md`` and the plots (:mod:`jobs.estimate.plots`)."""

from __future__ import annotations

import json
import math
import platform
import sys
from pathlib import Path

import numpy as np

from estimation.hrep import twist_from_eta
from estimation.logs import LogEstimate, LogSource, compare_estimators, odometry_drift

__all__ = ["write_outputs", "sample_columns", "summary", "report_markdown"]


def _key(method: str) -> str:
    """A method's name in array keys and column names (``IT+`` -> ``ITplus``)."""
    return method.replace("+", "plus")


def sample_columns(result: LogEstimate) -> dict[str, np.ndarray]:
    """The per-sample arrays by name, as ``samples.npz`` holds them (see the docs for each)."""
    cols: dict[str, np.ndarray] = {"t_s": result.t_s, "t_ns": result.t_ns, "beta": result.beta,
                                   "phidot": result.phidot, "out_of_range": result.out_of_range}
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
    return cols


def _write_csv(result: LogEstimate, modules, path: Path) -> None:
    """samples.csv: the columns of samples.npz flattened, one header name per column."""
    names = ["t_s"] + [f"beta_{m}" for m in modules] + [f"phidot_{m}" for m in modules] + ["out_of_range"]
    blocks = [result.t_s[:, None], result.beta, result.phidot, result.out_of_range[:, None].astype(np.float64)]
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


def summary(result: LogEstimate, source: LogSource, elapsed_s: float) -> dict:
    """The JSON summary: the log, the robot, the samples, the estimators, the odometry."""
    geom = source.geom
    dt = np.diff(result.t_ns) * 1e-9
    return {
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
        "estimators": compare_estimators(result),
        "odometry": {"method": result.odometry_method, "reference": result.truth.source if result.truth else None,
                     "drift": odometry_drift(result)},
        "elapsed_s": elapsed_s,
        "machine": platform.processor() or platform.machine(), "python": sys.version.split()[0],
    }


def _fmt(v, spec: str) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def report_markdown(s: dict, plots: list[str]) -> str:
    """``report.md`` from the :func:`summary`."""
    log, sm, est, odo = s["log"], s["samples"], s["estimators"], s["odometry"]
    lines = [f"# azimut estimate: {log['path']}", ""]
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
    lines += ["", "## Estimators on this log", "",
              "As `azimut bench-estimators` compares them on D2: qua of eq. (28)–(29), the share of finite unit "
              "λ̂, and the cost of each method's `estimate_eta` calls (λ̂, μ̂ and qua) on this log, this machine.", "",
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
    lines += ["", f"Machine: {s['machine']}, Python {s['python']}.", ""]
    return "\n".join(lines)


def write_outputs(result: LogEstimate, source: LogSource, out: Path, *, elapsed_s: float, plots: bool = True,
                  csv: bool = False) -> list[str]:
    """Write everything to ``out`` (created); returns the file names."""
    out.mkdir(parents=True, exist_ok=True)
    cols = sample_columns(result)
    np.savez(out / "samples.npz", **cols)
    files = ["samples.npz"]
    if csv:
        _write_csv(result, source.modules, out / "samples.csv")
        files.append("samples.csv")
    pngs: list[str] = []
    if plots:
        from jobs.estimate.plots import write_plots

        pngs = write_plots(result, source.geom, source.modules, out)
    s = summary(result, source, elapsed_s)
    (out / "summary.json").write_text(json.dumps(s, indent=2, allow_nan=True))
    (out / "report.md").write_text(report_markdown(s, pngs))
    return files + pngs + ["summary.json", "report.md"]
