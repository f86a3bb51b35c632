"""Rigid-body physics of N AZIMUT-3-like robots in one pymunk Space (top-down 2D).

One :class:`AzimutPhysics` simulates ``n_robots`` robots (the single env is ``n_robots=1``; the
vector env of issue 5 uses the same class with many). Robots do not collide with each other, only
with static obstacles.

Per robot, pymunk holds a chassis body and one module body per wheel. Module k's centre of mass is
its steering axis A_k, where a ``PivotJoint`` holds it to the chassis; a ``RotaryLimitJoint`` is the
hard stop at the steering range (module angle − chassis angle − α_k ∈ [β_min, β_max]). The module
body's angle is ``θ + γ_k = θ + α_k + β_k``, so its local X axis is the propulsion axis and the
contact point P_k sits at ``(b_k, 0)`` in module coordinates.

Everything else (steering motor, spring and damper, wheel spin, tires) is computed by one numba
kernel per substep over all robots × wheels (:func:`_substep_kernel`), which reads the bodies'
state with one ``pymunk.batch.get_space_bodies`` call and writes all forces and torques with one
``pymunk.batch.set_space_bodies`` call. The tire force acts at P_k, so its lateral part, at offset
b_k from A_k, twists the module against the compliant steering.

Per-robot parameters live in arrays (``wheel_params``) so that domain randomisation can vary them
robot by robot. After each step, ``summary`` (N, 11) and ``wheel_summary`` (N, n, 6) hold the
derived per-robot quantities (pose, twists, slip power, internal force, blow-up code; β, β̇, tire
forces and contact points in the chassis frame), computed by one compiled call for all robots.

Stability (default parameters, 8 substeps of 2.5 ms at the 20 ms control period):

* the tire acts on a module's steering DOF like a damper of rate ``μ N b² / (v_knee I_mod)``:
  439 1/s, so rate·dt = 1.1 (explicit damping is stable below 2; :meth:`_check_stability`
  refuses substeps above 1.5);
* the series spring: ω = sqrt(k_s / I_mod) = 55 rad/s, ω·dt = 0.14 (refused above 0.5);
* the wheel spin on the tire (rate c r² / I_w ≈ 290 1/s) and the propulsion velocity loop are
  integrated implicitly, so they put no bound on dt;
* pivot joints and hard stops are pymunk constraints (solver iterations: 20).

Robots have collision shapes only when there are obstacles (collisions cost about half of each
pymunk step). pymunk keeps solver state (warm-start impulses) between steps: :meth:`rebuild`
gives a fresh Space, which the single env does at each reset for bit-exact replay; a vector env
resetting one robot with :meth:`reset_robot` alone is deterministic but not bit-identical to a
fresh start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pymunk
import pymunk.batch as pb
from numba import njit

from .actuators import spring_torque_kernel, steer_motor_kernel, wheel_spin_kernel
from .params import RobotParams

__all__ = ["AzimutPhysics", "Obstacle", "BlowUpLimits", "WP"]

_STATE_FIELDS = (pb.BodyFields.POSITION | pb.BodyFields.ANGLE | pb.BodyFields.VELOCITY
                 | pb.BodyFields.ANGULAR_VELOCITY)
_FORCE_FIELDS = pb.BodyFields.FORCE | pb.BodyFields.TORQUE

#: Collision categories: robots collide with obstacles only, never with each other.
_CAT_ROBOT = 0b01
_CAT_OBSTACLE = 0b10


class WP:
    """Column indices of the per-wheel parameter array ``wheel_params`` (N, n, WP.COUNT)."""

    B, R, ALPHA, LOAD, MU, KNEE, K_S, C_S, KP, I_W, KV, BEARING, RR_TORQUE, RR_KNEE, \
        STEER_RATE, STEER_ACCEL, STEER_TORQUE, WHEEL_ACCEL, WHEEL_TORQUE, STEER_MIN, STEER_MAX = range(21)
    COUNT = 21


class MS:
    """Column indices of the per-wheel motor state array (N, n, MS.COUNT)."""

    THETA, OMEGA, PHIDOT_REF, PHIDOT, PHI = range(5)
    COUNT = 5


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


@dataclass(frozen=True)
class BlowUpLimits:
    """Thresholds beyond which the state is declared absurd (a numerical blow-up).

    Attributes:
        speed: chassis or module speed [m/s]. spin: |φ̇| [rad/s]. yaw_rate: body angular speed
        [rad/s]. position: |x|, |y| [m]. joint_gap: distance between a module and its axis on the
        chassis [m] (a torn pivot joint).
    """

    speed: float = 20.0
    spin: float = 500.0
    yaw_rate: float = 200.0
    position: float = 1e4
    joint_gap: float = 0.05


@njit(cache=True)
def _substep_kernel(state, forces, ms, cmd, wp, enabled, acc, n, dt):
    """One physics substep for all robots × wheels: actuators, spring, wheel spin and tires.

    state: (rows, 6) bodies' (x, y, angle, vx, vy, ω) from pymunk.batch, robot i's chassis at row
    i·(n+1) and its modules after it. Writes forces (rows, 3) = (Fx, Fy, τ) in world coordinates,
    updates ms (N, n, MS) in place, and accumulates acc (N, n, 4) = (ΣFx, ΣFy, Σ slip power, ΣF_lat).
    """
    n_robots = ms.shape[0]
    for i in range(n_robots):
        rc = i * (n + 1)
        th_c = state[rc, 2]
        w_c = state[rc, 5]
        on = enabled[i]
        tau_c = 0.0
        for k in range(n):
            rm = rc + 1 + k
            p = wp[i, k]
            b = p[0]
            r = p[1]
            th_m = state[rm, 2]
            w_m = state[rm, 5]
            beta = th_m - th_c - p[2]
            if beta > math.pi:  # wrapped by branches: atan2(sin, cos) costs ~30% of the kernel
                beta -= 2.0 * math.pi
            elif beta < -math.pi:
                beta += 2.0 * math.pi
            beta_dot = w_m - w_c
            # steering motor and series spring
            theta, omega = steer_motor_kernel(ms[i, k, 0], ms[i, k, 1], cmd[i, k, 0], beta, on,
                                              p[8], p[14], p[15], p[16], p[6], dt)
            tau_s = spring_torque_kernel(theta, omega, beta, beta_dot, on, p[6], p[7], p[16])
            ms[i, k, 0] = theta
            ms[i, k, 1] = omega
            # contact point velocity
            cth = math.cos(th_m)
            sth = math.sin(th_m)
            vpx = state[rm, 3] - w_m * b * sth
            vpy = state[rm, 4] + w_m * b * cth
            v_roll = vpx * sth - vpy * cth
            v_lat = vpx * cth + vpy * sth
            # propulsion set-point ramp
            ref = ms[i, k, 2]
            if on:
                dref = cmd[i, k, 1] - ref
                lim = p[17] * dt
                if dref > lim:
                    dref = lim
                elif dref < -lim:
                    dref = -lim
                ref += dref
            else:
                ref = ms[i, k, 3]
            mu_n = p[4] * p[3]
            phidot, f_long, f_lat, s_long = wheel_spin_kernel(
                ms[i, k, 3], ref, v_roll, v_lat, on, r, p[9], p[10], p[18], p[11],
                p[12] * p[3] * r, p[13], mu_n, p[5], dt)
            ms[i, k, 2] = ref
            ms[i, k, 3] = phidot
            ms[i, k, 4] += phidot * dt
            fx = f_long * sth + f_lat * cth
            fy = -f_long * cth + f_lat * sth
            forces[rm, 0] = fx
            forces[rm, 1] = fy
            forces[rm, 2] = b * (cth * fy - sth * fx) + tau_s
            tau_c -= tau_s
            acc[i, k, 0] += fx
            acc[i, k, 1] += fy
            acc[i, k, 2] += -(f_long * s_long + f_lat * v_lat)
            acc[i, k, 3] += f_lat
        forces[rc, 0] = 0.0
        forces[rc, 1] = 0.0
        forces[rc, 2] = tau_c


#: robot summary columns (``AzimutPhysics.summary``): pose, world velocity, body velocity, slip
#: power, internal force, blow-up code.
_SUM_X, _SUM_Y, _SUM_TH, _SUM_VX, _SUM_VY, _SUM_W, _SUM_BX, _SUM_BY, _SUM_SLIP, _SUM_INTERNAL, _SUM_CODE = range(11)
#: wheel summary columns: β, β̇, tire force in the chassis frame (x, y), P_k in the chassis frame (x, y).
_WS_BETA, _WS_BETA_DOT, _WS_FX, _WS_FY, _WS_PX, _WS_PY = range(6)

BLOWUP_MESSAGES = {
    1: "non-finite physics state",
    2: "body speed exceeds the blow-up limit",
    3: "body angular speed exceeds the blow-up limit",
    4: "wheel spin exceeds the blow-up limit",
    5: "position exceeds the blow-up limit",
    6: "steering pivot torn apart (module away from its axis)",
}


@njit(cache=True)
def _summary_kernel(state, ms, acc, wp, axis_xy, n, inv_sub, lim, out_r, out_w):
    """Per-step derived quantities for all robots (see the column constants), one call.

    Internal force: the tire forces F (2n, chassis frame) give the net wrench W = G F; the
    least-norm forces with the same wrench are F* = Gᵀ (G Gᵀ)⁻¹ W, and ‖F − F*‖ is the internal part.
    lim = (speed, yaw_rate, spin, position, joint_gap).
    """
    n_robots = ms.shape[0]
    G = np.zeros((3, 2 * n))
    F = np.zeros(2 * n)
    for i in range(n_robots):
        rc = i * (n + 1)
        x, y, th = state[rc, 0], state[rc, 1], state[rc, 2]
        vx, vy, w = state[rc, 3], state[rc, 4], state[rc, 5]
        c, s = math.cos(th), math.sin(th)
        out_r[i, 0] = x
        out_r[i, 1] = y
        out_r[i, 2] = th
        out_r[i, 3] = vx
        out_r[i, 4] = vy
        out_r[i, 5] = w
        out_r[i, 6] = c * vx + s * vy
        out_r[i, 7] = -s * vx + c * vy
        slip = 0.0
        code = 0
        finite = math.isfinite(x) and math.isfinite(y) and math.isfinite(th) and math.isfinite(vx) \
            and math.isfinite(vy) and math.isfinite(w)
        vmax = math.hypot(vx, vy)
        wmax = abs(w)
        pmax = max(abs(x), abs(y))
        spin = 0.0
        gap = 0.0
        for k in range(n):
            rm = rc + 1 + k
            for j in range(6):
                if not math.isfinite(state[rm, j]):
                    finite = False
            for j in range(ms.shape[2]):
                if not math.isfinite(ms[i, k, j]):
                    finite = False
            vmax = max(vmax, math.hypot(state[rm, 3], state[rm, 4]))
            wmax = max(wmax, abs(state[rm, 5]))
            pmax = max(pmax, abs(state[rm, 0]), abs(state[rm, 1]))
            spin = max(spin, abs(ms[i, k, 3]))
            ax = x + c * axis_xy[k, 0] - s * axis_xy[k, 1]
            ay = y + s * axis_xy[k, 0] + c * axis_xy[k, 1]
            gap = max(gap, math.hypot(state[rm, 0] - ax, state[rm, 1] - ay))
            beta = state[rm, 2] - th - wp[i, k, 2]
            beta = math.atan2(math.sin(beta), math.cos(beta))
            out_w[i, k, 0] = beta
            out_w[i, k, 1] = state[rm, 5] - w
            fxw = acc[i, k, 0] * inv_sub
            fyw = acc[i, k, 1] * inv_sub
            fx = c * fxw + s * fyw
            fy = -s * fxw + c * fyw
            out_w[i, k, 2] = fx
            out_w[i, k, 3] = fy
            gam = wp[i, k, 2] + beta
            px = axis_xy[k, 0] + wp[i, k, 0] * math.cos(gam)
            py = axis_xy[k, 1] + wp[i, k, 0] * math.sin(gam)
            out_w[i, k, 4] = px
            out_w[i, k, 5] = py
            slip += acc[i, k, 2] * inv_sub
            G[0, 2 * k] = 1.0
            G[1, 2 * k + 1] = 1.0
            G[2, 2 * k] = -py
            G[2, 2 * k + 1] = px
            F[2 * k] = fx
            F[2 * k + 1] = fy
        out_r[i, 8] = slip
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
                px, py = G[2, 2 * k + 1], -G[2, 2 * k]
                sx += px
                sy += py
                s2 += px * px + py * py
                wx += F[2 * k]
                wy += F[2 * k + 1]
                wz += px * F[2 * k + 1] - py * F[2 * k]
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
                px, py = G[2, 2 * k + 1], -G[2, 2 * k]
                dx = F[2 * k] - (x0 - py * x2)
                dy = F[2 * k + 1] - (x1 + px * x2)
                internal += dx * dx + dy * dy
            internal = math.sqrt(internal)
        out_r[i, 9] = internal
        if not finite:
            code = 1
        elif vmax > lim[0]:
            code = 2
        elif wmax > lim[1]:
            code = 3
        elif spin > lim[2]:
            code = 4
        elif pmax > lim[3]:
            code = 5
        elif gap > lim[4]:
            code = 6
        out_r[i, 10] = code


class AzimutPhysics:
    """N robots in one pymunk Space, stepped at ``control_period`` with ``substeps`` substeps.

    Args:
        params: the robot's physical parameters (shared by all robots; per-robot variations go
            through :meth:`set_wheel_params`).
        n_robots: number of robots N (1 for the single env).
        control_period: duration of one :meth:`step` [s].
        substeps: physics substeps per step; the substep is ``control_period / substeps``.
        blowup: thresholds of :meth:`check`.
        solver_iterations: pymunk solver iterations per substep (pivot joints and hard stops). The
            joints converge in fewer: 10 gave the same observations as 20 in a bang-bang-and-kicks
            stress run and within 1e-8 in random driving, for about 15% less time per step.

    State accessors return arrays with a leading robot axis N.
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
        self.wheel_params = self._default_wheel_params()
        self.motor_state = np.zeros((self.n_robots, self.n, MS.COUNT))
        self.commands = np.zeros((self.n_robots, self.n, 2))
        self.enabled = np.ones(self.n_robots, dtype=np.bool_)
        self.acc = np.zeros((self.n_robots, self.n, 4))
        self.obstacles: tuple[Obstacle, ...] = ()
        self.summary = np.zeros((self.n_robots, 11))
        self.wheel_summary = np.zeros((self.n_robots, self.n, 6))
        self._lim = np.array([self.blowup.speed, self.blowup.yaw_rate, self.blowup.spin, self.blowup.position,
                              self.blowup.joint_gap])
        self._axis_xy = np.ascontiguousarray(self.params.geometry.axis_xy)
        self._build_space()

    # ------------------------------------------------------------------ construction

    def _check_stability(self) -> None:
        """Refuse substeps at which the explicit parts (tire on the module's steering DOF, spring)
        would be unstable."""
        p = self.params
        load = p.static_normal_loads().max()
        c = p.tire.friction * load / p.tire.slip_knee
        b2 = float(np.max(p.geometry.b ** 2))
        rate_tire = c * max(b2, 1e-6) / p.steering.module_inertia
        omega_s = math.sqrt(p.steering.stiffness / p.steering.module_inertia)
        if rate_tire * self.dt > 1.5 or omega_s * self.dt > 0.5:
            raise ValueError(
                f"substep {self.dt:.4g} s too long for stability (tire rate·dt = {rate_tire * self.dt:.2f} "
                f"must be <= 1.5, spring ω·dt = {omega_s * self.dt:.2f} must be <= 0.5): raise substeps")

    def _default_wheel_params(self) -> np.ndarray:
        p, g = self.params, self.params.geometry
        wp = np.zeros((self.n_robots, self.n, WP.COUNT))
        wp[..., WP.B] = g.b
        wp[..., WP.R] = g.r
        wp[..., WP.ALPHA] = g.alpha
        wp[..., WP.LOAD] = p.static_normal_loads()
        wp[..., WP.MU] = p.tire.friction
        wp[..., WP.KNEE] = p.tire.slip_knee
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
        return wp

    def _build_space(self) -> None:
        p, g = self.params, self.params.geometry
        space = pymunk.Space()
        space.iterations = self.solver_iterations
        space.gravity = (0.0, 0.0)
        robot_filter = pymunk.ShapeFilter(categories=_CAT_ROBOT, mask=_CAT_OBSTACLE)
        # Collision shapes only matter against obstacles; without obstacles the bodies carry their
        # mass and inertia alone, which makes each pymunk step about twice as fast.
        with_shapes = bool(self.obstacles)
        self.chassis: list[pymunk.Body] = []
        self.modules: list[list[pymunk.Body]] = []
        bodies: list[pymunk.Body] = []
        self._joints: list[list[pymunk.Constraint]] = []
        for _ in range(self.n_robots):
            joints: list[pymunk.Constraint] = []
            self._joints.append(joints)
            ch = pymunk.Body(p.chassis.mass, p.chassis.inertia)
            space.add(ch)
            if with_shapes:
                box = pymunk.Poly.create_box(ch, (p.chassis.length, p.chassis.width))
                box.filter = robot_filter
                box.friction = 0.5
                space.add(box)
            bodies.append(ch)
            mods = []
            for k in range(self.n):
                m = pymunk.Body(p.steering.module_mass, p.steering.module_inertia)
                m.position = tuple(g.axis_xy[k])
                m.angle = float(g.alpha[k])
                r = float(g.r[k])
                space.add(m)
                pivot, stop = self._make_joints(ch, m, k)
                space.add(pivot, stop)
                joints.extend((pivot, stop))
                if with_shapes:
                    wheel = pymunk.Poly(m, [(float(g.b[k]) + dx, dy) for dx, dy in
                                            ((-0.025, -r), (0.025, -r), (0.025, r), (-0.025, r))])
                    wheel.filter = robot_filter
                    wheel.friction = 0.5
                    space.add(wheel)
                bodies.append(m)
                mods.append(m)
            self.chassis.append(ch)
            self.modules.append(mods)
        self.space = space
        self._bodies = bodies
        self._obstacle_shapes: list[pymunk.Shape] = []
        for ob in self.obstacles:
            self._add_obstacle(ob)
        self._setup_buffers()

    def _make_joints(self, ch: pymunk.Body, m: pymunk.Body, k: int) -> tuple[pymunk.Constraint, pymunk.Constraint]:
        """Module k's pivot joint at its steering axis and its steering hard stop."""
        g = self.params.geometry
        pivot = pymunk.PivotJoint(ch, m, tuple(g.axis_xy[k]), (0.0, 0.0))
        stop = pymunk.RotaryLimitJoint(ch, m, float(g.alpha[k] + g.steer_min), float(g.alpha[k] + g.steer_max))
        pivot.collide_bodies = False
        stop.collide_bodies = False
        return pivot, stop

    def renew_joints(self, robot: int) -> None:
        """Replace robot ``robot``'s joints by fresh ones (no accumulated impulses).

        pymunk warm-starts each constraint with the impulse it accumulated at the previous step;
        a fresh Space starts from zero. Fresh joints give a robot reset inside a running Space the
        same solver state as a fresh Space, so its episode replays bit for bit (without obstacle
        contacts). Chipmunk deletes a constraint by moving the array's last one into its slot and
        solves constraints in array order: removing this robot's joints last-first moves the final
        robot's block into its slots in order, and the new joints go at the end in order, so every
        robot keeps its joints contiguous and in creation order."""
        if not 0 <= robot < self.n_robots:
            raise ValueError(f"robot index {robot} out of range 0..{self.n_robots - 1}")
        old = self._joints[robot]
        for c in reversed(old):
            self.space.remove(c)
        ch, mods = self.chassis[robot], self.modules[robot]
        new: list[pymunk.Constraint] = []
        for k, m in enumerate(mods):
            new.extend(self._make_joints(ch, m, k))
        self.space.add(*new)
        self._joints[robot] = new

    def _setup_buffers(self) -> None:
        """(Re)create the batch buffers; check that pymunk.batch lists our bodies first, in order."""
        self._get_buf = pb.Buffer()
        pb.get_space_bodies(self.space, pb.BodyFields.BODY_ID, self._get_buf)
        ids = list(memoryview(self._get_buf.int_buf()).cast("P"))
        n_rows = len(ids)
        ours = [b.id for b in self._bodies]
        if ids[: len(ours)] != ours:
            raise RuntimeError("pymunk.batch does not list the robot bodies in creation order")
        self._n_rows = n_rows
        self._forces = np.zeros((n_rows, 3))
        self._set_buf = pb.Buffer()
        self._set_buf.set_float_buf(self._forces)
        # Fast path: the same C iterators that pymunk.batch.get/set_space_bodies call, with their
        # argument structs built once (saves ~40% of the per-substep Python overhead).
        self._fast = None
        ffi, lib = getattr(pb, "ffi", None), getattr(pb, "lib", None)
        if ffi is not None and lib is not None and hasattr(lib, "cpSpaceEachBody"):
            try:
                get_data = ffi.new("pmBatchedData *")
                get_data.fields = _STATE_FIELDS.value
                get_data.floatArray = self._get_buf._float_arr
                get_data.intArray = self._get_buf._int_arr
                set_data = ffi.new("pmBatchedData *")
                set_data.fields = _FORCE_FIELDS.value
                set_data.floatArray = self._set_buf._float_arr
                set_data.intArray = self._set_buf._int_arr
                self._fast = (lib, get_data, set_data, ffi.addressof(lib, "pmSpaceBodyGetIteratorFuncBatched"),
                              ffi.addressof(lib, "pmSpaceBodySetIteratorFuncBatched"))
            except (AttributeError, TypeError):  # pymunk.batch changed: use the public functions
                self._fast = None
        self._read_state()

    def _read_state(self) -> np.ndarray:
        buf = self._get_buf
        buf.clear()
        pb.get_space_bodies(self.space, _STATE_FIELDS, buf)
        self._state = np.frombuffer(buf.float_buf(), dtype=np.float64).reshape(self._n_rows, 6)
        _summary_kernel(self._state, self.motor_state, self.acc, self.wheel_params, self._axis_xy, self.n,
                        1.0 / self.substeps, self._lim, self.summary, self.wheel_summary)
        return self._state

    def _read_robot_state(self, robot: int) -> None:
        """Re-read one robot's bodies and recompute its summary rows (after a reset or a kick), in
        O(1) of the robot count where :meth:`_read_state` reads every body. Same values: the
        body properties and ``pymunk.batch`` read the same fields."""
        if self.n_robots == 1:
            self._read_state()
            return
        rows = np.empty((self.n + 1, 6))
        for j, b in enumerate((self.chassis[robot], *self.modules[robot])):
            p, v = b.position, b.velocity
            rows[j] = (p.x, p.y, b.angle, v.x, v.y, b.angular_velocity)
        r0 = robot * (self.n + 1)
        try:
            self._state[r0:r0 + self.n + 1] = rows
        except ValueError:  # a read-only buffer view: the next step reads the bodies anyway
            pass
        sl = slice(robot, robot + 1)
        _summary_kernel(rows, self.motor_state[sl], self.acc[sl], self.wheel_params[sl], self._axis_xy, self.n,
                        1.0 / self.substeps, self._lim, self.summary[sl], self.wheel_summary[sl])

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
        saved = [[(b.position, b.angle, b.velocity, b.angular_velocity, b.mass, b.moment)
                  for b in [self.chassis[i], *self.modules[i]]] for i in range(self.n_robots)]
        self._build_space()
        for i, bodies in enumerate(saved):
            for body, (pos, ang, vel, w, mass, moment) in zip([self.chassis[i], *self.modules[i]], bodies):
                body.mass, body.moment = mass, moment
                body.position, body.angle, body.velocity, body.angular_velocity = pos, ang, vel, w
        self._read_state()

    def rebuild(self) -> None:
        """Recreate the pymunk Space (same robots and obstacles, bodies at the origin).

        pymunk keeps solver state between steps (constraint impulses for warm starting, contact
        caches), so two episodes reset to the same state only replay bit-for-bit from a fresh Space.
        The single env rebuilds on every reset (about 0.2 ms); call :meth:`reset_robot` after."""
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
        for key in ("_get_buf", "_set_buf", "_state", "_forces", "_fast"):
            d.pop(key, None)
        return d

    def __setstate__(self, d: dict) -> None:
        self.__dict__.update(d)
        self._setup_buffers()

    # ------------------------------------------------------------------ reset and commands

    def set_wheel_params(self, wheel_params: np.ndarray) -> None:
        """Replace the per-robot, per-wheel parameter array (N, n, WP.COUNT), e.g. randomised."""
        wp = np.asarray(wheel_params, dtype=np.float64)
        if wp.shape != self.wheel_params.shape or not np.all(np.isfinite(wp)):
            raise ValueError(f"wheel_params must be finite with shape {self.wheel_params.shape}")
        self.wheel_params = np.ascontiguousarray(wp)

    def set_chassis_mass(self, robot: int, mass: float) -> None:
        """Change robot ``robot``'s chassis mass [kg] (inertia scaled with it)."""
        if not (math.isfinite(mass) and mass > 0):
            raise ValueError(f"mass must be > 0, got {mass!r}")
        ch = self.chassis[robot]
        ch.moment = self.params.chassis.inertia * mass / self.params.chassis.mass
        ch.mass = mass

    def reset_robot(self, robot: int, pose=(0.0, 0.0, 0.0), beta=None, twist=(0.0, 0.0, 0.0)) -> None:
        """Place robot ``robot`` at pose (x, y, θ) [m, m, rad] in the world, wheels at steering
        angles ``beta`` (n,) [rad] (default 0), moving with the chassis twist (ẋ, ẏ, θ̇) given in
        the chassis frame, wheels rolling without slip and motors at rest on their set-points."""
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
        for k, m in enumerate(self.modules[robot]):
            ax, ay = g.axis_xy[k]
            wx, wy = x + c * ax - s * ay, y + s * ax + c * ay
            m.angle = float(th + g.alpha[k] + beta[k])
            m.position = (wx, wy)
            m.velocity = (v_world[0] - w * (wy - y), v_world[1] + w * (wx - x))
            m.angular_velocity = w
            m.force = (0.0, 0.0)
            m.torque = 0.0
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
        self.commands[robot, :, 0] = beta
        self.commands[robot, :, 1] = phidot
        self.enabled[robot] = True
        self.acc[robot] = 0.0
        self._read_robot_state(robot)

    def overlapping_obstacles(self, robot: int = 0) -> list[int]:
        """Indices of the obstacles that overlap robot ``robot``'s chassis or wheels now."""
        if not self.obstacles:
            return []
        bodies = {self.chassis[robot], *self.modules[robot]}
        hits = set()
        for shape in self.space.shapes:
            if shape.body in bodies:
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
        self.commands[..., 0] = np.clip(beta_cmd, lim.steer_min, lim.steer_max)
        self.commands[..., 1] = np.clip(phidot_cmd, -lim.wheel_speed_max, lim.wheel_speed_max)

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
            m = self.modules[robot][int(k)]
            m.angular_velocity = m.angular_velocity + impulse / m.moment
        self._read_robot_state(robot)

    # ------------------------------------------------------------------ stepping

    def step(self) -> None:
        """Advance all robots by one control period (``substeps`` substeps)."""
        self.acc[:] = 0.0
        space, dt, n = self.space, self.dt, self.n
        ms, cmd, wp, en, acc, forces = self.motor_state, self.commands, self.wheel_params, self.enabled, self.acc, self._forces
        get_buf, set_buf, n_rows = self._get_buf, self._set_buf, self._n_rows
        if self._fast is None:
            get, put = pb.get_space_bodies, pb.set_space_bodies
            for _ in range(self.substeps):
                get_buf.clear()
                get(space, _STATE_FIELDS, get_buf)
                state = np.frombuffer(get_buf.float_buf(), dtype=np.float64).reshape(n_rows, 6)
                _substep_kernel(state, forces, ms, cmd, wp, en, acc, n, dt)
                put(space, _FORCE_FIELDS, set_buf)
                space.step(dt)
        else:
            lib, get_data, set_data, get_fn, set_fn = self._fast
            each, cstep, cspace = lib.cpSpaceEachBody, lib.cpSpaceStep, space._space
            get_arr, set_arr = get_buf._float_arr, set_buf._float_arr
            n_set = set_arr.num
            space.step(0.0)  # pymunk's own bookkeeping (body checks, deferred adds) once per step
            state, ptr = self._state, get_arr.arr
            for _ in range(self.substeps):
                get_arr.num = 0
                each(cspace, get_fn, get_data)
                if get_arr.arr != ptr:  # the C array moved (never for a fixed body count)
                    state = np.frombuffer(get_buf.float_buf(), dtype=np.float64).reshape(n_rows, 6)
                    ptr = get_arr.arr
                _substep_kernel(state, forces, ms, cmd, wp, en, acc, n, dt)
                set_arr.num = 0
                each(cspace, set_fn, set_data)
                set_arr.num = n_set
                cstep(cspace, dt)
        self._read_state()

    # ------------------------------------------------------------------ state

    def _robot_rows(self) -> np.ndarray:
        st = self._state[: self.n_robots * (self.n + 1)]
        return st.reshape(self.n_robots, self.n + 1, 6)

    def chassis_pose(self) -> np.ndarray:
        """(N, 3) chassis pose (x, y, θ) in the world [m, m, rad]."""
        return self.summary[:, 0:3].copy()

    def chassis_twist_world(self) -> np.ndarray:
        """(N, 3) chassis velocity (v_x, v_y) in the world and yaw rate θ̇ [m/s, m/s, rad/s]."""
        return self.summary[:, 3:6].copy()

    def chassis_twist(self) -> np.ndarray:
        """(N, 3) chassis twist ξ̇ = (ẋ, ẏ, θ̇) in the chassis frame R [m/s, m/s, rad/s]."""
        return self.summary[:, [6, 7, 5]]

    def steering_angles(self) -> np.ndarray:
        """(N, n) true steering angles β (wheel side of the spring) [rad]."""
        return self.wheel_summary[..., 0].copy()

    def steering_rates(self) -> np.ndarray:
        """(N, n) true steering rates β̇ [rad/s]."""
        return self.wheel_summary[..., 1].copy()

    def motor_angles(self) -> np.ndarray:
        """(N, n) steering motor angles θ_m [rad]."""
        return self.motor_state[..., MS.THETA].copy()

    def wheel_speeds(self) -> np.ndarray:
        """(N, n) true wheel spin rates φ̇ [rad/s]."""
        return self.motor_state[..., MS.PHIDOT].copy()

    def wheel_angles(self) -> np.ndarray:
        """(N, n) accumulated wheel angles φ [rad] (what the encoders count)."""
        return self.motor_state[..., MS.PHI].copy()

    def contact_points(self) -> np.ndarray:
        """(N, n, 2) contact points P_k in the world [m]."""
        rows = self._robot_rows()[:, 1:]
        b = self.wheel_params[..., WP.B]
        return np.stack([rows[..., 0] + b * np.cos(rows[..., 2]), rows[..., 1] + b * np.sin(rows[..., 2])], axis=-1)

    def tire_forces(self) -> np.ndarray:
        """(N, n, 2) tire forces on the robot in the world, averaged over the last step [N]."""
        return self.acc[..., :2] / self.substeps

    def tire_forces_body(self) -> np.ndarray:
        """(N, n, 2) tire forces in the chassis frame, averaged over the last step [N]."""
        return self.wheel_summary[..., 2:4].copy()

    def lateral_tire_forces(self) -> np.ndarray:
        """(N, n) tire force along the propulsion axis (lateral, no-slip direction), step mean [N]."""
        return self.acc[..., 3] / self.substeps

    def slip_power(self) -> np.ndarray:
        """(N,) power dissipated by tire slip Σ_k |F_k · v_slip,k|, averaged over the last step [W]."""
        return self.summary[:, 8].copy()

    def internal_force(self) -> np.ndarray:
        """(N,) norm of the internal (antagonistic) part of the tire forces, step mean [N].

        The tire forces F (2n values, chassis frame) map to the net wrench W = G F on the chassis
        (force and moment about the centre). The least-norm forces that give the same W are
        F* = Gᵀ(G Gᵀ)⁻¹ W; F − F* lies in the null space of G: forces that cancel out.
        """
        return self.summary[:, 9].copy()

    def energy(self) -> np.ndarray:
        """(N,) kinetic energy of all bodies and wheel spins plus steering spring energy [J]."""
        e = np.zeros(self.n_robots)
        for i in range(self.n_robots):
            for body in [self.chassis[i], *self.modules[i]]:
                v = body.velocity
                e[i] += 0.5 * body.mass * (v.x * v.x + v.y * v.y) + 0.5 * body.moment * body.angular_velocity ** 2
        wp = self.wheel_params
        e += 0.5 * np.sum(wp[..., WP.I_W] * self.motor_state[..., MS.PHIDOT] ** 2, axis=1)
        e += 0.5 * np.sum(wp[..., WP.K_S] * (self.motor_state[..., MS.THETA] - self.steering_angles()) ** 2, axis=1)
        return e

    def check(self) -> tuple[np.ndarray, list[str]]:
        """Blow-up detection: (ok (N,) bool, reason per robot, '' where ok)."""
        codes = self.summary[:, 10]
        ok = codes == 0
        if ok.all():
            return ok, [""] * self.n_robots
        return ok, [BLOWUP_MESSAGES.get(int(c), "") if c else "" for c in codes]
