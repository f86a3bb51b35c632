"""Actuator kernels: the wheel spin on the brush tire, the steering motor models, command latency."""

from __future__ import annotations

import math

import numpy as np
import pytest

from azimut_env.actuators import rolling_resistance_kernel, wheel_spin_step_kernel
from azimut_env.params import RobotParams, TireParams
from azimut_env.tire import stability_numbers, tire_step_kernel

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
        phidot = wheel_spin_step_kernel(phidot, ref, f[0], True, R, I_W, KV, TAU_W, BEARING, RR, TIRE.rolling_knee, DT)
        v += DT * f[0] / mass
        out.append((v, phidot, f[0]))
    return np.array(out)


def test_wheel_spin_without_load_follows_the_velocity_loop():
    """No tire force, no resistance: φ̇' = (I φ̇ + dt K_v ref)/(I + dt (K_v + b)) while unsaturated."""
    ph = 0.0
    for _ in range(3):
        new = wheel_spin_step_kernel(ph, 0.5, 0.0, True, R, I_W, KV, TAU_W, BEARING, 0.0, 0.02, DT)
        assert new == pytest.approx((I_W * ph + DT * KV * 0.5) / (I_W + DT * (KV + BEARING)))
        ph = new
    # a far set-point saturates the torque: φ̇' = φ̇ + dt τ_max / I (bearing implicit)
    new = wheel_spin_step_kernel(0.0, 20.0, 0.0, True, R, I_W, KV, TAU_W, BEARING, 0.0, 0.02, DT)
    assert new == pytest.approx(DT * TAU_W / (I_W + DT * BEARING))
    # motors off: only the load
    assert wheel_spin_step_kernel(2.0, 20.0, 10.0, False, R, I_W, KV, TAU_W, 0.0, 0.0, 0.02, DT) == \
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
