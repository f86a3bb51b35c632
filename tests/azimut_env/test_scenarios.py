"""Scenario tracks (azimut_env.tracks.scenarios): scaled to each preset, the shape each
complaint needs, holds, and the env building them for its robot."""

import math

import numpy as np
import pytest

from azimut_env.env import AzimutEnv
from azimut_env.params import RobotParams
from azimut_env.robot_file import PRESET_NAMES
from azimut_env.task.lap_time import nominal_duration
from azimut_env.tracks import SCENARIO_NAMES, Track, scenario_track, wrap_angle
from azimut_env.tracks.scenarios import ScenarioScale
from estimation import eta_from_twist


@pytest.mark.parametrize("robot", PRESET_NAMES)
@pytest.mark.parametrize("name", SCENARIO_NAMES)
def test_scenarios_scale_with_the_robot(robot, name):
    p = RobotParams.preset(robot)
    sc = ScenarioScale.of(p)
    tr = scenario_track(name, p)
    assert tr.name == name and not tr.closed
    assert tr.progress_radius == pytest.approx(sc.reach)
    r_phimax = float(np.min(p.geometry.r)) * p.limits.wheel_speed_max
    assert sc.v_max == pytest.approx(r_phimax) and sc.cruise == pytest.approx(0.5 * r_phimax)
    # the chassis never asked to go faster than the top wheel speed
    tw = tr.reference_twist(tr.s)
    assert np.max(np.hypot(tw[:, 0], tw[:, 1])) <= 0.8 * r_phimax * (1 + 1e-9)
    assert np.isfinite(nominal_duration(tr))


def test_swerve_scenarios_are_faster_and_bigger_than_azimut3():
    az, sw = (scenario_track("strafe90", RobotParams.preset(n)) for n in ("azimut3", "swerve"))
    assert sw.max_speed / az.max_speed == pytest.approx(RobotParams.preset("swerve").max_surface_speed / 1.6)
    assert sw.length > az.length


def test_reverse_turns_by_160_degrees_twice_at_rest():
    tr = scenario_track("reverse")
    turns = np.degrees(np.abs(wrap_angle(np.diff(tr.tangent))))
    # each reversal turns 160° in two steps of 80° across a 1 µm step along the bisector
    assert np.allclose(turns[turns > 1.0], 80.0, atol=0.01) and np.count_nonzero(turns > 1.0) == 4
    assert np.count_nonzero(tr.speed < 1e-9) >= 2 + 1  # the two reversals and the end


def test_strafe90_corners_are_90_degrees_at_a_fixed_heading():
    tr = scenario_track("strafe90")
    assert np.ptp(tr.heading) == 0.0
    turns = np.degrees(np.abs(wrap_angle(np.diff(tr.tangent))))
    assert np.allclose(turns[turns > 1.0], 90.0, atol=1e-6) and np.count_nonzero(turns > 1.0) == 3


def test_spin_switches_between_translation_and_rotation_in_place():
    tr = scenario_track("spin")
    tw = tr.reference_twist(tr.s, speed=np.ones_like(tr.s))
    trans = np.hypot(tw[:, 0], tw[:, 1])
    assert np.any((trans < 1e-9) & (np.abs(tw[:, 2]) > 0))  # spinning in place
    assert np.any((trans > 0.5) & (np.abs(tw[:, 2]) < 1e-9))  # translating
    assert np.any((trans > 0.5) & (np.abs(tw[:, 2]) > 0.1))  # both (drive and rotate)


@pytest.mark.parametrize("robot", PRESET_NAMES)
def test_icr_axis_passes_through_the_steering_axis_of_wheel_0(robot):
    p = RobotParams.preset(robot)
    tr = scenario_track("icr-axis", p)
    s = np.linspace(0.05 * tr.length, 0.95 * tr.length, 4000)
    th = tr.sample(s)[:, 2]
    tw = tr.reference_twist(s, speed=np.ones_like(s))
    body = np.stack([np.cos(th) * tw[:, 0] + np.sin(th) * tw[:, 1], -np.sin(th) * tw[:, 0] + np.cos(th) * tw[:, 1],
                     tw[:, 2]], axis=1)
    lam, _ = eta_from_twist(body)
    icr = lam[:, :2] / lam[:, 2:3]
    a0 = p.geometry.axis_xy[0]
    assert np.min(np.hypot(*(icr - a0).T)) < 0.01  # the ICR crosses A_0 (sampling leaves < 1 cm)
    assert np.hypot(*(icr[0] - a0)) > 0.3 and np.hypot(*(icr[-1] - a0)) > 0.3


@pytest.mark.parametrize("robot", ["azimut3", "swerve"])
def test_slalom_lateral_acceleration(robot):
    p = RobotParams.preset(robot)
    sc = ScenarioScale.of(p)
    tr = scenario_track("slalom", p)
    v = 0.8 * sc.v_max
    want = min(0.8 * sc.friction_accel, 0.7 * v * p.limits.steer_rate_max)
    # the weave y = A (1 − cos k x) with its travel direction swinging ±0.6 rad: A k = 0.6, and
    # its peak curvature A k² from the sampled path's extent (2 A) and the slope bound
    amp = np.ptp(tr.xy[:, 1]) / 2
    k = 0.6 / amp
    assert np.max(np.abs(np.diff(tr.xy[:, 1]) / np.diff(tr.xy[:, 0]))) == pytest.approx(0.6, rel=0.01)
    assert amp * k * k * v * v == pytest.approx(want, rel=0.01)
    if robot == "swerve":
        assert want == pytest.approx(0.8 * sc.friction_accel)  # near the friction limit
    assert np.ptp(tr.heading) == 0.0


def test_hold_scenario_and_track_holds():
    tr = scenario_track("hold")
    assert len(tr.holds) == 1 and tr.holds[0][1] == 2.0 and tr.hold_time == 2.0
    s0 = tr.holds[0][0]
    assert float(np.interp(s0, tr.s, tr.speed)) == pytest.approx(0.0, abs=1e-9)
    base = nominal_duration(Track("x", tr.xy, tr.heading, tr.speed, progress_radius=tr.progress_radius))
    assert nominal_duration(tr) == pytest.approx(base + 2.0)
    with pytest.raises(ValueError, match="open track"):
        Track("c", [[0, 0], [1, 0], [1, 1]], 0.0, 0.5, closed=True, holds=((0.5, 1.0),))
    for bad in (((5.0, 1.0),), ((0.5, 0.0),), ((0.5, 1.0), (0.2, 1.0)), "x"):
        with pytest.raises(ValueError):
            Track("o", [[0, 0], [1, 0]], 0.0, 0.5, holds=bad)


def test_env_builds_scenarios_for_its_robot():
    env = AzimutEnv(track="slalom", robot="swerve")
    env.reset(seed=0)
    assert env.track.name == "slalom"
    assert env.track.max_speed == pytest.approx(scenario_track("slalom", RobotParams.preset("swerve")).max_speed)
    env2 = AzimutEnv(track="circle")
    env2.reset(seed=0, options={"track": "hold"})
    assert env2.track.holds
    with pytest.raises(ValueError, match="unknown track"):
        AzimutEnv(track="zigzag")
    assert math.isfinite(env.track.length)
