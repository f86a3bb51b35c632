"""Tire-ground contact from vehicle dynamics: a brush tire with relaxation lengths, a pneumatic
trail and a contact-patch (dry-parking) torque.

Frames and slips
----------------
Wheel k rolls along ``d = (sin γ, −cos γ)`` and its propulsion axis (the no-slip, lateral direction)
is ``e = (cos γ, sin γ)``. With v(P) the velocity of the contact point P over the ground, the
inputs of the model are

* ``v_x = v(P)·d``         forward (rolling-direction) speed of the wheel over the ground [m/s];
* ``s_long = v_x − r φ̇``   longitudinal slip velocity (tread at P relative to the ground) [m/s];
* ``s_lat = v(P)·e``       lateral slip velocity [m/s];
* ``ω_z``                  yaw rate of the wheel plane over the ground (chassis yaw rate + β̇) [rad/s];
* ``N``                    normal load [N].

In steady rolling the slip ratio is ``κ = −s_long/|v_x|`` and the slip angle ``tan α = −s_lat/|v_x|``
(the sign conventions of Pacejka 2012, Ch. 1; forces below are on the robot, so F_y = C_α α opposes s_lat).

State (per wheel, three floats, all zero for an unloaded tire at rest)
---------------------------------------------------------------------
``(u_x, u_y, φ)``: longitudinal and lateral deflection of the contact patch relative to the rim
[m] and its twist about the vertical [rad]. Positive u is displacement of the rim over the stuck
tread in the +d / +e direction.

Equations
---------
1. Transient slip with relaxation lengths σ_κ, σ_α (Pacejka 2012, *Tire and Vehicle Dynamics*,
   3rd ed., Ch. 7, single-contact-point transient tire models: σ dv/dt + |V_x| v = σ V_sy)::

       du_x/dt = s_long − |v_x| u_x / σ_κ,      du_y/dt = s_lat − |v_x| u_y / σ_α.

   In steady rolling u_x/σ_κ = s_long/|v_x| = −κ and u_y/σ_α = −tan α, so the effective slips
   κ' = −u_x/σ_κ, α' = −u_y/σ_α are the slip ratio and angle lagged *in distance travelled*
   (ds = |v_x| dt): a misaligned wheel builds force by distance, not by speed. At rest
   (v_x = 0) u is the integral of the sliding: the tread sticks and the contact is a spring of
   stiffness k_y = C_α/σ_α (static friction) until it saturates.
2. Steady-state force of the brush model with a parabolic pressure distribution, combined slip on
   a friction circle (Pacejka 2012, Ch. 3, the brush model: F_y = μN(3ψ − 3ψ² + ψ³),
   ψ = θ|σ|, θ = C_α/(3μN))::

       (f_x, f_y) = (C_κ κ', C_α α'),   ψ = ‖(f_x, f_y)‖ / (3 μ N),
       F = μ N (1 − (1 − ψ)³) (f_x, f_y) / ‖(f_x, f_y)‖   for ψ < 1,   F = μN · direction for ψ ≥ 1.

   The slope at zero slip is the cornering stiffness C_α (and C_κ longitudinally); the force
   saturates at μN when ψ = 1, i.e. α_sl = 3μN / C_α. At ψ ≥ 1 the deflection is clipped back to
   ψ = 1 (no wind-up), so the tread slides and the force direction follows the sliding.
   C_α = c_α N and C_κ = c_κ N (stiffness coefficients per unit load).
3. Bristle damping (the σ₁ term of the LuGre model, Canudas de Wit et al. 1995)::

       F ← F − k τ_d du/dt  per direction (k = C/σ),   then ‖F‖ ≤ μN.

   It damps the stuck tread at rest and at low speed, where the relaxation term |v_x|/σ does
   not; in steady state du/dt = 0 and it changes nothing.
4. Self-aligning moment from the brush model's pneumatic trail (Pacejka 2012, Ch. 3: M_z =
   −μ N a ψ (1 − ψ)³ for the parabolic brush, so t = −M_z/F_y)::

       t(ψ) = a ψ (1 − ψ)³ / (1 − (1 − ψ)³)  →  a/3 at ψ → 0,  0 at ψ = 1 (full sliding),
       M_align = −sgn_ε(v_x) · t(ψ) · F_y,brush.

   a is the contact half-length. The lateral force acts a trail t behind the contact centre, so
   the moment turns the wheel plane toward the direction of travel, for misalignment either way
   and for rolling forward or backward. sgn_ε(v) = v/√(v² + ε²) with ε = ``TRAIL_SPEED_EPS``
   (no trail at rest, where the patch deflects uniformly).
5. Dry-parking (scrub) torque: a twist state of the patch with torsional stiffness
   ``k_φ = k_y a²/2`` (uniform bristles on a circular patch of radius a: k_φ = c ∫ r² dA with
   c = k_y/(πa²)), relaxed by rolling over σ_α, damped like the forces, and limited by the torque
   of full sliding over a circular patch with uniform pressure p = N/(πa²),
   ``∫₀^a μ p 2π ρ² dρ = (2/3) μ N a`` (a Hertzian pressure gives 3π/16 instead of 2/3; Johnson
   1985, *Contact Mechanics*, Ch. 7, twisting of a circular contact)::

       dφ/dt = ω_z − |v_x| φ / σ_α,    M_scrub = −k_φ φ − k_φ τ_d dφ/dt,
       |M_scrub| ≤ (2/3) μ N a · √(1 − (‖F‖/μN)²).

   The last factor shares the friction between sliding and spinning on an ellipsoidal limit
   surface (Howe & Cutkosky 1996, "Practical force-motion models for sliding manipulation",
   IJRR 15(6)): a fully sliding patch has no torsional grip left. The twist is clipped at the
   limit (no wind-up). While rolling, the twist relaxes over σ_α: the torque of steering a wheel
   fades with rolling speed (steady state M = k_φ σ_α ω_z/|v_x|).

Moments: ``M_align`` and ``M_scrub`` are pure couples about the vertical through P. The moment
about the steering axis A of the forces applied at P (offset b along e) is added by the caller:
``M_A = M_align + M_scrub + b (e × F) = M_align + M_scrub − b F_long``.

Integration (one call = one substep dt)
---------------------------------------
The relaxation term is implicit, ``u' = (u + dt s)/(1 + dt |v_x|/σ)`` (unconditionally stable);
the slips s come from the bodies' velocities at the start of the substep and the force from u'
is applied over the substep, i.e. the contact spring is integrated by symplectic Euler and the
damping explicitly. For a DOF of effective mass m seen at the contact (k = C/σ, c = k τ_d) the
scheme is stable iff (see :func:`stability_numbers`)::

       c dt / m < 2   and   k dt² / m + 2 c dt / m < 4,

with m the effective mass the contact sees in that direction: its compliances add,
``1/m = Σ_j ℓ_j²/I_j`` over the DOFs a force there moves (lever ℓ_j, inertia or mass I_j). Along
the rolling direction d: the wheel spin (r²/I_w), the module turning about its steering axis
(b²/I_mod, the contact is offset by b along e) and the chassis (1/M + |(P − O) × d|²/I); across
(along e): the chassis only (the force passes through the steering axis); the twist: the module's
yaw inertia I_mod (and the chassis').

For the whole robot the contact stiffnesses K = Σ_k (k_x J_xᵀJ_x + k_y J_yᵀJ_y + k_φ J_φᵀJ_φ) and
their damping C = τ_d K are proportional, so the condition holds mode by mode: with ω_max² the
largest eigenvalue of M⁻¹K (M the mass matrix of chassis, modules and spins),
``ω_max² dt (dt + 2 τ_d) < 4`` is exact for the linearised contact. For the default robot
ω_max ≈ 210 rad/s (a spin-and-module mode along d) and the figure is 1.38 at dt = 2.5 ms.

Parameter values and their sources: :class:`~azimut_env.params.TireParams`.

The scalar kernels are numba functions inlined into the physics substep (one loop over robots ×
wheels). :func:`tire_step` runs the same kernel over arrays, :func:`brush_forces` and
:func:`brush_trail` are the steady-state closed forms, for analysis and tests.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numba import njit

__all__ = [
    "TS",
    "TRAIL_SPEED_EPS",
    "tire_step_kernel",
    "brush_force_kernel",
    "brush_trail_kernel",
    "tire_step",
    "brush_forces",
    "brush_trail",
    "stability_numbers",
    "tire_elastic_energy",
]


class TS(IntEnum):
    """Columns of the per-wheel tire state (..., len(TS)): the contact patch's deflections
    u_x, u_y [m] and its twist φ [rad]."""

    U_LONG, U_LAT, TWIST = range(3)


#: speed [m/s] below which the aligning moment fades out (sgn_ε(v_x) = v_x/√(v_x² + ε²)).
TRAIL_SPEED_EPS = 0.01


@njit(cache=True, inline="always")
def brush_force_kernel(kappa: float, alpha: float, c_kappa: float, c_alpha: float, mu_n: float):
    """Steady-state brush force for effective slips (κ', α') [-, rad] (eq. 2 of the module).

    c_kappa = C_κ [N], c_alpha = C_α [N/rad], mu_n = μN [N]. Returns (F_x, F_y, ψ) with ψ the
    normalised slip (≥ 1: fully sliding) and F on the robot (F_y = C_α α' for small α')."""
    fx = c_kappa * kappa
    fy = c_alpha * alpha
    mag = math.sqrt(fx * fx + fy * fy)
    if mu_n <= 0.0 or not mag > 0.0:
        return 0.0, 0.0, 0.0
    psi = mag / (3.0 * mu_n)
    if psi >= 1.0:
        frac = 1.0
    else:
        q = 1.0 - psi
        frac = 1.0 - q * q * q
    s = mu_n * frac / mag
    return fx * s, fy * s, psi


@njit(cache=True, inline="always")
def brush_trail_kernel(psi: float, half_length: float) -> float:
    """Pneumatic trail t(ψ) [m] of the parabolic brush (eq. 4): a ψ(1−ψ)³/(1−(1−ψ)³), a/3 at 0."""
    if psi >= 1.0:
        return 0.0
    if psi < 1e-6:
        return half_length * (1.0 / 3.0 - 2.0 * psi / 3.0)  # series: (1 − ψ)³ψ/(3ψ − 3ψ² + ψ³)
    q = 1.0 - psi
    q3 = q * q * q
    return half_length * psi * q3 / (1.0 - q3)


@njit(cache=True, inline="always")
def tire_step_kernel(s_long: float, s_lat: float, v_x: float, omega_z: float, load: float,
                     u_long: float, u_lat: float, twist: float,
                     mu: float, c_kappa_coef: float, c_alpha_coef: float, sigma_long: float,
                     sigma_lat: float, half_length: float, damping_time: float, dt: float):
    """One substep of one tire (module docstring, eqs. 1–5).

    Args:
        s_long: longitudinal slip velocity v_x − r φ̇ [m/s]. s_lat: lateral slip velocity v(P)·e
            [m/s]. v_x: forward speed over the ground v(P)·d [m/s]. omega_z: yaw rate of the
            wheel plane over the ground [rad/s]. load: normal load N [N] (≤ 1e-9: no contact).
        u_long, u_lat, twist: the state (:class:`TS`) at the start of the substep [m, m, rad].
        mu: friction coefficient. c_kappa_coef: C_κ/N [-]. c_alpha_coef: C_α/N [1/rad].
        sigma_long, sigma_lat: relaxation lengths σ_κ, σ_α [m]. half_length: contact
            half-length a [m]. damping_time: τ_d [s]. dt: substep [s].

    Returns:
        (F_long, F_lat, M_align, M_scrub, u_long', u_lat', twist'): forces on the robot along d
        and e [N], couples about the vertical at P [N·m], and the new state.
    """
    if not load > 1e-9:  # wheel off the ground: no force, the patch relaxes to its free shape
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    mu_n = mu * load
    c_k = c_kappa_coef * load
    c_a = c_alpha_coef * load
    k_x = c_k / sigma_long
    k_y = c_a / sigma_lat
    speed = abs(v_x)
    # 1. deflections, relaxation implicit
    ux = (u_long + dt * s_long) / (1.0 + dt * speed / sigma_long)
    uy = (u_lat + dt * s_lat) / (1.0 + dt * speed / sigma_lat)
    # 2. brush force on the effective slips (κ', α') = (−u_x/σ_κ, −u_y/σ_α); clip the wind-up
    fx, fy, psi = brush_force_kernel(-ux / sigma_long, -uy / sigma_lat, c_k, c_a, mu_n)
    if psi > 1.0:
        ux /= psi
        uy /= psi
        psi = 1.0
    # 3. bristle damping, then the friction circle
    f_long = fx - k_x * damping_time * (ux - u_long) / dt
    f_lat = fy - k_y * damping_time * (uy - u_lat) / dt
    mag = math.sqrt(f_long * f_long + f_lat * f_lat)
    if mag > mu_n:
        s = mu_n / mag
        f_long *= s
        f_lat *= s
    # 4. aligning moment: the brush lateral force acts a trail t(ψ) behind the contact centre
    sgn = v_x / math.sqrt(v_x * v_x + TRAIL_SPEED_EPS * TRAIL_SPEED_EPS)
    m_align = -sgn * brush_trail_kernel(psi, half_length) * fy
    # 5. twist of the patch and the scrub torque on the ellipsoidal limit surface
    k_t = 0.5 * k_y * half_length * half_length
    share = min(1.0, (fx * fx + fy * fy) / (mu_n * mu_n))
    m_max = (2.0 / 3.0) * mu_n * half_length * math.sqrt(1.0 - share)
    tw = (twist + dt * omega_z) / (1.0 + dt * speed / sigma_lat)
    if k_t * abs(tw) > m_max:
        tw = m_max / k_t if tw > 0.0 else -m_max / k_t
    m_scrub = -k_t * tw - k_t * damping_time * (tw - twist) / dt
    if m_scrub > m_max:
        m_scrub = m_max
    elif m_scrub < -m_max:
        m_scrub = -m_max
    return f_long, f_lat, m_align, m_scrub, ux, uy, tw


@njit(cache=True)
def _tire_step_batch(s_long, s_lat, v_x, omega_z, load, state, prm, dt, out, new_state):
    for i in range(s_long.shape[0]):
        p = prm[i]
        r = tire_step_kernel(s_long[i], s_lat[i], v_x[i], omega_z[i], load[i], state[i, TS.U_LONG],
                             state[i, TS.U_LAT], state[i, TS.TWIST], p[0], p[1], p[2], p[3], p[4], p[5], p[6], dt)
        out[i, 0] = r[0]
        out[i, 1] = r[1]
        out[i, 2] = r[2]
        out[i, 3] = r[3]
        new_state[i, TS.U_LONG] = r[4]
        new_state[i, TS.U_LAT] = r[5]
        new_state[i, TS.TWIST] = r[6]


def _tire_param_row(tire) -> np.ndarray:
    """The kernel's parameter order from a :class:`~azimut_env.params.TireParams`."""
    return np.array([tire.friction, tire.longitudinal_stiffness, tire.cornering_stiffness,
                     tire.longitudinal_relaxation_length, tire.relaxation_length, tire.contact_half_length,
                     tire.damping_time], dtype=np.float64)


def tire_step(s_long, s_lat, v_x, omega_z, load, state, tire, dt: float):
    """:func:`tire_step_kernel` over arrays (broadcast together; ``state`` has a trailing axis of
    3, :class:`TS`). ``tire``: a :class:`~azimut_env.params.TireParams`.

    Returns ``(forces, new_state)``: forces (..., 4) = (F_long, F_lat, M_align, M_scrub) [N, N,
    N·m, N·m], new_state (..., 3)."""
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0, got {dt!r}")
    arrays = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (s_long, s_lat, v_x, omega_z, load)))
    shape = arrays[0].shape
    st = np.asarray(state, dtype=np.float64)
    if st.shape[-1:] != (len(TS),):
        raise ValueError(f"state must have a trailing axis of {len(TS)}, got shape {st.shape}")
    shape = np.broadcast_shapes(shape, st.shape[:-1])
    flat = [np.ascontiguousarray(np.broadcast_to(a, shape)).ravel() for a in arrays]
    st = np.ascontiguousarray(np.broadcast_to(st, shape + (len(TS),))).reshape(-1, len(TS))
    m = flat[0].shape[0]
    prm = np.ascontiguousarray(np.broadcast_to(_tire_param_row(tire), (m, 7)))
    out = np.empty((m, 4))
    new = np.empty((m, len(TS)))
    _tire_step_batch(*flat, st, prm, float(dt), out, new)
    return out.reshape(shape + (4,)), new.reshape(shape + (len(TS),))


def brush_forces(slip_ratio, slip_angle, load, tire) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state (F_long, F_lat) [N] of the brush model for slip ratio κ [-] and slip angle α
    [rad] (eq. 2 with κ' = κ, α' = tan α), arrays broadcast together."""
    k, a, n = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (slip_ratio, slip_angle, load)))
    n = np.maximum(n, 0.0)
    fx = tire.longitudinal_stiffness * n * k
    fy = tire.cornering_stiffness * n * np.tan(a)
    mu_n = tire.friction * n
    mag = np.hypot(fx, fy)
    psi = np.where(mu_n > 0, mag / np.where(mu_n > 0, 3.0 * mu_n, 1.0), 0.0)
    frac = 1.0 - (1.0 - np.minimum(psi, 1.0)) ** 3
    s = np.where(mag > 0, mu_n * frac / np.where(mag > 0, mag, 1.0), 0.0)
    return fx * s, fy * s


def brush_trail(psi, half_length: float) -> np.ndarray:
    """Pneumatic trail t(ψ) [m] of the parabolic brush for normalised slip ψ (eq. 4)."""
    psi = np.clip(np.asarray(psi, dtype=np.float64), 0.0, 1.0)
    q3 = (1.0 - psi) ** 3
    small = psi < 1e-6
    den = np.where(small, 1.0, 1.0 - q3)
    return np.where(small, half_length * (1.0 / 3.0 - 2.0 * psi / 3.0), half_length * psi * q3 / den)


def stability_numbers(tire, load: float, dt: float, mass_long: float, mass_lat: float,
                      inertia_twist: float) -> dict[str, float]:
    """Stability of the explicit contact spring and damper (module docstring, "Integration").

    For each contact direction, with k its stiffness, c = k τ_d, and m the smallest effective mass
    it drives: ``a = c dt/m``, ``b = k dt²/m``; symplectic Euler with explicit damping is stable
    iff a < 2 and b + 2a < 4 (the eigenvalues of the one-step map of m ẍ = −k x − c ẋ).

    Args:
        tire: :class:`~azimut_env.params.TireParams`. load: normal load N [N] (the largest).
        dt: substep [s]. mass_long, mass_lat: effective masses [kg] the contact sees along d and
            along e, 1/m = Σ ℓ²/I over the DOFs it moves (module docstring; for the default
            robot about 1.7 kg along d: spin r²/I_w = 0.21, module b²/I_mod = 0.32, chassis
            ≈ 0.05 1/kg). inertia_twist: yaw inertia the patch twist drives [kg·m²] (I_mod).

    Returns:
        ``{"<dir>_a", "<dir>_b", "<dir>_margin"}`` for dir in long, lat, twist, margin = b + 2a
        (stable below 4).
    """
    k_x = tire.longitudinal_stiffness * load / tire.longitudinal_relaxation_length
    k_y = tire.cornering_stiffness * load / tire.relaxation_length
    k_t = 0.5 * k_y * tire.contact_half_length ** 2
    out = {}
    for name, k, m in (("long", k_x, mass_long), ("lat", k_y, mass_lat), ("twist", k_t, inertia_twist)):
        a = k * tire.damping_time * dt / m
        b = k * dt * dt / m
        out[f"{name}_a"], out[f"{name}_b"], out[f"{name}_margin"] = a, b, b + 2 * a
    return out


def tire_elastic_energy(state, load, tire) -> np.ndarray:
    """Elastic energy [J] stored in deflected tires: ``state`` (..., 3) (:class:`TS`), ``load``
    (...) [N] broadcast with it.

    The work of the brush force along the current deflection: with z = (k_x u_x, k_y u_y),
    ψ = ‖z‖/(3μN) and the stiffness along u, k_u = ‖z‖²/(k_x u_x² + k_y u_y²),
    ``E = (3 μ²N²/k_u) (ψ + ((1 − ψ)⁴ − 1)/4)`` (→ ½ (k_x u_x² + k_y u_y²) at small ψ; exact for
    deflections along one axis), plus ``½ k_φ φ²`` for the twist. With k_x ≠ k_y the combined brush
    force is not exactly the gradient of an energy, so this is the energy along rays."""
    st = np.asarray(state, dtype=np.float64)
    n = np.maximum(np.asarray(load, dtype=np.float64), 0.0)
    ux, uy, tw = st[..., 0], st[..., 1], st[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        k_x = tire.longitudinal_stiffness * n / tire.longitudinal_relaxation_length
        k_y = tire.cornering_stiffness * n / tire.relaxation_length
        quad = k_x * ux * ux + k_y * uy * uy
        z = np.hypot(k_x * ux, k_y * uy)
        mu_n = tire.friction * n
        psi = np.minimum(np.where(mu_n > 0, z / (3.0 * mu_n), 0.0), 1.0)
        k_u = np.where(quad > 0, z * z / quad, 1.0)
        e = np.where(quad > 0, 3.0 * mu_n * mu_n / k_u * (psi + ((1.0 - psi) ** 4 - 1.0) / 4.0), 0.0)
    k_t = 0.5 * k_y * tire.contact_half_length ** 2
    return e + 0.5 * k_t * tw * tw
