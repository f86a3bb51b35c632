"""The antagonism measure (:mod:`azimut_env.physics.antagonism`): closed forms and properties of
the stiffness-weighted internal force, and the issue's checks in the physics: a perfectly
coordinated robot (wheels held on the constraining surface, no motor lag) reads below 0.5 N on
``circle`` at 0.4 / 0.8 / 1.2 m/s and accelerating on a straight line, where the minimum-norm
null-space force reads its acceleration floor; one wheel 5° off reads what the null-space force
reads."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from azimut_env.params import RobotParams
from azimut_env.physics.antagonism import (
    antagonism_forces,
    antagonism_kernel,
    natural_forces,
    slip_damping,
    slip_damping_kernel,
    wrench_map,
)
from azimut_env.physics.engine import WP, AzimutPhysics
from azimut_env.physics.layout import WS_CONTACT
from azimut_env.tracks import make_track
from estimation import eta_from_twist, steering_from_lambda, wheel_speeds


def _kernel(forces, contacts, gamma, dampings) -> float:
    f = np.ascontiguousarray(forces, dtype=np.float64)
    p = np.ascontiguousarray(contacts, dtype=np.float64)
    d = np.asarray(dampings, dtype=np.float64)
    return antagonism_kernel(p, f, np.ascontiguousarray(gamma, dtype=np.float64), np.ascontiguousarray(d[:, 0]),
                             np.ascontiguousarray(d[:, 1]), p.shape[0])


def _rigid_slip_forces(contacts, gamma, dampings, xi) -> np.ndarray:
    """F = −D J ξ: the forces of a rigid slip field ξ = (v_x, v_y, ω), wheel by wheel."""
    p = np.asarray(contacts)
    out = np.empty_like(p)
    for k, (px, py) in enumerate(p):
        s = np.array([xi[0] - xi[2] * py, xi[1] + xi[2] * px])
        d = np.array([math.sin(gamma[k]), -math.cos(gamma[k])])
        e = np.array([math.cos(gamma[k]), math.sin(gamma[k])])
        out[k] = -(dampings[k][0] * d * (d @ s) + dampings[k][1] * e * (e @ s))
    return out


_finite = dict(allow_nan=False, allow_infinity=False)


@st.composite
def _robots(draw):
    """n wheels with random contact points, angles, loads, speeds, tire and drive parameters."""
    n = draw(st.integers(2, 6))
    floats = lambda lo, hi: st.floats(lo, hi, **_finite)  # noqa: E731
    contacts = np.array([[draw(floats(-1.0, 1.0)), draw(floats(-1.0, 1.0))] for _ in range(n)])
    # two contacts at least 5 cm apart: the wrench map has rank 3
    if max(np.linalg.norm(contacts[i] - contacts[j]) for i in range(n) for j in range(i + 1, n)) < 0.05:
        contacts[1] = contacts[0] + [0.3, 0.1]
    gamma = np.array([draw(floats(-math.pi, math.pi)) for _ in range(n)])
    dampings = slip_damping(
        [draw(floats(5.0, 300.0)) for _ in range(n)], [draw(floats(-2.0, 2.0)) for _ in range(n)],
        [draw(floats(5.0, 30.0)) for _ in range(n)], [draw(floats(5.0, 30.0)) for _ in range(n)],
        [draw(floats(0.005, 0.1)) for _ in range(n)], [draw(floats(0.005, 0.1)) for _ in range(n)],
        [draw(floats(0.03, 0.2)) for _ in range(n)], [draw(floats(0.5, 50.0)) for _ in range(n)])
    xi = np.array([draw(floats(-0.05, 0.05)), draw(floats(-0.05, 0.05)), draw(floats(-0.1, 0.1))])
    return contacts, gamma, dampings, xi


@settings(max_examples=200, deadline=None)
@given(_robots())
def test_any_rigid_slip_field_reads_zero_whatever_the_loads_and_stiffnesses(robot):
    contacts, gamma, dampings, xi = robot
    forces = _rigid_slip_forces(contacts, gamma, dampings, xi)
    scale = np.linalg.norm(forces) + 1e-12
    assert _kernel(forces, contacts, gamma, dampings) <= 1e-9 * scale
    assert np.linalg.norm(antagonism_forces(forces, contacts, gamma, dampings)) <= 1e-9 * scale


@settings(max_examples=200, deadline=None)
@given(_robots(), st.lists(st.floats(-50.0, 50.0, **_finite), min_size=12, max_size=12))
def test_it_is_an_internal_force_and_reads_exactly_what_was_added_to_a_rigid_field(robot, raw):
    """F − F_nat lies in null(Jᵀ); adding an internal force f (Jᵀ f = 0) to the forces of a rigid slip
    field reads ‖f‖ (the projection along range(D J) onto null(Jᵀ) keeps f)."""
    contacts, gamma, dampings, xi = robot
    n = contacts.shape[0]
    J = wrench_map(contacts)
    g = np.asarray(raw[:2 * n])
    f = (g - J @ np.linalg.pinv(J) @ g).reshape(n, 2)  # the part of g in null(Jᵀ)
    forces = _rigid_slip_forces(contacts, gamma, dampings, xi) + f
    anta = antagonism_forces(forces, contacts, gamma, dampings)
    tol = 1e-9 * (np.linalg.norm(forces) + 1.0)
    assert np.abs(J.T @ anta.reshape(-1)).max() <= tol
    natural = natural_forces(forces, contacts, gamma, dampings)
    assert np.abs(J.T @ (natural - forces).reshape(-1)).max() <= tol
    assert np.allclose(anta, f, atol=tol)
    assert _kernel(forces, contacts, gamma, dampings) == pytest.approx(np.linalg.norm(f), abs=tol)


@settings(max_examples=200, deadline=None)
@given(_robots(), st.lists(st.floats(-50.0, 50.0, **_finite), min_size=12, max_size=12),
       st.floats(-math.pi, math.pi, **_finite), st.floats(-3.0, 3.0, **_finite), st.floats(-3.0, 3.0, **_finite))
def test_it_does_not_depend_on_the_frame_or_the_reference_point(robot, raw, phi, tx, ty):
    """Rotating the frame by φ (forces, contact points and wheel angles) and moving the reference
    point of the moments by (t_x, t_y) leave the antagonism unchanged."""
    contacts, gamma, dampings, _ = robot
    n = contacts.shape[0]
    forces = np.asarray(raw[:2 * n]).reshape(n, 2)
    R = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
    base = _kernel(forces, contacts, gamma, dampings)
    moved = _kernel(forces @ R.T, contacts @ R.T + [tx, ty], gamma + phi, dampings)
    assert moved == pytest.approx(base, rel=1e-7, abs=1e-9 * (np.linalg.norm(forces) + 1.0))


def test_unloaded_and_single_wheels_are_handled():
    contacts = np.array([[0.2, 0.2], [-0.2, 0.2], [-0.2, -0.2], [0.2, -0.2]])
    gamma = np.zeros(4)
    assert _kernel(np.zeros((4, 2)), contacts, gamma, np.zeros((4, 2))) == 0.0  # nothing loaded, no force
    one = np.zeros((4, 2))
    one[0] = [3.0, 0.0]
    single = np.zeros((4, 2))
    single[0] = [500.0, 800.0]
    assert _kernel(one, contacts, gamma, single) == pytest.approx(0.0, abs=1e-6)  # one wheel: all natural
    d = slip_damping_kernel(86.0, 0.5, 15.0, 12.0, 0.02, 0.02, 1.0, 0.08, 0.0)
    assert d[0] == 0.0 and d[1] == pytest.approx(12.0 * 86.0 / 0.52)  # a free wheel takes no longitudinal force
    d = slip_damping_kernel(86.0, 0.5, 15.0, 12.0, 0.02, 0.02, 1.0, 0.08, 8.0)
    assert 1.0 / d[0] == pytest.approx(0.52 / (15.0 * 86.0) + 0.08 ** 2 / 8.0)  # tire and drive in series


# ---------------------------------------------------------------------- in the physics

def _setpoints(geom, twist):
    lam, mu = eta_from_twist(np.asarray(twist, dtype=float))
    beta = steering_from_lambda(lam, geom)
    return beta, wheel_speeds(lam, mu, geom, beta=beta)


def _coordinated(params: RobotParams, com_height: float = 0.0) -> RobotParams:
    """Wheels held on the constraining surface with no motor lag: a steering spring 100× stiffer
    (its damper 10×: the stiff reference of tests/data/make_physics_v1_reference.py, 40 substeps),
    a drive velocity loop 100× stiffer and no ramp or torque limit on the drive."""
    p = params
    return dataclasses.replace(
        p, chassis=dataclasses.replace(p.chassis, com_height=com_height),
        steering=dataclasses.replace(p.steering, stiffness=100 * p.steering.stiffness, damping=10 * p.steering.damping),
        wheel=dataclasses.replace(p.wheel, velocity_gain=100 * p.wheel.velocity_gain),
        limits=dataclasses.replace(p.limits, wheel_accel_max=1e4, wheel_torque_max=1e3))


def _circle_radius() -> float:
    xy = make_track("circle").xy
    return float(np.ptp(xy[:, 0]) / 2)


@pytest.mark.parametrize("speed", [0.4, 0.8, 1.2])
def test_a_coordinated_robot_on_circle_reads_no_antagonism(speed):
    """On ``circle`` (1.5 m) at 0.4 / 0.8 / 1.2 m/s, set-points from the exact kinematics: the
    antagonism reads 0.018 / 0.025 / 0.098 N where the null-space force reads 0.36 / 1.44 / 3.16 N
    (the inner and outer wheels roll at different speeds, so a common slip loads them unequally)."""
    params = _coordinated(RobotParams())
    phys = AzimutPhysics(params, substeps=40)
    twist = (speed, 0.0, speed / _circle_radius())
    beta, phidot = _setpoints(params.geometry, twist)
    phys.reset_robot(0, (0.0, 0.0, 0.0), beta, twist)
    phys.set_commands(beta[None], phidot[None])
    anta, null = [], []
    for t in range(150):
        phys.step()
        if t >= 100:
            anta.append(phys.antagonism()[0])
            null.append(phys.nullspace_force()[0])
    assert max(anta) < 0.5
    assert np.mean(anta) < 0.2 * np.mean(null)


@pytest.mark.parametrize("com_height", [0.0, 0.2])
def test_a_coordinated_robot_accelerating_on_a_straight_line_reads_no_antagonism(com_height):
    """From rest to 1.2 m/s at 1 m/s² on a straight line, with static loads and with a load
    transfer (h = 0.2 m: the rear wheels carry 12 % more than the front ones): the antagonism
    reads at most 0.23 / 0.25 N where the null-space force reads up to 0.23 / 1.96 N (with equal
    loads both read the same small residual: what the stiff springs still let the modules toe)."""
    params = _coordinated(RobotParams(), com_height)
    phys = AzimutPhysics(params, substeps=40)
    beta, _ = _setpoints(params.geometry, (1.0, 0.0, 0.0))
    phys.reset_robot(0, (0.0, 0.0, 0.0), beta)
    anta, null = [], []
    for t in range(60):
        beta, phidot = _setpoints(params.geometry, ((t + 1) * phys.control_period, 0.0, 0.0))
        phys.set_commands(beta[None], phidot[None])
        phys.step()
        anta.append(phys.antagonism()[0])
        null.append(phys.nullspace_force()[0])
    assert phys.chassis_twist()[0, 0] == pytest.approx(1.2, rel=0.02)
    assert max(anta[5:]) < 0.5
    if com_height > 0:
        assert np.mean(null[5:]) > 5 * np.mean(anta[5:])


@pytest.mark.parametrize("speed", [0.05, 0.5])
def test_one_wheel_5_degrees_off_reads_what_the_nullspace_force_reads(speed):
    """Straight ahead with one wheel commanded 5° off (the default robot): 46.5 / 51.7 N both ways,
    equal within 1 %; the physics' value is the NumPy form's and an internal force."""
    params = RobotParams()
    phys = AzimutPhysics(params)
    beta, phidot = _setpoints(params.geometry, (speed, 0.0, 0.0))
    phys.reset_robot(0, (0.0, 0.0, 0.0), beta, (speed, 0.0, 0.0))
    off = beta.copy()
    off[0] += math.radians(5.0)
    phys.set_commands(off[None], phidot[None])
    anta, null = [], []
    for t in range(100):
        phys.step()
        if t >= 50:
            anta.append(phys.antagonism()[0])
            null.append(phys.nullspace_force()[0])
    assert np.mean(null) > 40.0
    assert np.mean(anta) == pytest.approx(np.mean(null), rel=0.01)
    forces = phys.tire_forces_body()[0]
    contacts = phys.wheel_summary[0, :, WS_CONTACT]
    gamma = phys.wheel_params[0, :, WP.ALPHA] + phys.steering_angles()[0]
    vector = antagonism_forces(forces, contacts, gamma, phys.slip_dampings()[0])
    assert phys.antagonism()[0] == pytest.approx(np.linalg.norm(vector), rel=1e-9)
    assert np.abs(wrench_map(contacts).T @ vector.reshape(-1)).max() < 1e-9 * np.linalg.norm(forces)


def test_the_summary_is_zero_before_any_step_and_after_a_reset():
    phys = AzimutPhysics(n_robots=2)
    assert np.all(phys.antagonism() == 0.0) and np.all(phys.slip_dampings() == 0.0)
    beta, phidot = _setpoints(phys.params.geometry, (0.5, 0.0, 0.3))
    for i in range(2):
        phys.reset_robot(i, (0.0, 0.0, 0.0), beta + 0.1 * i)
    phys.set_commands(np.stack([beta, beta]), np.stack([phidot, phidot]))
    phys.step()
    assert phys.antagonism()[1] > phys.antagonism()[0] > 0.0
    phys.reset_robot(1)
    assert phys.antagonism()[1] == 0.0 and phys.antagonism()[0] > 0.0
