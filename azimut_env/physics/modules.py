"""The steering module's joint: its friction, and the coupling of a module whose centre of mass
is off its steering axis with the chassis (physics v3). Scalar and small-array numba kernels
that :func:`azimut_env.physics.kernels.step_kernel` calls, and the mechanical energy.

Steering friction
-----------------
The joint between module and chassis has Coulomb friction with stiction and a Stribeck region
(Canudas de Wit, Olsson, Åström, Lischinsky, "A new model for control of systems with friction",
IEEE Trans. Automatic Control 40(3), 1995, eq. 3, the steady-state curve of their LuGre model;
Armstrong-Hélouvry, Dupont, Canudas de Wit, "A survey of models, analysis tools and compensation
methods for the control of machines with friction", Automatica 30(7), 1994)::

    τ_f(ω) = τ_c + (τ_s − τ_c) exp(−(ω/ω_s)²)            (ω = |β̇|, the sliding speed)

It is integrated as a **velocity-level impulse** (the time-stepping treatment of dry friction of
Stewart & Trinkle, "An implicit time-stepping scheme for rigid body dynamics with inelastic
collisions and Coulomb friction", Int. J. Numerical Methods in Engineering 39, 1996): after the
substep's forces have given the joint the relative rate β̇' = ω_k' − θ̇', the friction applies
the angular impulse j (on the module; −j on the chassis) that would stop the joint,
j* = −β̇' / g with g = 1/I_m + 1/I the joint's inverse effective inertia (exactly, J M⁻¹ Jᵀ of
the mass matrix below when the module is coupled), clipped to what friction can give in the
substep, |j| ≤ τ_f(|β̇|) dt with β̇ the rate at the **start** of the substep:

* a joint at rest (β̇ = 0) gets the breakaway torque τ_s: it stays stuck (β̇' = 0 exactly) as long
  as the torque on it, j*/dt, is at most τ_s, and breaks away above, independent of dt and g;
* a sliding joint gets τ_f(|β̇|), and stops exactly in the substep where friction can stop it.

The impulse opposes β̇' and never reverses it, so it cannot chatter, and it never adds kinetic
energy: ΔT = j β̇' + g j²/2 ≤ 0 for j β̇' ≤ 0, |j| ≤ |β̇'|/g. It has no stiffness: no bound on dt.
The n joints share the chassis, so each joint's impulse moves the others' relative rates: the
impulses are resolved by projected Gauss–Seidel (:data:`FRICTION_PASSES` passes over the joints,
each updating its joint's total impulse within its bound, fewer when a pass changed no impulse;
the bounds and, for coupled modules, each joint's impulse response are computed once per substep,
:func:`coupled_joint_responses`; Erleben, "Velocity-based shock
propagation for multibody dynamics animation", ACM Trans. Graphics 26(2), 2007, §3). Each update
is a coordinate-descent step on the kinetic energy over the bounds, so none adds energy, and
stuck joints stay stuck to round-off (one pass left a creep of j/I per substep).
(LuGre's bristle state would add a stiffness σ₀ with its own step bound, for the pre-sliding
displacement this model leaves out.) Friction acts whether or not the motors are on.

Module centre of mass off the steering axis
-------------------------------------------
With the module's centre of mass C_k at c_k from A_k along the propulsion axis (u_k =
(cos γ_k, sin γ_k), the direction of b_k), C_k = O + w_k + c_k u_k with w_k = R(θ) a_k, and the
generalised coordinates q = (x, y, θ, γ_1..γ_n) (γ_k = θ + α_k + β_k, the module's absolute angle,
whose rate is the code's absolute module rate ω_k), the kinetic energy T = ½ q̇ᵀ M q̇ has

    M_vv = M (total mass) I₂,  M_θθ = I (about the centre, modules at their axes),
    M_γγ,k = I_A,k (about the axis),  M_vγ,k = m_k c_k J u_k,  M_θγ,k = m_k c_k (w_k · u_k),

(J the rotation by 90°; M_vθ = 0, the robot's centre of mass with the modules at their axes being
at O, as ``ChassisParams`` states), and Lagrange's equations move the velocity-squared terms of
the acceleration of C_k (−θ̇² w_k − γ̇_k² c_k u_k) to the right-hand side:

    M q̈ = Q + Σ_k m_k γ̇_k² c_k u_k                                  (on v)
              + Σ_k m_k c_k γ̇_k² (w_k × u_k)                        (on θ)
              + m_k c_k θ̇² (u_k × w_k)                              (on γ_k)

with Q the generalised forces of the v2 model (tire forces, spring, couples). (The modules'
θ̇² w_k terms on v cancel the chassis's own, the centre of mass being at O, as M_vθ does.) M is solved by its
Schur complement on the body block: S = diag(M, M, I) − Σ_k B_k B_kᵀ / I_A,k (3×3, B_k =
m_k c_k (J u_k, w_k·u_k)), then γ̈_k = (Q_γ,k − B_k · a)/I_A,k: O(n) per substep. With c_k = 0 the
system is the v2 one exactly (and the kernel runs the v2 code). The pymunk body (obstacle
contacts only) keeps the total mass and the moment I.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from azimut_env.physics.actuators import clamp_sym
from azimut_env.physics.antagonism import sym3_cofactors
from azimut_env.physics.layout import BODY, CS, JS, MS, WP
from azimut_env.physics.tire import TS

__all__ = ["FRICTION_PASSES", "stribeck_torque", "friction_impulse", "friction_impulse_within", "coupled_factor",
           "coupled_apply", "coupled_joint_responses", "coupling_row", "mass_matrix", "module_impulse_response",
           "mechanical_energy"]

#: projected Gauss–Seidel passes over the steering joints' friction impulses per substep
FRICTION_PASSES = 4


@njit(cache=True, inline="always")
def stribeck_torque(speed: float, coulomb: float, static: float, stribeck_speed: float) -> float:
    """τ_f = τ_c + (τ_s − τ_c) exp(−(ω/ω_s)²) [N·m] at the sliding speed ω = ``speed`` >= 0 [rad/s]."""
    x = speed / stribeck_speed
    x2 = x * x
    if x2 == 0.0:  # exp(−0) = 1 and exp(−x²) = 0 below the smallest subnormal: the same numbers, no call
        return coulomb + (static - coulomb)
    if x2 > 746.0:
        return coulomb + (static - coulomb) * 0.0
    return coulomb + (static - coulomb) * math.exp(-x2)


@njit(cache=True, inline="always")
def friction_impulse(rel: float, rel_start: float, inv_inertia: float, applied: float, coulomb: float,
                     static: float, stribeck_speed: float, dt: float) -> float:
    """The steering joint's friction impulse [N·m·s] on the module over one substep (the chassis
    gets the opposite), as a new total given the ``applied`` total so far: the impulse that stops
    the joint's relative rate ``rel`` [rad/s] (inverse effective inertia ``inv_inertia``
    [1/(kg·m²)]), ``applied − rel/g``, clipped to ±τ_f(|rel_start|) dt (``rel_start``: the rate at
    the start of the substep). Apply the difference to ``applied``. See the module docstring."""
    return friction_impulse_within(rel, inv_inertia, applied,
                                   stribeck_torque(abs(rel_start), coulomb, static, stribeck_speed) * dt)


@njit(cache=True, inline="always")
def friction_impulse_within(rel: float, inv_inertia: float, applied: float, lim: float) -> float:
    """:func:`friction_impulse` with its bound ``lim`` = τ_f(|rel_start|) dt [N·m·s] given: the
    substep computes the bound once per joint, not once per Gauss–Seidel pass (the same numbers)."""
    return clamp_sym(applied - rel / inv_inertia, lim)


@njit(cache=True, inline="always")
def coupling_row(cg: float, sg: float, arm_x: float, arm_y: float, mc: float, out, k: int) -> None:
    """B_k = m c (−sin γ, cos γ, w·u) into ``out[k]`` (the module's column of M_vγ, M_θγ), from
    cos γ, sin γ (the substep has them) and m c = ``mc``."""
    out[k, 0] = -mc * sg
    out[k, 1] = mc * cg
    out[k, 2] = mc * (arm_x * cg + arm_y * sg)


@njit(cache=True, inline="always")
def coupled_factor(B, D, mass: float, inertia: float, S_inv) -> None:
    """S⁻¹ (3, 3) of the Schur complement S = diag(M, M, I) − Σ_k B_k B_kᵀ / D_k (B (n, 3), D (n,)
    the modules' inertias about their axes), written into ``S_inv``."""
    s00 = mass
    s11 = mass
    s22 = inertia
    s01 = 0.0
    s02 = 0.0
    s12 = 0.0
    for k in range(B.shape[0]):
        d = 1.0 / D[k]
        b0, b1, b2 = B[k, 0], B[k, 1], B[k, 2]
        s00 -= b0 * b0 * d
        s11 -= b1 * b1 * d
        s22 -= b2 * b2 * d
        s01 -= b0 * b1 * d
        s02 -= b0 * b2 * d
        s12 -= b1 * b2 * d
    c00, c01, c02, c11, c12, c22 = sym3_cofactors(s00, s01, s02, s11, s12, s22)
    inv_det = 1.0 / (s00 * c00 + s01 * c01 + s02 * c02)
    S_inv[0, 0] = c00 * inv_det
    S_inv[0, 1] = S_inv[1, 0] = c01 * inv_det
    S_inv[0, 2] = S_inv[2, 0] = c02 * inv_det
    S_inv[1, 1] = c11 * inv_det
    S_inv[1, 2] = S_inv[2, 1] = c12 * inv_det
    S_inv[2, 2] = c22 * inv_det


@njit(cache=True, inline="always")
def coupled_apply(B, D, S_inv, z0: float, z1: float, z2: float, zg, out_g):
    """M⁻¹ z for z = (z0, z1, z2, zg (n,)) by the Schur complement: returns the body part
    (a_x, a_y, a_θ) and writes the module part into ``out_g`` (n,)."""
    r0 = z0
    r1 = z1
    r2 = z2
    for k in range(B.shape[0]):
        f = zg[k] / D[k]
        r0 -= B[k, 0] * f
        r1 -= B[k, 1] * f
        r2 -= B[k, 2] * f
    a0 = S_inv[0, 0] * r0 + S_inv[0, 1] * r1 + S_inv[0, 2] * r2
    a1 = S_inv[1, 0] * r0 + S_inv[1, 1] * r1 + S_inv[1, 2] * r2
    a2 = S_inv[2, 0] * r0 + S_inv[2, 1] * r1 + S_inv[2, 2] * r2
    for k in range(B.shape[0]):
        out_g[k] = (zg[k] - B[k, 0] * a0 - B[k, 1] * a1 - B[k, 2] * a2) / D[k]
    return a0, a1, a2


@njit(cache=True, inline="always")
def coupled_joint_responses(B, D, S_inv, body_out, joint_out) -> None:
    """For each joint k, the response M⁻¹ z_k to its unit impulse pair z_k = (0, 0, −1, e_k) (+1
    on module k, −1 on the chassis's rotation): the body part into ``body_out[k]`` (3,), the
    modules' into ``joint_out[k]`` (n,). The same numbers as :func:`coupled_apply` on z_k, without
    its zero terms (the friction's Gauss–Seidel passes reuse them over a substep)."""
    n = B.shape[0]
    for k in range(n):
        f = 1.0 / D[k]
        r0 = 0.0 - B[k, 0] * f
        r1 = 0.0 - B[k, 1] * f
        r2 = -1.0 - B[k, 2] * f
        a0 = S_inv[0, 0] * r0 + S_inv[0, 1] * r1 + S_inv[0, 2] * r2
        a1 = S_inv[1, 0] * r0 + S_inv[1, 1] * r1 + S_inv[1, 2] * r2
        a2 = S_inv[2, 0] * r0 + S_inv[2, 1] * r1 + S_inv[2, 2] * r2
        body_out[k, 0] = a0
        body_out[k, 1] = a1
        body_out[k, 2] = a2
        for kk in range(n):
            joint_out[k, kk] = ((1.0 if kk == k else 0.0) - B[kk, 0] * a0 - B[kk, 1] * a1 - B[kk, 2] * a2) / D[kk]


def mass_matrix(mass: float, inertia: float, arm: np.ndarray, gam: np.ndarray, module_mass: np.ndarray,
                com: np.ndarray, axis_inertia: np.ndarray) -> np.ndarray:
    """The (3 + n, 3 + n) mass matrix M of q = (x, y, θ, γ_1..γ_n) (module docstring): body mass
    ``mass`` [kg] and moment ``inertia`` [kg·m²], arms w_k = ``arm`` (n, 2) [m] (world axes),
    module angles γ_k = ``gam`` (n,) [rad], masses m_k, offsets c_k [m], inertias about the
    axes I_A,k [kg·m²] (each (n,))."""
    n = gam.shape[0]
    M = np.zeros((3 + n, 3 + n))
    M[0, 0] = M[1, 1] = mass
    M[2, 2] = inertia
    mc = module_mass * com
    cg, sg = np.cos(gam), np.sin(gam)
    B = np.stack([-mc * sg, mc * cg, mc * (arm[:, 0] * cg + arm[:, 1] * sg)], axis=-1)
    M[:3, 3:] = B.T
    M[3:, :3] = B
    M[3:, 3:] = np.diag(axis_inertia)
    return M


def module_impulse_response(body: np.ndarray, theta: float, axis_xy: np.ndarray, wp: np.ndarray, beta: np.ndarray,
                            impulses: np.ndarray) -> np.ndarray:
    """Δq̇ (3 + n) = M⁻¹ z of one robot for external angular impulses ``impulses`` (n,) [N·m·s] on
    its modules about their axes (z = (0, 0, 0, impulses)): body (M, I) ``body``, heading
    ``theta`` [rad], axes ``axis_xy`` (n, 2) in the chassis frame, wheel parameters ``wp`` (n, WP),
    steering angles ``beta`` (n,) [rad]."""
    c, s = math.cos(theta), math.sin(theta)
    arm = np.stack([c * axis_xy[:, 0] - s * axis_xy[:, 1], s * axis_xy[:, 0] + c * axis_xy[:, 1]], -1)
    gam = theta + wp[:, WP.ALPHA] + beta
    M = mass_matrix(float(body[BODY.MASS]), float(body[BODY.MOMENT]), arm, gam, wp[:, WP.M_MOD], wp[:, WP.COM],
                    wp[:, WP.I_MOD])
    return np.linalg.solve(M, np.concatenate([np.zeros(3), impulses]))


def mechanical_energy(state: np.ndarray, body: np.ndarray, js: np.ndarray, ms: np.ndarray, ts: np.ndarray,
                      wp: np.ndarray, axis_xy: np.ndarray, loads: np.ndarray) -> np.ndarray:
    """(N,) kinetic energy ½ q̇ᵀ M q̇ (chassis with the module masses, module rotations about their
    axes and, for modules with c > 0, their coupling with the chassis; wheel spins) plus the
    elastic energy of the steering springs and of the tires' contact patches [J].

    state (rows >= N, CS) chassis states, body (N, BODY), js (N, n, JS), ms (N, n, MS), ts (N, n,
    TS), wp (N, n, WP), axis_xy (n, 2), loads (N, n) the normal loads now [N]."""
    N = body.shape[0]
    st = state[:N]
    m, inertia = body[:, BODY.MASS], body[:, BODY.MOMENT]
    vx, vy, w = st[:, CS.VX], st[:, CS.VY], st[:, CS.W]
    e = 0.5 * m * (vx ** 2 + vy ** 2) + 0.5 * inertia * w ** 2
    omega = js[..., JS.OMEGA]
    e += 0.5 * np.sum(wp[..., WP.I_MOD] * omega ** 2, axis=1)
    mc = wp[..., WP.M_MOD] * wp[..., WP.COM]
    if np.any(mc != 0):  # ω_k B_k · (v, θ̇): the coupling of the offset centres of mass
        th = st[:, CS.TH, None]
        gam = th + wp[..., WP.ALPHA] + js[..., JS.BETA]
        cg, sg = np.cos(gam), np.sin(gam)
        arm_x = np.cos(th) * axis_xy[None, :, 0] - np.sin(th) * axis_xy[None, :, 1]
        arm_y = np.sin(th) * axis_xy[None, :, 0] + np.cos(th) * axis_xy[None, :, 1]
        cross = -sg * vx[:, None] + cg * vy[:, None] + (arm_x * cg + arm_y * sg) * w[:, None]
        e += np.sum(mc * omega * cross, axis=1)
    e += 0.5 * np.sum(wp[..., WP.I_W] * ms[..., MS.PHIDOT] ** 2, axis=1)
    e += 0.5 * np.sum(wp[..., WP.K_S] * (ms[..., MS.THETA] - js[..., JS.BETA]) ** 2, axis=1)
    # the tire's contact springs: k_x = C_κ/σ_κ, k_y = C_α/σ_α, twist k_y a²/2 (tire module)
    k_x = wp[..., WP.C_KAPPA] * loads / wp[..., WP.SIGMA_LONG]
    k_y = wp[..., WP.C_ALPHA] * loads / wp[..., WP.SIGMA_LAT]
    k_t = 0.5 * k_y * wp[..., WP.HALF_LEN] ** 2
    e += 0.5 * np.sum(k_x * ts[..., TS.U_LONG] ** 2 + k_y * ts[..., TS.U_LAT] ** 2 + k_t * ts[..., TS.TWIST] ** 2,
                      axis=1)
    return e
