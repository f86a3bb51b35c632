"""Scenario tracks: one per situation swerve-drive users report as failing, each isolating one.

``reverse``, ``spin``, ``strafe90``, ``icr-axis``, ``hold``, ``slalom`` (:data:`SCENARIO_NAMES`),
built by :func:`scenario_track` for a given robot. Every length and speed is a multiple of the
robot's own scales (:class:`ScenarioScale`), so a scenario asks the same of a 1.6 m/s AZIMUT-3
and of a 4.7 m/s swerve robot:

* v_max = r φ̇_max, the top wheel surface speed (smallest wheel); the cruise speed is v_max/2;
* a = r φ̈_max, the wheel acceleration limit at the surface; speed ramps brake at a/2, over
  ``ramp`` = v²/a metres;
* reach = max_k (l_k + |b_k|), how far a contact point is from the centre; the legs are
  max(6 reach, 1.5 s of cruise + two ramps) long, the spins turn at cruise/reach (wheels at the
  cruise speed), the track's progress radius is the reach (a spin's progress speed is the
  wheels' speed);
* μ g, the friction limit of the lateral acceleration, and the steering rate limit β̇_max, which
  bounds the lateral acceleration a translating robot can take at speed v to v β̇_max (``slalom``).

The user reports cited below are public issue threads (repository, number, title, year).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from azimut_env.params import RobotParams
from azimut_env.tracks.library import TRACK_NAMES, make_track
from azimut_env.tracks.track import Track

__all__ = ["SCENARIO_NAMES", "ALL_TRACK_NAMES", "ScenarioScale", "scenario_track", "named_track", "reverse_scenario",
           "spin_scenario", "strafe90_scenario", "icr_axis_scenario", "hold_scenario", "slalom_scenario"]

SCENARIO_NAMES = ("reverse", "spin", "strafe90", "icr-axis", "hold", "slalom")
#: every track name the env, ``azimut eval`` and the episode runner take
ALL_TRACK_NAMES = TRACK_NAMES + SCENARIO_NAMES
_SPACING = 0.02  # [m] between samples


@dataclass(frozen=True)
class ScenarioScale:
    """The robot's scales the scenarios are built from (module docstring).

    Attributes:
        v_max: top wheel surface speed r φ̇_max [m/s]. cruise: v_max / 2 [m/s].
        accel: wheel acceleration limit at the surface r φ̈_max [m/s²].
        reach: max_k (l_k + |b_k|) [m]. friction_accel: μ g [m/s²].
    """

    v_max: float
    cruise: float
    accel: float
    reach: float
    friction_accel: float

    @classmethod
    def of(cls, params: RobotParams) -> ScenarioScale:
        g, lim = params.geometry, params.limits
        r = float(np.min(g.r))
        return cls(v_max=r * lim.wheel_speed_max, cruise=0.5 * r * lim.wheel_speed_max, accel=r * lim.wheel_accel_max,
                   reach=float(np.max(g.l + np.abs(g.b))), friction_accel=params.tire.friction * params.gravity)

    @property
    def ramp(self) -> float:
        """Distance [m] to brake from the cruise speed at half the acceleration limit."""
        return self.cruise**2 / self.accel

    @property
    def leg(self) -> float:
        """Length [m] of a scenario's straight leg."""
        return max(6.0 * self.reach, 1.5 * self.cruise + 2.0 * self.ramp)


def _line(p0, p1) -> np.ndarray:
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    count = max(1, int(math.ceil(np.hypot(*(p1 - p0)) / _SPACING)))
    return p0 + (np.arange(count) / count)[:, None] * (p1 - p0)


def _spin(p, th0: float, dth: float, rho: float) -> tuple[np.ndarray, np.ndarray]:
    """Samples of a rotation in place at p from heading th0 by dth [rad] (without the last)."""
    count = max(2, int(math.ceil(abs(dth) * rho / _SPACING)))
    return np.repeat(np.asarray(p, float)[None], count, axis=0), th0 + dth * np.arange(count) / count


def _stops_profile(track: Track, stops, v: float, ramp: float) -> np.ndarray:
    """v on the track's progress, falling as sqrt to 0 at each progress in ``stops`` over ``ramp``."""
    scale = np.ones_like(track.s)
    for s0 in stops:
        scale = np.minimum(scale, np.sqrt(np.clip(np.abs(track.s - s0) / ramp, 0.0, 1.0)))
    return v * scale


def _finish(name: str, xy, th, sc: ScenarioScale, stops_at=(), holds=()) -> Track:
    """A track through the samples at the cruise speed, stopping at the sample indices
    ``stops_at`` (and holding there for ``holds`` [s] each), with ramps at both ends."""
    xy, th = np.asarray(xy, float), np.asarray(th, float)
    base = Track(name, xy, th, sc.cruise, progress_radius=sc.reach)
    stops = [float(base.s[i]) for i in stops_at]
    v = _stops_profile(base, stops, sc.cruise, sc.ramp)
    hold = tuple((s, d) for s, d in zip(stops, holds))
    return Track(name, base.xy, base.heading, v, progress_radius=sc.reach, holds=hold).with_ramps(sc.ramp)


def reverse_scenario(sc: ScenarioScale) -> Track:
    """**A command reversing through zero.** Three straight legs at a fixed heading (0.3 rad, so
    the travel is oblique to the chassis and no wheel sits at a symmetric angle): out, back at
    160° from the first leg, out again parallel to the first; the speed falls to zero at each
    reversal and rises again. The return leg is 20° off the way out (not 180°) so that the two
    legs do not overlap (the reference would be ambiguous there) and so that every module must
    turn by 20° or 160° at rest, the choice the per-module ``optimize`` makes one wheel at a time.
    (Each reversal point is followed by a 1 µm step along the bisector of the two legs: the
    track's reference direction, central differences of its samples, then turns from one leg to
    the other through the bisector instead of nearly cancelling at a one-sample cusp, where a
    path follower would stall short of the point.)

    Isolates: wpilibsuite/allwpilib issue #5313, "Swerve Drive Optimize does not consider full
    robot" (2023: per-module optimisation turns one module the other way, a "huge yaw" on it);
    REVrobotics/MAXSwerve-Java-Template pull request #16, "Fix slew rate limiter drift when
    stopping" (2023: the direction slew limiter swept the travel direction back while coasting to
    a stop), and its issue #10 (quick forward/back reversals); frankarobotics/franka_ros2 issue
    #246, "SwerveDriveController: module steering rate is unbounded with respect to the
    commanded twist" (modules slew at full speed when a command reverses)."""
    d = sc.leg
    back = math.radians(160.0)
    p1 = np.array([d, 0.0])
    p2 = p1 + d * np.array([math.cos(back), math.sin(back)])
    p3 = p2 + np.array([d, 0.0])
    a, b, c = _line((0.0, 0.0), p1), _line(p1, p2), _line(p2, p3)
    bis = 1e-6 * np.array([math.cos(0.5 * back), math.sin(0.5 * back)])  # 80°: between 0° and 160° at both
    xy = np.vstack([a, b[:1], b[:1] + bis, b[1:], c[:1], c[:1] + bis, c[1:], p3[None]])
    i1 = len(a)
    i2 = i1 + len(b) + 1
    return _finish("reverse", xy, np.full(len(xy), 0.3), sc, stops_at=(i1, i2))


def spin_scenario(sc: ScenarioScale) -> Track:
    """**Switching between translation and spinning in place.** A translation; a spin in place by
    π (the speed through zero at each switch); a translation on along the same line (the robot
    now backward to it); a translation of the same length while the heading turns back by π (drive
    and rotate together, entered from the translation without stopping); a spin in place by π/2.
    Spins turn at cruise/reach, the wheels at the cruise speed.

    Isolates: wpilibsuite/allwpilib issue #5349, "Use Pose2d.log() to fix swerve drive veering
    off straight line while driving and rotating" (2023); mjansen4857/pathplanner issue #1059,
    "Swerve Setpoint Generator should use field-relative speeds" (2025: the robot spirals when
    spinning while driving); and the ICR's jump from the horizon (translation) to the centre
    (spin) that a switch asks of the wheels."""
    d, rho = sc.leg, sc.reach
    a = _line((0.0, 0.0), (d, 0.0))
    s1_xy, s1_th = _spin((d, 0.0), 0.0, math.pi, rho)
    b = _line((d, 0.0), (2 * d, 0.0))
    c = _line((2 * d, 0.0), (3 * d, 0.0))
    c_th = math.pi - math.pi * np.arange(len(c)) / len(c)
    s2_xy, s2_th = _spin((3 * d, 0.0), 0.0, math.pi / 2, rho)
    xy = np.vstack([a, s1_xy, b, c, s2_xy, [[3 * d, 0.0]]])
    th = np.concatenate([np.zeros(len(a)), s1_th, np.full(len(b), math.pi), c_th, s2_th, [math.pi / 2]])
    i1 = len(a)
    i2 = i1 + len(s1_xy)
    i3 = i2 + len(b) + len(c)
    return _finish("spin", xy, th, sc, stops_at=(i1, i2, i3))


def strafe90_scenario(sc: ScenarioScale) -> Track:
    """**A 90° change of travel direction.** A staircase at a fixed heading 0: legs along X, Y,
    X, Y of the chassis, sharp corners where the speed falls to zero and the travel direction
    turns by exactly 90°, so every module must turn by 90° (either way: at exactly 90° the
    measurement noise decides each module's way for a per-module optimisation).

    Isolates: wpilibsuite/allwpilib issue #5313, "Swerve Drive Optimize does not consider full
    robot" (2023: three modules 88° off turn one way, the fourth at 92° the other);
    frankarobotics/franka_ros2 issue #246 (the steering rate is unbounded when the commanded
    direction changes)."""
    d = sc.leg
    pts = np.array([[0.0, 0.0], [d, 0.0], [d, d], [2 * d, d], [2 * d, 2 * d]])
    legs = [_line(pts[j], pts[j + 1]) for j in range(4)]
    xy = np.vstack(legs + [pts[-1:]])
    corners = np.cumsum([len(seg) for seg in legs[:3]])
    return _finish("strafe90", xy, np.zeros(len(xy)), sc, stops_at=tuple(int(i) for i in corners))


def icr_axis_scenario(sc: ScenarioScale, params: RobotParams) -> Track:
    """**The ICR crossing a wheel's steering axis.** The robot turns at a constant rate about an
    ICR that moves, in the chassis frame, on a straight line through the steering axis A_0 of
    wheel 0, perpendicular to O A_0, from 1.5 reach before it to 1.5 reach after it at a quarter
    of the cruise speed. Wheel 0's steering angle is undefined where the ICR is on its axis
    (estimation paper, eq. (21)) and its wheel speed passes through zero there; the turn rate
    keeps every contact point within the cruise speed.

    Isolates: ros-controls/ros2_controllers issue #1425, "Add a controller for a four wheel
    independent steering / drive mobile base, aka a swerve drive" (the discussion of twists the
    wheels cannot take: the admissible set is discontinuous, and the ICR on a steering axis is
    where it breaks)."""
    g = params.geometry
    a0 = g.axis_xy[0]
    u = np.array([-a0[1], a0[0]]) / np.hypot(*a0)
    half = 1.5 * sc.reach
    v_icr = 0.25 * sc.cruise
    T = 2.0 * half / v_icr
    # the turn rate that keeps the farthest contact point at the cruise speed
    icr_path = a0 + np.outer(np.linspace(-half, half, 9), u)
    farthest = float(np.max(np.linalg.norm(g.axis_xy[None, :, :] - icr_path[:, None, :], axis=-1)))
    omega = sc.cruise / (farthest + float(np.max(np.abs(g.b))))
    dt = _SPACING / sc.cruise
    t = np.arange(0.0, T + dt / 2, dt)
    pose = np.zeros((t.size, 3))
    for i in range(1, t.size):
        p = a0 + (t[i - 1] / T - 0.5) * 2.0 * half * u  # the ICR in the chassis frame
        x, y, th = pose[i - 1]
        c, s = math.cos(th), math.sin(th)
        icr = np.array([x + c * p[0] - s * p[1], y + s * p[0] + c * p[1]])
        rel = np.array([x, y]) - icr
        w = omega * dt
        cw, sw = math.cos(w), math.sin(w)
        pose[i, :2] = icr + np.array([cw * rel[0] - sw * rel[1], sw * rel[0] + cw * rel[1]])
        pose[i, 2] = th + w
    base = Track("icr-axis", pose[:, :2], pose[:, 2], sc.cruise, progress_radius=sc.reach)
    speed = np.append(np.diff(base.s) / dt, 0.0)  # the progress speed of the motion as designed
    speed[-1] = speed[-2]
    return Track("icr-axis", base.xy, base.heading, speed, progress_radius=sc.reach).with_ramps(sc.ramp)


def hold_scenario(sc: ScenarioScale, hold_s: float = 2.0) -> Track:
    """**Modules must not turn while the command is zero: stop, hold, go.** A straight leg at a
    fixed heading (0.3 rad), a stop, ``hold_s`` seconds of an exactly zero command
    (``Track.holds``), then on along the same line.

    Isolates: wpilibsuite/allwpilib issue #4204, "Maintain swerve module angles when robot
    stops" (2022, fixed by pull request #4208: inverse kinematics of a zero chassis speed turned
    the modules); CrossTheRoadElec/Phoenix-Releases issue #87, "SwerveDrive rotates all modules
    when commanded zero ChassisSpeeds" (2025: the modules formed the rotate-in-place circle as
    the robot stopped, from a small rotation output); ros-controls/ros2_controllers pull request
    #1694 (wheels straighten when the commands stop)."""
    d = sc.leg
    a, b = _line((0.0, 0.0), (d, 0.0)), _line((d, 0.0), (2 * d, 0.0))
    xy = np.vstack([a, b, [[2 * d, 0.0]]])
    return _finish("hold", xy, np.full(len(xy), 0.3), sc, stops_at=(len(a),), holds=(hold_s,))


def slalom_scenario(sc: ScenarioScale, steer_rate_max: float) -> Track:
    """**Driving near the friction limit.** A weave y = A (1 − cos k x) over two periods at a
    fixed heading (the robot translates, as a field-oriented swerve robot does), at 0.8 v_max,
    with the peak lateral acceleration a = v² A k² = min(0.8 μ g, 0.7 v β̇_max): 0.8 μ g where the
    steering can turn the wheels fast enough (the travel direction turns at a/v), else as near as
    the steering rate allows (AZIMUT-3's 4 rad/s gives 0.46 μ g at 1.28 m/s; the swerve preset
    reaches 0.8 μ g). The travel direction swings ±0.6 rad (A k = 0.6), inside the ±45° that
    AZIMUT-class wheels cover without a stop. Straight run-in and run-out legs to reach the speed.

    Isolates: Shenzhen-Robotics-Alliance/maple-sim issue #96, "Improve Accuracy by Simulating
    Force on Each Swerve Module" (2025) and pull request #123, "Simulates dynamic weight
    distribution" (per-module friction near the limit); mjansen4857/pathplanner issue #947 (2024:
    deceleration limited like acceleration near the torque and friction limits)."""
    v = 0.8 * sc.v_max
    a_lat = min(0.8 * sc.friction_accel, 0.7 * v * steer_rate_max)
    kappa = a_lat / (v * v)
    k = kappa / 0.6
    amp = 0.6 / k
    run = max(v * v / sc.accel, 2.0 * sc.reach)
    length = 2 * (2 * math.pi / k)
    x = np.arange(0.0, length, _SPACING / 2)
    xy = np.vstack([_line((-run, 0.0), (0.0, 0.0)), np.stack([x, amp * (1.0 - np.cos(k * x))], axis=1),
                    _line((length, 0.0), (length + run, 0.0))[1:], [[length + run, 0.0]]])
    return Track("slalom", xy, 0.0, v, progress_radius=sc.reach).with_ramps(run)


def scenario_track(name: str, params: RobotParams | None = None) -> Track:
    """The scenario ``name`` (:data:`SCENARIO_NAMES`) for the robot ``params`` (default
    ``RobotParams()``), scaled as the module docstring says."""
    if name not in SCENARIO_NAMES:
        raise ValueError(f"unknown scenario {name!r}; choose from {', '.join(SCENARIO_NAMES)}")
    params = params if params is not None else RobotParams()
    sc = ScenarioScale.of(params)
    if name == "icr-axis":
        return icr_axis_scenario(sc, params)
    if name == "slalom":
        return slalom_scenario(sc, params.limits.steer_rate_max)
    return {"reverse": reverse_scenario, "spin": spin_scenario, "strafe90": strafe90_scenario,
            "hold": hold_scenario}[name](sc)


def named_track(name: str, params: RobotParams | None = None, rng: np.random.Generator | None = None) -> Track:
    """A built-in track (:func:`~azimut_env.tracks.library.make_track`; ``random`` draws from
    ``rng``) or a scenario for the robot ``params`` (:func:`scenario_track`), by name
    (:data:`ALL_TRACK_NAMES`)."""
    if name in SCENARIO_NAMES:
        return scenario_track(name, params)
    return make_track(name, rng=rng)
