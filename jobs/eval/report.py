"""``azimut eval``'s report: ``report.md`` and ``metrics.json``, readable without the README.

``report.md`` opens with a verdict (per track and speed scale, the fastest finisher, the least slip
per metre and the least lateral error: :mod:`jobs.eval.verdict`), then says what ran (controllers,
tracks, seeds, speed scales, the robot each controller drove, limits in words), which code ran it
(package version and git commit, :func:`jobs.records.provenance`), the summary table (mean
over seeds, with the bootstrap interval in brackets only where one is shown), with several speed
scales the fronts (:mod:`jobs.eval.fronts`), the plots per track
and controller, the per-seed rows when there are several seeds, and a "Columns" section that
defines every column (:mod:`jobs.glossary`). Counts print as integers. ``metrics.json`` holds the
same as strict JSON (``null`` for undefined values; :func:`jobs.records.write_json`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from jobs.glossary import COUNT_METRICS, GLOSSARY
from jobs.glossary import glossary_lines as _glossary_lines
from jobs.records import provenance_text, write_json

__all__ = ["SUMMARY_COLUMNS", "SCENARIO_COLUMNS", "FRONT_COLUMNS", "write_campaign_report", "limits_text",
           "format_value", "interval_shown", "summary_cell"]

#: the metrics of the summary table, in order: (key, format, scale); headers from jobs.glossary
SUMMARY_COLUMNS = [
    ("completed", "{:.2f}", 1.0),
    ("rms_lateral_m", "{:.2f}", 100.0),
    ("max_lateral_m", "{:.2f}", 100.0),
    ("rms_heading_rad", "{:.2f}", 180.0 / math.pi),
    ("completion_time_s", "{:.1f}", 1.0),
    ("slip_energy_J", "{:.2f}", 1.0),
    ("slip_energy_per_m", "{:.2f}", 1.0),
    ("mean_antagonism_N", "{:.2f}", 1.0),
    ("antagonism_distance_weighted_N", "{:.2f}", 1.0),
    ("mean_nullspace_force_N", "{:.2f}", 1.0),
    ("mean_qua", "{:.4f}", 1.0),
    ("mean_qua_moving", "{:.4f}", 1.0),
    ("min_qua_moving", "{:.4f}", 1.0),
    ("standstill_share", "{:.2f}", 1.0),
    ("standstill_slip_energy_J", "{:.2f}", 1.0),
    ("standstill_mean_antagonism_N", "{:.2f}", 1.0),
    ("limit_violation_steps", "{:.1f}", 1.0),
    ("reconfigure_events", "{:.1f}", 1.0),
    ("return", "{:.1f}", 1.0),
]
#: the columns of a track's fronts table (``--speed-scales``, :mod:`jobs.eval.fronts`), after the
#: controller and the speed scale
FRONT_COLUMNS = [("completed", "{:.2f}", 1.0), ("completion_time_s", "{:.1f}", 1.0),
                 ("slip_energy_per_m", "{:.2f}", 1.0), ("rms_lateral_m", "{:.2f}", 100.0)]
#: the scenarios' own columns (``control.episode.scenario_metrics``), shown when a scenario ran
SCENARIO_COLUMNS = [
    ("peak_steer_rate_cmd", "{:.2f}", 1.0),
    ("peak_steer_rate", "{:.2f}", 1.0),
    ("setpoint_flips", "{:.1f}", 1.0),
    ("travel_reversals", "{:.1f}", 1.0),
    ("hold_chassis_m", "{:.2f}", 1000.0),
    ("hold_yaw_rad", "{:.3f}", 180.0 / math.pi),
    ("hold_steer_rad", "{:.2f}", 180.0 / math.pi),
    ("hold_steer_cmd_rad", "{:.2f}", 180.0 / math.pi),
]


def format_value(key: str, value, fmt: str, scale: float = 1.0) -> str:
    """One table cell: ``-`` for a missing or non-finite value, a count as an integer when it is
    one (a mean over seeds keeps its decimal), otherwise ``fmt`` of ``scale·value``."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    v = scale * value
    if key in COUNT_METRICS and float(v).is_integer():
        return str(int(v))
    return fmt.format(v)


def interval_shown(stats: dict) -> bool:
    """Whether a summary cell shows a bootstrap interval: several seeds that did not all agree."""
    return (bool(stats) and stats.get("n", 0) >= 2 and math.isfinite(stats.get("mean", math.nan))
            and stats["lo"] != stats["hi"])


def summary_cell(key: str, stats: dict, fmt: str, scale: float) -> str:
    """A summary table cell: the mean over seeds, and its interval in brackets where one is shown."""
    if not stats or stats.get("n", 0) == 0 or not math.isfinite(stats["mean"]):
        return "-"
    mean = format_value(key, stats["mean"], fmt, scale)
    if not interval_shown(stats):
        return mean
    return f"{mean} [{format_value(key, stats['lo'], fmt, scale)}, {format_value(key, stats['hi'], fmt, scale)}]"


def _where(item: dict, scales: bool) -> str:
    """The leading cells of a row: controller, track and, with ``scales``, the speed scale."""
    return f"| {item['controller']} | {item['track']} | " + (f"{item.get('speed_scale', 1.0):g} | " if scales else "")


def _summary_table(cells: list[dict], columns: list = SUMMARY_COLUMNS, scales: bool = False) -> list[str]:
    heads = [GLOSSARY[k].header for k, _, _ in columns]
    speed = f"{GLOSSARY['speed_scale'].header} | " if scales else ""
    lines = [f"| controller | track | {speed}episodes ok/failed | " + " | ".join(heads) + " |",
             "|---|---|---|" + "---|" * (len(columns) + scales)]
    for cell in cells:
        stats = cell["metrics"]
        lines.append(f"{_where(cell, scales)}{cell['ok']}/{cell['failed']} | "
                     + " | ".join(summary_cell(k, stats.get(k, {}), fmt, scale) for k, fmt, scale in columns) + " |")
    return lines


def _seed_table(rows: list[dict], columns: list = SUMMARY_COLUMNS, scales: bool = False) -> list[str]:
    cols = [c for c in columns if c[0] != "completed"]
    speed = f"{GLOSSARY['speed_scale'].header} | " if scales else ""
    lines = [f"| controller | track | {speed}seed | status | done | "
             + " | ".join(GLOSSARY[k].header for k, _, _ in cols) + " |",
             "|---|---|---|---|---|" + "---|" * (len(cols) + scales)]
    for r in rows:
        if r.get("status") != "ok":
            lines.append(f"{_where(r, scales)}{r['seed']} | failed: {str(r.get('error', ''))[:80]} "
                         "| - | " + " | ".join("-" for _ in cols) + " |")
            continue
        vals = [format_value(k, r.get(k), fmt, scale) for k, fmt, scale in cols]
        done = format_value("done", r.get("completed"), "{}")
        lines.append(f"{_where(r, scales)}{r['seed']} | ok | {done} | " + " | ".join(vals) + " |")
    return lines


def limits_text(limits) -> str:
    """The actuator limits in words (an ``ActuatorLimits``): steering range, rates, torques."""
    lo, hi = limits.steer_min, limits.steer_max
    steer = ("steering unlimited (no stops)" if not (math.isfinite(lo) and math.isfinite(hi))
             else f"steering range [{math.degrees(lo):.0f}°, {math.degrees(hi):.0f}°]")
    return (f"{steer}; steering rate ≤ {limits.steer_rate_max:g} rad/s, acceleration ≤ {limits.steer_accel_max:g} "
            f"rad/s², torque ≤ {limits.steer_torque_max:g} N·m; wheel speed ≤ {limits.wheel_speed_max:g} rad/s, "
            f"acceleration ≤ {limits.wheel_accel_max:g} rad/s², torque ≤ {limits.wheel_torque_max:g} N·m")


def _statistics_sentence(cells: list[dict], campaign: dict) -> str:
    n_seeds = len(campaign["seeds"])
    failed = ("; failed episodes are left out of the statistics and counted in 'episodes ok/failed'")
    if any(interval_shown(s) for c in cells for s in c["metrics"].values() if isinstance(s, dict)):
        return (f"Mean over the {n_seeds} seeds and, in brackets, the {100 * campaign['level']:.0f}% "
                f"percentile-bootstrap interval of the mean ({campaign['n_resamples']} resamples, seeded; no bracket "
                f"where fewer than two seeds have a value or all gave the same){failed}.")
    if n_seeds == 1:
        return f"One seed: each cell is that episode's value (no interval: run several seeds with --seeds){failed}."
    return f"Mean over the {n_seeds} seeds, which gave the same value in every cell (no interval){failed}."


_PLOT_GUIDE = ("Per track, the controllers overlaid: their trajectories, and their slip power, antagonism and "
               "null-space force over time. Per controller and track: the trajectory over the track (the paper's "
               "Fig. 9; red crosses: stops to turn wheels in place), the measured steering angles in pairs against "
               "the surface S(λ) of consistent configurations (Fig. 10), qua over time (Fig. 11; grey bands: the "
               "controller stopped or turning wheels in place), the estimated ICR λ̂ on the unit sphere seen from "
               "above (colour: time), and each wheel's commands against their limits.")


def _what_ran_lines(campaign: dict, scales: list[float], reference: float) -> list[str]:
    """The "What ran" section: controllers, tracks, seeds, speed scales, robot, limits, executor and
    provenance."""
    from jobs.eval.robots import env_kwargs_sentence, limits_sentence

    seeds = campaign["seeds"]
    several = len(scales) > 1
    specs = campaign.get("controller_specs") or {}
    named = "".join(f"; {name} = {spec}" for name, spec in specs.items())
    return ["", "## What ran", "",
            f"Controllers {', '.join(campaign['controllers'])}{named}; tracks {', '.join(campaign['tracks'])}; "
            f"seeds {_seed_text(seeds)} ({len(seeds)}); "
            + (f"speed scales {', '.join(f'{x:g}' for x in scales)} (the fronts below; plots of ×{reference:g})"
               if several else f"speed scale {scales[0]}") + "; domain randomisation "
            f"{campaign['domain_randomization']}; kicks {'on' if campaign['kicks'] else 'off'}"
            + (f"; max time {campaign['max_time']} s" if campaign.get("max_time") else "") + ".",
            (campaign.get("robot_sentence") or f"Robot {campaign.get('robot', 'azimut3')}"
             + (f" (imperfections: {campaign['imperfections']})" if campaign.get("imperfections") else ""))
            + f"; control period {campaign['control_period']} s; "
            f"{limits_sentence(campaign['limits'])}.",
            *([text] if (text := env_kwargs_sentence(campaign.get("env_kwargs") or {})) else []),
            f"Executor {campaign['executor']} with {campaign['workers']} worker(s); {campaign['computed']} episode(s) "
            f"computed, {campaign['resumed']} resumed; wall time {campaign['wall_s']:.1f} s.",
            f"Produced by {provenance_text(campaign.get('provenance') or {})}."]


def _undefined_and_failed_lines(rows: list[dict], several: bool) -> list[str]:
    """The episodes whose per-metre metrics are undefined, and the failed episodes, one bullet each."""
    lines: list[str] = []
    undefined = sorted({f"{r['controller']} on {r['track']}" + (f" ×{r['speed_scale']:g}" if several else "")
                        + f", seed {r['seed']}: {r['per_m_reason']}" for r in rows if r.get("per_m_reason")})
    if undefined:
        lines += ["", "Per-metre metrics undefined (left out of their means):", ""] + [f"- {u}" for u in undefined]
    failed = [r for r in rows if r.get("status") != "ok"]
    if failed:
        lines += ["", "Failed episodes (an error of the episode's own code is not retried; its traceback is in "
                  "the episode's record):", ""]
        lines += [f"- {r['controller']} on {r['track']}" + (f" ×{r.get('speed_scale', 1.0):g}" if several else "")
                  + f", seed {r['seed']}: {r.get('error')} (after "
                  f"{r.get('attempts', 1)} attempt(s))" + (f"; traceback in `{r['record']}`" if r.get("record") else "")
                  for r in failed]
    return lines


def _plot_lines(campaign: dict, cells: list[dict], plots: dict, compare: dict, table: list, several: bool,
                reference: float, at: str) -> list[str]:
    """The "Plots" section: per track, the comparisons, then each controller's summary row and plots."""
    by_cell = {(c["controller"], c["track"]): c for c in cells if c.get("speed_scale", reference) == reference}
    lines = ["", "## Plots", "", f"Plots are of seed {campaign['plot_seed']}{at}. {_PLOT_GUIDE}"]
    for track in campaign["tracks"]:
        lines += ["", f"### {track}", ""]
        for f in compare.get(track, []):
            lines.append(f"![{Path(f).stem}]({f})")
        for controller in campaign["controllers"]:
            cell = by_cell.get((controller, track))
            lines += ["", f"#### {controller} on {track}", ""]
            if cell is not None:
                lines += _summary_table([cell], table, several)
            lines.append("")
            for f in plots.get((controller, track), []):
                lines.append(f"![{Path(f).stem}]({f})")
    return lines


def _media_lines(campaign: dict, at: str) -> list[str]:
    """The "Videos" and "Episodes as ROS 2 bags" sections, where the campaign wrote any."""
    lines: list[str] = []
    if campaign.get("videos"):
        lines += ["", "## Videos", "", f"Seed {campaign['seeds'][0]}{at}, the env's top-down view of each episode "
                  "(the true ICR as a green ring, the estimated one as a red dot, the propulsion axes in orange):", ""]
        lines += [f"- {what}: [{f}]({f})" for what, f in campaign["videos"].items()]
    if campaign.get("exports"):
        lines += ["", "## Episodes as ROS 2 bags", "", "Joint states, the estimated ICR, the true pose and odometry "
                  "(docs/logs.md); open the .mcap in Foxglove, or `azimut estimate DIR --robot ...` reads it back:", ""]
        lines += [f"- {what}: [{f}]({f})" for what, f in campaign["exports"].items()]
    return lines


def write_campaign_report(out: Path, rows: list[dict], cells: list[dict], campaign: dict,
                          plots: dict[tuple[str, str], list[str]], compare: dict[str, list[str]],
                          fronts: Sequence[str] = ()) -> None:
    """``report.md`` and ``metrics.json`` in ``out`` (plots are paths relative to ``out``; the plots
    of a (controller, track) and the comparisons are of the reference speed scale; ``fronts``: the
    Markdown lines of the fronts section, :func:`jobs.eval.fronts.fronts_lines`, with several
    speed scales)."""
    write_json(out / "metrics.json", {"campaign": campaign, "summary": cells, "episodes": rows})
    seeds = campaign["seeds"]
    from azimut_env.tracks import SCENARIO_NAMES

    table = SUMMARY_COLUMNS + (SCENARIO_COLUMNS if any(t in SCENARIO_NAMES for t in campaign["tracks"]) else [])
    from jobs.eval.verdict import verdict_lines

    scales = [float(x) for x in campaign.get("speed_scales") or [campaign.get("speed_scale") or 1.0]]
    several = len(scales) > 1
    reference = campaign.get("reference_scale", scales[0])
    lines = ["# azimut eval", "", "## Verdict", "",
             f"Best per track{' and speed scale' if several else ''} (means over "
             f"{'the seeds' if len(seeds) > 1 else 'one seed'}, from the summary table below; the least slip is "
             "ranked by the slip energy per metre travelled, which crawling or standing still does not lower):", ""]
    lines += verdict_lines(cells, list(campaign["tracks"]), list(campaign["controllers"]))
    lines += _what_ran_lines(campaign, scales, reference)
    lines += ["", "## Summary", "", _statistics_sentence(cells, campaign), ""]
    lines += _summary_table(cells, table, several)
    lines += _undefined_and_failed_lines(rows, several)
    lines += list(fronts)
    at = f" at speed scale ×{reference:g}" if several else ""
    if plots or compare:
        lines += _plot_lines(campaign, cells, plots, compare, table, several, reference, at)
    lines += _media_lines(campaign, at)
    columns = ["controller", "track"] + (["speed_scale"] if several else []) + ["episodes"] + [k for k, _, _ in table]
    if len(seeds) > 1:
        lines += ["", "## Per-seed rows", ""] + _seed_table(rows, table, several)
        columns += ["seed", "status", "done"]
    lines += [""] + _glossary_lines(columns) + [""]
    (out / "report.md").write_text("\n".join(lines))


def _seed_text(seeds: Sequence[int]) -> str:
    seeds = list(seeds)
    if len(seeds) > 2 and seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}-{seeds[-1]}"
    return ",".join(map(str, seeds))
