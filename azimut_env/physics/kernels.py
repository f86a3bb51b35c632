"""The compiled kernels of :class:`~azimut_env.physics.engine.AzimutPhysics`: N robots' substeps
(:func:`step_kernel`) and the per-step summary (:func:`summary_kernel`), each one call for all
robots. Every array is indexed by the names of :mod:`azimut_env.physics.layout`.

Model (physics v2)
------------------
Per robot the generalised coordinates are the chassis pose (x, y, θ) and the steering angles
β_k of the n modules, plus each wheel's spin φ_k and its motors' states. Module k's centre of mass
lies on its steering axis A_k (fixed in the chassis frame R at ``axis_xy[k]``); its propulsion
axis makes γ_k = α_k + β_k with X_R and its contact point is P_k = A_k + b_k (cos γ_k, sin γ_k).

pymunk holds **one body per robot**: the chassis carrying the module masses at their axes (mass
M = m_c + n m_m, moment about the centre I = I_c + m_m Σ_k l_k², centre of mass at the origin of
R). Each module's own rotational inertia I_m about A_k is a separate joint DOF. Eliminating the
pivot reaction (it passes through A_k) gives the exact Newton–Euler equations of the system:

    M v̇            = Σ_k F_k                                          (chassis translation)
    I θ̈            = Σ_k (A_k − O) × F_k − Σ_k τ_s,k + τ_stop          (chassis rotation)
    I_m (θ̈ + β̈_k)  = τ_s,k + (P_k − A_k) × F_k + M_z,k − τ_stop,k       (module k about A_k)

with F_k the tire force at P_k, τ_s,k = k_s (θ_m,k − β_k) + c_s (θ̇_m,k − β̇_k) the series spring
and damper to the motor angle θ_m,k (clipped to the motor's torque limit; the DC motor model
has its own limits, ``actuators.steer_actuator_kernel``), M_z,k = M_align + M_scrub the tire's
couples about the vertical at the contact (``tire.tire_step_kernel``: the pneumatic trail's
aligning moment and the patch-twist scrub / dry-parking torque) and τ_stop the hard-stop
impulses (equal and opposite on module and chassis). The
module equation in β reads I_m β̈_k = τ_k − I_m θ̈: the −I_m θ̈ coupling. It is integrated in the
absolute module rate ω_k = θ̇ + β̇_k, for which it is the plain I_m ω̇_k = τ_k, so the coupling is
exact with no matrix to invert; β̇_k = ω_k − θ̇ is recovered from it. The tire force acts on the
chassis at A_k; its moment about A_k and M_z,k act on the module's steering DOF, where the series
spring holds them and passes them to the chassis. Since P_k − A_k = b_k e_k lies along the
propulsion axis, the lateral force (along e_k) has no moment about A_k; the moment of the force
is −b_k F_long,k, the longitudinal force at the sidewise offset. What turns a misaligned wheel
toward its rolling direction is M_align; what resists steering a loaded wheel at rest is M_scrub
(and the rolling of the offset contact point, resisted by the wheel's spin and motor). The steering
angle is a coordinate, so the contact point is exactly A_k + b_k (cos γ_k, sin γ_k): there is no
pivot to drift (the error is zero by construction).

Integration: semi-implicit (symplectic) Euler at the substep dt = control_period / substeps.
All forces and torques are evaluated at the start of the substep (the tire's relaxation and the
wheel's propulsion loop implicitly, see ``tire.tire_step_kernel`` and
``actuators.wheel_spin_step_kernel``), then

    ω_k' = ω_k + dt τ_k / I_m,   v' = v + dt ΣF / M,   θ̇' = θ̇ + dt τ_c / I,
    β_k' = β_k + dt (ω_k' − θ̇'),  x' = x + dt v',  θ' = θ + dt θ̇'.

**Unlimited steering** (``WP.STEER_MIN``, ``WP.STEER_MAX`` = −inf, +inf): no stop; the
steering motor's position loop turns the short way to its set-point (the representative of
β_cmd modulo 2π nearest θ_m, as swerve modules' continuous-input position loops do), and β is
kept in ]−π, π] by shifting β and θ_m together by 2π when it leaves (the dynamics see only
β̇, sin/cos of β and the spring's twist θ_m − β, which the shift leaves unchanged).

**Hard stops**, exact: if β_k' leaves [β_min, β_max] it is set onto the stop and, if β̇_k' still
points outward, an angular impulse J = −(1 + e) β̇_k' / (1/I_m + 1/I) acts on the module (+J) and
the chassis (−J), leaving the rebound rate −e β̇_k' (e = ``stop_restitution``, default 0, an
inelastic stop). Modules are resolved in order k = 0..n−1 (sequential impulses). The stop is
never penetrated.

**Normal loads** N_k follow the robot's current mass M: N = L (M g, −h M a_x, −h M a_y) with
L = ``RobotParams.load_map()`` (least-norm loads on the axes: M g / 4 for four symmetric wheels)
and h = ``ChassisParams.com_height`` (0: static loads; h > 0: load transfer from the chassis
acceleration a, in R, of the previous substep), clipped at 0 (a lifted wheel).

Convergence in the substep: first order, as expected of symplectic Euler with velocity-dependent
forces. ``azimut bench-env --convergence`` measures it (an open-loop replay of smooth kinematic
set-points against 256 substeps, :mod:`azimut_env.physics.convergence`); its figures are in the
documentation (``docs/results/bench-env.md``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from azimut_env.physics.actuators import (
    dc_torque_limits_kernel,
    rolling_resistance_kernel,
    steer_actuator_kernel,
    wheel_spin_step_kernel,
)
from azimut_env.physics.antagonism import antagonism_kernel, slip_damping_kernel
from azimut_env.physics.blowup import BlowUp
from azimut_env.physics.layout import ACC, BODY, CMD, CS, JS, MS, RS, WP, WS
from azimut_env.physics.modules import (
    FRICTION_PASSES,
    coupled_apply,
    coupled_factor,
    coupled_joint_responses,
    coupling_row,
    friction_impulse_within,
    stribeck_torque,
)
from azimut_env.physics.tire import TS, tire_step_kernel
from estimation.threads import BlockKernel

__all__ = ["step_kernel", "summary_kernel", "STEP_BLOCKS", "SUMMARY_BLOCKS"]

_CS_COUNT = len(CS)


@njit(cache=True, inline="always")
def _wrap_two_pi(x: float) -> float:
    """x modulo 2π into ]−π, π]."""
    return math.pi - (math.pi - x) % (2.0 * math.pi)


# One long function on purpose: the env's whole physics step is one numba call over all robots and
# substeps, with no allocation per substep and each wheel's state kept in locals; split into
# helpers it would cost a call per wheel per substep or reorder float operations (bit-identity).
@njit(cache=True, error_model="numpy")
def step_kernel(state, js, ms, ts, cmd, wp, en, acc, body, accel, axis_xy, transfer, com_h, restitution, dc, drive_dc,
                n, dt, substeps, integrate, lo, hi):
    """``substeps`` substeps of the robots ``lo`` to ``hi - 1`` (see the module docstring for the
    equations; a block of :class:`estimation.threads.BlockKernel`, its work arrays its own).

    state (rows, CS): chassis pose and velocity in the world, robot i at row i, updated in place
    (velocities always; positions too when ``integrate``, else pymunk moves the bodies). js
    (N, n, JS), ms (N, n, MS), ts (N, n, TS): joint, motor and tire states, updated. cmd
    (N, n, CMD): set-points. wp (N, n, WP): parameters. en (N,): motors on. acc (N, n, ACC):
    accumulates the tire forces and slip power per wheel. body (N, BODY): mass and moment.
    accel (N, 2): chassis acceleration (a_x, a_y) in R from the tire forces at the last substep,
    updated. transfer (n, 2): the load change on each axis per unit moment (M_x, M_y) [1/m] (the
    last two columns of ``RobotParams.load_map``); com_h: the centre of mass height h [m].
    restitution: the hard stops' e. dc: the steering motor model (False: kinematic position
    source; True: DC motor with back-EMF, ``actuators.steer_actuator_kernel``). drive_dc: the
    drive motors' torque–speed line (``WheelParams.drive_model == "dc"``) on top of their current
    limit.
    """
    omega_new = np.empty(n)
    # the coupled modules' mass matrix (modules.py): B (n, 3), D (n,), S⁻¹, generalised forces, responses
    B = np.zeros((n, 3))
    D = np.ones(n)
    S_inv = np.zeros((3, 3))
    q_gam = np.zeros(n)
    resp = np.zeros(n)
    unit = np.zeros(n)
    j_fric = np.zeros(n)
    # per joint, fixed over a substep's friction passes: bound τ_f dt, inverse effective inertia,
    # and (coupled modules) the response of the body (3) and of every module (n) to its impulse pair
    fric_lim = np.zeros(n)
    fric_g = np.ones(n)
    fric_body = np.zeros((n, 3))
    fric_joint = np.zeros((n, n))
    for i in range(lo, hi):
        mass = body[i, BODY.MASS]
        inertia = body[i, BODY.MOMENT]
        on = en[i]
        x, y, th = state[i, CS.X], state[i, CS.Y], state[i, CS.TH]
        vx, vy, w = state[i, CS.VX], state[i, CS.VY], state[i, CS.W]
        ax_r, ay_r = accel[i, 0], accel[i, 1]
        coupled = False
        friction = False
        for k in range(n):
            coupled = coupled or wp[i, k, WP.COM] != 0.0
            friction = friction or wp[i, k, WP.FRIC_S] > 0.0
            D[k] = wp[i, k, WP.I_MOD]
        for _ in range(substeps):
            c = math.cos(th)
            s = math.sin(th)
            fx_sum = 0.0
            fy_sum = 0.0
            tau_c = 0.0
            cx = 0.0  # the coupled modules' velocity-squared terms on (v, θ)
            cy = 0.0
            cth = 0.0
            w0 = w
            for k in range(n):
                p = wp[i, k]
                b = p[WP.B]
                r = p[WP.R]
                beta = js[i, k, JS.BETA]
                wm = js[i, k, JS.OMEGA]
                beta_dot = wm - w
                # steering motor and series spring; without stops (unlimited steering) the motor
                # turns the short way to its set-point: the turn of β_cmd nearest its angle
                target = cmd[i, k, CMD.BETA]
                if p[WP.STEER_MAX] == math.inf:
                    target = ms[i, k, MS.THETA] + _wrap_two_pi(target - ms[i, k, MS.THETA])
                theta_before = ms[i, k, MS.THETA]
                theta, omega, tau_s = steer_actuator_kernel(
                    dc, ms[i, k, MS.THETA], ms[i, k, MS.OMEGA], target, beta, beta_dot, on, p[WP.KP],
                    p[WP.STEER_RATE], p[WP.STEER_ACCEL], p[WP.STEER_TORQUE], p[WP.K_S], p[WP.C_S], p[WP.MOTOR_STALL],
                    p[WP.MOTOR_NO_LOAD], p[WP.MOTOR_INERTIA], dt)
                ms[i, k, MS.THETA] = theta
                ms[i, k, MS.OMEGA] = omega
                # steering axis A_k (relative to the chassis centre, world axes) and contact point
                axw = c * axis_xy[k, 0] - s * axis_xy[k, 1]
                ayw = s * axis_xy[k, 0] + c * axis_xy[k, 1]
                gam = th + p[WP.ALPHA] + beta
                cg = math.cos(gam)
                sg = math.sin(gam)
                vpx = vx - w * ayw - wm * b * sg
                vpy = vy + w * axw + wm * b * cg
                v_roll = vpx * sg - vpy * cg
                v_lat = vpx * cg + vpy * sg
                # propulsion set-point ramp
                ref = ms[i, k, MS.PHIDOT_REF]
                if on:
                    dref = cmd[i, k, CMD.PHIDOT] - ref
                    lim = p[WP.WHEEL_ACCEL] * dt
                    if dref > lim:
                        dref = lim
                    elif dref < -lim:
                        dref = -lim
                    ref += dref
                else:
                    ref = ms[i, k, MS.PHIDOT]
                # normal load: static share of the current mass plus load transfer
                load = p[WP.LOAD]
                if com_h > 0.0:
                    load -= com_h * mass * (transfer[k, 0] * ax_r + transfer[k, 1] * ay_r)
                    if load < 0.0:
                        load = 0.0
                # tire (brush model with relaxation; tire.tire_step_kernel) and wheel spin
                phidot = ms[i, k, MS.PHIDOT]
                s_long = v_roll - r * phidot
                f_long, f_lat, m_align, m_scrub, ts[i, k, TS.U_LONG], ts[i, k, TS.U_LAT], ts[i, k, TS.TWIST] = \
                    tire_step_kernel(s_long, v_lat, v_roll, wm, load, ts[i, k, TS.U_LONG], ts[i, k, TS.U_LAT],
                                     ts[i, k, TS.TWIST], p[WP.MU], p[WP.C_KAPPA], p[WP.C_ALPHA], p[WP.SIGMA_LONG],
                                     p[WP.SIGMA_LAT], p[WP.HALF_LEN], p[WP.DAMP_TIME], dt)
                tau_hi = p[WP.WHEEL_TORQUE]
                tau_lo = -tau_hi
                if drive_dc:
                    tau_lo, tau_hi = dc_torque_limits_kernel(phidot, p[WP.DRIVE_STALL], p[WP.DRIVE_NO_LOAD], tau_hi)
                phidot_before = phidot
                phidot = wheel_spin_step_kernel(phidot, ref, f_long, on, r, p[WP.I_W], p[WP.KV], tau_lo, tau_hi,
                                                p[WP.BEARING], p[WP.RR_TORQUE] * load * r, p[WP.RR_KNEE], dt)
                # the motors' work on the robot this substep: the steering motor's through the spring
                # (τ_s Δθ_m) and the drive's (τ_m φ̇' dt, τ_m recovered from the implicit spin update)
                tau_drive = (p[WP.I_W] * (phidot - phidot_before) / dt + p[WP.BEARING] * phidot + r * f_long
                             - rolling_resistance_kernel(phidot_before, r, p[WP.RR_TORQUE] * load * r, p[WP.RR_KNEE]))
                acc[i, k, ACC.WORK] += tau_s * (theta - theta_before) + tau_drive * phidot * dt
                ms[i, k, MS.PHIDOT_REF] = ref
                ms[i, k, MS.PHIDOT] = phidot
                ms[i, k, MS.PHI] += phidot * dt
                fx = f_long * sg + f_lat * cg
                fy = -f_long * cg + f_lat * sg
                fx_sum += fx
                fy_sum += fy
                tau_c += axw * fy - ayw * fx - tau_s
                # on the module about A_k: spring, the force's moment −b F_long, aligning and scrub couples
                tau_m = tau_s - b * f_long + m_align + m_scrub
                acc[i, k, ACC.FX] += fx
                acc[i, k, ACC.FY] += fy
                acc[i, k, ACC.SLIP] += abs(f_long * s_long + f_lat * v_lat)
                acc[i, k, ACC.LOAD] += load
                acc[i, k, ACC.ROLL] += abs(v_roll)
                if not coupled:
                    omega_new[k] = wm + dt * tau_m / p[WP.I_MOD]
                    continue
                # centre of mass off the axis (modules.py): the velocity-squared terms and the module's column of M
                mc = p[WP.M_MOD] * p[WP.COM]
                cross = axw * sg - ayw * cg  # w_k × u_k
                cx += mc * wm * wm * cg  # (the θ̇² w_k terms cancel the chassis's own: the centre of mass is at O)
                cy += mc * wm * wm * sg
                cth += mc * wm * wm * cross
                q_gam[k] = tau_m - mc * w * w * cross
                coupling_row(cg, sg, axw, ayw, mc, B, k)
                omega_new[k] = wm
            # chassis velocities (symplectic Euler: positions move with the new velocities)
            if coupled:
                coupled_factor(B, D, mass, inertia, S_inv)
                a0, a1, a2 = coupled_apply(B, D, S_inv, fx_sum + cx, fy_sum + cy, tau_c + cth, q_gam, resp)
                vx += dt * a0
                vy += dt * a1
                w += dt * a2
                for k in range(n):
                    omega_new[k] += dt * resp[k]
            else:
                vx += dt * fx_sum / mass
                vy += dt * fy_sum / mass
                w += dt * tau_c / inertia
            ax_r = (c * fx_sum + s * fy_sum) / mass
            ay_r = (-s * fx_sum + c * fy_sum) / mass
            # steering joint friction: velocity-level impulses, projected Gauss–Seidel (modules.py)
            if friction:
                if coupled:
                    coupled_joint_responses(B, D, S_inv, fric_body, fric_joint)
                for k in range(n):
                    j_fric[k] = 0.0
                    if wp[i, k, WP.FRIC_S] <= 0.0:
                        continue
                    fric_lim[k] = stribeck_torque(abs(js[i, k, JS.OMEGA] - w0), wp[i, k, WP.FRIC_C],
                                                  wp[i, k, WP.FRIC_S], wp[i, k, WP.STRIBECK]) * dt
                    if coupled:
                        fric_g[k] = fric_joint[k, k] - fric_body[k, 2]
                    else:
                        fric_g[k] = 1.0 / wp[i, k, WP.I_MOD] + 1.0 / inertia
                for _ in range(FRICTION_PASSES):
                    moved = False
                    for k in range(n):
                        if wp[i, k, WP.FRIC_S] <= 0.0:
                            continue
                        rel = omega_new[k] - w
                        j = friction_impulse_within(rel, fric_g[k], j_fric[k], fric_lim[k]) - j_fric[k]
                        if j == 0.0:
                            continue
                        moved = True
                        if coupled:
                            vx += j * fric_body[k, 0]
                            vy += j * fric_body[k, 1]
                            w += j * fric_body[k, 2]
                            for kk in range(n):
                                omega_new[kk] += j * fric_joint[k, kk]
                        else:
                            omega_new[k] += j / wp[i, k, WP.I_MOD]
                            w -= j / inertia
                        j_fric[k] += j
                    if not moved:  # a pass that moved nothing: the next ones would not either
                        break
            # steering angles, exact hard stops by projection and a stop impulse
            for k in range(n):
                i_m = wp[i, k, WP.I_MOD]
                wm = omega_new[k]
                beta = js[i, k, JS.BETA] + dt * (wm - w)
                lo = wp[i, k, WP.STEER_MIN]
                hi = wp[i, k, WP.STEER_MAX]
                if beta > hi or beta < lo:
                    beta = hi if beta > hi else lo
                    rel = wm - w
                    if (beta == hi and rel > 0.0) or (beta == lo and rel < 0.0):
                        if coupled:  # the impulse pair through M⁻¹: every module and the body respond
                            unit[k] = 1.0
                            r0, r1, r2 = coupled_apply(B, D, S_inv, 0.0, 0.0, -1.0, unit, resp)
                            unit[k] = 0.0
                            j = -(1.0 + restitution) * rel / (resp[k] - r2)
                            vx += j * r0
                            vy += j * r1
                            w += j * r2
                            for kk in range(n):
                                omega_new[kk] += j * resp[kk]
                            wm = omega_new[k]
                        else:
                            j = -(1.0 + restitution) * rel / (1.0 / i_m + 1.0 / inertia)
                            wm += j / i_m
                            w -= j / inertia
                elif hi == math.inf and (beta > math.pi or beta <= -math.pi):
                    # unlimited steering: the joint angle is kept in ]−π, π] (what an absolute
                    # encoder reads), the motor angle shifted by the same turn (the spring's
                    # twist θ_m − β is unchanged)
                    turn = beta - _wrap_two_pi(beta)
                    beta -= turn
                    ms[i, k, MS.THETA] -= turn
                js[i, k, JS.BETA] = beta
                js[i, k, JS.OMEGA] = wm
            if coupled:  # a later module's stop impulse moved the earlier ones too
                for k in range(n):
                    js[i, k, JS.OMEGA] = omega_new[k]
            if integrate:
                x += dt * vx
                y += dt * vy
                th += dt * w
        state[i, CS.X] = x
        state[i, CS.Y] = y
        state[i, CS.TH] = th
        state[i, CS.VX] = vx
        state[i, CS.VY] = vy
        state[i, CS.W] = w
        accel[i, 0] = ax_r
        accel[i, 1] = ay_r


# One long function on purpose: every per-step summary column in one numba call, reusing the same
# work arrays across robots; split, it would allocate or pass them around and repeat the loops.
@njit(cache=True)
def summary_kernel(state, js, ms, acc, wp, en, axis_xy, n, inv_sub, memory, speed_max, yaw_rate_max, spin_max,
                   position_max, out_r, out_w, lo, hi):
    """Per-step derived quantities of the robots ``lo`` to ``hi - 1``: out_r (N, RS) and out_w
    (N, n, WS) (a block of :class:`estimation.threads.BlockKernel`, its work arrays its own).

    Null-space force: the tire forces F (2n, chassis frame) give the net wrench W = G F; the
    least-norm forces with the same wrench are F* = Gᵀ (G Gᵀ)⁻¹ W, and ‖F − F*‖ is their null-space
    part. Antagonism: ‖F − F_nat‖ with F_nat the distribution of W that a common rigid slip gives,
    weighted by the wheels' slip dampings of their step-mean loads and rolling speeds, in series with
    the drive's velocity loop (its gain, or the bearing's damping where ``en`` (N,) has the motors
    off; ``memory`` the τ of :func:`~azimut_env.physics.antagonism.slip_damping_kernel`;
    :mod:`azimut_env.physics.antagonism`). The blow-up code (:class:`~azimut_env.physics.blowup.BlowUp`)
    compares with the ``*_max`` limits.
    """
    P = np.zeros((n, 2))
    F = np.zeros((n, 2))
    gams = np.zeros(n)
    d_long = np.zeros(n)
    d_lat = np.zeros(n)
    for i in range(lo, hi):
        x, y, th = state[i, CS.X], state[i, CS.Y], state[i, CS.TH]
        vx, vy, w = state[i, CS.VX], state[i, CS.VY], state[i, CS.W]
        c, s = math.cos(th), math.sin(th)
        for j in range(_CS_COUNT):  # the summary starts with the chassis state (physics_layout.RS)
            out_r[i, RS.X + j] = state[i, CS.X + j]
        out_r[i, RS.BX] = c * vx + s * vy
        out_r[i, RS.BY] = -s * vx + c * vy
        slip = 0.0
        code = BlowUp.NONE.value
        finite = math.isfinite(x) and math.isfinite(y) and math.isfinite(th) and math.isfinite(vx) \
            and math.isfinite(vy) and math.isfinite(w)
        vmax = math.hypot(vx, vy)
        wmax = abs(w)
        pmax = max(abs(x), abs(y))
        spin = 0.0
        for k in range(n):
            for j in range(js.shape[2]):
                if not math.isfinite(js[i, k, j]):
                    finite = False
            for j in range(ms.shape[2]):
                if not math.isfinite(ms[i, k, j]):
                    finite = False
            wmax = max(wmax, abs(js[i, k, JS.OMEGA]))
            spin = max(spin, abs(ms[i, k, MS.PHIDOT]))
            beta = js[i, k, JS.BETA]
            out_w[i, k, WS.BETA] = beta
            out_w[i, k, WS.BETA_DOT] = js[i, k, JS.OMEGA] - w
            fxw = acc[i, k, ACC.FX] * inv_sub
            fyw = acc[i, k, ACC.FY] * inv_sub
            fx = c * fxw + s * fyw
            fy = -s * fxw + c * fyw
            out_w[i, k, WS.FX] = fx
            out_w[i, k, WS.FY] = fy
            gam = wp[i, k, WP.ALPHA] + beta
            px = axis_xy[k, 0] + wp[i, k, WP.B] * math.cos(gam)
            py = axis_xy[k, 1] + wp[i, k, WP.B] * math.sin(gam)
            out_w[i, k, WS.PX] = px
            out_w[i, k, WS.PY] = py
            slip += acc[i, k, ACC.SLIP] * inv_sub
            P[k, 0] = px
            P[k, 1] = py
            F[k, 0] = fx
            F[k, 1] = fy
            gams[k] = gam
            d_long[k], d_lat[k] = slip_damping_kernel(
                acc[i, k, ACC.LOAD] * inv_sub, acc[i, k, ACC.ROLL] * inv_sub, wp[i, k, WP.C_KAPPA],
                wp[i, k, WP.C_ALPHA], wp[i, k, WP.SIGMA_LONG], wp[i, k, WP.SIGMA_LAT], memory, wp[i, k, WP.R],
                wp[i, k, WP.KV] if en[i] else wp[i, k, WP.BEARING])
        out_r[i, RS.SLIP] = slip
        internal = 0.0
        antagonism = 0.0
        if finite:
            # G Gᵀ = [[n, 0, −Σp_y], [0, n, Σp_x], [−Σp_y, Σp_x, Σ|p|²]], solved in closed form
            sx = 0.0
            sy = 0.0
            s2 = 0.0
            wx = 0.0
            wy = 0.0
            wz = 0.0
            for k in range(n):
                px, py = P[k, 0], P[k, 1]
                sx += px
                sy += py
                s2 += px * px + py * py
                wx += F[k, 0]
                wy += F[k, 1]
                wz += px * F[k, 1] - py * F[k, 0]
            a11 = float(n)
            a13 = -sy
            a23 = sx
            a33 = s2
            # Schur complement on the third unknown
            schur = a33 - (a13 * a13 + a23 * a23) / a11
            x2 = (wz - (a13 * wx + a23 * wy) / a11) / schur if schur > 1e-12 else 0.0
            x0 = (wx - a13 * x2) / a11
            x1 = (wy - a23 * x2) / a11
            for k in range(n):
                px, py = P[k, 0], P[k, 1]
                dx = F[k, 0] - (x0 - py * x2)
                dy = F[k, 1] - (x1 + px * x2)
                internal += dx * dx + dy * dy
            internal = math.sqrt(internal)
            antagonism = antagonism_kernel(P, F, gams, d_long, d_lat, n)
        out_r[i, RS.NULLSPACE] = internal
        out_r[i, RS.ANTAGONISM] = antagonism
        if not finite:
            code = BlowUp.NON_FINITE.value
        elif vmax > speed_max:
            code = BlowUp.SPEED.value
        elif wmax > yaw_rate_max:
            code = BlowUp.YAW_RATE.value
        elif spin > spin_max:
            code = BlowUp.SPIN.value
        elif pmax > position_max:
            code = BlowUp.POSITION.value
        out_r[i, RS.CODE] = code


#: the substeps and the summary over blocks of robots, one per thread (:mod:`estimation.threads`;
#: a block: at least 4 robots, about 20 µs of substeps; the summary's blocks at least 16)
STEP_BLOCKS = BlockKernel(step_kernel, min_rows=4)
SUMMARY_BLOCKS = BlockKernel(summary_kernel, min_rows=16)
