"""Actuator kernels: the wheel spin on the brush tire, the steering motor models, command latency."""

from __future__ import annotations

import math

import numpy as np
import pytest

from azimut_env.params import RobotParams
from azimut_env.physics.actuators import rolling_resistance_kernel, wheel_spin_step_kernel
from azimut_env.physics.tire import stability_numbers, tire_step_kernel

P = RobotParams()
TIRE = P.tire
R = float(P.geometry.r[0])
N = 86.0
DT = 0.0025
I_W, KV, TAU_W, BEARING = P.wheel.inertia, P.wheel.velocity_gain, P.limits.wheel_torque_max, P.wheel.bearing_damping
RR = TIRE.rolling_resistance * N * R


def _tire_args():
    t = TIRE
    return (t.friction, t.longitudinal_stiffness, t.cornering_stiffness, t.longitudinal_relaxation_length,
            t.relaxation_length, t.contact_half_length, t.damping_time)


def _drive(mass, ref, seconds, v0=0.0, phidot0=0.0, load=N):
    """A quarter robot (mass) on one driven wheel, straight line: returns (v, φ̇, F_long) histories."""
    v, phidot = v0, phidot0
    st = (0.0, 0.0, 0.0)
    out = []
    for _ in range(int(round(seconds / DT))):
        f = tire_step_kernel(v - R * phidot, 0.0, v, 0.0, load, *st, *_tire_args(), DT)
        st = f[4:]
        phidot = wheel_spin_step_kernel(phidot, ref, f[0], True, R, I_W, KV, -TAU_W, TAU_W, BEARING, RR,
                                        TIRE.rolling_knee, DT)
        v += DT * f[0] / mass
        out.append((v, phidot, f[0]))
    return np.array(out)


def test_wheel_spin_without_load_follows_the_velocity_loop():
    """No tire force, no resistance: φ̇' = (I φ̇ + dt K_v ref)/(I + dt (K_v + b)) while unsaturated."""
    ph = 0.0
    for _ in range(3):
        new = wheel_spin_step_kernel(ph, 0.5, 0.0, True, R, I_W, KV, -TAU_W, TAU_W, BEARING, 0.0, 0.02, DT)
        assert new == pytest.approx((I_W * ph + DT * KV * 0.5) / (I_W + DT * (KV + BEARING)))
        ph = new
    # a far set-point saturates the torque: φ̇' = φ̇ + dt τ_max / I (bearing implicit)
    new = wheel_spin_step_kernel(0.0, 20.0, 0.0, True, R, I_W, KV, -TAU_W, TAU_W, BEARING, 0.0, 0.02, DT)
    assert new == pytest.approx(DT * TAU_W / (I_W + DT * BEARING))
    # motors off: only the load
    assert wheel_spin_step_kernel(2.0, 20.0, 10.0, False, R, I_W, KV, -TAU_W, TAU_W, 0.0, 0.0, 0.02, DT) == \
        pytest.approx(2.0 - DT * R * 10.0 / I_W)


def test_rolling_resistance_fades_near_rest():
    assert rolling_resistance_kernel(10.0, R, 1.0, 0.02) == -1.0
    assert rolling_resistance_kernel(-10.0, R, 1.0, 0.02) == 1.0
    assert rolling_resistance_kernel(0.1, R, 1.0, 0.02) == pytest.approx(-0.1 * R / 0.02)
    assert rolling_resistance_kernel(0.0, R, 1.0, 0.02) == 0.0


def test_driven_wheel_on_the_brush_tire_accelerates_the_robot_and_settles():
    """Spin + tire + quarter robot at dt = 2.5 ms: reaches the set-point speed with a small slip,
    no oscillation left (the documented stability numbers are well inside the bound)."""
    mass, ref = 8.75, 10.0  # 0.8 m/s
    num = stability_numbers(TIRE, N, DT, mass_long=I_W / R**2, mass_lat=1.0, inertia_twist=1.0)
    assert num["long_margin"] < 1.0
    h = _drive(mass, ref, 4.0)
    v, phidot, f = h[-1]
    assert v == pytest.approx(R * ref, rel=0.02)
    # the steady slip ratio carries the rolling resistance and bearing: κ = F/C_κ
    kappa = (R * phidot - v) / v
    assert kappa == pytest.approx(f / (TIRE.longitudinal_stiffness * N), rel=0.05, abs=1e-5)
    assert np.ptp(h[-200:, 2]) < 0.05
    # peak traction while accelerating hard: at most μN, and the motor torque limit is reached first
    assert np.max(np.abs(h[:, 2])) <= TIRE.friction * N + 1e-9


def test_wheel_driven_against_a_held_robot_stalls_or_slides():
    """τ_max/r = 62.5 N < μN = 68.8 N: the tread sticks and the motor stalls; on a light load
    (μN = 40 N) the wheel spins up and slides at μN."""
    h = _drive(1e9, 20.0, 1.0)  # a robot that does not move
    assert abs(h[-1, 2]) == pytest.approx(TAU_W / R, rel=1e-3)
    assert abs(h[-1, 1]) < 0.05
    h = _drive(1e9, 20.0, 1.0, load=50.0)
    assert abs(h[-1, 2]) == pytest.approx(TIRE.friction * 50.0, rel=1e-6)
    assert h[-1, 1] > 10.0
    assert np.all(np.isfinite(h))


def test_braking_on_a_light_load_locks_within_the_friction_limit():
    mass = 8.75
    h = _drive(mass, 0.0, 2.0, v0=1.0, phidot0=1.0 / R, load=20.0)
    assert np.all(np.abs(h[:, 2]) <= TIRE.friction * 20.0 + 1e-9)
    assert abs(h[-1, 0]) < 0.02


# ---------------------------------------------------------------------- steering motor models

from azimut_env.params import SteeringMotorParams  # noqa: E402
from azimut_env.physics.actuators import dc_torque_limits_kernel, steer_actuator_kernel  # noqa: E402

SM = SteeringMotorParams(model="dc")
LIM = P.limits
K_S, C_S, KP = P.steering.stiffness, P.steering.damping, P.steering.position_gain
I_MOD = P.steering.module_inertia


def _steer(dc, load_torque, seconds=1.2, beta0=-1.5, target=1.5):
    """A module (inertia I_mod) against a constant torque −τ_L, driven through the series spring
    toward ``target``: returns the history of (β, β̇, θ_m, θ̇_m, τ_s)."""
    theta, omega, beta, beta_dot = beta0, 0.0, beta0, 0.0
    out = []
    for _ in range(int(round(seconds / DT))):
        theta, omega, tau_s = steer_actuator_kernel(dc, theta, omega, target, beta, beta_dot, True, KP,
                                                    LIM.steer_rate_max, LIM.steer_accel_max, LIM.steer_torque_max,
                                                    K_S, C_S, SM.stall_torque, SM.no_load_speed, SM.rotor_inertia, DT)
        beta_dot += DT * (tau_s - load_torque) / I_MOD
        beta += DT * beta_dot
        out.append((beta, beta_dot, theta, omega, tau_s))
    return np.array(out)


def test_dc_torque_speed_line():
    ts, w0, tmax = 30.0, 6.5, 15.0
    assert dc_torque_limits_kernel(0.0, ts, w0, tmax) == (-15.0, 15.0)  # current-limited at rest
    lo, hi = dc_torque_limits_kernel(4.0, ts, w0, tmax)
    assert hi == pytest.approx(ts * (1 - 4.0 / w0)) and lo == -15.0  # motoring on the line, braking at the limit
    lo, hi = dc_torque_limits_kernel(-4.0, ts, w0, tmax)
    assert lo == pytest.approx(-ts * (1 - 4.0 / w0)) and hi == 15.0
    assert dc_torque_limits_kernel(w0, ts, w0, tmax)[1] == pytest.approx(0.0)
    assert dc_torque_limits_kernel(3 * w0, ts, w0, tmax) == (-15.0, -15.0)  # overdriven: brakes at the limit


def test_dc_motor_follows_the_kinematic_profile_when_unloaded():
    kin = _steer(False, 0.0, 0.6, beta0=0.0, target=0.8)
    dc = _steer(True, 0.0, 0.6, beta0=0.0, target=0.8)
    assert np.max(np.abs(kin[:, 2] - dc[:, 2])) < 1e-12
    assert np.max(np.abs(kin[:, 0] - dc[:, 0])) < 1e-12


def test_back_emf_limits_the_steering_rate_under_load():
    """Against τ_L = 14 N·m the DC motor slows to ω₀ (1 − τ_L/τ_stall) = 3.47 rad/s; the kinematic
    position source keeps its 4 rad/s (its spring torque stays below its 15 N·m clip)."""
    tau_l = 14.0
    for dc, rate in ((False, LIM.steer_rate_max), (True, SM.no_load_speed * (1 - tau_l / SM.stall_torque))):
        h = _steer(dc, tau_l)
        mid = (h[:, 0] > -0.3) & (h[:, 0] < 0.3)
        assert mid.sum() > 20
        assert h[mid, 1] == pytest.approx(rate, rel=2e-3)
        assert h[mid, 4] == pytest.approx(tau_l, rel=2e-3)
    assert SM.no_load_speed * (1 - tau_l / SM.stall_torque) < 0.9 * LIM.steer_rate_max
    # no load: both at the rate limit
    h = _steer(True, 0.0)
    mid = (h[:, 0] > -0.3) & (h[:, 0] < 0.3)
    assert h[mid, 1] == pytest.approx(LIM.steer_rate_max, rel=5e-3)  # the module still rings (ζ ≈ 0.27)


def test_dc_motor_against_a_blocked_module_stalls_at_the_current_limit():
    theta, omega = 0.0, 0.0
    for _ in range(800):
        theta, omega, tau_s = steer_actuator_kernel(True, theta, omega, 1.0, 0.0, 0.0, True, KP, LIM.steer_rate_max,
                                                    LIM.steer_accel_max, LIM.steer_torque_max, K_S, C_S,
                                                    SM.stall_torque, SM.no_load_speed, SM.rotor_inertia, DT)
    assert tau_s == pytest.approx(LIM.steer_torque_max, rel=1e-6)
    assert abs(omega) < 1e-6


def test_motor_params_are_validated():
    with pytest.raises(ValueError, match="model"):
        SteeringMotorParams(model="servo")
    with pytest.raises(ValueError):
        SteeringMotorParams(no_load_speed=0.0)
    with pytest.raises(ValueError):
        SteeringMotorParams(rotor_inertia=math.nan)
    assert not SteeringMotorParams().is_dc and SM.is_dc


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_f = st.floats(-1e3, 1e3, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(_f, _f, st.floats(-2.0, 2.0), st.floats(-2.0, 2.0), _f, st.booleans(), st.booleans(), st.floats(1e-5, 0.01))
def test_steering_kernels_finite_on_finite_input(theta, omega, target, beta, beta_dot, enabled, dc, dt):
    out = steer_actuator_kernel(dc, theta, omega, target, beta, beta_dot, enabled, KP, LIM.steer_rate_max,
                                LIM.steer_accel_max, LIM.steer_torque_max, K_S, C_S, SM.stall_torque,
                                SM.no_load_speed, SM.rotor_inertia, dt)
    assert all(math.isfinite(x) for x in out)
    if not enabled:
        assert out[1] == 0.0  # braked


@settings(max_examples=200, deadline=None)
@given(_f, _f, st.floats(-1e4, 1e4), st.booleans(), st.floats(1e-5, 0.01))
def test_wheel_spin_kernel_finite_on_finite_input(phidot, ref, f_long, enabled, dt):
    new = wheel_spin_step_kernel(phidot, ref, f_long, enabled, R, I_W, KV, -TAU_W, TAU_W, BEARING, RR,
                                 TIRE.rolling_knee, dt)
    assert math.isfinite(new)
