"""Rigid-body physics of N AZIMUT-3-like robots (top-down 2D): one rigid body per robot in a
pymunk Space, the steering modules as joint coordinates in a compiled substep.

One :class:`AzimutPhysics` simulates ``n_robots`` robots (the single env is ``n_robots=1``; the
vector env uses the same class with many). Robots do not collide with each other, only with
static obstacles.

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

**Hard stops**, exact: if β_k' leaves [β_min, β_max] it is set onto the stop and, if β̇_k' still
points outward, an angular impulse J = −(1 + e) β̇_k' / (1/I_m + 1/I) acts on the module (+J) and
the chassis (−J), leaving the rebound rate −e β̇_k' (e = ``stop_restitution``, default 0, an
inelastic stop). Modules are resolved in order k = 0..n−1 (sequential impulses). The stop is
never penetrated.

**Normal loads** N_k follow the robot's current mass M: N = L (M g, −h M a_x, −h M a_y) with
L = ``RobotParams.load_map()`` (least-norm loads on the axes: M g / 4 for four symmetric wheels)
and h = ``ChassisParams.com_height`` (0: static loads; h > 0: load transfer from the chassis
acceleration a, in R, of the previous substep), clipped at 0 (a lifted wheel).

Without obstacles the whole control period (all substeps, all robots) is one compiled call
(:func:`_step_kernel`) that integrates the chassis too; pymunk's bodies are read before it and
written after it. With obstacles pymunk integrates the chassis: each substep the kernel's velocity
change is handed to pymunk as a force and torque, and ``space.step`` integrates them and resolves
the contacts (Chipmunk moves the position with the velocity of the start of the substep, then
updates the velocity: explicit Euler for the chassis pose while in the presence of obstacles).
Robots have collision shapes (the chassis box; the wheels lie within its footprint up to 2 cm)
only when there are obstacles.

Stability budget (default parameters, 8 substeps of 2.5 ms at the 20 ms control period), enforced
by :meth:`AzimutPhysics._check_stability` at construction (``ValueError`` past a bound; the figures
are :meth:`AzimutPhysics.stability_figures`):

* the tire's contact is a spring k = C/σ with bristle damper c = k τ_d, integrated by symplectic
  Euler with explicit damping (``tire.stability_numbers``): for the effective mass m it drives,
  stable iff a = c dt/m < 2 and b + 2a < 4 with b = k dt²/m. Along the rolling direction d the
  contact moves the wheel spin (r²/I_w), the module about its axis (b²/I_m) and the chassis:
  m = 1.6 kg, margin b + 2a = 1.25; across (e) only the chassis: 0.15; the patch twist on I_m:
  0.004. Refused above 3 (the margins grow with the load: room for 2.4× the nominal load, for
  randomised masses and load transfer; :meth:`AzimutPhysics.set_chassis_mass` refuses a mass
  that would take a margin past 4). The relaxation itself (|v_x| dt/σ) is implicit: no bound;
* the series spring on the module: ω = sqrt(k_s / I_m) = 55 rad/s, ω·dt = 0.14 (symplectic Euler
  is stable below 2; refused above 0.5), its damper c_s dt / I_m = 0.075 (refused above 1);
* the propulsion velocity loop and bearing are implicit in the spin, and the DC steering motor's
  rotor (``SteeringMotorParams.model = "dc"``) on the spring is implicit: no bound on dt;
* the hard stops are exact projections (no stiffness, no bound on dt);
* load transfer (h > 0) closes a loop N → F → a → N; its gain is at most 2 μ h / ℓ (ℓ the
  shorter wheelbase, between the axes along x or y; the worst case has the front and rear wheels
  saturated in opposite directions). It is explicit with a one-substep lag: refused at gain ≥ 1
  (h ≥ 0.27 m for the default robot).

The default 8 substeps pass with room; 5 is the fewest the budget accepts.

Convergence in the substep (``azimut bench-env --convergence``: an open-loop replay of 30 s of
smooth kinematic set-points, 11.5 m of path, against 256 substeps): first order, as expected of
symplectic Euler with velocity-dependent forces; observed order 1.0–1.2 between 6 and 64
substeps. At the default 8 substeps the chassis path is off by 23 mm at most (12.7 mm at the end,
0.25° of heading) and β by 2.3° at most (in the steering transients). v1 (pymunk joints, viscous
tire), same replay: 38 mm and 2.3°.

Per-robot parameters live in arrays (``wheel_params``) so that domain randomisation can vary them
robot by robot. After each step, ``summary`` (N, 11) and ``wheel_summary`` (N, n, 6) hold the
derived per-robot quantities (pose, twists, slip power, internal force, blow-up code; β, β̇, tire
forces and contact points in the chassis frame), computed by one compiled call for all robots.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pymunk
import pymunk.batch as pb
from numba import njit

from .actuators import steer_actuator_kernel, wheel_spin_step_kernel
from .params import RobotParams
from .blowup import BLOWUP_MESSAGES, BlowUp, BlowUpLimits
from .physics_layout import ACC, BODY, CMD, CS, JS, MS, RS, RS_POSE, RS_TWIST_BODY, WP, WS, WS_FORCE
from .tire import TS, stability_numbers, tire_step_kernel

__all__ = ["AzimutPhysics", "Obstacle", "BlowUpLimits", "WP", "MS", "JS", "TS", "ACC", "BODY", "CMD", "CS", "RS", "WS"]

_STATE_FIELDS = (pb.BodyFields.POSITION | pb.BodyFields.ANGLE | pb.BodyFields.VELOCITY
                 | pb.BodyFields.ANGULAR_VELOCITY)
_FORCE_FIELDS = pb.BodyFields.FORCE | pb.BodyFields.TORQUE

#: Collision categories: robots collide with obstacles only, never with each other.
_CAT_ROBOT = 0b01
_CAT_OBSTACLE = 0b10


@dataclass(frozen=True)
class Obstacle:
    """A static obstacle: a circle (``radius`` > 0, centre ``(x, y)``) or a convex polygon
    (``vertices`` in world coordinates [m]).

    Attributes:
        x, y: centre of a circle [m]. radius: circle radius [m] (0 for a polygon).
        vertices: polygon vertices [(x, y), ...] [m] (empty for a circle).
    """

    x: float = 0.0
    y: float = 0.0
    radius: float = 0.0
    vertices: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        if self.vertices:
            if len(self.vertices) < 3 or not np.all(np.isfinite(np.asarray(self.vertices, dtype=float))):
                raise ValueError("Obstacle polygon needs >= 3 finite vertices")
            object.__setattr__(self, "vertices", tuple((float(a), float(b)) for a, b in self.vertices))
        elif not (self.radius > 0 and math.isfinite(self.radius) and math.isfinite(self.x) and math.isfinite(self.y)):
            raise ValueError(f"Obstacle circle needs a finite centre and radius > 0, got {self}")

    @classmethod
    def coerce(cls, spec) -> "Obstacle":
        """Accept an Obstacle, an ``(x, y, radius)`` triple, a dict of fields, or a vertex list."""
        if isinstance(spec, Obstacle):
            return spec
        if isinstance(spec, dict):
            return cls(**spec)
        arr = np.asarray(spec, dtype=float)
        if arr.shape == (3,):
            return cls(float(arr[0]), float(arr[1]), float(arr[2]))
        if arr.ndim == 2 and arr.shape[1] == 2:
            return cls(vertices=tuple(map(tuple, arr)))
        raise ValueError(f"cannot interpret {spec!r} as an obstacle: give (x, y, radius) or [(x, y), ...]")


@njit(cache=True, error_model="numpy")
def _step_kernel(state, js, ms, ts, cmd, wp, en, acc, body, accel, axis_xy, lmap, com_h, gravity, restitution,
                 dc, n, dt, substeps, integrate):
    """``substeps`` substeps of every robot (see the module docstring for the equations).

    state: (rows, 6) chassis (x, y, θ, vx, vy, θ̇) in the world, robot i at row i, updated in
    place (velocities always; positions too when ``integrate``, else pymunk moves the bodies).
    js (N, n, JS), ms (N, n, MS), ts (N, n, TS): joint, motor and tire states, updated. cmd
    (N, n, 2): set-points.
    wp (N, n, WP): parameters. en (N,): motors on. acc (N, n, ACC): accumulates (ΣFx, ΣFy, Σ slip
    power) per wheel. body (N, BODY): (M, I). accel (N, 2): chassis acceleration in R from
    the tire forces at the last substep (load transfer), updated. lmap (n, 3): the load map.
    dc: the steering motor model (False: kinematic position source; True: DC motor with back-EMF,
    ``actuators.steer_actuator_kernel``).
    """
    n_robots = ms.shape[0]
    omega_new = np.empty(n)
    for i in range(n_robots):
        mass = body[i, BODY.MASS]
        inertia = body[i, BODY.MOMENT]
        on = en[i]
        x, y, th = state[i, CS.X], state[i, CS.Y], state[i, CS.TH]
        vx, vy, w = state[i, CS.VX], state[i, CS.VY], state[i, CS.W]
        ax_r, ay_r = accel[i, 0], accel[i, 1]
        for _ in range(substeps):
            c = math.cos(th)
            s = math.sin(th)
            fx_sum = 0.0
            fy_sum = 0.0
            tau_c = 0.0
            for k in range(n):
                p = wp[i, k]
                b = p[WP.B]
                r = p[WP.R]
                beta = js[i, k, JS.BETA]
                wm = js[i, k, JS.OMEGA]
                beta_dot = wm - w
                # steering motor and series spring
                theta, omega, tau_s = steer_actuator_kernel(
                    dc, ms[i, k, MS.THETA], ms[i, k, MS.OMEGA], cmd[i, k, CMD.BETA], beta, beta_dot, on, p[WP.KP],
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
                    load -= com_h * mass * (lmap[k, 1] * ax_r + lmap[k, 2] * ay_r)
                    if load < 0.0:
                        load = 0.0
                # tire (brush model with relaxation; tire.tire_step_kernel) and wheel spin
                phidot = ms[i, k, MS.PHIDOT]
                s_long = v_roll - r * phidot
                f_long, f_lat, m_align, m_scrub, ts[i, k, TS.U_LONG], ts[i, k, TS.U_LAT], ts[i, k, TS.TWIST] = \
                    tire_step_kernel(s_long, v_lat, v_roll, wm, load, ts[i, k, TS.U_LONG], ts[i, k, TS.U_LAT],
                                     ts[i, k, TS.TWIST], p[WP.MU], p[WP.C_KAPPA], p[WP.C_ALPHA], p[WP.SIGMA_LONG],
                                     p[WP.SIGMA_LAT], p[WP.HALF_LEN], p[WP.DAMP_TIME], dt)
                phidot = wheel_spin_step_kernel(phidot, ref, f_long, on, r, p[WP.I_W], p[WP.KV], p[WP.WHEEL_TORQUE],
                                                p[WP.BEARING], p[WP.RR_TORQUE] * load * r, p[WP.RR_KNEE], dt)
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
                omega_new[k] = wm + dt * tau_m / p[WP.I_MOD]
                acc[i, k, ACC.FX] += fx
                acc[i, k, ACC.FY] += fy
                acc[i, k, ACC.SLIP] += abs(f_long * s_long + f_lat * v_lat)
            # chassis velocities (symplectic Euler: positions move with the new velocities)
            vx += dt * fx_sum / mass
            vy += dt * fy_sum / mass
            w += dt * tau_c / inertia
            ax_r = (c * fx_sum + s * fy_sum) / mass
            ay_r = (-s * fx_sum + c * fy_sum) / mass
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
                        j = -(1.0 + restitution) * rel / (1.0 / i_m + 1.0 / inertia)
                        wm += j / i_m
                        w -= j / inertia
                js[i, k, JS.BETA] = beta
                js[i, k, JS.OMEGA] = wm
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


@njit(cache=True)
def _summary_kernel(state, js, ms, acc, wp, axis_xy, n, inv_sub, speed_max, yaw_rate_max, spin_max, position_max,
                    out_r, out_w):
    """Per-step derived quantities for all robots (see the column constants), one call.

    Internal force: the tire forces F (2n, chassis frame) give the net wrench W = G F; the
    least-norm forces with the same wrench are F* = Gᵀ (G Gᵀ)⁻¹ W, and ‖F − F*‖ is the internal part.
    The blow-up code (:class:`~azimut_env.blowup.BlowUp`) compares with the ``*_max`` limits.
    """
    n_robots = ms.shape[0]
    P = np.zeros((n, 2))
    F = np.zeros((n, 2))
    for i in range(n_robots):
        x, y, th = state[i, CS.X], state[i, CS.Y], state[i, CS.TH]
        vx, vy, w = state[i, CS.VX], state[i, CS.VY], state[i, CS.W]
        c, s = math.cos(th), math.sin(th)
        out_r[i, RS.X] = x
        out_r[i, RS.Y] = y
        out_r[i, RS.TH] = th
        out_r[i, RS.VX] = vx
        out_r[i, RS.VY] = vy
        out_r[i, RS.W] = w
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
        out_r[i, RS.SLIP] = slip
        internal = 0.0
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
        out_r[i, RS.INTERNAL] = internal
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


class AzimutPhysics:
    """N robots in one pymunk Space, stepped at ``control_period`` with ``substeps`` substeps.

    Args:
        params: the robot's physical parameters (shared by all robots; per-robot variations go
            through :meth:`set_wheel_params` and :meth:`set_chassis_mass`).
        n_robots: number of robots N (1 for the single env).
        control_period: duration of one :meth:`step` [s].
        substeps: physics substeps per step; the substep is ``control_period / substeps``.
        blowup: thresholds of :meth:`check`.
        solver_iterations: pymunk solver iterations per substep (obstacle contacts only since the
            steering modules left pymunk; kept as a knob).

    State accessors return arrays with a leading robot axis N. The state of record between steps
    is the pymunk chassis bodies (pose, velocity) plus ``joint_state`` (β, module rates),
    ``motor_state`` and ``chassis_accel``; all of it pickles.
    """

    def __init__(self, params: RobotParams | None = None, n_robots: int = 1, control_period: float = 0.02,
                 substeps: int = 8, blowup: BlowUpLimits | None = None, solver_iterations: int = 20) -> None:
        self.params = params if params is not None else RobotParams()
        if int(n_robots) != n_robots or n_robots < 1:
            raise ValueError(f"n_robots must be a positive integer, got {n_robots!r}")
        if not (math.isfinite(control_period) and control_period > 0):
            raise ValueError(f"control_period must be > 0 [s], got {control_period!r}")
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
        self.n_robots = int(n_robots)
        self.n = self.params.n
        self.control_period = float(control_period)
        self.substeps = int(substeps)
        if int(solver_iterations) != solver_iterations or solver_iterations < 1:
            raise ValueError(f"solver_iterations must be a positive integer, got {solver_iterations!r}")
        self.solver_iterations = int(solver_iterations)
        self.dt = self.control_period / self.substeps
        self.blowup = blowup if blowup is not None else BlowUpLimits()
        self._check_stability()
        p = self.params
        self._load_map = np.ascontiguousarray(p.load_map())
        self._module_mass = float(p.steering.module_mass)
        self._module_axis_moment = float(p.steering.module_mass * np.sum(p.geometry.l ** 2))
        self.wheel_params = self._default_wheel_params()
        self.motor_state = np.zeros((self.n_robots, self.n, len(MS)))
        self.joint_state = np.zeros((self.n_robots, self.n, len(JS)))
        #: (N, n, len(TS)) tire states (contact patch deflections u_long, u_lat [m], twist [rad])
        self.tire_state = np.zeros((self.n_robots, self.n, len(TS)))
        self.commands = np.zeros((self.n_robots, self.n, len(CMD)))
        self.enabled = np.ones(self.n_robots, dtype=np.bool_)
        self.acc = np.zeros((self.n_robots, self.n, len(ACC)))
        #: (N, 2) body mass M [kg] and moment I [kg·m²] about the centre (modules at their axes)
        self.body_inertia = np.tile(self._body_inertia(p.chassis.mass), (self.n_robots, 1))
        #: (N, 2) chassis acceleration in R from the tire forces of the last substep [m/s²]
        self.chassis_accel = np.zeros((self.n_robots, 2))
        self.obstacles: tuple[Obstacle, ...] = ()
        self.summary = np.zeros((self.n_robots, len(RS)))
        self.wheel_summary = np.zeros((self.n_robots, self.n, len(WS)))
        self._axis_xy = np.ascontiguousarray(self.params.geometry.axis_xy)
        self._build_space()

    # ------------------------------------------------------------------ construction

    def stability_figures(self) -> dict[str, tuple[float, float]]:
        """The dimensionless figures of the stability budget (module docstring) for these
        parameters and this substep, each with its bound: ``{name: (value, bound)}``."""
        p, g, dt = self.params, self.params.geometry, self.dt
        load = float(p.static_normal_loads().max())
        i_m = p.steering.module_inertia
        mass, inertia = (float(v) for v in self._body_inertia(p.chassis.mass))
        reach2 = float(np.max((g.l + np.abs(g.b)) ** 2))
        # the effective mass each contact direction sees at P, 1/m = Σ ℓ²/I over the DOFs it
        # moves: along d the wheel spin (r²/I_w), the module about its axis (b²/I_m) and the
        # chassis; along e the chassis only (the module's rotation moves P along d)
        chassis_inv = 1.0 / mass + reach2 / inertia
        m_long = 1.0 / (float(np.max(g.r ** 2 / p.wheel.inertia)) + float(np.max(g.b ** 2)) / i_m + chassis_inv)
        m_lat = 1.0 / chassis_inv
        tire = stability_numbers(p.tire, load, dt, m_long, m_lat, i_m)
        ext = [float(np.ptp(g.axis_xy[:, 0])), float(np.ptp(g.axis_xy[:, 1]))]
        half = min(e for e in ext if e > 0) / 2.0
        out = {}
        for d in ("long", "lat", "twist"):
            out[f"tire_{d}_damping"] = (tire[f"{d}_a"], 1.5)
            out[f"tire_{d}_margin"] = (tire[f"{d}_margin"], 3.0)
        out["spring_omega_dt"] = (math.sqrt(p.steering.stiffness / i_m) * dt, 0.5)
        out["spring_damping_dt"] = (p.steering.damping / i_m * dt, 1.0)
        out["load_transfer_gain"] = (p.tire.friction * p.chassis.com_height / half, 1.0)
        return out

    def _check_stability(self) -> None:
        """Refuse parameter/substep combinations past the stability budget (module docstring)."""
        bad = {k: v for k, v in self.stability_figures().items() if not v[0] < v[1] * (1 + 1e-12)}
        if bad:
            what = ", ".join(f"{k} = {v:.3g} (must be <= {b})" for k, (v, b) in bad.items())
            hint = "lower com_height" if set(bad) == {"load_transfer_gain"} else "raise substeps"
            raise ValueError(f"substep {self.dt:.4g} s with these parameters is outside the stability budget: "
                             f"{what}: {hint}")

    def _body_inertia(self, chassis_mass: float) -> np.ndarray:
        """(M, I) of the robot body with a chassis of mass ``chassis_mass`` (plate inertia scaled
        with it) and the modules' masses at their steering axes."""
        ch = self.params.chassis
        return np.array([chassis_mass + self.n * self.params.steering.module_mass,
                         ch.inertia * chassis_mass / ch.mass
                         + self.params.steering.module_mass * float(np.sum(self.params.geometry.l ** 2))])

    def _default_wheel_params(self) -> np.ndarray:
        p, g = self.params, self.params.geometry
        wp = np.zeros((self.n_robots, self.n, len(WP)))
        wp[..., WP.B] = g.b
        wp[..., WP.R] = g.r
        wp[..., WP.ALPHA] = g.alpha
        wp[..., WP.LOAD] = p.static_normal_loads()
        wp[..., WP.MU] = p.tire.friction
        wp[..., WP.K_S] = p.steering.stiffness
        wp[..., WP.C_S] = p.steering.damping
        wp[..., WP.KP] = p.steering.position_gain
        wp[..., WP.I_W] = p.wheel.inertia
        wp[..., WP.KV] = p.wheel.velocity_gain
        wp[..., WP.BEARING] = p.wheel.bearing_damping
        wp[..., WP.RR_TORQUE] = p.tire.rolling_resistance
        wp[..., WP.RR_KNEE] = p.tire.rolling_knee
        lim = p.limits
        wp[..., WP.STEER_RATE] = lim.steer_rate_max
        wp[..., WP.STEER_ACCEL] = lim.steer_accel_max
        wp[..., WP.STEER_TORQUE] = lim.steer_torque_max
        wp[..., WP.WHEEL_ACCEL] = lim.wheel_accel_max
        wp[..., WP.WHEEL_TORQUE] = lim.wheel_torque_max
        wp[..., WP.STEER_MIN] = lim.steer_min
        wp[..., WP.STEER_MAX] = lim.steer_max
        wp[..., WP.I_MOD] = p.steering.module_inertia
        t = p.tire
        wp[..., WP.C_KAPPA] = t.longitudinal_stiffness
        wp[..., WP.C_ALPHA] = t.cornering_stiffness
        wp[..., WP.SIGMA_LONG] = t.longitudinal_relaxation_length
        wp[..., WP.SIGMA_LAT] = t.relaxation_length
        wp[..., WP.HALF_LEN] = t.contact_half_length
        wp[..., WP.DAMP_TIME] = t.damping_time
        m = p.steer_motor
        wp[..., WP.MOTOR_STALL] = m.stall_torque
        wp[..., WP.MOTOR_NO_LOAD] = m.no_load_speed
        wp[..., WP.MOTOR_INERTIA] = m.rotor_inertia
        return wp

    def _build_space(self) -> None:
        p = self.params
        space = pymunk.Space()
        space.iterations = self.solver_iterations
        space.gravity = (0.0, 0.0)
        robot_filter = pymunk.ShapeFilter(categories=_CAT_ROBOT, mask=_CAT_OBSTACLE)
        # Collision shapes only matter against obstacles; without obstacles the bodies carry their
        # mass and inertia alone and pymunk is not stepped at all.
        with_shapes = bool(self.obstacles)
        self.chassis: list[pymunk.Body] = []
        for i in range(self.n_robots):
            mass, moment = self.body_inertia[i]
            ch = pymunk.Body(float(mass), float(moment))
            space.add(ch)
            if with_shapes:
                box = pymunk.Poly.create_box(ch, (p.chassis.length, p.chassis.width))
                box.filter = robot_filter
                box.friction = 0.5
                space.add(box)
            self.chassis.append(ch)
        self.space = space
        self._obstacle_shapes: list[pymunk.Shape] = []
        for ob in self.obstacles:
            self._add_obstacle(ob)
        self._setup_buffers()

    def _setup_buffers(self) -> None:
        """(Re)create the batch buffers; check that pymunk.batch lists our bodies first, in order."""
        self._get_buf = pb.Buffer()
        pb.get_space_bodies(self.space, pb.BodyFields.BODY_ID, self._get_buf)
        ids = list(memoryview(self._get_buf.int_buf()).cast("P"))
        ours = [b.id for b in self.chassis]
        if ids[: len(ours)] != ours:
            raise RuntimeError("pymunk.batch does not list the robot bodies first, in creation order")
        # rows beyond N (pymunk's static body, once it holds obstacle shapes) are read and written
        # back unchanged
        self._n_rows = len(ids)
        self._state = np.zeros((self._n_rows, 6))
        self._set_buf = pb.Buffer()
        self._set_buf.set_float_buf(self._state)
        self._forces = np.zeros((self._n_rows, 3))
        self._before = np.zeros((self.n_robots, 3))
        self._force_buf = pb.Buffer()
        self._force_buf.set_float_buf(self._forces)
        # Fast path: the same C iterators that pymunk.batch.get/set_space_bodies call, with their
        # argument structs built once (saves most of the per-call Python overhead).
        self._fast = None
        ffi, lib = getattr(pb, "ffi", None), getattr(pb, "lib", None)
        if ffi is not None and lib is not None and hasattr(lib, "cpSpaceEachBody"):
            try:
                get_data = ffi.new("pmBatchedData *")
                get_data.fields = _STATE_FIELDS.value
                get_data.floatArray = self._get_buf._float_arr
                get_data.intArray = self._get_buf._int_arr
                set_data = ffi.new("pmBatchedData *")
                set_data.fields = _STATE_FIELDS.value
                set_data.floatArray = self._set_buf._float_arr
                set_data.intArray = self._set_buf._int_arr
                self._fast = (lib, get_data, set_data, ffi.addressof(lib, "pmSpaceBodyGetIteratorFuncBatched"),
                              ffi.addressof(lib, "pmSpaceBodySetIteratorFuncBatched"))
            except (AttributeError, TypeError):  # pymunk.batch changed: use the public functions
                self._fast = None
        self._read_state()

    def _get_bodies(self) -> None:
        """Copy every chassis body's (x, y, θ, vx, vy, θ̇) from pymunk into ``_state``."""
        buf = self._get_buf
        if self._fast is None:
            buf.clear()
            pb.get_space_bodies(self.space, _STATE_FIELDS, buf)
        else:
            lib, get_data, _, get_fn, _ = self._fast
            buf._float_arr.num = 0
            lib.cpSpaceEachBody(self.space._space, get_fn, get_data)
        self._state[:] = np.frombuffer(buf.float_buf(), dtype=np.float64).reshape(self._n_rows, 6)

    def _put_bodies(self) -> None:
        """Write ``_state`` into every chassis body."""
        if self._fast is None:
            pb.set_space_bodies(self.space, _STATE_FIELDS, self._set_buf)
        else:
            lib, _, set_data, _, set_fn = self._fast
            arr = self._set_buf._float_arr
            num = arr.num
            arr.num = 0
            lib.cpSpaceEachBody(self.space._space, set_fn, set_data)
            arr.num = num

    def _put_forces(self) -> None:
        """Write ``_forces`` (N rows of Fx, Fy, τ, world frame) as the chassis bodies' force and torque."""
        pb.set_space_bodies(self.space, _FORCE_FIELDS, self._force_buf)

    def _summarize(self) -> None:
        _summary_kernel(self._state, self.joint_state, self.motor_state, self.acc, self.wheel_params, self._axis_xy,
                        self.n, 1.0 / self.substeps, self.blowup.speed, self.blowup.yaw_rate,
                        self.blowup.spin, self.blowup.position, self.summary, self.wheel_summary)

    def _read_state(self) -> np.ndarray:
        self._get_bodies()
        self._summarize()
        return self._state

    def _read_robot_state(self, robot: int) -> None:
        """Re-read one robot's body and recompute its summary row (after a reset or a kick), in
        O(1) of the robot count."""
        b = self.chassis[robot]
        p, v = b.position, b.velocity
        self._state[robot] = (p.x, p.y, b.angle, v.x, v.y, b.angular_velocity)
        sl = slice(robot, robot + 1)
        _summary_kernel(self._state[sl], self.joint_state[sl], self.motor_state[sl], self.acc[sl],
                        self.wheel_params[sl], self._axis_xy, self.n, 1.0 / self.substeps, self.blowup.speed,
                        self.blowup.yaw_rate, self.blowup.spin, self.blowup.position, self.summary[sl],
                        self.wheel_summary[sl])

    def _add_obstacle(self, ob: Obstacle) -> None:
        body = self.space.static_body
        if ob.vertices:
            shape = pymunk.Poly(body, ob.vertices)
        else:
            shape = pymunk.Circle(body, ob.radius, (ob.x, ob.y))
        shape.filter = pymunk.ShapeFilter(categories=_CAT_OBSTACLE, mask=_CAT_ROBOT)
        shape.friction = 0.5
        shape.elasticity = 0.2
        self.space.add(shape)
        self._obstacle_shapes.append(shape)

    def _build_space_keep_state(self) -> None:
        """Rebuild the Space and copy every robot body's state over."""
        saved = [(b.position, b.angle, b.velocity, b.angular_velocity) for b in self.chassis]
        self._build_space()
        for body, (pos, ang, vel, w) in zip(self.chassis, saved):
            body.angle = ang
            body.position, body.velocity, body.angular_velocity = pos, vel, w
        self._read_state()

    def rebuild(self) -> None:
        """Recreate the pymunk Space (same robots and obstacles, bodies at the origin).

        pymunk keeps contact caches between steps, so with obstacles two episodes reset to the
        same state only replay bit-for-bit from a fresh Space. The single env rebuilds on every
        reset; call :meth:`reset_robot` after."""
        self._build_space()

    def set_obstacles(self, obstacles: Sequence = ()) -> None:
        """Replace the static obstacles (Obstacle, (x, y, radius) or vertex lists)."""
        obs = tuple(Obstacle.coerce(o) for o in obstacles)
        for shape in self._obstacle_shapes:
            self.space.remove(shape)
        self._obstacle_shapes = []
        had_shapes = bool(self.obstacles)
        self.obstacles = obs
        if bool(obs) != had_shapes:  # robots need (or no longer need) collision shapes
            self._build_space_keep_state()
            return
        for ob in obs:
            self._add_obstacle(ob)
        self._setup_buffers()

    # ------------------------------------------------------------------ pickling

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        for key in ("_get_buf", "_set_buf", "_force_buf", "_fast"):
            d.pop(key, None)
        return d

    def __setstate__(self, d: dict) -> None:
        self.__dict__.update(d)
        state = self._state.copy()
        self._setup_buffers()
        self._state[:] = state

    # ------------------------------------------------------------------ reset and commands

    def set_wheel_params(self, wheel_params: np.ndarray) -> None:
        """Replace the per-robot, per-wheel parameter array (N, n, len(WP)), e.g. randomised."""
        wp = np.asarray(wheel_params, dtype=np.float64)
        if wp.shape != self.wheel_params.shape or not np.all(np.isfinite(wp)):
            raise ValueError(f"wheel_params must be finite with shape {self.wheel_params.shape}")
        self.wheel_params = np.ascontiguousarray(wp)

    def set_chassis_mass(self, robot: int, mass: float) -> None:
        """Change robot ``robot``'s chassis mass [kg] (without the modules; the plate's inertia
        scales with it). The body's mass and moment and the wheels' static normal loads follow."""
        if not (math.isfinite(mass) and mass > 0):
            raise ValueError(f"mass must be > 0, got {mass!r}")
        if not 0 <= robot < self.n_robots:
            raise ValueError(f"robot index {robot} out of range 0..{self.n_robots - 1}")
        m_tot, moment = self._body_inertia(mass)
        scale = m_tot / self.params.total_mass  # the loads, so the tire's contact stiffness, scale with it
        worst = max(v for k, (v, _) in self.stability_figures().items() if k.endswith("_margin"))
        if worst * scale >= 4.0:
            raise ValueError(f"chassis mass {mass} kg loads the tires {scale:.2f}x the nominal: the contact's "
                             f"stability margin {worst * scale:.2f} would reach 4 at this substep: raise substeps")
        self.body_inertia[robot] = (m_tot, moment)
        ch = self.chassis[robot]
        ch.moment = float(moment)
        ch.mass = float(m_tot)
        self.wheel_params[robot, :, WP.LOAD] = self.params.static_normal_loads(m_tot)

    def normal_loads(self) -> np.ndarray:
        """(N, n) normal loads N_k now [N]: the static share of each robot's current mass plus,
        with ``com_height`` > 0, the load transfer of the last substep's acceleration."""
        loads = self.wheel_params[..., WP.LOAD].copy()
        h = self.params.chassis.com_height
        if h > 0:
            m = self.body_inertia[:, BODY.MASS, None]
            a = self.chassis_accel
            loads -= h * m * (self._load_map[None, :, 1] * a[:, 0:1] + self._load_map[None, :, 2] * a[:, 1:2])
            np.maximum(loads, 0.0, out=loads)
        return loads

    def reset_robot(self, robot: int, pose=(0.0, 0.0, 0.0), beta=None, twist=(0.0, 0.0, 0.0)) -> None:
        """Place robot ``robot`` at pose (x, y, θ) [m, m, rad] in the world, wheels at steering
        angles ``beta`` (n,) [rad] (default 0, clipped into the steering range), moving with the
        chassis twist (ẋ, ẏ, θ̇) given in the chassis frame, wheels rolling without slip and motors
        at rest on their set-points."""
        g = self.params.geometry
        pose = np.asarray(pose, dtype=np.float64)
        twist = np.asarray(twist, dtype=np.float64)
        beta = np.zeros(self.n) if beta is None else np.asarray(beta, dtype=np.float64)
        if pose.shape != (3,) or twist.shape != (3,) or beta.shape != (self.n,):
            raise ValueError("reset_robot needs pose (3,), twist (3,) and beta (n,)")
        if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(twist)) and np.all(np.isfinite(beta))):
            raise ValueError("reset_robot: non-finite pose, twist or beta")
        beta = np.clip(beta, g.steer_min + 1e-9, g.steer_max)
        x, y, th = pose
        c, s = math.cos(th), math.sin(th)
        v_world = np.array([c * twist[0] - s * twist[1], s * twist[0] + c * twist[1]])
        w = float(twist[2])
        ch = self.chassis[robot]
        ch.angle = float(th)  # the angle first: the position setter uses the (maybe non-finite) transform
        ch.position = (float(x), float(y))
        ch.velocity = tuple(v_world)
        ch.angular_velocity = w
        ch.force = (0.0, 0.0)
        ch.torque = 0.0
        self.joint_state[robot, :, JS.BETA] = beta
        self.joint_state[robot, :, JS.OMEGA] = w
        self.tire_state[robot] = 0.0  # unloaded patches: a rolling start builds its slip by distance
        self.chassis_accel[robot] = 0.0
        # wheel spins that roll without slip: r φ̇ = v(P)·d
        gam = th + g.alpha + beta
        px = x + c * g.axis_xy[:, 0] - s * g.axis_xy[:, 1] + g.b * np.cos(gam)
        py = y + s * g.axis_xy[:, 0] + c * g.axis_xy[:, 1] + g.b * np.sin(gam)
        vpx = v_world[0] - w * (py - y)
        vpy = v_world[1] + w * (px - x)
        phidot = (vpx * np.sin(gam) - vpy * np.cos(gam)) / g.r
        ms = self.motor_state[robot]
        ms[:, MS.THETA] = beta
        ms[:, MS.OMEGA] = 0.0
        ms[:, MS.PHIDOT_REF] = phidot
        ms[:, MS.PHIDOT] = phidot
        ms[:, MS.PHI] = 0.0
        self.commands[robot, :, CMD.BETA] = beta
        self.commands[robot, :, CMD.PHIDOT] = phidot
        self.enabled[robot] = True
        self.acc[robot] = 0.0
        self._read_robot_state(robot)

    def overlapping_obstacles(self, robot: int = 0) -> list[int]:
        """Indices of the obstacles that overlap robot ``robot``'s chassis now."""
        if not self.obstacles:
            return []
        hits = set()
        for shape in self.chassis[robot].shapes:
            for info in self.space.shape_query(shape):
                if info.shape in self._obstacle_shapes:
                    hits.add(self._obstacle_shapes.index(info.shape))
        return sorted(hits)

    def set_commands(self, beta_cmd, phidot_cmd) -> None:
        """Set-points for all robots: β_cmd (N, n) [rad], φ̇_cmd (N, n) [rad/s] (clipped to limits)."""
        lim = self.params.limits
        beta_cmd = np.asarray(beta_cmd, dtype=np.float64).reshape(self.n_robots, self.n)
        phidot_cmd = np.asarray(phidot_cmd, dtype=np.float64).reshape(self.n_robots, self.n)
        if not (np.all(np.isfinite(beta_cmd)) and np.all(np.isfinite(phidot_cmd))):
            raise ValueError("set_commands: set-points contain NaN or inf")
        self.commands[..., CMD.BETA] = np.clip(beta_cmd, lim.steer_min, lim.steer_max)
        self.commands[..., CMD.PHIDOT] = np.clip(phidot_cmd, -lim.wheel_speed_max, lim.wheel_speed_max)

    def set_motors_enabled(self, enabled) -> None:
        """Motors on (True) or off (False) per robot: off means zero propulsion torque and the
        steering motors braked at their current angle."""
        self.enabled[:] = np.broadcast_to(np.asarray(enabled, dtype=np.bool_), (self.n_robots,))

    def kick(self, robot: int, wheels: Sequence[int], impulse: float) -> None:
        """An angular impulse [N·m·s] on the modules ``wheels`` of robot ``robot``, about their
        steering axes (like a collision knocking the wheels to other angles)."""
        if not math.isfinite(impulse):
            raise ValueError(f"kick impulse must be finite, got {impulse!r}")
        for k in wheels:
            if not 0 <= int(k) < self.n:
                raise ValueError(f"kick: wheel index {k} out of range 0..{self.n - 1}")
        for k in wheels:
            self.joint_state[robot, int(k), JS.OMEGA] += impulse / self.wheel_params[robot, int(k), WP.I_MOD]
        self._read_robot_state(robot)

    # ------------------------------------------------------------------ stepping

    def step(self, times: dict[str, float] | None = None) -> None:
        """Advance all robots by one control period (``substeps`` substeps).

        ``times``: if given, the seconds spent in each stage are added to it under the keys
        ``read``, ``force`` (the compiled kernel), ``write``, ``space_step`` and ``summary``
        (``azimut bench-env``'s split)."""
        self.acc[:] = 0.0
        p = self.params
        args = (self.joint_state, self.motor_state, self.tire_state, self.commands, self.wheel_params, self.enabled, self.acc,
                self.body_inertia, self.chassis_accel, self._axis_xy, self._load_map, float(p.chassis.com_height),
                float(p.gravity), float(p.steering.stop_restitution), bool(p.steer_motor.is_dc), self.n, self.dt)
        tm = times
        t = time.perf_counter() if tm is not None else 0.0
        self._get_bodies()
        if tm is not None:
            t = _lap(tm, "read", t)
        state = self._state
        if not self.obstacles:  # the whole control period in one compiled call
            _step_kernel(state, *args, self.substeps, True)
            if tm is not None:
                t = _lap(tm, "force", t)
            self._put_bodies()
            if tm is not None:
                t = _lap(tm, "write", t)
        else:  # pymunk integrates the bodies (forces from the kernel's velocity change) and resolves contacts
            space, dt, N = self.space, self.dt, self.n_robots
            forces, before = self._forces, self._before
            for j in range(self.substeps):
                if j:
                    self._get_bodies()
                    if tm is not None:
                        t = _lap(tm, "read", t)
                before[:] = state[:N, CS.VX:CS.W + 1]
                _step_kernel(state, *args, 1, False)
                # the same velocity change, as the force and torque pymunk applies in its step
                forces[:N, 0:2] = (state[:N, CS.VX:CS.VY + 1] - before[:, 0:2]) * (self.body_inertia[:, BODY.MASS, None] / dt)
                forces[:N, 2] = (state[:N, CS.W] - before[:, 2]) * (self.body_inertia[:, BODY.MOMENT] / dt)
                self._put_forces()
                if tm is not None:
                    t = _lap(tm, "force", t)
                space.step(dt)
                if tm is not None:
                    t = _lap(tm, "space_step", t)
            self._get_bodies()
            if tm is not None:
                t = _lap(tm, "read", t)
        self._summarize()
        if tm is not None:
            _lap(tm, "summary", t)

    # ------------------------------------------------------------------ state

    def chassis_pose(self) -> np.ndarray:
        """(N, 3) chassis pose (x, y, θ) in the world [m, m, rad]."""
        return self.summary[:, RS_POSE].copy()

    def chassis_twist(self) -> np.ndarray:
        """(N, 3) chassis twist ξ̇ = (ẋ, ẏ, θ̇) in the chassis frame R [m/s, m/s, rad/s]."""
        return self.summary[:, RS_TWIST_BODY]

    def steering_angles(self) -> np.ndarray:
        """(N, n) true steering angles β (wheel side of the spring) [rad]."""
        return self.wheel_summary[..., WS.BETA].copy()

    def steering_rates(self) -> np.ndarray:
        """(N, n) true steering rates β̇ [rad/s]."""
        return self.wheel_summary[..., WS.BETA_DOT].copy()

    def motor_angles(self) -> np.ndarray:
        """(N, n) steering motor angles θ_m [rad]."""
        return self.motor_state[..., MS.THETA].copy()

    def wheel_speeds(self) -> np.ndarray:
        """(N, n) true wheel spin rates φ̇ [rad/s]."""
        return self.motor_state[..., MS.PHIDOT].copy()

    def axis_points(self) -> np.ndarray:
        """(N, n, 2) steering axes A_k in the world [m]."""
        x, y, th = (self.summary[:, col, None] for col in (RS.X, RS.Y, RS.TH))
        c, s = np.cos(th), np.sin(th)
        a = self._axis_xy
        return np.stack([x + c * a[:, 0] - s * a[:, 1], y + s * a[:, 0] + c * a[:, 1]], axis=-1)

    def contact_points(self) -> np.ndarray:
        """(N, n, 2) contact points P_k = A_k + b_k (cos γ, sin γ) in the world [m]."""
        gam = self.summary[:, RS.TH, None] + self.wheel_params[..., WP.ALPHA] + self.joint_state[..., JS.BETA]
        b = self.wheel_params[..., WP.B]
        return self.axis_points() + b[..., None] * np.stack([np.cos(gam), np.sin(gam)], axis=-1)

    def tire_forces_body(self) -> np.ndarray:
        """(N, n, 2) tire forces in the chassis frame, averaged over the last step [N]."""
        return self.wheel_summary[..., WS_FORCE].copy()

    def slip_power(self) -> np.ndarray:
        """(N,) power dissipated by tire slip Σ_k |F_k · v_slip,k|, averaged over the last step [W]."""
        return self.summary[:, RS.SLIP].copy()

    def internal_force(self) -> np.ndarray:
        """(N,) norm of the internal (antagonistic) part of the tire forces, step mean [N].

        The tire forces F (2n values, chassis frame) map to the net wrench W = G F on the chassis
        (force and moment about the centre). The least-norm forces that give the same W are
        F* = Gᵀ(G Gᵀ)⁻¹ W; F − F* lies in the null space of G: forces that cancel out.
        """
        return self.summary[:, RS.INTERNAL].copy()

    def energy(self) -> np.ndarray:
        """(N,) kinetic energy (chassis with the module masses, module rotations, wheel spins)
        plus the elastic energy of the steering springs and the tires' contact patches [J]."""
        st = self._state[: self.n_robots]
        m, inertia = self.body_inertia[:, BODY.MASS], self.body_inertia[:, BODY.MOMENT]
        e = 0.5 * m * (st[:, CS.VX] ** 2 + st[:, CS.VY] ** 2) + 0.5 * inertia * st[:, CS.W] ** 2
        wp = self.wheel_params
        e += 0.5 * np.sum(wp[..., WP.I_MOD] * self.joint_state[..., JS.OMEGA] ** 2, axis=1)
        e += 0.5 * np.sum(wp[..., WP.I_W] * self.motor_state[..., MS.PHIDOT] ** 2, axis=1)
        e += 0.5 * np.sum(wp[..., WP.K_S] * (self.motor_state[..., MS.THETA] - self.joint_state[..., JS.BETA]) ** 2,
                          axis=1)
        # the tire's contact springs: k_x = C_κ/σ_κ, k_y = C_α/σ_α, twist k_y a²/2 (tire module)
        loads = self.normal_loads()
        ts = self.tire_state
        k_x = wp[..., WP.C_KAPPA] * loads / wp[..., WP.SIGMA_LONG]
        k_y = wp[..., WP.C_ALPHA] * loads / wp[..., WP.SIGMA_LAT]
        k_t = 0.5 * k_y * wp[..., WP.HALF_LEN] ** 2
        e += 0.5 * np.sum(k_x * ts[..., TS.U_LONG] ** 2 + k_y * ts[..., TS.U_LAT] ** 2 + k_t * ts[..., TS.TWIST] ** 2,
                          axis=1)
        return e

    def check(self) -> tuple[np.ndarray, list[str]]:
        """Blow-up detection: (ok (N,) bool, reason per robot, '' where ok)."""
        codes = self.summary[:, RS.CODE]
        ok = codes == BlowUp.NONE
        if ok.all():
            return ok, [""] * self.n_robots
        return ok, [BLOWUP_MESSAGES.get(int(c), "") if c else "" for c in codes]


def _lap(times: dict[str, float], key: str, t0: float) -> float:
    """Add the time since ``t0`` to ``times[key]``; return now."""
    t = time.perf_counter()
    times[key] = times.get(key, 0.0) + t - t0
    return t
