"""``twist-setpoint``: a swerve setpoint generator in the manner of Team 254's ``SwerveSetpointGenerator``.

Sources: Team 254, *FRC-2022-Public*, ``com/team254/lib/swerve/SwerveSetpointGenerator.java``
(github.com/Team254/FRC-2022-Public, MIT licence), and its port into PathPlannerLib 2025
(``com.pathplanner.lib.util.swerve.SwerveSetpointGenerator``, documented on PathPlanner's "Swerve
Setpoint Generator" page, pathplanner.dev). Written from their published description, adapted to
this project's actuator model; no code is taken from them.

The published method, per control period: from the previous *setpoint* (chassis speeds and module
states, not the measurements) move toward the target chassis speeds ξ_t by the largest s ∈ [0, 1]
such that every module's steering change stays within what its steering can do this period and
every drive speed change within its acceleration; a stopped module that must turn first holds the
chassis (s = 0) while it turns in place; when every module would have to turn by more than 90°, stop
the chassis first, then turn the modules in place toward the nearer of the two headings; when the
command is zero keep the module headings; desaturate the target's wheel speeds. PathPlannerLib adds
torque and friction limits from a robot model; this adaptation keeps to the actuator limits that
every controller here gets (:mod:`control.limits`).

Adapted here, with c the previous chassis setpoint, ξ(s) = c + s (ξ_t − c), module k's velocity at
its steering axis v_k(s) = (v_x − ω y_k, v_y + ω x_k) (linear in s), and the steering angle whose
rolling direction is along v_k, β = atan2(v_y, v_x) + π/2 − α (the conventions of
:mod:`control.twist.wpilib`):

* **Steering window.** The commanded β may change this period by Δ ∈ [lo, hi] = dt ·
  [max(−β̇_max, β̇_prev − β̈_max dt), min(β̇_max, β̇_prev + β̈_max dt)] (the rate *and* the
  acceleration limit, from the previous commanded rate; 254 bounds the change by β̇_max dt only),
  narrowed by braking caps: a moving module does not turn faster than it can still stop at its
  goal (its angle at s = 1), nor (stops) at its steering stop: the step toward a goal d away is d
  if d ≤ β̈_max dt² (it lands, and can stop next period), else ω dt with d − ω dt = ω²/(2 β̈_max).
* **Heading along s.** A moving module aligned with its velocity (within 45°) follows the
  velocity's direction continuously, β(s) = β(0) + ∠(v_k(0), v_k(s)). Past the point where the
  segment v_k(0) → v_k(1) comes within ``speed_deadband`` of zero (the module reverses or stops),
  and for a module at rest or off its velocity's axis, β(s) is the representative of the axis of
  v_k(s) the module takes: with unlimited steering the nearer of β and β + π to its previous
  command, with stops the one inside ]β_min, β_max]. Below the deadband, and on a zero command,
  the heading is held (the module brakes if it turns).
* **Module conditions at s.** The module steps toward β(s) within its window; the *lag* left,
  |β(s) − β_c| (at most π/2), may slip the wheel sideways at |v_k(s)| sin(lag): at most
  ``slip_speed``. This is 254's condition (the steering change within what the steering can do)
  relaxed by a sideways-slip tolerance, so a module that must decelerate its turn, or that starts
  misaligned, holds the chassis only as far as its slip requires (254 sets s = 0 while a stopped
  module turns; here the chassis may crawl at the slip speed meanwhile). The wheel command
  r φ̇ = v_k(s)·w(β_c) − ω b_k (w the rolling direction; the contact-point offset of
  :mod:`control.twist.wpilib`), times cos(β_c − β_measured) with cosine compensation, must keep
  |φ̇| ≤ φ̇_max and |φ̇ − φ̇_prev| ≤ φ̈_max dt on these actual commands.
* **Largest s.** s = 1 if every module's conditions hold there, else the largest s of a grid of
  ``grid`` points where they all hold, refined by ``iterations`` bisection steps (254 bounds each
  module's s by root finding; the conditions here are not monotone in s, hence the grid). Where no
  grid point satisfies every module, the modules no point satisfies are left out (254's "override
  steering": they decouple from ξ(s)), and failing that the point satisfying the most is taken.
  The commands are then clipped: every steering step into its window, every wheel speed into
  the φ̇, φ̈ limits. So no command ever exceeds |β̇| ≤ β̇_max, |β̈| ≤ β̈_max, |φ̇| ≤ φ̇_max,
  |φ̈| ≤ φ̈_max (:func:`control.limits.limit_violations`), whatever the targets.
* **Flips.** The chassis stops first (target 0, headings held), when some module moves faster than
  ``slip_speed`` and either every module, aligned, would turn its velocity by more than 90° along
  s (254's rule), or, with steering stops, some aligned module's heading would go past its stop by
  more than ``stop_hysteresis`` and slip more than ``slip_speed`` if held there (AZIMUT's ±90°: the
  module must turn the other way round, which it can only do with its wheel at rest). Stopped,
  the modules turn toward their targets' axes (the nearer representative with unlimited steering,
  which never crosses a stop) while the chassis waits or crawls, then it accelerates again.
* **Zero command** (every component within ``zero_twist``, PathPlannerLib's 1e-6): the target is 0
  and the headings are held; the chassis decelerates.
* **Desaturation.** The target is scaled so its wheel speeds (with the offset term) are within
  φ̇_max, as ``desaturateWheelSpeeds`` does in both sources.

Unlike ``twist`` (:mod:`control.twist.wpilib`: a slew-rate limiter on the twist and WPILib's module
states sent as they are), every command here is within the actuator limits, and the modules stay
on the chassis motion up to the slip tolerance, except where the override decouples them. The
commanded mode is :class:`~control.icr.config.Mode` STOPPING during a stop-first, RECONFIGURING
while the target is not zero and every module's setpoint speed is below the deadband (the modules
turn in place), RUNNING otherwise; ``events`` counts the stop-first sequences.

:class:`SetpointController` is the reference (NumPy, one robot); :class:`SetpointBatch` steps N
robots in one compiled call (:mod:`control.twist.setpoint_compiled`), bit for bit the reference's
(``atan2``/``hypot`` the C library's on both sides, :mod:`estimation.libm`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from azimut_env.validation import check_fields, check_positive_fields
from control.commands import WheelCommand
from control.icr.config import Mode
from control.twist.base import TwistBatchBase, TwistControllerBase
from control.twist.wpilib import discretize_twist
from estimation.libm import atan2, hypot

__all__ = ["SetpointConfig", "SetpointController", "SetpointBatch", "braking_step", "TOL"]

#: relative slack of the feasibility tests of s (the final clips are exact)
TOL = 1e-9


@dataclass(frozen=True)
class SetpointConfig:
    """Options of the setpoint generator (see the module docstring).

    Attributes:
        discretize: apply ``ChassisSpeeds.discretize`` to the target (PathPlannerLib's generator
            discretizes too).
        cosine_compensation: scale each wheel speed by cos(β_c − β_measured).
        offset_correction: the contact point's speed r φ̇ = v(A)·w − ω b.
        speed_deadband: module speed [m/s] below which a module counts as stopped (its heading
            free, held or turned in place).
        slip_speed: largest sideways slip speed [m/s] of a module whose steering lags the direction
            of its velocity (|v_k| sin(lag)) for s to count as feasible; above ``speed_deadband``,
            so that a module whose speed is just past the deadband never holds the chassis.
        stop_hysteresis: with steering stops, a module whose heading would go past its stop by
            less than this [rad] stays at the stop (the chassis slows as its slip requires) instead
            of stopping the chassis to turn the other way round (the ICR controller's
            ``stop_hysteresis``, 6°).
        zero_twist: a target whose |v_x|, |v_y| [m/s] and |ω| [rad/s] are all within this is zero.
        steer_rate_scale, steer_accel_scale, wheel_accel_scale: fractions in ]0, 1] of the
            actuator limits β̇_max, β̈_max, φ̈_max the generator plans with.
        grid: grid points of the search for s (≥ 1).
        iterations: bisection steps refining s (≥ 0).
    """

    discretize: bool = True
    cosine_compensation: bool = True
    offset_correction: bool = True
    speed_deadband: float = 0.001
    slip_speed: float = 0.02
    zero_twist: float = 1e-6
    stop_hysteresis: float = math.radians(6.0)
    steer_rate_scale: float = 1.0
    steer_accel_scale: float = 1.0
    wheel_accel_scale: float = 1.0
    grid: int = 8
    iterations: int = 12

    def __post_init__(self) -> None:
        check_fields(self)
        check_positive_fields(self, "speed_deadband", "slip_speed", "zero_twist", "stop_hysteresis", allow_zero=True)
        if not self.slip_speed > self.speed_deadband:
            raise ValueError(f"SetpointConfig.slip_speed must exceed speed_deadband ({self.speed_deadband!r}), got "
                             f"{self.slip_speed!r}")
        for name in ("steer_rate_scale", "steer_accel_scale", "wheel_accel_scale"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 < v <= 1):
                raise ValueError(f"SetpointConfig.{name} must be in ]0, 1], got {v!r}")
        if not 1 <= self.grid <= 1000:
            raise ValueError(f"SetpointConfig.grid must be in 1..1000, got {self.grid!r}")
        if not 0 <= self.iterations <= 60:
            raise ValueError(f"SetpointConfig.iterations must be in 0..60, got {self.iterations!r}")


def braking_step(d, accel: float, dt: float) -> np.ndarray:
    """Largest steering step [rad] toward a goal ``d`` ≥ 0 away after which braking at ``accel``
    [rad/s²] still stops at the goal: d itself if d ≤ accel dt² (the rate d/dt can stop in the
    next period), else ω dt with d − ω dt = ω²/(2 accel)."""
    d = np.maximum(np.asarray(d, dtype=np.float64), 0.0)
    return np.where(d <= accel * dt * dt, d, accel * (np.sqrt(dt * dt + 2.0 * d / accel) - dt) * dt)


def _clip(x, lo, hi):
    return np.minimum(np.maximum(x, lo), hi)


class SetpointController(TwistControllerBase):
    """The setpoint generator for one robot, stateful (previous chassis setpoint ``twist``, previous
    commands, whether it is stopping first, its stop-first sequences since reset ``events``).

    Args:
        geom, limits, dt [s], config: see :class:`SetpointConfig`.
    """

    config_type = SetpointConfig

    def reset(self, beta=None, phidot=None) -> None:
        """Forget the history; start from measured angles (default 0) at rest."""
        super().reset(beta, phidot)
        self.stopping = False
        self.events = 0

    # -- the pieces of one step ---------------------------------------------------------------

    def _rep(self, beta):
        """The representative of each propulsion axis β (mod π) the module takes: the nearer to
        the previous command (unlimited steering), the one inside the stops (limited)."""
        g = self.geom
        if g.unlimited_steering:
            return self.beta + (np.mod(beta - self.beta + np.pi / 2, np.pi) - np.pi / 2)
        return g.steer_max - np.mod(g.steer_max - beta, np.pi)

    def _in_range(self, beta):
        g = self.geom
        if g.unlimited_steering:
            return np.ones(beta.shape, dtype=np.bool_)
        return (beta > g.steer_min) & (beta <= g.steer_max)

    def _prepare(self, t, hold: bool):
        """Per-module quantities of the segment from the setpoint to the target ``t`` (3,); with
        ``hold`` (a zero target) every module keeps its heading (braking if it turns)."""
        g, cfg, dt, c = self.geom, self.config, self.dt, self.twist
        db = cfg.speed_deadband
        x, y = g.axis_xy[:, 0], g.axis_xy[:, 1]
        p = {"hold": hold}
        p["v0x"], p["v0y"] = c[0] - c[2] * y, c[1] + c[2] * x
        v1x, v1y = t[0] - t[2] * y, t[1] + t[2] * x
        p["dvx"], p["dvy"] = v1x - p["v0x"], v1y - p["v0y"]
        p["c2"], p["dw"] = c[2], t[2] - c[2]
        n0, n1 = hypot(p["v0x"], p["v0y"]), hypot(v1x, v1y)
        dd = p["dvx"] * p["dvx"] + p["dvy"] * p["dvy"]
        with np.errstate(divide="ignore", invalid="ignore"):
            tm = np.where(dd > 0, _clip(-(p["v0x"] * p["dvx"] + p["v0y"] * p["dvy"]) / dd, 0.0, 1.0), 0.0)
        near = hypot(p["v0x"] + tm * p["dvx"], p["v0y"] + tm * p["dvy"]) < db
        moving, goal = n0 >= db, n1 >= db
        beta0 = np.where(moving, self._rep(atan2(p["v0y"], p["v0x"]) + np.pi / 2 - g.alpha), self.beta)
        theta1 = atan2(p["v0x"] * v1y - p["v0y"] * v1x, p["v0x"] * v1x + p["v0y"] * v1y)
        # a module more than 45° off its velocity's axis (turning toward a target while the chassis
        # crawls) heads straight for its target's axis instead of following the velocity round
        aligned = np.abs(beta0 - self.beta) <= np.pi / 4
        cont = moving & ~near & aligned
        beta_g = np.where(cont, beta0 + theta1, self._rep(atan2(v1y, v1x) + np.pi / 2 - g.alpha))
        d = beta_g - self.beta
        p.update(n0=n0, tm=tm, near=near, moving=moving, beta0=beta0, direct=~(moving & aligned))
        past = np.minimum(np.where(beta_g > g.steer_max, beta_g - g.steer_max, g.steer_min - beta_g), np.pi / 2)
        p["crossing"] = cont & goal & ~self._in_range(beta_g) & (past > cfg.stop_hysteresis) \
            & (n1 * np.sin(past) > cfg.slip_speed)
        p["flip"] = cont & goal & (np.abs(theta1) > np.pi / 2)
        # the steering window of this period, and the braking caps
        a, w = self.limits.steer_accel_max * cfg.steer_accel_scale, self.limits.steer_rate_max * cfg.steer_rate_scale
        lo = np.maximum(-w, self.rate - a * dt) * dt
        hi = np.minimum(w, self.rate + a * dt) * dt
        if g.unlimited_steering:
            sb_lo, sb_hi = np.full(g.n, -np.inf), np.full(g.n, np.inf)
        else:
            sb_lo, sb_hi = -braking_step(self.beta - g.steer_min, a, dt), braking_step(g.steer_max - self.beta, a, dt)
        gstep = np.where(goal, np.where(d >= 0, braking_step(d, a, dt), -braking_step(-d, a, dt)), 0.0)
        capped = moving & goal
        gb_lo = np.where(capped & (d < 0), gstep, -np.inf)
        gb_hi = np.where(capped & (d >= 0), gstep, np.inf)
        p.update(lo=lo, hi=hi, b_lo=np.maximum(sb_lo, gb_lo), b_hi=np.minimum(sb_hi, gb_hi))
        p["free"] = _clip(_clip(gstep, sb_lo, sb_hi), lo, hi)
        return p

    def _phidot(self, p, s, vx, vy, delta, now):
        g, cfg = self.geom, self.config
        beta = self.beta + delta
        gamma = g.alpha + beta
        ph = vx * np.sin(gamma) - vy * np.cos(gamma)
        if cfg.offset_correction:
            ph = ph - (p["c2"] + s * p["dw"]) * g.b
        ph = ph / g.r
        if cfg.cosine_compensation:
            ph = ph * np.cos(beta - now)
        return ph

    def _eval(self, p, s, now):
        """At s: (ok, Δ, |v|, vx, vy) of every module: Δ its steering step (toward its angle at s,
        within its window), ok: its conditions hold."""
        g, cfg, dt = self.geom, self.config, self.dt
        db = cfg.speed_deadband
        vx, vy = p["v0x"] + s * p["dvx"], p["v0y"] + s * p["dvy"]
        nv = hypot(vx, vy)
        free = (nv < db) | p["hold"]
        rep_mode = p["direct"] | (p["near"] & (s >= p["tm"]))
        beta_rep = self._rep(atan2(vy, vx) + np.pi / 2 - g.alpha)
        beta_cont = p["beta0"] + atan2(p["v0x"] * vy - p["v0y"] * vx, p["v0x"] * vx + p["v0y"] * vy)
        beta_s = np.where(rep_mode, beta_rep, beta_cont)
        want = beta_s - self.beta
        step = _clip(_clip(want, p["b_lo"], p["b_hi"]), p["lo"], p["hi"])
        lag = np.minimum(np.abs(want - step), np.pi / 2)
        delta = np.where(free, p["free"], step)
        ok = free | (nv * np.sin(lag) <= cfg.slip_speed)
        ph = self._phidot(p, s, vx, vy, delta, now)
        aw = self.limits.wheel_accel_max * cfg.wheel_accel_scale
        ok = ok & (np.abs(ph) <= self.limits.wheel_speed_max * (1.0 + TOL)) \
            & (np.abs(ph - self.phidot) <= aw * dt * (1.0 + TOL))
        return ok, delta, nv, vx, vy

    def _search(self, p, table, mask, now) -> float:
        """The largest feasible s for the modules of ``mask`` (-1.0 if no grid point is)."""
        G = self.config.grid
        for j in range(G - 1, -1, -1):
            if np.all(table[j] | ~mask):
                lo, hi = j / G, (j + 1) / G
                for _ in range(self.config.iterations):
                    mid = 0.5 * (lo + hi)
                    if np.all(self._eval(p, mid, now)[0] | ~mask):
                        lo = mid
                    else:
                        hi = mid
                return lo
        return -1.0

    def _choose_s(self, p, now) -> float:
        ok1 = self._eval(p, 1.0, now)[0]
        if np.all(ok1):
            return 1.0
        G = self.config.grid
        table = np.array([self._eval(p, j / G, now)[0] for j in range(G)] + [ok1])
        s = self._search(p, table, np.ones(self.geom.n, dtype=np.bool_), now)
        if s < 0:
            s = self._search(p, table, np.any(table, axis=0), now)
        if s < 0:
            counts = np.sum(table, axis=1)
            s = int(np.flatnonzero(counts == counts.max())[-1]) / G
        return s

    def step(self, twist, beta_meas) -> WheelCommand:
        """Set-points for the chassis-frame twist target (v_x, v_y, ω) given measured β (n,)."""
        g, cfg, dt = self.geom, self.config, self.dt
        twist, now = self._step_inputs(twist, beta_meas)
        t = discretize_twist(twist, dt) if cfg.discretize else twist.copy()
        # desaturate the target: its wheel speeds within φ̇_max
        vx, vy = t[0] - t[2] * g.axis_xy[:, 1], t[1] + t[2] * g.axis_xy[:, 0]
        beta1 = np.where(hypot(vx, vy) >= cfg.speed_deadband, self._rep(atan2(vy, vx) + np.pi / 2 - g.alpha),
                         self.beta)
        gamma = g.alpha + beta1
        ph = vx * np.sin(gamma) - vy * np.cos(gamma)
        if cfg.offset_correction:
            ph = ph - t[2] * g.b
        top = float(np.max(np.abs(ph / g.r)))
        if top > self.limits.wheel_speed_max:
            t = t * (self.limits.wheel_speed_max / top)
        zero = bool(np.all(np.abs(t) <= cfg.zero_twist))
        if zero:
            t = np.zeros(3)
        p = self._prepare(t, zero)
        stop = (not zero) and bool(np.any(p["n0"] > cfg.slip_speed)) \
            and bool(np.any(p["crossing"]) or np.all(p["flip"]))
        if stop:  # stop first (254's recursion with a zero target)
            t = np.zeros(3)
            p = self._prepare(t, True)
        s = self._choose_s(p, now)
        ok, delta, nv, vx, vy = self._eval(p, s, now)
        phidot = self._phidot(p, s, vx, vy, delta, now)
        aw = self.limits.wheel_accel_max * cfg.wheel_accel_scale
        phidot = _clip(phidot, self.phidot - aw * dt, self.phidot + aw * dt)
        phidot = _clip(phidot, -self.limits.wheel_speed_max, self.limits.wheel_speed_max)
        c = self.twist
        self.twist = np.array([c[0] + s * (t[0] - c[0]), c[1] + s * (t[1] - c[1]), c[2] + s * (t[2] - c[2])])
        beta = self.beta + delta
        rate = (beta - self.beta) / dt
        if stop and not self.stopping:
            self.events += 1
        self.stopping = stop
        mode = Mode.STOPPING if stop else (Mode.RECONFIGURING if (not zero and np.all(nv < cfg.speed_deadband))
                                           else Mode.RUNNING)
        return self._command(beta, rate, phidot, info={"twist": self.twist.copy(), "s": s, "stop": stop,
                                                       "decoupled": ~ok, "mode": int(mode), "events": self.events})


class SetpointBatch(TwistBatchBase):
    """N setpoint generators stepped by row in one compiled call
    (:func:`control.twist.setpoint_compiled.setpoint_step_kernel`, :meth:`SetpointController.step`
    of each robot, bit for bit), with the commands in (M, n) arrays; per robot, ``twist`` (N, 3) is
    its chassis setpoint, ``stopping`` (N,) whether it is stopping first, ``events`` (N,) its
    stop-first sequences since reset.

    Args:
        num: robots N; geom, limits, dt [s], config: as :class:`SetpointController`; num_threads:
            threads of the compiled step (None: the cores this process may use; any count gives
            the same bits).
    """

    config_type = SetpointConfig

    def _setup(self, cfg: SetpointConfig) -> None:
        limits = self.limits
        self._flags = np.array([cfg.discretize, cfg.offset_correction, cfg.cosine_compensation], dtype=np.bool_)
        self._params = np.array([cfg.speed_deadband, cfg.zero_twist,
                                 limits.steer_rate_max * cfg.steer_rate_scale,
                                 limits.steer_accel_max * cfg.steer_accel_scale, limits.wheel_speed_max,
                                 limits.wheel_accel_max * cfg.wheel_accel_scale, cfg.slip_speed,
                                 cfg.stop_hysteresis])
        self._search = np.array([cfg.grid, cfg.iterations], dtype=np.int64)
        self.stopping = np.zeros(self.num, dtype=np.bool_)
        self.events = np.zeros(self.num, dtype=np.int64)

    def reset(self, rows, beta, phidot) -> None:
        """Restart the robots ``rows`` from their measured β, φ̇ (M, n), at rest (as
        :meth:`SetpointController.reset`)."""
        rows = np.asarray(rows, dtype=np.intp)
        super().reset(rows, beta, phidot)
        self.stopping[rows] = False
        self.events[rows] = 0

    def step(self, rows, twists, beta_meas) -> WheelCommand:
        """Set-points of the robots ``rows`` (None: all) for their chassis-frame twist targets
        (M, 3) given their measured β (M, n); ``info``: ``twist`` (M, 3) the new chassis
        setpoints, ``s`` (M,), ``stop`` (M,) bool, ``decoupled`` (M, n) bool."""
        from control.twist.setpoint_compiled import SETPOINT_STEP

        idx, twists, beta_meas = self._step_inputs(rows, twists, beta_meas)
        g, M = self.geom, idx.size
        out = np.empty((5, M, g.n))
        twist_out, s_out = np.empty((M, 3)), np.empty(M)
        mode, stop = np.empty(M, dtype=np.int64), np.empty(M, dtype=np.bool_)
        decoupled = np.empty((M, g.n), dtype=np.bool_)
        self._run(SETPOINT_STEP, idx, twists, beta_meas, self.twist, self.beta, self.rate, self.phidot, self.stopping,
                  self.events, self._flags, self._params, self._search, g.alpha, g.axis_xy, g.b, g.r,
                  float(g.steer_min), float(g.steer_max), bool(g.unlimited_steering), self.dt, out[0], out[1], out[2],
                  out[3], out[4], twist_out, s_out, mode, stop, decoupled)
        return self._command(out, mode=mode, events=self.events[idx].copy(),
                             info={"twist": twist_out, "s": s_out, "stop": stop, "decoupled": decoupled})
