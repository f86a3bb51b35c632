"""The twist-based baseline: a swerve controller in the style of WPILib's SwerveDriveKinematics.

This is what most swerve robots run, with WPILib's own remedies, so that a comparison with the ICR
controller is the one a swerve-drive user would make. Per control period, from a chassis twist
target ξ̇_d = (v_x, v_y, ω) (chassis frame; the same path follower feeds both controllers):

1. a slew-rate limiter on the twist (what teams put on their inputs; on the (v_x, v_y) vector, so
   that braking keeps the direction of travel);
2. ``ChassisSpeeds.discretize``: the twist that moves along an arc to where the constant twist
   would be after one period (the fix for "skew when translating while rotating");
3. ``toSwerveModuleStates``: per-module inverse kinematics at the steering axis A_k,
   v_k = (v_x − ω y_k, v_y + ω x_k); heading = atan2(v_k), speed = ‖v_k‖; a module whose speed is
   below ``speed_deadband`` keeps its previous heading (WPILib keeps headings for a zero twist;
   teams extend it to near-zero speeds);
4. ``desaturateWheelSpeeds``: all speeds scaled so the fastest is within φ̇_max;
5. ``SwerveModuleState.optimize``: if the heading error to the measured angle exceeds 90°, turn
   the other way (heading + π) and negate the speed. With AZIMUT's hard stops the steering range
   is ]−π/2, π/2], one representative only: a heading outside it is flipped back into it. With
   unlimited steering (``RobotGeometry.unlimited_steering``, swerve modules) there is no flip-back:
   the module takes the nearer of β and β + π, as WPILib's does, its angle continuing past ±π;
6. cosine compensation: speed ·= cos(heading error to the measured angle).

Mapping to this robot (conventions of ``estimation.kinematics``): the wheel rolls toward
(sin γ, −cos γ), γ = α + β, so a module heading ψ is β = ψ + π/2 − α. Because the contact point
is b_k off the steering axis along the propulsion axis, its speed differs from A_k's by ω b_k:
r φ̇ = v(A_k)·d − ω b_k (``offset_correction``, on by default: it is the exact static inverse
kinematics and only helps the baseline). The steer-to-drive coupling −b β̇ is an ICR-controller
feature (WPILib modules are coaxial); it can be turned on with ``coupling=True``.

``atan2`` and ``hypot`` are the C library's (:mod:`estimation.libm`), so that
:class:`SwerveController` (the reference, one robot) and the compiled step of :class:`SwerveBatch`
(:mod:`control.twist.compiled`) give the same bits on every CPU.

The baseline sends these set-points as they are: WPILib does not rate-limit module angles (the
motor controllers do). Steps where the set-points change faster than the actuator limits are
counted by the evaluation as commanded-limit violations; the env's motors saturate them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from azimut_env.validation import check_fields, check_positive_fields
from control.commands import WheelCommand
from control.limits import ActuatorLimits
from control.twist.base import TwistBatchBase, TwistControllerBase
from estimation.geometry import RobotGeometry
from estimation.libm import atan2, hypot

__all__ = ["SwerveConfig", "SwerveController", "SwerveBatch", "discretize_twist", "module_states", "optimize_module",
           "desaturate", "slew_limit", "slew_limit_twist"]


@dataclass(frozen=True)
class SwerveConfig:
    """Options of the swerve baseline (defaults: WPILib's behaviour with its remedies on).

    Attributes:
        discretize: apply ``ChassisSpeeds.discretize``.
        optimize: apply ``SwerveModuleState.optimize`` (flip past 90°).
        cosine_compensation: scale speed by cos(heading error).
        desaturate: apply ``desaturateWheelSpeeds`` at φ̇_max.
        speed_deadband: module speed [m/s] below which the heading is held.
        slew_linear: slew-rate limit on v_x and v_y [m/s²]; None derives it from the wheel
            acceleration limit (0.7 r φ̈_max, as the ICR controller's μ ramp).
        slew_angular: slew-rate limit on ω [rad/s²]; None derives it as slew_linear / max l_k.
        offset_correction: the contact point's speed r φ̇ = v(A)·d − ω b (see module docstring).
        coupling: add the sidewise wheel's −b β̇ / r (not WPILib; off by default).
    """

    discretize: bool = True
    optimize: bool = True
    cosine_compensation: bool = True
    desaturate: bool = True
    speed_deadband: float = 0.01
    slew_linear: float | None = None
    slew_angular: float | None = None
    offset_correction: bool = True
    coupling: bool = False

    def __post_init__(self) -> None:
        check_fields(self)  # the bools included
        check_positive_fields(self, "speed_deadband", allow_zero=True)
        for name in ("slew_linear", "slew_angular"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ValueError(f"SwerveConfig.{name} must be None or finite and > 0, got {v!r}")


def slew_limit(value, previous, rate, dt: float) -> np.ndarray:
    """WPILib ``SlewRateLimiter``: move from ``previous`` toward ``value`` by at most rate·dt."""
    value, previous = np.asarray(value, dtype=np.float64), np.asarray(previous, dtype=np.float64)
    step = np.asarray(rate, dtype=np.float64) * dt
    return previous + np.clip(value - previous, -step, step)


def slew_limit_twist(twist, previous, linear: float, angular: float, dt: float) -> np.ndarray:
    """Slew-rate limit on a twist: the (v_x, v_y) vector changes by at most ``linear``·dt (so the
    direction of travel is kept while braking, unlike per-axis limiters, which swing the modules
    when the robot stops), ω by at most ``angular``·dt."""
    twist, previous = np.asarray(twist, dtype=np.float64), np.asarray(previous, dtype=np.float64)
    dv = twist[:2] - previous[:2]
    norm = float(hypot(dv[0], dv[1]))
    if norm > linear * dt:
        dv *= linear * dt / norm
    return np.array([previous[0] + dv[0], previous[1] + dv[1],
                     float(slew_limit(twist[2], previous[2], angular, dt))])


def discretize_twist(twist, dt: float) -> np.ndarray:
    """WPILib ``ChassisSpeeds.discretize``: the twist whose exponential over dt ends at the pose
    (v_x dt, v_y dt, ω dt), i.e. ``Pose2d(...).log() / dt``. Batched over leading axes."""
    tw = np.asarray(twist, dtype=np.float64)
    x, y, th = tw[..., 0] * dt, tw[..., 1] * dt, tw[..., 2] * dt
    half = 0.5 * th
    cos_m1 = np.cos(th) - 1.0
    small = np.abs(cos_m1) < 1e-9
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.where(small, 1.0 - th * th / 12.0, -(half * np.sin(th)) / np.where(small, 1.0, cos_m1))
    # translation rotated by Rotation2d(h, −half) and scaled by hypot(h, half) (WPILib Pose2d.log)
    nrm = hypot(h, half)
    c, s = h / nrm, -half / nrm
    tx = (x * c - y * s) * nrm
    ty = (x * s + y * c) * nrm
    return np.stack([tx / dt, ty / dt, th / dt], axis=-1)


def module_states(twist, geom: RobotGeometry) -> tuple[np.ndarray, np.ndarray]:
    """WPILib ``toSwerveModuleStates`` at the steering axes: (heading ψ_k [rad], speed [m/s]), (n,)
    each, with v_k = (v_x − ω y_k, v_y + ω x_k)."""
    tw = np.asarray(twist, dtype=np.float64)
    vx = tw[0] - tw[2] * geom.axis_xy[:, 1]
    vy = tw[1] + tw[2] * geom.axis_xy[:, 0]
    return atan2(vy, vx), hypot(vx, vy)


def optimize_module(beta_des, speed, beta_now, geom: RobotGeometry, enabled: bool = True):
    """WPILib ``optimize`` in β: flip by π and negate the speed if the error exceeds π/2; then
    keep β inside the steering range (hard stops): flip back if it left (not with unlimited
    steering: β is then within π/2 of ``beta_now``, any real). Returns (β, speed)."""
    beta_des = np.asarray(beta_des, dtype=np.float64)
    speed = np.asarray(speed, dtype=np.float64).copy()
    err = np.mod(beta_des - beta_now + np.pi, 2 * np.pi) - np.pi
    beta = beta_now + err
    if enabled:
        flip = np.abs(err) > np.pi / 2
        beta = np.where(flip, beta - np.sign(err) * np.pi, beta)
        speed = np.where(flip, -speed, speed)
    if geom.unlimited_steering:
        return beta, speed
    out_hi, out_lo = beta > geom.steer_max, beta <= geom.steer_min
    while np.any(out_hi | out_lo):
        beta = np.where(out_hi, beta - np.pi, np.where(out_lo, beta + np.pi, beta))
        speed = np.where(out_hi | out_lo, -speed, speed)
        out_hi, out_lo = beta > geom.steer_max, beta <= geom.steer_min
    return beta, speed


def desaturate(phidot, max_speed: float) -> np.ndarray:
    """WPILib ``desaturateWheelSpeeds``: scale all so that max |φ̇| ≤ max_speed."""
    phidot = np.asarray(phidot, dtype=np.float64)
    m = float(np.max(np.abs(phidot)))
    return phidot * (max_speed / m) if m > max_speed else phidot


class SwerveController(TwistControllerBase):
    """The baseline, stateful (previous twist for the slew limiter, previous commands).

    Args:
        geom, limits, dt [s], config: see :class:`SwerveConfig`.
    """

    config_type = SwerveConfig

    def __init__(self, geom: RobotGeometry, limits: ActuatorLimits, dt: float = 0.02,
                 config: SwerveConfig | None = None) -> None:
        super().__init__(geom, limits, dt, config)
        lin = self.config.slew_linear or 0.7 * limits.wheel_accel_max * float(np.min(geom.r))
        ang = self.config.slew_angular or lin / float(np.max(geom.l))
        self._slew = np.array([lin, lin, ang])

    def step(self, twist, beta_meas) -> WheelCommand:
        """Set-points for the chassis-frame twist target (v_x, v_y, ω) given measured β (n,)."""
        g, cfg, dt = self.geom, self.config, self.dt
        twist, beta_meas = self._step_inputs(twist, beta_meas)
        tw = slew_limit_twist(twist, self.twist, self._slew[0], self._slew[2], dt)
        self.twist = tw
        tw_k = discretize_twist(tw, dt) if cfg.discretize else tw
        heading, speed = module_states(tw_k, g)
        beta_des = heading + np.pi / 2 - g.alpha
        hold = speed < cfg.speed_deadband
        beta_des = np.where(hold, self.beta, beta_des)
        beta, speed = optimize_module(beta_des, speed, beta_meas, g, cfg.optimize)
        beta = np.where(hold, self.beta, beta)
        rphi = speed.copy()
        if cfg.offset_correction:
            rphi = rphi - tw_k[2] * g.b
        if cfg.cosine_compensation:
            rphi = rphi * np.cos(beta - beta_meas)
        rate = (beta - self.beta) / dt
        if cfg.coupling:
            rphi = rphi - g.b * rate
        phidot = rphi / g.r
        if cfg.desaturate:
            phidot = desaturate(phidot, self.limits.wheel_speed_max)
        return self._command(beta, rate, phidot, info={"twist": tw_k})


class SwerveBatch(TwistBatchBase):
    """N baselines stepped by row in one compiled call (:func:`control.twist.compiled.swerve_step_kernel`,
    :meth:`SwerveController.step` of each robot, bit for bit), with the commands in (M, n) arrays;
    ``twist`` (N, 3) is each robot's slew-limited twist.

    Args:
        num: robots N; geom, limits, dt [s], config: as :class:`SwerveController`; num_threads:
            threads of the compiled step (None: the cores this process may use; any count gives
            the same bits).
    """

    config_type = SwerveConfig

    def _setup(self, cfg: SwerveConfig) -> None:
        from control.twist.compiled import FLAGS

        self._flags = np.array([getattr(cfg, name) for name in FLAGS], dtype=np.bool_)
        self._slew = SwerveController(self.geom, self.limits, self.dt, cfg)._slew
        self._deadband = float(cfg.speed_deadband)

    def step(self, rows, twists, beta_meas) -> WheelCommand:
        """Set-points of the robots ``rows`` (None: all) for their chassis-frame twist targets
        (M, 3) given their measured β (M, n); ``info["twist"]`` (M, 3) the discretised twists."""
        from control.twist.compiled import SWERVE_STEP

        idx, twists, beta_meas = self._step_inputs(rows, twists, beta_meas)
        g, M = self.geom, idx.size
        out = np.empty((5, M, g.n))
        twist_out = np.empty((M, 3))
        self._run(SWERVE_STEP, idx, twists, beta_meas, self.twist, self.beta, self.rate, self.phidot, self._slew,
                  self._flags, self._deadband, g.alpha, g.axis_xy, g.b, g.r, float(g.steer_min), float(g.steer_max),
                  bool(g.unlimited_steering), float(self.limits.wheel_speed_max), self.dt, out[0], out[1], out[2],
                  out[3], out[4], twist_out)
        return self._command(out, info={"twist": twist_out})
