"""Physics v2: steering modules as joint coordinates (no pivot drift, exact stops), the coupling
between module and chassis, normal loads that follow the mass, the stability budget, and
agreement with the v1 model (pymunk pivot and limit joints) where both should agree."""

from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path

import numpy as np
import pytest

from azimut_env.params import ChassisParams, RobotParams, SteeringParams, TireParams
from azimut_env.physics.engine import JS, RS, TS, WP, AzimutPhysics
from estimation import eta_from_twist, steering_from_lambda, wheel_speeds

V1 = np.load(Path(__file__).parent.parent / "data" / "physics_v1_reference.npz")


def _setpoints(geom, twist):
    lam, mu = eta_from_twist(np.asarray(twist, dtype=float))
    beta = steering_from_lambda(lam, geom)
    return beta, wheel_speeds(lam, mu, geom, beta=beta)


def _angular_momentum(phys, i=0):
    """Total angular momentum about the world origin [kg·m²/s]: chassis with the module masses
    (centre of mass at the chassis origin) plus the modules' own spins."""
    m, inertia = phys.body_inertia[i]
    x, y, vx, vy, w = (phys.summary[i, col] for col in (RS.X, RS.Y, RS.VX, RS.VY, RS.W))
    return (m * (x * vy - y * vx) + inertia * w
            + np.sum(phys.wheel_params[i, :, WP.I_MOD] * phys.joint_state[i, :, JS.OMEGA]))


def _bang_bang(phys, steps, rng, kick_every=0):
    """Random ±limit steering and propulsion commands (and kicks): worst case for the stops.
    Returns the largest |β| beyond the range, the largest pivot error, and the largest |β| seen."""
    g = phys.params.geometry
    lim = phys.params.limits
    pen = piv = 0.0
    peak = 0.0
    for j in range(steps):
        if j % 5 == 0:
            beta_cmd = rng.choice([lim.steer_min, lim.steer_max], size=(phys.n_robots, phys.n))
            phidot_cmd = rng.choice([-1.0, 1.0], size=(phys.n_robots, phys.n)) * lim.wheel_speed_max
            phys.set_commands(beta_cmd, phidot_cmd)
        if kick_every and j % kick_every == 0:
            for i in range(phys.n_robots):
                phys.kick(i, [0, 1, 2, 3], float(rng.choice([-3.0, 3.0])))
        phys.step()
        assert phys.check()[0].all()
        beta = phys.steering_angles()
        pen = max(pen, float(np.max(beta - g.steer_max)), float(np.max(g.steer_min - beta)))
        peak = max(peak, float(np.max(np.abs(beta))))
        # pivot: A_k rigidly at axis_xy[k] in the chassis frame, P_k at b_k from A_k along γ_k
        pose = phys.chassis_pose()
        c, s = np.cos(pose[:, 2:3]), np.sin(pose[:, 2:3])
        a_world = pose[:, None, :2] + np.stack([c * g.axis_xy[:, 0] - s * g.axis_xy[:, 1],
                                                s * g.axis_xy[:, 0] + c * g.axis_xy[:, 1]], -1)
        gam = pose[:, 2:3] + g.alpha + beta
        p_world = a_world + g.b[:, None] * np.stack([np.cos(gam), np.sin(gam)], -1)
        piv = max(piv, float(np.max(np.abs(phys.contact_points() - p_world))))
    return pen, piv, peak


def test_bang_bang_and_kicks_never_penetrate_the_stops_and_pivots_stay_exact():
    phys = AzimutPhysics(n_robots=3)
    for i in range(3):
        phys.reset_robot(i, (0.0, 0.0, 0.0), np.zeros(4))
    pen, piv, peak = _bang_bang(phys, 300, np.random.default_rng(0), kick_every=25)
    assert peak >= np.pi / 2 - 1e-9  # the stops were hit
    assert pen <= np.deg2rad(0.05) and pen <= 1e-12  # never beyond: projected onto the stop
    assert piv <= 1e-6


def test_a_stop_impulse_conserves_angular_momentum():
    """Motors braked, (almost) no friction: spring and stop torques are internal, so the total
    angular momentum stays while kicked modules slam into their stops."""
    p = RobotParams(tire=TireParams(friction=1e-9), steering=SteeringParams(stiffness=5.0, damping=0.0))
    phys = AzimutPhysics(p)
    phys.reset_robot(0, (0.0, 0.0, 0.0), np.zeros(4), twist=(0.0, 0.0, 0.3))
    phys.set_motors_enabled(False)
    phys.kick(0, [0, 1], 2.0)  # 100 rad/s: through the spring into the upper stop
    l0 = _angular_momentum(phys)
    peak = 0.0
    for _ in range(20):
        phys.step()
        peak = max(peak, float(np.max(phys.steering_angles()[0])))
        assert _angular_momentum(phys) == pytest.approx(l0, rel=1e-7)  # friction 1e-9 μ: ~1e-9
    assert np.pi / 2 - 0.02 < peak <= np.pi / 2  # at the stop (a free module would swing past it)


def test_stop_restitution_sets_the_rebound():
    """A module driven into its stop at relative rate v (spring off, tires unloaded) comes back at −e v."""
    for e in (0.0, 0.5):
        p = RobotParams(steering=SteeringParams(stiffness=1e-6, damping=0.0, stop_restitution=e), gravity=1e-9)
        phys = AzimutPhysics(p)
        phys.reset_robot(0, (0.0, 0.0, 0.0), np.full(4, 1.5))
        phys.set_motors_enabled(False)
        phys.kick(0, [0], 0.02 * 2.0)  # 2 rad/s toward the stop at π/2, 0.07 rad away
        for _ in range(5):
            phys.step()
        assert phys.steering_angles()[0, 0] <= np.pi / 2
        assert phys.steering_rates()[0, 0] == pytest.approx(-e * 2.0, abs=1e-3)


def test_chassis_carries_the_module_masses_and_loads_follow_the_mass():
    p = RobotParams()
    phys = AzimutPhysics(p, n_robots=2)
    m_tot = p.chassis.mass + 4 * p.steering.module_mass
    assert phys.chassis[0].mass == pytest.approx(m_tot)
    assert phys.chassis[0].moment == pytest.approx(p.chassis.inertia
                                                   + p.steering.module_mass * np.sum(p.geometry.l ** 2))
    assert np.allclose(phys.normal_loads(), m_tot * p.gravity / 4)
    phys.set_chassis_mass(1, 40.0)
    assert np.allclose(phys.normal_loads()[1], (40.0 + 8.0) * p.gravity / 4)
    assert np.allclose(phys.normal_loads()[0], m_tot * p.gravity / 4)
    assert phys.chassis[1].mass == pytest.approx(48.0)


def test_domain_randomisation_keeps_the_loads_consistent_with_the_mass():
    from azimut_env.env import AzimutEnv

    env = AzimutEnv(domain_randomization=0.3)
    for seed in range(4):
        env.reset(seed=seed)
        phys = env.physics
        assert np.sum(phys.normal_loads()[0]) == pytest.approx(phys.chassis[0].mass * env.params.gravity)
        assert phys.body_inertia[0, 0] == pytest.approx(phys.chassis[0].mass)


def test_load_transfer_moves_load_to_the_rear_when_accelerating():
    geom = RobotParams().geometry
    p = RobotParams(chassis=ChassisParams(com_height=0.15))
    phys = AzimutPhysics(p)
    beta, phidot = _setpoints(geom, (1.0, 0.0, 0.0))
    phys.reset_robot(0, (0.0, 0.0, 0.0), beta)
    phys.set_commands(beta[None], phidot[None])
    phys.step()
    loads = phys.normal_loads()[0]
    front = geom.axis_xy[:, 0] > 0
    assert np.sum(loads) == pytest.approx(p.total_mass * p.gravity)
    assert loads[~front].mean() > loads[front].mean() + 1.0
    # Σ N_k x_k = −h M a_x
    a_x = phys.chassis_accel[0, 0]
    assert a_x > 0.5
    assert np.sum(loads * geom.axis_xy[:, 0]) == pytest.approx(-0.15 * p.total_mass * a_x, rel=1e-9)


def test_stability_budget_is_enforced_at_construction():
    with pytest.raises(ValueError, match="spring_omega_dt"):
        AzimutPhysics(RobotParams(steering=SteeringParams(stiffness=6000.0)))
    AzimutPhysics(RobotParams(steering=SteeringParams(stiffness=6000.0)), substeps=40)
    with pytest.raises(ValueError, match="load_transfer_gain"):
        AzimutPhysics(RobotParams(chassis=ChassisParams(com_height=0.3)))
    with pytest.raises(ValueError, match="tire_long_margin"):
        AzimutPhysics(RobotParams(tire=TireParams(longitudinal_relaxation_length=0.002)))
    AzimutPhysics(RobotParams(tire=TireParams(longitudinal_relaxation_length=0.002)), substeps=64)
    phys = AzimutPhysics()
    with pytest.raises(ValueError, match="stability margin"):
        phys.set_chassis_mass(0, 300.0)  # 8.8x the load: the contact spring would go unstable
    assert phys.body_inertia[0, 0] == pytest.approx(35.0)  # refused, nothing changed
    figs = AzimutPhysics().stability_figures()
    assert all(v < bound for v, bound in figs.values())


def test_pickle_round_trip_continues_bit_for_bit():
    geom = RobotParams().geometry
    beta, phidot = _setpoints(geom, (0.4, 0.1, 0.5))
    phys = AzimutPhysics(n_robots=2)
    for i in range(2):
        phys.reset_robot(i, (0.1 * i, 0.0, 0.2), beta)
    phys.set_commands(np.stack([beta, beta + 0.2]), np.stack([phidot, phidot]))
    for _ in range(10):
        phys.step()
    clone = pickle.loads(pickle.dumps(phys))
    for _ in range(20):
        phys.step()
        clone.step()
    assert np.array_equal(phys.summary, clone.summary)
    assert np.array_equal(phys.joint_state, clone.joint_state)


# ---------------------------------------------------------------------- v1 (pymunk joints) vs v2


@pytest.mark.parametrize("name", ["straight", "rotate", "combined"])
def test_kinematic_driving_agrees_with_v1(name):
    """Driving on the kinematic set-points: same twist and path as the pymunk-joint model."""
    geom = RobotParams().geometry
    tw = {"straight": (0.6, 0, 0), "rotate": (0, 0, 1.2), "combined": (0.3, 0.2, 0.5)}[name]
    beta, phidot = _setpoints(geom, tw)
    phys = AzimutPhysics()
    phys.reset_robot(0, (0.0, 0.0, 0.0), beta)
    phys.set_commands(beta[None], phidot[None])
    poses, twists = [], []
    for _ in range(150):
        phys.step()
        poses.append(phys.chassis_pose()[0])
        twists.append(phys.chassis_twist()[0])
    poses, twists = np.array(poses), np.array(twists)
    assert np.max(np.abs(twists[-50:] - V1[f"{name}_twist"][-50:])) < 0.01 * max(np.abs(tw).max(), 0.1)
    assert np.max(np.hypot(*(poses[:, :2] - V1[f"{name}_pose"][:, :2]).T)) < 0.01  # 1 cm over 3 s
    assert np.max(np.abs(poses[:, 2] - V1[f"{name}_pose"][:, 2])) < np.deg2rad(0.5)


def test_steady_steering_under_a_stiff_spring_agrees_with_v1():
    """A tight circle with a 100× stiffer spring: β sits on the motor angles in both models."""
    p = RobotParams()
    stiff = dataclasses.replace(p, steering=dataclasses.replace(p.steering, stiffness=6000.0, damping=6.0))
    phys = AzimutPhysics(stiff, substeps=40)
    beta, phidot = _setpoints(p.geometry, (0.0, 1.2, 1.5))
    phys.reset_robot(0, (0.0, 0.0, 0.0), beta)
    phys.set_commands(beta[None], phidot[None])
    for _ in range(100):
        phys.step()
    assert np.max(np.abs(phys.steering_angles()[0] - V1["stiff_circle_beta"])) < np.deg2rad(0.05)
    assert np.max(np.abs(phys.motor_angles()[0] - phys.steering_angles()[0])) < np.deg2rad(0.05)
    assert np.allclose(phys.chassis_twist()[0], V1["stiff_circle_twist"], atol=0.02)


def test_module_angles_under_slow_motion_agree_with_v1():
    """Sinusoidal steering commands while creeping at 0.1 m/s: the motors move identically and the
    modules lag them by the same peak deflection (set by module inertia, spring and motor
    acceleration). The tires differ (v1: viscous; v2: brush tire with aligning and scrub
    torques), so β agrees to a few degrees, not exactly (measured: 2.5° max, 0.9° RMS)."""
    geom = RobotParams().geometry
    phys = AzimutPhysics()
    b0, w0 = _setpoints(geom, (0.1, 0.0, 0.0))
    phys.reset_robot(0, (0.0, 0.0, 0.0), b0)
    betas, motors = [], []
    for cmd in V1["slow_cmd"]:
        phys.set_commands(cmd[None], w0[None])
        phys.step()
        betas.append(phys.steering_angles()[0])
        motors.append(phys.motor_angles()[0])
    betas, motors = np.array(betas), np.array(motors)
    assert np.max(np.abs(motors - V1["slow_motor"])) < 1e-9
    peak_v1 = np.max(np.abs(V1["slow_beta"] - V1["slow_motor"]))
    assert np.max(np.abs(betas - motors)) == pytest.approx(peak_v1, rel=0.1)
    assert np.max(np.abs(betas - V1["slow_beta"])) < np.deg2rad(3.0)
    assert np.sqrt(np.mean((betas - V1["slow_beta"]) ** 2)) < np.deg2rad(1.0)


# ---------------------------------------------------------------------- the tire on the steering DOF


def _steer_at_rest(gravity, steps=10):
    p = RobotParams(gravity=gravity)
    phys = AzimutPhysics(p)
    phys.reset_robot(0, (0.0, 0.0, 0.0), np.zeros(4))
    phys.set_commands(np.full((1, 4), 0.6), np.zeros((1, 4)))
    lag = 0.0
    for _ in range(steps):
        phys.step()
        lag = max(lag, float(np.max(phys.motor_angles()[0] - phys.steering_angles()[0])))
    return lag, phys


def test_scrub_torque_resists_steering_a_loaded_wheel_at_standstill():
    """Steering at rest: the loaded tire's patch twist (dry-parking torque) and the rolling of the
    offset contact point hold the module back; the spring deflects more than with unloaded tires."""
    lag_loaded, phys = _steer_at_rest(9.81)
    lag_free, _ = _steer_at_rest(1e-6)
    assert lag_loaded > lag_free + np.deg2rad(0.5)
    assert np.max(np.abs(phys.tire_state[0, :, TS.TWIST])) > 0  # the patch twisted
    # the robot itself stays put (static friction): the chassis barely moves
    assert np.hypot(*phys.chassis_pose()[0, :2]) < 2e-3


def test_aligning_moment_turns_a_misaligned_wheel_toward_the_travel_direction():
    """Driving straight with one wheel commanded 5° off, the module deflects from its motor
    toward the rolling direction (β − θ_m has the sign of β_kin − β_cmd), for either sign."""
    geom = RobotParams().geometry
    beta, phidot = _setpoints(geom, (0.5, 0.0, 0.0))
    for off in (np.deg2rad(5.0), -np.deg2rad(5.0)):
        cmd = beta.copy()
        cmd[0] += off
        phys = AzimutPhysics()
        phys.reset_robot(0, (0.0, 0.0, 0.0), cmd)
        phys.set_commands(cmd[None], phidot[None])
        for _ in range(50):
            phys.step()
        defl = phys.steering_angles()[0, 0] - phys.motor_angles()[0, 0]
        assert np.sign(defl) == -np.sign(off)
        assert abs(defl) > np.deg2rad(0.05)


@pytest.mark.slow
def test_substep_convergence_is_first_order():
    """``azimut bench-env --convergence`` on a 10 s replay: the error halves when the substeps double."""
    from azimut_env.physics.convergence import substep_convergence

    rows = substep_convergence((8, 16, 32), reference=128, seconds=10.0)
    orders = [r["order"] for r in rows[1:]]
    assert all(0.8 < o < 1.6 for o in orders), orders
    assert rows[0]["max_position_error"] < 0.03


def test_dc_steering_motor_is_wired_into_the_substep():
    """model "dc": nearly unloaded (wheels in the air) the steering follows the kinematic model; on the
    ground, turning a loaded wheel against the scrub torque, the torque-speed line slows it."""
    from azimut_env.params import SteeringMotorParams

    def turn(model, gravity):
        p = RobotParams(steer_motor=SteeringMotorParams(model=model, stall_torque=3.0), gravity=gravity)
        phys = AzimutPhysics(p)
        phys.reset_robot(0, (0.0, 0.0, 0.0), np.zeros(4))
        phys.set_commands(np.full((1, 4), 1.0), np.zeros((1, 4)))
        for _ in range(10):
            phys.step()
        return phys.motor_angles()[0]

    # only the module's inertia loads it (7e-5 rad behind after 0.2 s)
    assert np.allclose(turn("dc", 1e-6), turn("kinematic", 1e-6), atol=1e-3)
    assert np.all(turn("dc", 9.81) < turn("kinematic", 9.81) - 0.01)
