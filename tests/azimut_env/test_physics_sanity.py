"""Physics sanity of azimut_env.physics.engine: straight driving, rotation in place, coasting, and the
internal force of concurrent vs non-concurrent propulsion axes."""

from __future__ import annotations

import numpy as np
import pytest

from azimut_env.params import RobotParams, TireParams
from azimut_env.physics.engine import AzimutPhysics
from azimut_env.physics.layout import WS_CONTACT
from azimut_env.physics.tire import brush_forces
from estimation import eta_from_twist, steering_from_lambda, wheel_speeds


def _kinematic_setpoints(geom, twist):
    lam, mu = eta_from_twist(np.asarray(twist, dtype=float))
    beta = steering_from_lambda(lam, geom)
    return beta, wheel_speeds(lam, mu, geom, beta=beta)


def _drive(phys, beta, phidot, seconds, start_twist=(0.0, 0.0, 0.0)):
    phys.reset_robot(0, (0.0, 0.0, 0.0), beta, start_twist)
    phys.set_commands(beta[None], phidot[None])
    for _ in range(int(round(seconds / phys.control_period))):
        phys.step()
        ok, why = phys.check()
        assert ok[0], why


def test_straight_driving_goes_straight_at_r_phidot():
    phys = AzimutPhysics()
    geom = phys.params.geometry
    v = 0.6
    beta, phidot = _kinematic_setpoints(geom, (v, 0.0, 0.0))
    assert np.allclose(np.abs(phidot) * geom.r, v)
    _drive(phys, beta, phidot, 3.0)
    twist = phys.chassis_twist()[0]
    pose = phys.chassis_pose()[0]
    assert twist[0] == pytest.approx(v, rel=0.02)
    assert abs(twist[1]) < 1e-3 and abs(twist[2]) < 1e-3
    assert abs(pose[1]) < 1e-3 and abs(pose[2]) < 1e-3
    # measured spin rates agree with rolling without slip: r φ̇ = v
    assert np.allclose(np.abs(phys.wheel_speeds()[0]) * geom.r, twist[0], rtol=0.01)


def test_rotation_in_place_turns_at_the_kinematic_rate():
    phys = AzimutPhysics()
    geom = phys.params.geometry
    w = 1.2
    beta, phidot = _kinematic_setpoints(geom, (0.0, 0.0, w))
    _drive(phys, beta, phidot, 3.0)
    twist = phys.chassis_twist()[0]
    assert twist[2] == pytest.approx(w, rel=0.03)
    assert np.hypot(*phys.chassis_pose()[0, :2]) < 5e-3


@pytest.mark.parametrize("twist", [(0.8, 0.0, 0.0), (0.3, 0.4, 0.6), (0.0, 0.0, 1.5)])
def test_coasting_with_motors_off_comes_to_rest_and_never_gains_energy(twist):
    phys = AzimutPhysics()
    geom = phys.params.geometry
    beta, _ = _kinematic_setpoints(geom, twist)
    phys.reset_robot(0, (0.0, 0.0, 0.3), beta, twist)
    phys.set_motors_enabled(False)
    energy = [phys.energy()[0]]
    for _ in range(400):  # 8 s
        phys.step()
        energy.append(phys.energy()[0])
    energy = np.array(energy)
    assert energy[0] > 1.0
    # never gains energy (tolerance for the constraint solver's position correction)
    assert np.all(np.diff(energy) <= 1e-6 * energy[0] + 1e-9)
    assert energy[-1] < 1e-3 * energy[0]
    assert np.linalg.norm(phys.chassis_twist()[0]) < 0.01


def _internal_and_slip(beta, phidot, seconds=1.0):
    phys = AzimutPhysics()
    _drive(phys, beta, phidot, seconds)
    f, p = [], []
    for _ in range(10):
        phys.step()
        f.append(phys.nullspace_force()[0])
        p.append(phys.slip_power()[0])
    return float(np.mean(f)), float(np.mean(p))


def test_non_concurrent_axes_fight_and_concurrent_ones_do_not():
    geom = RobotParams().geometry
    beta, phidot = _kinematic_setpoints(geom, (0.15, 0.05, 0.2))  # slow, ICR well defined
    f_ok, p_ok = _internal_and_slip(beta, phidot)
    bad = beta.copy()
    bad[0] += 0.35  # one wheel 20° off the constraining surface
    bad[2] -= 0.25
    f_bad, p_bad = _internal_and_slip(bad, phidot)
    assert f_ok < 3.0 and p_ok < 0.05
    assert f_bad > 10 * max(f_ok, 1.0)
    assert p_bad > 10 * max(p_ok, 0.01)


def test_tire_longitudinal_force_deflects_the_compliant_steering():
    """Driving around a tight circle, the measured β sit off the motor angles (spring deflection).

    The tire force acts at P_k, b_k from the steering axis along the propulsion axis: its lateral
    part points along that offset and has no moment about A_k; the longitudinal part has the
    moment −b_k F_long, which the series spring holds."""
    phys = AzimutPhysics()
    geom = phys.params.geometry
    beta, phidot = _kinematic_setpoints(geom, (0.0, 1.2, 1.5))
    _drive(phys, beta, phidot, 2.0)
    deflection = phys.motor_angles()[0] - phys.steering_angles()[0]
    assert np.max(np.abs(deflection)) > np.deg2rad(0.2)


def test_tire_model_saturates_on_the_friction_circle():
    """The brush tire's steady forces stay inside μN and reach it at large slip (tests/azimut_env/test_tire.py
    has the closed forms)."""
    tire = TireParams()
    kappa = np.array([0.001, 0.5, -3.0])
    alpha = np.array([0.0, 0.5, 0.3])
    fl, fa = brush_forces(kappa, alpha, np.full(3, 80.0), tire)
    mag = np.hypot(fl, fa)
    assert mag[0] == pytest.approx(tire.longitudinal_stiffness * 80 * 0.001, rel=0.01)
    assert np.allclose(mag[1:], tire.friction * 80)
    assert np.all(fl * kappa >= 0)  # F_x = C_κ κ: along the slip ratio


def test_parameters_are_validated():
    with pytest.raises(ValueError):
        TireParams(friction=-1.0)
    with pytest.raises(ValueError, match="substep"):
        AzimutPhysics(substeps=1)
    with pytest.raises(ValueError):
        AzimutPhysics(n_robots=0)


def test_many_robots_in_one_space_match_the_single_robot():
    """The batched physics: N robots in one Space evolve like N separate ones (no interaction)."""
    geom = RobotParams().geometry
    twists = [(0.5, 0.0, 0.0), (0.0, 0.0, 1.0), (0.2, 0.3, 0.4)]
    multi = AzimutPhysics(n_robots=3)
    singles = []
    sp = [_kinematic_setpoints(geom, tw) for tw in twists]
    for i, (beta, phidot) in enumerate(sp):
        multi.reset_robot(i, (0.0, 0.0, 0.0), beta)
        s = AzimutPhysics()
        s.reset_robot(0, (0.0, 0.0, 0.0), beta)
        s.set_commands(beta[None], phidot[None])
        singles.append(s)
    multi.set_commands(np.array([b for b, _ in sp]), np.array([p for _, p in sp]))
    for _ in range(50):
        multi.step()
        for s in singles:
            s.step()
    for i, s in enumerate(singles):
        assert np.allclose(multi.chassis_pose()[i], s.chassis_pose()[0], atol=1e-6)


def test_blow_up_is_detected_not_returned_as_nan():
    phys = AzimutPhysics()
    phys.reset_robot(0)
    phys.chassis[0].velocity = (float("nan"), 0.0)
    phys.step()
    ok, why = phys.check()
    assert not ok[0] and "non-finite" in why[0]


def test_nullspace_force_is_the_minimum_norm_null_space_part_of_the_tire_forces():
    geom = RobotParams().geometry
    beta, phidot = _kinematic_setpoints(geom, (0.3, 0.1, 0.5))
    beta[1] += 0.3
    phys = AzimutPhysics()
    _drive(phys, beta, phidot, 0.5)
    f = phys.tire_forces_body()[0].ravel()
    p = phys.wheel_summary[0, :, WS_CONTACT]
    G = np.zeros((3, 8))
    G[0, 0::2] = 1
    G[1, 1::2] = 1
    G[2, 0::2] = -p[:, 1]
    G[2, 1::2] = p[:, 0]
    internal = np.linalg.norm(f - np.linalg.pinv(G) @ (G @ f))
    assert internal > 1.0
    assert phys.nullspace_force()[0] == pytest.approx(internal, rel=1e-9)
    # the contact points are A_k + b_k (cos γ_k, sin γ_k)
    gam = geom.alpha + phys.steering_angles()[0]
    assert np.allclose(p, geom.axis_xy + geom.b[:, None] * np.stack([np.cos(gam), np.sin(gam)], 1))


def test_obstacles_add_and_remove_collision_shapes():
    phys = AzimutPhysics()
    phys.reset_robot(0, (0.0, 0.0, 0.0))
    assert len(phys.space.shapes) == 0
    phys.set_obstacles([(3.0, 0.0, 0.5)])
    assert len(phys.space.shapes) == 1 + 1  # obstacle and the chassis box (the wheels lie within it)
    phys.set_obstacles([])
    assert len(phys.space.shapes) == 0


def test_chassis_collides_with_an_obstacle():
    phys = AzimutPhysics()
    geom = phys.params.geometry
    phys.set_obstacles([(1.0, 0.0, 0.2)])
    beta, phidot = _kinematic_setpoints(geom, (0.5, 0.0, 0.0))
    _drive(phys, beta, phidot, 4.0)
    assert phys.chassis_pose()[0, 0] < 1.0 - 0.2 - 0.29  # stopped by the obstacle (half-width 0.3)


def test_hard_stops_hold_after_a_kick():
    phys = AzimutPhysics()
    phys.reset_robot(0, (0.0, 0.0, 0.0), np.zeros(4))
    phys.kick(0, [0, 1], 0.5)  # 25 rad/s on the modules
    phys.kick(0, [2, 3], -0.5)
    peak = 0.0
    for _ in range(50):
        phys.step()
        peak = max(peak, np.max(np.abs(phys.steering_angles()[0])))
        assert phys.check()[0][0]
    assert peak > 0.2  # the wheels were knocked (0.29 rad at 128 substeps)
    assert peak < np.pi / 2 + 0.02  # but not through the stops
