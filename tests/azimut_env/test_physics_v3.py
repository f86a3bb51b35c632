"""Physics v3: the imperfections the paper names (steering friction with stiction, the module's
centre of mass off its axis, the drive's torque–speed line, geometric imperfections), each
against a closed form or a property."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from azimut_env.params import RobotParams, SteeringParams, TireParams
from azimut_env.physics.engine import JS, MS, WP, AzimutPhysics
from azimut_env.physics.modules import friction_impulse, stribeck_torque

TAU_C, TAU_S, W_S = 0.5, 0.75, 0.02


def _frictional(stiffness=60.0, mu=1e-9, **steering) -> RobotParams:
    """A robot with steering friction and (almost) frictionless tires: the joint alone holds."""
    st_ = dict(stiffness=stiffness, friction_coulomb=TAU_C, friction_static=TAU_S, stribeck_speed=W_S)
    st_.update(steering)
    return RobotParams(tire=TireParams(friction=mu), steering=SteeringParams(**st_))


def _spring_torque(phys, k=0):
    p = phys.params.steering
    ms, js = phys.motor_state[0, k], phys.joint_state[0, k]
    return p.stiffness * (ms[MS.THETA] - js[JS.BETA]) + p.damping * (ms[MS.OMEGA] - (js[JS.OMEGA] - phys.summary[0, 5]))


# ---------------------------------------------------------------------------------------- friction


def test_stribeck_curve_closed_form():
    assert stribeck_torque(0.0, TAU_C, TAU_S, W_S) == TAU_S
    assert stribeck_torque(W_S, TAU_C, TAU_S, W_S) == pytest.approx(TAU_C + (TAU_S - TAU_C) / math.e)
    assert stribeck_torque(100 * W_S, TAU_C, TAU_S, W_S) == pytest.approx(TAU_C)


@settings(max_examples=300, deadline=None)
@given(rel=st.floats(-50, 50), rel0=st.floats(-50, 50), g=st.floats(1e-3, 1e3), tc=st.floats(0, 5),
       extra=st.floats(0, 5), ws=st.floats(1e-4, 1), dt=st.floats(1e-5, 0.05), frac=st.floats(-1, 1))
def test_friction_impulse_never_reverses_the_joint_nor_adds_energy(rel, rel0, g, tc, extra, ws, dt, frac):
    lim = stribeck_torque(abs(rel0), tc, tc + extra, ws) * dt
    applied = frac * lim  # a projected Gauss–Seidel pass starts from the total applied so far
    j = friction_impulse(rel, rel0, g, applied, tc, tc + extra, ws, dt) - applied
    after = rel + g * j
    assert j * rel <= 0.0
    assert after * rel >= -1e-12 * abs(rel)  # stops at most: never reversed
    assert j * rel + 0.5 * g * j * j <= 1e-12 * (1 + rel * rel / g)  # ΔT ≤ 0
    assert abs(applied + j) <= lim * (1 + 1e-12)


def _hold(phys, beta_cmd, steps):
    phys.set_commands(np.full((1, 4), beta_cmd), np.zeros((1, 4)))
    for _ in range(steps):
        phys.step()
        assert phys.check()[0].all()


def test_dead_band_a_command_within_tau_s_over_k_s_does_not_move_the_module():
    """With the spring in series, the motor winds it by β_cmd; below τ_s / k_s the joint stays
    stuck exactly (the dead band the paper's "stiction" implies)."""
    phys = AzimutPhysics(_frictional())
    phys.reset_robot(0)
    band = TAU_S / 60.0
    _hold(phys, 0.95 * band, 100)  # 2 s: the motor is there, the spring holds 0.95 τ_s
    assert np.allclose(phys.motor_angles(), 0.95 * band, atol=1e-12)
    assert np.max(np.abs(phys.steering_angles())) < 1e-9
    # the same command without friction moves the module all the way
    free = AzimutPhysics(_frictional(friction_coulomb=0.0, friction_static=0.0))
    free.reset_robot(0)
    _hold(free, 0.95 * band, 100)
    assert np.allclose(free.steering_angles(), 0.95 * band, atol=1e-4)


def test_breakaway_torque_is_the_static_friction():
    """Ramp the motor slowly: the module leaves rest when the spring torque reaches τ_s (to the
    ramp's resolution), independent of the substep."""
    for substeps in (8, 32):
        phys = AzimutPhysics(_frictional(), substeps=substeps)
        phys.reset_robot(0)
        ramp = 0.002  # rad per step: 0.12 N·m of spring torque per step at k_s = 60
        torque_at_break = None
        for j in range(1, 200):
            phys.set_commands(np.full((1, 4), j * ramp), np.zeros((1, 4)))
            before = _spring_torque(phys)
            phys.step()
            if abs(phys.steering_angles()[0, 0]) > 1e-9:
                torque_at_break = before
                break
        # the motor advances ramp per step (rate-limited loop lags a little): the spring torque
        # at the last stuck step is below τ_s and the next one crosses it
        assert torque_at_break is not None
        assert TAU_S - 60.0 * ramp - 0.05 <= torque_at_break <= TAU_S + 1e-9


def test_after_breakaway_the_module_settles_within_the_dead_band():
    phys = AzimutPhysics(_frictional())
    phys.reset_robot(0)
    _hold(phys, 0.3, 150)
    defl = phys.motor_angles() - phys.steering_angles()
    assert np.all(np.abs(defl) <= TAU_S / 60.0 + 1e-9)
    assert np.all(phys.steering_angles() > 0.3 - TAU_S / 60.0 - 1e-9)
    assert np.max(np.abs(phys.steering_rates())) < 1e-9  # stuck again: the joint's rate is exactly zero


def test_energy_never_gained_while_coasting_with_friction():
    """Motors off (propulsion free, steering braked), the robot rolling and its modules kicked:
    the mechanical energy never rises from one control step to the next."""
    for params in (_frictional(mu=0.8), RobotParams(steering=SteeringParams(friction_coulomb=1.0,
                                                                             friction_static=1.5))):
        phys = AzimutPhysics(params)
        phys.reset_robot(0, twist=(0.8, 0.2, 0.5))
        phys.set_motors_enabled(False)
        phys.kick(0, [0, 2], 0.05)
        e = [float(phys.energy()[0])]
        for _ in range(300):
            phys.step()
            e.append(float(phys.energy()[0]))
        rise = np.diff(e)
        assert np.all(rise <= 1e-9 * e[0]), f"energy rose by {rise.max():.3g} J"
        assert e[-1] < 0.5 * e[0]


def _angular_momentum(phys, i=0):
    """About the world origin: ``x p_y − y p_x + p_θ + Σ_k p_γk`` with p = M q̇ the generalised
    momentum (q = (x, y, θ, γ_k); a rotation of the whole robot about O moves θ and every γ_k)."""
    m, inertia = phys.body_inertia[i]
    x, y, vx, vy, w = (phys.summary[i, col] for col in (0, 1, 3, 4, 5))
    wp, js = phys.wheel_params[i], phys.joint_state[i]
    omega = js[:, JS.OMEGA]
    gam = phys.summary[i, 2] + wp[:, WP.ALPHA] + js[:, JS.BETA]
    mc = wp[:, WP.M_MOD] * wp[:, WP.COM]
    th = phys.summary[i, 2]
    arm = np.stack([np.cos(th) * phys._axis_xy[:, 0] - np.sin(th) * phys._axis_xy[:, 1],
                    np.sin(th) * phys._axis_xy[:, 0] + np.cos(th) * phys._axis_xy[:, 1]], -1)
    px = m * vx + np.sum(-mc * np.sin(gam) * omega)
    py = m * vy + np.sum(mc * np.cos(gam) * omega)
    along = arm[:, 0] * np.cos(gam) + arm[:, 1] * np.sin(gam)
    p_th = inertia * w + np.sum(mc * along * omega)
    p_gam = wp[:, WP.I_MOD] * omega + mc * (-np.sin(gam) * vx + np.cos(gam) * vy + along * w)
    return x * py - y * px + p_th + np.sum(p_gam)


def test_friction_is_internal_angular_momentum_is_conserved():
    """Motors braked, (almost) frictionless tires: friction, spring and stop torques are
    internal pairs, so the angular momentum stays while kicked modules slide and hit their stops."""
    p = _frictional(stiffness=5.0, damping=0.0)
    phys = AzimutPhysics(p)
    phys.reset_robot(0, twist=(0.0, 0.0, 0.3))
    phys.set_motors_enabled(False)
    phys.kick(0, [0, 1], 2.0)  # 100 rad/s: through the spring and the friction into the upper stop
    phys.kick(0, [2], 0.01)
    l0 = _angular_momentum(phys)
    stuck = 0
    for _ in range(100):
        phys.step()
        assert _angular_momentum(phys) == pytest.approx(l0, rel=1e-7)  # friction 1e-9 μ: ~1e-9
        stuck += int(np.sum(np.abs(phys.steering_rates()) < 1e-12))
    assert stuck > 0  # friction held some joints


def test_friction_parameters_are_validated():
    with pytest.raises(ValueError, match="friction_static"):
        SteeringParams(friction_coulomb=1.0, friction_static=0.5)
    with pytest.raises(ValueError, match="stribeck_speed"):
        SteeringParams(stribeck_speed=0.0)
    with pytest.raises(ValueError, match="friction_coulomb"):
        SteeringParams(friction_coulomb=-1.0)
    assert not SteeringParams().has_friction and dataclasses.replace(SteeringParams(), friction_static=0.1).has_friction


# ---------------------------------------------------------------------------------- module centre of mass

URDF_MODULE = dict(module_mass=1.876, com_offset=0.0714, module_inertia=0.0151)


def _robot_com(phys, i=0):
    """The robot's centre of mass in the world: O plus Σ m_k c_k u_k / M (the chassis with the
    modules at their axes has it at O)."""
    wp, js = phys.wheel_params[i], phys.joint_state[i]
    gam = phys.summary[i, 2] + wp[:, WP.ALPHA] + js[:, JS.BETA]
    mc = wp[:, WP.M_MOD] * wp[:, WP.COM]
    off = np.array([np.sum(mc * np.cos(gam)), np.sum(mc * np.sin(gam))]) / phys.body_inertia[i, 0]
    return phys.summary[i, :2] + off


def _swing(substeps):
    """A module kicked on a robot at rest, no external force: (largest drift of the robot's centre
    of mass, largest chassis displacement, largest swing) over 1 s [m, m, rad]."""
    p = _frictional(stiffness=5.0, damping=0.0, friction_coulomb=0.0, friction_static=0.0, **URDF_MODULE)
    phys = AzimutPhysics(p, substeps=substeps)
    phys.reset_robot(0)
    phys.set_motors_enabled(False)
    com0 = _robot_com(phys)
    phys.kick(0, [0], 0.03)
    drift = moved = swing = 0.0
    for _ in range(50):
        phys.step()
        drift = max(drift, float(np.linalg.norm(_robot_com(phys) - com0)))
        moved = max(moved, float(np.linalg.norm(phys.summary[0, :2])))
        swing = max(swing, abs(float(phys.steering_angles()[0, 0])))
    return drift, moved, swing


def test_an_offset_module_swinging_leaves_the_robot_centre_of_mass_still():
    """No external force (frictionless tires, motors braked): a kicked module whose centre of mass
    is off its axis swings the chassis the other way (by about m c Δu / M) and the robot's centre
    of mass stays, to the integrator's first order in the substep."""
    d8, moved, swing = _swing(8)
    d32, _, _ = _swing(32)
    m, c = URDF_MODULE["module_mass"], URDF_MODULE["com_offset"]
    assert moved == pytest.approx(m * c * 2 * math.sin(swing / 2) / (27.0 + 4 * m), rel=0.15)
    assert d8 < 0.15 * moved  # 4e-5 m of 4.4e-4 m at the default substep
    assert d32 < 0.3 * d8  # first order: 4x the substeps, 1/4 the drift


def _momentum_drift(substeps, kick):
    p = _frictional(stiffness=5.0, damping=0.0, **URDF_MODULE)
    phys = AzimutPhysics(p, substeps=substeps)
    phys.reset_robot(0, twist=(0.1, 0.0, 0.3))
    phys.set_motors_enabled(False)
    phys.kick(0, [0, 1], kick)
    l0 = _angular_momentum(phys)
    drift = 0.0
    for _ in range(50):
        phys.step()
        drift = max(drift, abs(_angular_momentum(phys) / l0 - 1))
    return drift


def test_offset_modules_conserve_angular_momentum_to_first_order():
    """Friction, spring and the coupling are internal: the angular momentum stays, up to the
    first-order error of the velocity-squared terms (explicit in the substep; ~(ω dt) relative)."""
    assert _momentum_drift(8, 0.01) < 1e-3  # modules at a few rad/s (steering speeds): 1e-4
    d8, d32 = _momentum_drift(8, 0.3), _momentum_drift(32, 0.3)  # kicked to ~20 rad/s
    assert d8 < 0.05 and d32 < 0.35 * d8


def test_offset_module_energy_never_rises_while_coasting():
    p = RobotParams(steering=SteeringParams(friction_coulomb=0.5, friction_static=0.75, **URDF_MODULE))
    phys = AzimutPhysics(p)
    phys.reset_robot(0, twist=(0.8, 0.2, 0.5))
    phys.set_motors_enabled(False)
    phys.kick(0, [1, 3], 0.05)
    e = [float(phys.energy()[0])]
    for _ in range(300):
        phys.step()
        e.append(float(phys.energy()[0]))
    assert np.all(np.diff(e) <= 1e-9 * e[0])


def test_module_inertia_must_exceed_m_c_squared():
    with pytest.raises(ValueError, match="module_inertia"):
        SteeringParams(module_mass=2.0, com_offset=0.1, module_inertia=0.02)


# ---------------------------------------------------------------------------------- drive torque–speed line

def _spin_to_steady(load_torque, ref, torque_max, stall=59.0, w0=22.0, bearing=0.005, seconds=3.0):
    """One wheel spin on the DC drive (no tire: a constant load torque), to its steady rate."""
    from azimut_env.physics.actuators import dc_torque_limits_kernel, wheel_spin_step_kernel
    phidot, dt, inertia, r = 0.0, 0.0025, 0.03, 0.08
    for _ in range(int(seconds / dt)):
        lo, hi = dc_torque_limits_kernel(phidot, stall, w0, torque_max)
        phidot = wheel_spin_step_kernel(phidot, ref, load_torque / r, True, r, inertia, 8.0, lo, hi, bearing, 0.0,
                                        0.02, dt)
    return phidot


def test_drive_runs_free_at_the_no_load_speed_and_stalls_at_the_stall_torque():
    """Free running (set-point beyond ω₀, no load): τ_stall (1 − φ̇/ω₀) = b φ̇, so
    φ̇ = ω₀ / (1 + b ω₀/τ_stall). Under a load τ_L (current limit above it): φ̇ = ω₀ (1 − τ_L/τ_stall)
    without bearing loss. At τ_L = τ_stall the wheel stands still."""
    assert _spin_to_steady(0.0, 40.0, 1e3) == pytest.approx(22.0 / (1 + 0.005 * 22.0 / 59.0), rel=1e-6)
    assert _spin_to_steady(20.0, 40.0, 1e3, bearing=0.0) == pytest.approx(22.0 * (1 - 20.0 / 59.0), rel=1e-6)
    assert abs(_spin_to_steady(59.0, 40.0, 1e3, bearing=0.0)) < 1e-9
    # the current limit (5 N·m) binds first: a 10 N·m load drives the wheel backward at its limit
    assert _spin_to_steady(10.0, 40.0, 5.0, seconds=0.5) < 0.0


def test_dc_drive_is_wired_into_the_substep():
    """A robot told 20 rad/s on drives whose no-load speed is 10 rad/s rolls at about 10 rad/s;
    the current-limit model reaches 20."""
    from azimut_env.params import WheelParams
    speeds = {}
    for model in ("current_limit", "dc"):
        phys = AzimutPhysics(RobotParams(wheel=WheelParams(drive_model=model, drive_no_load_speed=10.0)))
        phys.reset_robot(0, beta=np.zeros(4))
        for _ in range(150):
            phys.set_commands(np.zeros((1, 4)), np.full((1, 4), 20.0))
            phys.step()
        speeds[model] = float(np.mean(phys.wheel_speeds()))
    assert speeds["current_limit"] == pytest.approx(20.0, rel=0.02)
    assert 8.5 < speeds["dc"] < 10.0


def test_drive_params_are_validated():
    from azimut_env.params import WheelParams
    with pytest.raises(ValueError, match="drive_model"):
        WheelParams(drive_model="ac")
    with pytest.raises(ValueError, match="drive_no_load_speed"):
        WheelParams(drive_no_load_speed=0.0)


@settings(max_examples=300, deadline=None)
@given(omega=st.floats(-100, 100), stall=st.floats(0.1, 200), w0=st.floats(0.5, 100), tmax=st.floats(0.1, 200))
def test_dc_torque_range_is_the_torque_speed_line_clipped_at_the_current_limit(omega, stall, w0, tmax):
    """τ_hi(ω) = min(τ_max, τ_stall (1 − ω/ω₀)) and τ_lo(ω) = max(−τ_max, −τ_stall (1 + ω/ω₀)) while
    they bracket a torque (|ω| below the no-load speed); the range is odd in ω (τ_lo(ω) =
    −τ_hi(−ω)). Its two ends: the stall point (ω = 0: τ_stall, or the current limit below it) and
    the free-running point (ω = ω₀: no motoring torque left)."""
    from azimut_env.physics.actuators import dc_torque_limits_kernel
    lo, hi = dc_torque_limits_kernel(omega, stall, w0, tmax)
    lo_m, hi_m = dc_torque_limits_kernel(-omega, stall, w0, tmax)
    assert lo == pytest.approx(-hi_m, abs=1e-12) and hi == pytest.approx(-lo_m, abs=1e-12)
    assert -tmax <= lo <= hi <= tmax
    if abs(omega) < w0:
        assert hi == pytest.approx(min(tmax, stall * (1 - omega / w0)), rel=1e-12)
        assert lo == pytest.approx(max(-tmax, -stall * (1 + omega / w0)), rel=1e-12)
    assert dc_torque_limits_kernel(0.0, stall, w0, tmax) == (-min(stall, tmax), min(stall, tmax))
    assert dc_torque_limits_kernel(w0, stall, w0, tmax)[1] == 0.0


def test_energy_never_gained_while_coasting_with_every_paper_imperfection():
    """The whole "paper" preset at once (steering friction, offset modules, the DC drive line,
    steering-axis offsets, radius errors, the softer spring): motors off, the robot rolling and
    two modules kicked, the mechanical energy never rises from one control step to the next."""
    from azimut_env.imperfections import with_imperfections
    params = with_imperfections(RobotParams(), "paper")
    assert params.steering.has_friction and params.wheel.drive_model == "dc"
    phys = AzimutPhysics(params)
    phys.reset_robot(0, twist=(0.8, 0.2, 0.5))
    phys.set_motors_enabled(False)
    phys.kick(0, [0, 2], 0.05)
    e = [float(phys.energy()[0])]
    for _ in range(300):
        phys.step()
        assert phys.check()[0].all()
        e.append(float(phys.energy()[0]))
    rise = np.diff(e)
    assert np.all(rise <= 1e-9 * e[0]), f"energy rose by {rise.max():.3g} J"
    assert e[-1] < 0.5 * e[0]


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 6))
def test_joint_responses_are_coupled_apply_on_each_unit_impulse_pair(seed, n):
    """The friction passes' precomputed responses (modules.coupled_joint_responses) are
    :func:`coupled_apply` on z_k = (0, 0, −1, e_k), to the bit; and they are M⁻¹ z_k."""
    from azimut_env.physics.modules import coupled_apply, coupled_factor, coupled_joint_responses, mass_matrix
    rng = np.random.default_rng(seed)
    mass, inertia = 27.0 + 4 * 1.876, 2.0
    arm = rng.uniform(-0.4, 0.4, (n, 2))
    gam = rng.uniform(-np.pi, np.pi, n)
    m_mod, com = np.full(n, 1.876), rng.uniform(0.0, 0.08, n)
    D = np.full(n, 0.0151) + m_mod * com ** 2
    mc = m_mod * com
    B = np.stack([-mc * np.sin(gam), mc * np.cos(gam), mc * (arm[:, 0] * np.cos(gam) + arm[:, 1] * np.sin(gam))], -1)
    S_inv = np.zeros((3, 3))
    coupled_factor(B, D, mass, inertia, S_inv)
    body, joint = np.zeros((n, 3)), np.zeros((n, n))
    coupled_joint_responses(B, D, S_inv, body, joint)
    M = mass_matrix(mass, inertia, arm, gam, m_mod, com, D)
    for k in range(n):
        unit, resp = np.zeros(n), np.zeros(n)
        unit[k] = 1.0
        assert tuple(body[k]) == coupled_apply(B, D, S_inv, 0.0, 0.0, -1.0, unit, resp)
        assert np.array_equal(joint[k], resp)
        z = np.concatenate([[0.0, 0.0, -1.0], unit])
        np.testing.assert_allclose(np.concatenate([body[k], joint[k]]), np.linalg.solve(M, z), rtol=1e-9, atol=1e-12)
