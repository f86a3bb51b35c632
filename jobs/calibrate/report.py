"""The outputs of ``azimut calibrate``: ``calibration.json`` (for ``azimut estimate --calibration``
and for programs) and ``report.md`` (for the team)."""

from __future__ import annotations

import json
import platform
import sys
from pathlib import Path

__all__ = ["write_outputs", "report_markdown"]


def _f(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def _code_forms(result: dict) -> list[str]:
    """The offsets in the forms robot code takes them."""
    mods = result["modules"]
    lines = ["## Paste into your code", ""]
    if not result["common_offset_observable"]:
        lines += ["**These offsets are relative**: this log does not fix the turn all modules share. Point one "
                  "wheel straight ahead by hand, and shift every offset by the same angle so that it reads 0.", ""]
    lines += [
             "`steer_offset_deg` is what to **add** to the angle as logged. Robot code usually subtracts an offset "
             "from the raw encoder (BaseFalconSwerve/WPILib templates `angleOffset`, YAGSL's "
             "`absoluteEncoderOffset`, AdvantageKit's `zeroRotation`): there the offset is the negative. CTRE's "
             "`MagnetOffset` (Phoenix 6, in rotations) is added by the CANcoder itself. If the angles in this log "
             "already had your offsets subtracted (module states, `Adjusted` encoders), the values below are "
             "corrections: subtract them from the offsets your code has now.", "",
             "| module | add to logged angle [deg] | code offset to subtract [deg, 0–360) | [rad] | CTRE MagnetOffset "
             "[rotations] |", "|---|---:|---:|---:|---:|"]
    for m in mods:
        add = m["steer_offset_deg"]
        sub = (-add) % 360.0
        rad = sub * 3.141592653589793 / 180.0
        rot = ((add / 360.0) + 0.5) % 1.0 - 0.5
        lines.append(f"| {m['name']} | {add:+.2f} | {sub:.2f} | {rad:.4f} | {rot:+.5f} |")
    lines += ["", "Java (BaseFalconSwerve/WPILib style, `Cancoder − angleOffset`):", "", "```java"]
    lines += [f"public static final Rotation2d angleOffset{k} = "
              f"Rotation2d.fromDegrees({(-m['steer_offset_deg']) % 360.0:.2f}); // {m['name']}"
              for k, m in enumerate(mods)]
    lines += ["```", ""]
    return lines


def _summary_lines(result: dict) -> list[str]:
    """The robot, the samples, IT's quality before and after, and what the log fixes (common offset,
    wheel factors), with the fit's notes."""
    mods, before, after, cur = result["modules"], result["before"], result["after"], result["current"]
    sm = result["samples"]
    lines: list[str] = []
    rob = result["robot"]
    conv = result["log"].get("steer_convention") or ("heading" if "states_entry" in result["log"] else "beta")
    lines.append(f"Robot: {rob['n']} modules ({', '.join(rob['modules'])}) at α = "
                 f"{', '.join(f'{a:.1f}' for a in rob['alpha_deg'])}°, l = {', '.join(f'{x:.3f}' for x in rob['l_m'])} "
                 f"m, b = {', '.join(f'{x:.3f}' for x in rob['b_m'])} m; angles read as "
                 + ("module headings (WPILib's convention)" if conv == "heading" else
                    "the paper's β (a log of WPILib headings needs --steer-convention heading)") + ".")
    lines.append(f"Calibrated on {sm['moving']} moving samples ({sm['fitted']} fitted) of {sm['read']} read over "
                 f"{sm['duration_s']:.1f} s; moving: the wheels' rigid fit moves a steering axis at "
                 f"{result['moving_speed_mps']} m/s or faster.")
    qa = 100 * after["qua_IT_mean"]
    qb = 100 * before["qua_IT_mean"]
    line = f"IT's quality while moving: {qb:.2f}% as logged"
    if cur is not None:
        line += f", {100 * cur['qua_IT_mean']:.2f}% with your current offsets"
    lines.append(line + f", **{qa:.2f}% calibrated** (100%: the wheels agree on one centre of rotation).")
    worst = max(mods, key=lambda m: abs(m.get("change_from_current_deg", 0.0)))
    if cur is not None:
        lines.append(f"Largest change from your current offsets: module {worst['name']}, "
                     f"{worst['change_from_current_deg']:+.2f}°.")
    lines.append("The common offset of all modules is " + (
        f"fixed by the log (±{result['common_offset_std_deg']:.2f}°)." if result["common_offset_observable"]
        else "not fixed by this log (the robot barely turns, no gyro): the offsets are relative"
             + (" and keep your current offsets' common part." if cur is not None else ", with a mean of zero.")))
    lines.append("Wheel factors are " + ("absolute (the gyro's yaw rate fixes them)." if result["wheel_scale_absolute"]
                                         else "relative (geometric mean 1)."))
    for note in result["notes"]:
        lines.append(f"Note: {note}")
    lines.append(f"Fit: {result['fit']['iterations']} Gauss–Newton iterations, RMS residual "
                 f"{result['fit']['rms_residual_deg']:.2f}° per sample (outliers included; Huber-weighted in the fit).")
    return lines


def _offsets_table(result: dict) -> list[str]:
    """The offsets and wheel factors per module, with their uncertainties."""
    mods, cur = result["modules"], result["current"]
    lines: list[str] = []
    lines += ["", "## Offsets and wheel factors", "",
              "Uncertainty: the standard error of the fit, and half the difference between the fits on the first "
              "and second halves of the moving samples (errors that repeat through the log show in neither; '-' "
              "where a half alone cannot be fitted).", "",
              "| module | steer offset [deg] | ± s.e. | halves ± | " + ("change from current [deg] | " if cur else "")
              + "wheel factor | ± s.e. | halves ± |",
              "|---|---:|---:|---:|" + ("---:|" if cur else "") + "---:|---:|---:|"]
    for m in mods:
        lines.append(f"| {m['name']} | {m['steer_offset_deg']:+.3f} | {m['steer_offset_std_deg']:.3f} | "
                     f"{_f(m['steer_offset_halves_spread_deg'], '.3f')} | "
                     + (f"{m['change_from_current_deg']:+.3f} | " if cur else "")
                     + f"{m['wheel_scale']:.4f} | {m['wheel_scale_std']:.4f} | "
                     f"{_f(m['wheel_scale_halves_spread'], '.4f')} |")
    return lines


def _before_after_table(result: dict) -> list[str]:
    """IT's quality and each module's departure as logged, with the current offsets and calibrated."""
    mods, before, after, cur = result["modules"], result["before"], result["after"], result["current"]
    lines: list[str] = []
    lines += ["", "## Before and after (moving samples)", "",
              "Departure: the measured steering angle minus the constraining surface at IT's estimate, per module "
              "[deg]: signed mean / mean |·| / 95th percentile.", "",
              "| | IT qua mean % | IT qua p5 % | " + " | ".join(m["name"] for m in mods) + " |",
              "|---|---:|---:|" + "---:|" * len(mods)]
    rows = [("as logged", before)] + ([("your current offsets", cur)] if cur else []) + [("calibrated", after)]
    for label, fig in rows:
        deps = [f"{s:+.2f} / {a:.2f} / {p:.2f}" for s, a, p in zip(fig["departure_signed_mean_deg"],
                                                                   fig["departure_mean_abs_deg"],
                                                                   fig["departure_p95_deg"])]
        lines.append(f"| {label} | {100 * fig['qua_IT_mean']:.3f} | {100 * fig['qua_IT_p5']:.3f} | "
                     + " | ".join(deps) + " |")
    return lines


def report_markdown(result: dict, elapsed_s: float) -> str:
    """``report.md``: warnings, summary, the offsets table, before and after, the code forms."""
    lines = [f"# azimut calibrate: {result['log'].get('path', '')}", ""]
    for w in result.get("warnings", []):
        lines.append(f"**Check before pasting:** {w}")
    if result.get("warnings"):
        lines.append("")
    lines += _summary_lines(result)
    lines += _offsets_table(result)
    lines += _before_after_table(result)
    lines += [""] + _code_forms(result)
    lines += ["Apply it to an estimate: `azimut estimate LOG ... --calibration calibration.json`.", "",
              f"Calibrated in {elapsed_s:.1f} s (reading included); machine "
              f"{platform.processor() or platform.machine()}, Python {sys.version.split()[0]}.", ""]
    return "\n".join(lines)


def write_outputs(result: dict, source, out: Path, *, elapsed_s: float) -> list[str]:
    out.mkdir(parents=True, exist_ok=True)
    (out / "calibration.json").write_text(json.dumps({**result, "elapsed_s": elapsed_s}, indent=2))
    (out / "report.md").write_text(report_markdown(result, elapsed_s))
    return ["calibration.json", "report.md"]
