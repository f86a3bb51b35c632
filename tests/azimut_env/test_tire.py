"""The brush tire of azimut_env.physics.tire against its closed forms (unit tests on the kernels).

Env-level behaviour (loads, the steering modules) is tested with the physics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from azimut_env.params import TireParams
from azimut_env.physics.tire import (
    TRAIL_SPEED_EPS,
    brush_forces,
    brush_trail,
    stability_numbers,
    tire_elastic_energy,
    tire_step,
    tire_step_kernel,
)

TIRE = TireParams()
N = 86.0  # [N] a quarter of the 35 kg robot
DT = 0.0025
MU_N = TIRE.friction * N
C_A = TIRE.cornering_stiffness * N
C_K = TIRE.longitudinal_stiffness * N
A = TIRE.contact_half_length
SIG = TIRE.relaxation_length
K_Y = C_A / SIG
K_T = 0.5 * K_Y * A * A
M_SCRUB = 2.0 / 3.0 * MU_N * A


def _args(tire=TIRE):
    return (tire.friction, tire.longitudinal_stiffness, tire.cornering_stiffness, tire.longitudinal_relaxation_length,
            tire.relaxation_length, tire.contact_half_length, tire.damping_time)


def _run(s_long, s_lat, v_x, omega_z, steps, load=N, state=(0.0, 0.0, 0.0), dt=DT, tire=TIRE):
    """Integrate the kernel with prescribed (kinematic) slips; returns the last outputs."""
    ux, uy, tw = state
    out = None
    for _ in range(steps):
        out = tire_step_kernel(s_long, s_lat, v_x, omega_z, load, ux, uy, tw, *_args(tire), dt)
        ux, uy, tw = out[4:]
    return out


def _carried(alpha, speed, distance, kappa=0.0):
    """A wheel carried at ``speed`` with slip angle α (F_y = C_α α > 0 for α > 0) and slip ratio κ
    over ``distance``: tan α = −s_lat/|v_x|, κ = −s_long/|v_x|."""
    steps = int(round(distance / (speed * DT)))
    return _run(-kappa * speed, -math.tan(alpha) * speed, speed, 0.0, steps)


# ---------------------------------------------------------------------- steady state


def test_cornering_stiffness_is_the_slope_at_zero_slip_angle():
    alpha = np.array([1e-5, -1e-4])  # [rad]: ψ ≤ 5e-4, the curve is C_α α (1 − ψ + ψ²/3)
    _, fy = brush_forces(0.0, alpha, N, TIRE)
    assert np.allclose(fy / np.tan(alpha), C_A, rtol=1e-3)
    # the kernel, rolled 20 relaxation lengths, reaches the closed form
    for a in np.radians([0.05, 1.0, -2.0, 6.0]):
        out = _carried(a, 0.5, 20 * SIG)
        assert out[1] == pytest.approx(brush_forces(0.0, a, N, TIRE)[1], rel=1e-6, abs=1e-9)


def test_lateral_force_saturates_at_mu_n():
    a_sl = TIRE.saturation_slip_angle
    _, fy = brush_forces(0.0, [a_sl, 0.3, -0.6, 1.2], N, TIRE)
    assert np.allclose(np.abs(fy), MU_N)
    _, fy_below = brush_forces(0.0, 0.9 * a_sl, N, TIRE)
    assert fy_below < MU_N
    for a in (0.3, -0.5):
        out = _carried(a, 0.5, 20 * SIG)
        assert out[1] == pytest.approx(math.copysign(MU_N, a), rel=1e-9)


def test_longitudinal_force_from_slip_ratio():
    fx, _ = brush_forces([1e-4, -1e-4], 0.0, N, TIRE)
    assert np.allclose(fx / np.array([1e-4, -1e-4]), C_K, rtol=1e-3)
    for kappa in (0.01, -0.05, 0.5, -1.0):
        out = _carried(0.0, 0.5, 20 * SIG, kappa=kappa)
        assert out[0] == pytest.approx(brush_forces(kappa, 0.0, N, TIRE)[0], rel=1e-6)
    assert abs(_carried(0.0, 0.5, 20 * SIG, kappa=0.8)[0]) == pytest.approx(MU_N)
    # a wheel spinning on the spot (v_x = 0, r φ̇ = 1 m/s) slides at μN, driving the robot forward
    out = _run(-1.0, 0.0, 0.0, 0.0, 400)
    assert out[0] == pytest.approx(MU_N)


def test_combined_slip_stays_on_the_friction_circle():
    kappa, alpha = 0.02, math.radians(2.0)
    fx, fy = brush_forces(kappa, alpha, N, TIRE)
    lin = np.array([C_K * kappa, C_A * math.tan(alpha)])
    psi = np.hypot(*lin) / (3 * MU_N)
    assert np.hypot(fx, fy) == pytest.approx(MU_N * (1 - (1 - psi) ** 3))
    assert fx * lin[1] - fy * lin[0] == pytest.approx(0.0, abs=1e-9)  # along the linear force (2-D cross)
    # beyond sliding: |F| = μN in the direction of the slip, and each part below its pure-slip value
    fx, fy = brush_forces(0.3, math.radians(15.0), N, TIRE)
    assert np.hypot(fx, fy) == pytest.approx(MU_N)
    assert fx < brush_forces(0.3, 0.0, N, TIRE)[0] and fy < brush_forces(0.0, math.radians(15.0), N, TIRE)[1]
    out = _carried(math.radians(15.0), 0.5, 20 * SIG, kappa=0.3)
    assert np.hypot(out[0], out[1]) == pytest.approx(MU_N)
    assert out[0] == pytest.approx(fx, rel=1e-6) and out[1] == pytest.approx(fy, rel=1e-6)


# ---------------------------------------------------------------------- relaxation and rest


def test_static_friction_holds_a_push_below_mu_n():
    """A quarter-robot mass at rest pushed sideways with 0.6 μN: the tread sticks; the body settles
    at the brush deflection of that force, within the saturation deflection 3μNσ/C_α."""
    m, push = 8.75, 0.6 * MU_N
    x = v = 0.0
    state = (0.0, 0.0, 0.0)
    xs = []
    for _ in range(4000):  # 10 s
        out = tire_step_kernel(0.0, v, 0.0, 0.0, N, *state, *_args(), DT)
        state = out[4:]
        v += DT * (push + out[1]) / m
        x += DT * v
        xs.append(x)
    xs = np.array(xs)
    psi = 1 - (1 - push / MU_N) ** (1 / 3)
    x_eq = 3 * MU_N * SIG * psi / C_A
    u_sat = 3 * MU_N * SIG / C_A
    assert xs[-1] == pytest.approx(x_eq, rel=1e-4)
    assert np.max(xs) <= u_sat < SIG
    assert abs(v) < 1e-6  # no creep
    assert np.max(np.abs(xs[-400:] - x_eq)) < 1e-7


def test_a_push_above_mu_n_slides():
    m, push = 8.75, 1.2 * MU_N
    v = 0.0
    state = (0.0, 0.0, 0.0)
    for _ in range(800):
        out = tire_step_kernel(0.0, v, 0.0, 0.0, N, *state, *_args(), DT)
        state = out[4:]
        v += DT * (push + out[1]) / m
    assert out[1] == pytest.approx(-MU_N)
    assert v > 0.9 * (push - MU_N) / m * 800 * DT - 0.01


def test_misaligned_wheel_builds_force_by_distance_not_speed():
    """5° off, carried at 0.05 m/s and 0.5 m/s over the same distances: the same force (the old
    viscous tire gave 10× less at 0.05 m/s)."""
    alpha = math.radians(5.0)
    for dist in (1 * SIG, 3 * SIG, 5 * SIG):
        slow = _carried(alpha, 0.05, dist)[1]
        fast = _carried(alpha, 0.5, dist)[1]
        assert slow >= 0.5 * fast
        # they differ by the bristle damping's transient, τ_d V/σ e^{−s/σ} of the force, and the
        # first-order relaxation step at 0.5 m/s, dt V/σ
        tol = TIRE.damping_time * 0.5 / SIG * math.exp(-dist / SIG) + DT * 0.5 / SIG + 0.01
        assert slow == pytest.approx(fast, rel=tol)
    f_ss = brush_forces(0.0, alpha, N, TIRE)[1]
    assert _carried(alpha, 0.05, 5 * SIG)[1] == pytest.approx(f_ss, rel=0.01)


def test_lateral_build_up_is_the_first_order_lag_in_distance():
    """Linear range: F_y(s) = C_α α (1 − e^{−s/σ}) (up to the first-order step dt·V/σ and the
    damping term C_α τ_d V α e^{−s/σ}/σ)."""
    alpha, speed = math.radians(0.01), 0.05  # ψ < 1e-3: linear
    for dist in (0.5 * SIG, SIG, 2 * SIG):
        f = _carried(alpha, speed, dist)[1]
        lag = 1 - math.exp(-dist / SIG)
        damp = TIRE.damping_time * speed / SIG * math.exp(-dist / SIG)
        assert f == pytest.approx(C_A * math.tan(alpha) * (lag + damp), rel=speed * DT / SIG + 2e-3)


# ---------------------------------------------------------------------- moments


def _world_case(gamma, heading, speed, rolling_back=False):
    """Wheel plane at γ (rolling direction d = (sin γ, −cos γ), axle e = (cos γ, sin γ)); the wheel
    carried over the ground with velocity of direction ``heading``. Returns (s_lat, v_x, the angle
    from the travelled wheel direction ±d to the velocity, CCW positive)."""
    d = np.array([math.sin(gamma), -math.cos(gamma)])
    e = np.array([math.cos(gamma), math.sin(gamma)])
    v = speed * np.array([math.cos(heading), math.sin(heading)])
    v_x, s_lat = float(v @ d), float(v @ e)
    fwd = d if v_x >= 0 else -d
    ang = math.atan2(fwd[0] * v[1] - fwd[1] * v[0], fwd @ v)
    return s_lat, v_x, ang


@pytest.mark.parametrize("mis", [3.0, -3.0, 8.0, -8.0])
@pytest.mark.parametrize("backward", [False, True])
def test_aligning_moment_turns_the_wheel_toward_its_travel(mis, backward):
    gamma = 0.3
    d_heading = math.atan2(-math.cos(gamma), math.sin(gamma)) + (math.pi if backward else 0.0)
    s_lat, v_x, ang = _world_case(gamma, d_heading + math.radians(mis), 0.5)
    assert ang == pytest.approx(math.radians(mis))
    out = _run(0.0, s_lat, v_x, 0.0, int(20 * SIG / (0.5 * DT)))
    m_align = out[2]
    assert math.copysign(1.0, m_align) == math.copysign(1.0, ang)  # toward the direction of travel
    # size: t(ψ)·|F_y| with the brush trail
    psi = C_A * abs(math.tan(math.radians(mis))) / (3 * MU_N)
    sgn = abs(v_x) / math.hypot(v_x, TRAIL_SPEED_EPS)
    assert abs(m_align) == pytest.approx(sgn * float(brush_trail(psi, A)) * abs(out[1]), rel=1e-6)


def test_pneumatic_trail_is_a_third_of_the_half_length_and_vanishes_at_sliding():
    assert float(brush_trail(0.0, A)) == pytest.approx(A / 3)
    assert float(brush_trail(1e-4, A)) == pytest.approx(A / 3, rel=1e-3)
    assert float(brush_trail(1.0, A)) == 0.0
    psi = np.linspace(0, 1, 101)
    t = brush_trail(psi, A)
    assert np.all(np.diff(t) <= 0)
    # brush closed form: M_z = μ N a ψ (1 − ψ)³
    f = MU_N * (1 - (1 - psi[1:]) ** 3)
    assert np.allclose(t[1:] * f, MU_N * A * psi[1:] * (1 - psi[1:]) ** 3)
    out = _carried(math.radians(0.005), 0.5, 20 * SIG)  # ψ < 1e-3
    assert out[2] / out[1] == pytest.approx(-A / 3 * 0.5 / math.hypot(0.5, TRAIL_SPEED_EPS), rel=2e-3)
    out = _carried(math.radians(40), 0.5, 20 * SIG)
    assert out[2] == 0.0


def test_scrub_torque_at_rest_is_two_thirds_mu_n_a():
    """Steering a loaded wheel on the spot: the torque saturates at (2/3) μ N a, resisting."""
    for w in (1.0, -2.0):
        out = _run(0.0, 0.0, 0.0, w, 400)
        assert out[3] == pytest.approx(-math.copysign(M_SCRUB, w), rel=1e-12)
    # a small twist, then held: the torque −k_φ φ stays (no creep at rest)
    out = _run(0.0, 0.0, 0.0, 0.5, 8)  # 0.01 rad
    held = _run(0.0, 0.0, 0.0, 0.0, 2000, state=out[4:])
    assert held[6] == pytest.approx(0.01, rel=1e-12)
    assert held[3] == pytest.approx(-K_T * 0.01, rel=1e-9)
    assert K_T * 0.01 < M_SCRUB


def test_scrub_torque_fades_with_rolling_speed():
    """Rolling at V while steering at ω_z: steady twist σ ω_z / V (below the limit)."""
    w = 0.5
    for speed in (0.5, 1.0):
        out = _run(0.0, 0.0, speed, w, int(20 * SIG / (speed * DT)))
        assert out[3] == pytest.approx(-K_T * SIG * w / speed, rel=1e-6)
        assert abs(out[3]) < M_SCRUB
    slow = _run(0.0, 0.0, 0.01, w, 4000)
    assert abs(slow[3]) == pytest.approx(M_SCRUB)


def test_sliding_patch_has_no_torsional_grip_left():
    out = _run(0.0, 0.5, 0.0, 1.0, 400)  # sliding sideways at 0.5 m/s while steering
    assert abs(out[1]) == pytest.approx(MU_N)
    assert out[3] == 0.0


def test_unloaded_wheel_gives_nothing():
    out = tire_step_kernel(0.3, -0.2, 1.0, 2.0, 0.0, 1e-3, -1e-3, 0.1, *_args(), DT)
    assert out == (0.0,) * 7
    out = tire_step_kernel(0.3, -0.2, 1.0, 2.0, -5.0, 1e-3, -1e-3, 0.1, *_args(), DT)
    assert out == (0.0,) * 7


# ---------------------------------------------------------------------- numerics


def _mass_on_tire(mass, steps, dt=DT):
    """A mass on one tire at rest, kicked sideways at 0.1 m/s: max |v| [m/s] over the last 100
    steps."""
    v = 0.1
    state = (0.0, 0.0, 0.0)
    vs = []
    for _ in range(steps):
        out = tire_step_kernel(0.0, v, 0.0, 0.0, N, *state, *_args(), dt)
        state = out[4:]
        v += dt * out[1] / mass
        vs.append(abs(v))
    return max(vs[-100:])


def test_documented_stability_bound_is_the_real_one():
    """b + 2a < 4 (symplectic Euler, explicit damping): stable just inside, unstable just outside."""
    # the defaults: module I_mod/b² = 3.1 kg across, wheel spin I_w/r² = 4.7 kg along
    num = stability_numbers(TIRE, N, DT, mass_long=0.03 / 0.08**2, mass_lat=0.02 / 0.08**2, inertia_twist=0.02)
    assert num["lat_margin"] < 1.0 and num["long_margin"] < 1.0 and num["twist_margin"] < 0.01
    # find the mass at which the lateral margin is 4: k dt²/m + 2 k τ_d dt/m = 4
    m4 = (K_Y * DT * DT + 2 * K_Y * TIRE.damping_time * DT) / 4.0
    assert _mass_on_tire(1.05 * m4, 3000) < 1e-9
    # outside, the oscillation grows until the tread slides (a limit cycle at μN, not a decay)
    assert _mass_on_tire(0.95 * m4, 3000) > 0.1


def test_tire_step_batched_matches_the_kernel():
    rng = np.random.default_rng(0)
    args = rng.normal(size=(5, 5)) * [0.2, 0.2, 0.5, 1.0, 0.0]
    args[:, 4] = rng.uniform(0, 150, size=5)
    state = rng.normal(size=(5, 3)) * [1e-3, 1e-3, 0.01]
    forces, new = tire_step(args[:, 0], args[:, 1], args[:, 2], args[:, 3], args[:, 4], state, TIRE, DT)
    for i in range(5):
        ref = tire_step_kernel(*args[i, :5], *state[i], *_args(), DT)
        assert tuple(forces[i]) == ref[:4] and tuple(new[i]) == ref[4:]
    with pytest.raises(ValueError):
        tire_step(0, 0, 0, 0, N, np.zeros(2), TIRE, DT)
    with pytest.raises(ValueError):
        tire_step(0, 0, 0, 0, N, np.zeros(3), TIRE, 0.0)


_speed = st.floats(-1e3, 1e3, allow_nan=False)
_defl = st.floats(-1.0, 1.0, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(_speed, _speed, _speed, _speed, st.floats(-10.0, 1e4), _defl, _defl, st.floats(-10.0, 10.0),
       st.floats(1e-5, 0.01))
def test_finite_inputs_give_finite_bounded_outputs(s_long, s_lat, v_x, w, load, ux, uy, tw, dt):
    out = tire_step_kernel(s_long, s_lat, v_x, w, load, ux, uy, tw, *_args(), dt)
    assert all(math.isfinite(x) for x in out)
    mu_n = TIRE.friction * max(load, 0.0)
    assert math.hypot(out[0], out[1]) <= mu_n * (1 + 1e-12) + 1e-12
    assert abs(out[3]) <= 2 / 3 * mu_n * A * (1 + 1e-12) + 1e-12
    assert abs(out[2]) <= A / 3 * mu_n * (1 + 1e-9) + 1e-12
    # the deflection never winds up beyond sliding
    if load > 0:
        psi = math.hypot(C_K / N * load * out[4] / TIRE.longitudinal_relaxation_length,
                         C_A / N * load * out[5] / SIG) / (3 * mu_n)
        assert psi <= 1 + 1e-9


def test_tire_params_are_validated():
    for bad in (dict(cornering_stiffness=0.0), dict(relaxation_length=-0.01), dict(contact_half_length=math.nan),
                dict(damping_time=-1.0), dict(longitudinal_stiffness=math.inf), dict(friction=-1.0)):
        with pytest.raises(ValueError):
            TireParams(**bad)
    assert TireParams(damping_time=0.0).damping_time == 0.0


def test_elastic_energy_is_the_work_of_the_brush_force():
    """Along one axis, E(u) = ∫ F du (numerical quadrature), ½ k u² at small deflection."""
    k_x = C_K / TIRE.longitudinal_relaxation_length
    for axis, k in ((1, K_Y), (0, k_x)):
        u = np.linspace(0.0, 0.9 * (3 * MU_N / k), 2001)
        st = np.zeros((u.size, 3))
        st[:, axis] = u
        psi = k * u / (3 * MU_N)
        force = MU_N * (1 - (1 - psi) ** 3)
        work = np.concatenate([[0.0], np.cumsum(0.5 * (force[1:] + force[:-1]) * np.diff(u))])
        assert np.allclose(tire_elastic_energy(st, N, TIRE), work, rtol=1e-5, atol=1e-7)  # trapezoid error
    small = tire_elastic_energy([1e-7, -2e-7, 0.0], N, TIRE)
    assert small == pytest.approx(0.5 * (k_x * 1e-14 + K_Y * 4e-14), rel=1e-5)
    assert tire_elastic_energy([0.0, 0.0, 0.01], N, TIRE) == pytest.approx(0.5 * K_T * 1e-4)
    assert tire_elastic_energy([1e-3, 1e-3, 0.1], 0.0, TIRE) == 0.0


def test_domain_randomisation_draws_the_tire_with_a_fixed_contact_stiffness():
    """Slip stiffness and relaxation lengths share a factor (σ = C/k, k the carcass stiffness):
    C/σ, and so the contact's stability figures, stay; the patch size varies on its own."""
    from azimut_env.env import AzimutEnv
    from azimut_env.physics.engine import WP

    env = AzimutEnv(domain_randomization=0.4)
    seen = []
    for seed in range(3):
        env.reset(seed=seed)
        w = env.physics.wheel_params[0]
        assert np.allclose(w[:, WP.C_ALPHA] / w[:, WP.SIGMA_LAT], TIRE.cornering_stiffness / SIG)
        assert np.allclose(w[:, WP.C_KAPPA] / w[:, WP.SIGMA_LONG],
                           TIRE.longitudinal_stiffness / TIRE.longitudinal_relaxation_length)
        assert np.all(np.abs(w[:, WP.C_ALPHA] / TIRE.cornering_stiffness - 1) <= 0.4 + 1e-12)
        seen.append((w[0, WP.C_ALPHA], w[0, WP.HALF_LEN]))
    seen = np.array(seen)
    assert np.ptp(seen[:, 0]) > 0 and np.ptp(seen[:, 1]) > 0
    plain = AzimutEnv()
    plain.reset(seed=0)
    assert plain.physics.wheel_params[0, 0, WP.C_ALPHA] == TIRE.cornering_stiffness
