"""What every column of the jobs' reports means, in one place: the metrics of an episode
(:func:`control.episode.episode_metrics`) and the other columns of ``azimut eval``'s and
``azimut train --seeds``' tables.

:data:`GLOSSARY` maps a metric key (or a column name) to its table header and definition;
:func:`glossary_lines` writes the Markdown section a report ends with, for the columns it shows.
Definitions cite the estimation paper where they use it: L. Clavien, M. Lauria, F. Michaud,
"Estimation of the Instantaneous Centre of Rotation with Nonholonomic Omnidirectional Mobile
Robots" (its equations (28)–(29) define qua).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

from control.episode import MIN_DISTANCE_M

__all__ = ["Column", "GLOSSARY", "KICK_GLOSSARY", "COUNT_METRICS", "glossary_lines"]


class Column(NamedTuple):
    """One column of a report table."""

    header: str
    definition: str


_QUA = ("qua, the estimation quality of the paper's eq. (28)–(29): qua = 1 − ln(500·m + 1)/ln(501) with "
        "m = Σ_k (q_k − β_k)² / (n·π²) the squared distance, scaled to [0, 1], between the measured steering angles "
        "q of the n wheels and the angles β = S(λ̂) they would have if they all turned about the estimated ICR λ̂; "
        "1 when the measured wheels agree with one instantaneous centre of rotation, lower as they disagree")
_MOVING = ("the moving steps: the controller in its RUNNING mode (not stopping, not turning wheels in place; a "
           "controller without modes always is) and the true chassis speed μ = ‖(ẋ, ẏ, θ̇)‖ above 0.05 m/s")

_LIMITS = ("measured on the set-points themselves whatever rates the controller declares (those the env applies: "
           "read back from the action of a controller that sends its own): the steering rate (β_k − β_{k−1})/dt, "
           "the steering acceleration (its difference over dt), the wheel acceleration (φ̇_k − φ̇_{k−1})/dt, the "
           "wheel speed φ̇_k, and the steering angle β_k against its stops; dt the control period, the first step "
           "differenced against the measured steering angles and wheel speeds at the reset (at rest), with "
           "unlimited steering the angle's change taken the short way round; a rate the controller declares over its "
           "limit counts too; by more than 1e-6 relative (floating rounding; plus a float32 action's own rounding)")

#: metric key or column name -> (header, definition)
GLOSSARY: dict[str, Column] = {
    "controller": Column("controller", "the controller driving the robot: icr (the ICR-based controller on the IT "
                                       "estimate), twist (the WPILib-style swerve baseline), twist-setpoint (a "
                                       "swerve setpoint generator after Team 254's, within the actuator limits), or "
                                       "a trained policy by its short name"),
    "track": Column("track", "the reference path with its heading and speed profiles (random: a track drawn from "
                             "the episode's seed)"),
    "seed": Column("seed", "the episode's seed: sensor noise, start noise, the random track, domain randomisation "
                           "and kicks are drawn from it"),
    "episodes": Column("episodes ok/failed", "episodes that ran to their end (finished or not) / episodes whose "
                                             "run raised an error, after a retry (left out of every statistic)"),
    "status": Column("status", "ok, or failed with the error"),
    "seeds": Column("seeds", "the number of trained seeds with a final evaluation on the track"),
    "completed": Column("done share", "the share of episodes that finished the track (one lap of a closed track, "
                                      "the end of an open one) before the time limit, without leaving the track"),
    "done": Column("done", "yes when the episode finished the track (see done share)"),
    "rms_lateral_m": Column("RMS lat [cm]", "root mean square over the episode's steps of the lateral error: the "
                                            "true distance from the chassis centre to the track's path"),
    "max_lateral_m": Column("max lat [cm]", "the largest lateral error of the episode"),
    "rms_heading_rad": Column("RMS head [deg]", "root mean square of the heading error θ − θ_ref (the chassis "
                                                "heading against the track's heading profile)"),
    "completion_time_s": Column("time [s]", "the simulated time to finish the track; - when it was not finished"),
    "slip_energy_J": Column("slip energy [J]", "the energy the tires dissipated by slipping, ∫ Σ_k |F_k · v_slip,k| "
                                               "dt over the episode (tire force times slip velocity, all wheels)"),
    "mean_antagonism_N": Column(
        "mean antagonism [N]", "the mean over steps of the antagonism of the wheels: the norm of the tire forces minus "
                               "the distribution of their net force and moment that one common rigid slip of the "
                               "chassis would give, each wheel weighted by its tire's slip stiffness (load over "
                               "rolling speed): forces of wheels that push against each other; 0 when every wheel "
                               "is on the constraining surface and at its speed, whatever the loads, the rolling "
                               "speeds and the acceleration (docs/physics.md, Antagonism)"),
    "distance_m": Column("distance [m]", "the path length of the true chassis centre, ∫ |v| dt: its speed |v| = "
                                         "‖(ẋ, ẏ)‖ at the end of each control step times the control period, summed "
                                         "(the same samples and rule as the slip energy)"),
    "slip_energy_per_m": Column(
        "slip per m [J/m]", "the slip energy divided by the distance the chassis centre travelled (distance [m]): what "
                            "the tires dissipate per metre of path, which a controller does not lower by crawling or "
                            f"standing still; - when the chassis travelled less than {100 * MIN_DISTANCE_M:g} cm "
                            "(metrics.json: null, and per_m_reason says why)"),
    "antagonism_distance_weighted_N": Column(
        "antagonism over distance [N]", "the antagonism averaged over the distance instead of the time, ∫ A |v| dt / "
                                        "∫ |v| dt with |v| the chassis centre's speed: a step at rest weighs nothing, "
                                        "so time spent standing still does not dilute the fighting while moving; - "
                                        "as for slip per m"),
    "standstill_slip_energy_J": Column(
        "standstill slip [J]", "the slip energy over the standstill steps alone (the steps that are not moving steps, "
                               "as in standstill share): the tires' fighting while the robot stops or turns its wheels "
                               "in place; 0 without such steps"),
    "standstill_mean_antagonism_N": Column(
        "standstill antagonism [N]", "the mean antagonism over the standstill steps alone (as in standstill share); "
                                     "- without such steps"),
    "speed_scale": Column("speed ×", "the factor the track's speed profile was multiplied by (--speed-scale; "
                                     "--speed-scales runs each controller at several)"),
    "mean_nullspace_force_N": Column(
        "mean null-space force [N]", "the mean over steps of the minimum-norm null-space force (the internal force of "
                                     "earlier reports): the norm of the tire forces minus the least-norm forces giving "
                                     "the same net force and moment; it contains an acceleration floor, since wheels "
                                     "rolling at different speeds or loads share a force unequally even when they "
                                     "agree on one instantaneous centre of rotation"),
    "mean_qua": Column("mean qua (all)", f"the mean over all steps of {_QUA}"),
    "min_qua": Column("min qua (all)", "the smallest qua of the episode"),
    "mean_qua_moving": Column("mean qua moving", f"the mean of qua over {_MOVING}; stops and in-place "
                                                 "reconfigurations, where the wheels turn with the chassis at rest, "
                                                 "are left out"),
    "min_qua_moving": Column("min qua moving", "the smallest qua over the moving steps"),
    "standstill_share": Column("standstill share", "the share of steps that are not moving steps (stopped, or "
                                                   "turning wheels in place)"),
    "limit_violation_steps": Column(
        "limit-exceeded steps", "the number of control steps whose wheel commands exceeded an actuator limit, "
                                f"{_LIMITS}"),
    "reconfigure_events": Column("stop+reconfig", "the number of times the ICR controller stopped the robot to turn "
                                                  "its wheels in place (a steering stop or axis on the way, or a "
                                                  "knocked wheel); 0 for controllers that never stop"),
    "return": Column("return", "the sum of the env's per-step rewards over the episode (Azimut-v2's reward: "
                               "progress minus the tracking, overspeed, slip, antagonism, action-rate and "
                               "off-track costs), what the RL agents maximise"),
}

#: the columns of the kick study's table (``azimut eval --kick-runs N``, :mod:`jobs.eval.robustness`)
KICK_GLOSSARY: dict[str, Column] = {
    "runs": Column("runs", "trials: the robot starts at rest at a random progress on the paper track and, 2 s later, "
                           "1–4 random wheels get an angular impulse of ±0.2–1.0 N·m·s about their steering axes "
                           "(like a collision); each trial runs 6 s after the kick"),
    "recovered": Column("recovered", "trials that ran without an error and without a command over a limit, whose "
                                     "lateral error was back under 5 cm for good within 3 s of the kick"),
    "failed": Column("failed", "trials whose run ended on an error (a physics failure, off the track)"),
    "limit_violation_steps": Column("limit-exceeded steps", "control steps whose commands exceeded an actuator "
                                                            "limit (as in azimut eval's table), summed over the "
                                                            "trials"),
    "recovery": Column("recovery time p50/p90/max [s]", "from the kick until the lateral error is under 5 cm for "
                                                        "good: median, 90th percentile and largest over the trials "
                                                        "that got there"),
    "settle": Column("wheels settled p50/p90/max [s]", "from the kick until every measured steering angle is within "
                                                       "5° of its command (modulo π) for good"),
    "lateral": Column("max lateral after kick p50/p90/max [cm]", "the largest lateral error after the kick"),
    "peak_beta": Column("peak β error p50/max [deg]", "the largest difference between a measured and a commanded "
                                                      "steering angle (modulo π) after the kick"),
}

#: metrics that count something: printed as integers (a mean over seeds with its decimal)
COUNT_METRICS = frozenset({"limit_violation_steps", "reconfigure_events", "setpoint_flips", "travel_reversals",
                           "hold_steps"})

_HOLD = "while the command was a hold (the track held the robot still: the follower commanded exactly zero)"
# the scenarios' own metrics (control.episode.scenario_metrics; azimut_env.tracks.scenarios)
GLOSSARY.update({
    "peak_steer_rate_cmd": Column("peak β̇ cmd [rad/s]", "the largest steering rate the controller commanded, any "
                                                        "module, any step"),
    "peak_steer_rate": Column("peak β̇ [rad/s]", "the largest steering rate of the wheels themselves (their true "
                                                "angles' change over a control period, modulo 2π)"),
    "setpoint_flips": Column("set-point flips", "module set-points that jumped by more than 90° in one control "
                                                "period (a flip of the wheel about its axis)"),
    "travel_reversals": Column("travel reversals", "the times a rolling module's commanded travel direction (its "
                                                   "steering angle, plus π when its wheel turns backward) turned by "
                                                   "more than 90° between consecutive steps while the chassis moved; "
                                                   "by design on the reverse scenario"),
    "hold_steps": Column("hold steps", f"the control periods {_HOLD}"),
    "hold_chassis_m": Column("hold: chassis [mm]", f"the path length of the chassis centre {_HOLD}"),
    "hold_yaw_rad": Column("hold: yaw [deg]", f"the heading travel of the chassis {_HOLD}"),
    "hold_steer_rad": Column("hold: steer [deg]", f"the largest steering travel Σ|Δβ| of a module {_HOLD}"),
    "hold_steer_cmd_rad": Column("hold: steer cmd [deg]", f"the largest commanded steering travel of a module "
                                                          f"{_HOLD}"),
})


def glossary_lines(keys: Iterable[str], glossary: dict[str, Column] | None = None,
                   title: str = "## Columns") -> list[str]:
    """The Markdown lines of a section (``title``) defining the columns ``keys`` (each once, in
    order) from ``glossary`` (default :data:`GLOSSARY`)."""
    glossary = GLOSSARY if glossary is None else glossary
    lines, seen = [title, ""], set()
    for key in keys:
        if key in seen:
            continue
        seen.add(key)
        col = glossary[key]
        lines.append(f"- **{col.header}**: {col.definition}.")
    return lines
