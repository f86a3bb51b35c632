"""The WPILib-style twist baseline and the path follower (no physics needed)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from kinematic_model import KinematicRobot

from azimut_env.tracks import Track
from control.follow.path_follower import PathFollower, PathFollowerConfig
from control.twist.wpilib import (
    SwerveConfig,
    SwerveController,
    desaturate,
    discretize_twist,
    module_states,
    optimize_module,
    slew_limit,
)


def _exp_pose(twist, dt):
    """Pose reached from the origin after dt at a constant chassis twist (SE(2) exponential)."""
    vx, vy, w = np.asarray(twist) * dt
    if abs(w) < 1e-12:
        return np.array([vx, vy, 0.0])
    s, c = math.sin(w), math.cos(w)
    return np.array([(s * vx - (1 - c) * vy) / w, ((1 - c) * vx + s * vy) / w, w])


def _drive(ctl, robot, twist, steps: int, dt: float = 0.02):
    """Drive the kinematic robot for ``steps`` control periods at a constant twist target;
    returns the last (twist, slip) of the robot."""
    for _ in range(steps):
        cmd = ctl.step(np.asarray(twist, dtype=float), robot.beta)
        out = robot.step(cmd.beta, cmd.phidot, dt)
    return out


@pytest.mark.parametrize("twist", [(1.0, 0.0, 0.0), (0.5, -0.2, 1.5), (0.0, 0.3, -2.0)])
def test_discretize_is_the_log_of_the_one_period_pose(twist):
    dt = 0.1
    d = discretize_twist(np.array(twist), dt)
    np.testing.assert_allclose(_exp_pose(d, dt), np.array(twist) * dt, atol=1e-12)
    if twist[2] == 0:
        np.testing.assert_allclose(d, twist)


def test_module_states_translation_and_rotation(geom):
    heading, speed = module_states(np.array([0.0, 1.0, 0.0]), geom)
    np.testing.assert_allclose(heading, np.pi / 2)
    np.testing.assert_allclose(speed, 1.0)
    heading, speed = module_states(np.array([0.0, 0.0, 1.0]), geom)
    np.testing.assert_allclose(speed, geom.l)
    np.testing.assert_allclose(np.cos(heading - geom.alpha), 0.0, atol=1e-12)  # tangential


def test_optimize_flips_and_stays_in_range(geom):
    beta, speed = optimize_module(np.array([1.4, 1.0, -1.0, 3.0]), np.ones(4), np.array([-1.4, 1.0, 0.0, 0.0]), geom)
    assert np.all(beta > geom.steer_min) and np.all(beta <= geom.steer_max)
    # wheel 0: 2.8 rad from −1.4, WPILib would flip, but 1.4 − π is past the stop: flipped back
    np.testing.assert_allclose(beta, [1.4, 1.0, -1.0, 3.0 - np.pi])
    np.testing.assert_allclose(speed, [1, 1, 1, -1])


def test_desaturate_and_slew():
    np.testing.assert_allclose(desaturate(np.array([10.0, -40.0]), 20.0), [5.0, -20.0])
    np.testing.assert_allclose(desaturate(np.array([1.0, -2.0]), 20.0), [1.0, -2.0])
    np.testing.assert_allclose(slew_limit([1.0, -1.0, 0.0], [0.0, 0.0, 0.0], [2.0, 2.0, 2.0], 0.1), [0.2, -0.2, 0.0])


def test_swerve_drives_straight_without_slip_and_holds_at_zero(geom, limits):
    ctl = SwerveController(geom, limits, 0.02)
    robot = KinematicRobot.at_rest(geom)
    ctl.reset(robot.beta)
    twist, slip = _drive(ctl, robot, [0.6, 0.2, 0.0], 100)
    assert slip < 1e-9
    np.testing.assert_allclose(twist, [0.6, 0.2, 0.0], atol=1e-9)
    beta_stop = robot.beta.copy()
    _drive(ctl, robot, [0.0, 0.0, 0.0], 50)
    np.testing.assert_allclose(robot.beta, beta_stop)  # WPILib keeps headings at zero speed
    np.testing.assert_allclose(robot.phidot, 0.0, atol=1e-12)


def test_swerve_rotation_uses_contact_point_speed(geom, limits):
    """With offset b, r φ̇ = v(A)·d − ω b realises the twist exactly (no slip)."""
    ctl = SwerveController(geom, limits, 0.02, SwerveConfig(discretize=False))
    robot = KinematicRobot.at_rest(geom, beta=np.zeros(4))
    ctl.reset(robot.beta)
    twist, slip = _drive(ctl, robot, [0.3, 0.0, 0.8], 200)
    assert slip < 1e-9
    np.testing.assert_allclose(twist, [0.3, 0.0, 0.8], atol=1e-9)


def test_swerve_bad_input(geom, limits):
    ctl = SwerveController(geom, limits, 0.02)
    with pytest.raises(ValueError):
        ctl.step(np.array([np.nan, 0, 0]), np.zeros(4))
    with pytest.raises(ValueError):
        ctl.step(np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError):
        SwerveConfig(speed_deadband=-1.0)


def _line_track():
    return Track.from_waypoints([[0.0, 0.0], [5.0, 0.0]], heading=0.3, speed=0.5, ramp=0.0)


def test_follower_corrects_toward_the_path_with_independent_heading():
    pf = PathFollower(_line_track(), PathFollowerConfig(preview=0.0))
    out = pf.step(np.array([1.0, 0.1, 0.3]))  # 10 cm left of the path, heading on profile
    c, s = math.cos(0.3), math.sin(0.3)
    world = np.array([c * out.twist[0] - s * out.twist[1], s * out.twist[0] + c * out.twist[1]])
    assert world[0] == pytest.approx(0.5, abs=1e-6)  # feed-forward along the path
    assert world[1] < -0.2  # back toward the path
    assert out.twist[2] == pytest.approx(0.0, abs=1e-9)  # heading already on its profile
    out = pf.step(np.array([1.0, 0.0, 0.0]))  # heading off by −0.3 rad: turn, path unchanged
    assert out.twist[2] > 0
    assert out.mu == pytest.approx(np.linalg.norm(out.twist))


def test_follower_integrates_only_while_progressing_along_the_track():
    """Anti-windup: a robot standing 3 cm off the path (turning its wheels in place after a knock)
    with its chassis shaking sideways does not wind the integral up; driving along the path does."""
    pf = PathFollower(_line_track(), PathFollowerConfig(preview=0.0))
    rng = np.random.default_rng(0)
    for _ in range(100):  # shakes by up to ±2 mm a step, but makes no progress
        pf.step(np.array([1.0 + rng.uniform(-1e-3, 1e-3), 0.03 + rng.uniform(-2e-3, 2e-3), 0.3]))
    assert abs(pf._integral) < 5 * 0.03 * 0.02  # a few steps at most, while the shaking starts
    before = pf._integral
    for k in range(10):
        pf.step(np.array([1.0 + 0.01 * (k + 1), 0.03, 0.3]))  # 0.5 m/s along the path
    assert pf._integral < before - 5 * 0.03 * 0.02  # integrates, toward the path (the robot is to its left)


def test_follower_bad_input():
    with pytest.raises(ValueError):
        PathFollower("paper")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        PathFollower(_line_track()).step(np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError):
        PathFollowerConfig(k_pos=0.0)
