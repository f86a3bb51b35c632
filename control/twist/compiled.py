"""The WPILib-style twist baseline's step for N robots in one numba call.

:func:`swerve_step_kernel` is :meth:`control.twist.wpilib.SwerveController.step` (the NumPy
reference, one robot) row by row, with the same operations in the same order (``atan2`` and
``hypot`` the C library's on both sides), so :class:`~control.twist.wpilib.SwerveBatch`, which
calls it, gives every robot the reference's commands bit for bit
(``tests/control/test_twist_compiled.py``).

Per robot the state is the slew-limited twist of the last step (3,), and the last commands β, β̇,
φ̇ (n,); ``flags`` holds the options of :class:`~control.twist.wpilib.SwerveConfig` in the order
of :data:`FLAGS`. With unlimited steering (``RobotGeometry.unlimited_steering``) the measured
angle is first brought onto the commands' turn and there is no flip-back into a range.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimation.threads import BlockKernel

__all__ = ["swerve_step_kernel", "SWERVE_STEP", "FLAGS", "discretize_twist_kernel"]

#: the SwerveConfig booleans, in the order of the kernel's ``flags``
FLAGS = ("discretize", "optimize", "cosine_compensation", "desaturate", "offset_correction", "coupling")


@njit(cache=True, inline="always")
def discretize_twist_kernel(vx: float, vy: float, w: float, dt: float) -> tuple[float, float, float]:
    """WPILib's ``ChassisSpeeds.discretize``: the twist whose pose exponential over ``dt`` is the
    straight move (vx dt, vy dt) with the turn w dt (the twist baselines' ``discretize`` flag)."""
    x, y, th = vx * dt, vy * dt, w * dt
    half = 0.5 * th
    cos_m1 = math.cos(th) - 1.0
    if abs(cos_m1) < 1e-9:
        h = 1.0 - th * th / 12.0
    else:
        h = -(half * math.sin(th)) / cos_m1
    nrm = math.hypot(h, half)
    c, s = h / nrm, -half / nrm
    return (x * c - y * s) * nrm / dt, (x * s + y * c) * nrm / dt, th / dt


# One long function on purpose: one numba call per control step for all robots, no allocation,
# each robot's state kept in locals between the stages; split, it costs calls per robot or breaks
# bit-identity with the reference path.
@njit(cache=True)
def swerve_step_kernel(rows, twists, beta_meas, state_twist, state_beta, state_rate, state_phidot, slew, flags,
                       deadband, alpha, axis_xy, b, r, steer_min, steer_max, unlimited, wheel_speed_max, dt,
                       beta_out, phidot_out, rate_out, accel_out, phiddot_out, twist_out, lo, hi) -> None:
    """Step the robots ``rows[lo:hi]`` (a block of :class:`estimation.threads.BlockKernel`; the
    inputs checked finite before): twist targets (M, 3) and measured β (M, n) in, the state
    (N, …) updated in place, the commands (M, n) and the discretised twists (M, 3) out."""
    n = alpha.shape[0]
    heading = np.empty(n)
    speed = np.empty(n)
    for m in range(lo, hi):
        i = rows[m]
        prev = state_twist[i]
        # slew_limit_twist: the (v_x, v_y) vector by at most slew·dt, ω by at most slew_ω·dt
        dv0 = twists[m, 0] - prev[0]
        dv1 = twists[m, 1] - prev[1]
        norm = math.hypot(dv0, dv1)
        if norm > slew[0] * dt:
            f = slew[0] * dt / norm
            dv0 = dv0 * f
            dv1 = dv1 * f
        step_w = slew[2] * dt
        t0, t1 = prev[0] + dv0, prev[1] + dv1
        t2 = prev[2] + min(max(twists[m, 2] - prev[2], -step_w), step_w)
        state_twist[i, 0], state_twist[i, 1], state_twist[i, 2] = t0, t1, t2
        if flags[0]:
            k0, k1, k2 = discretize_twist_kernel(t0, t1, t2, dt)
        else:
            k0, k1, k2 = t0, t1, t2
        twist_out[m, 0], twist_out[m, 1], twist_out[m, 2] = k0, k1, k2
        for k in range(n):  # module_states, then the heading as β
            vx = k0 - k2 * axis_xy[k, 1]
            vy = k1 + k2 * axis_xy[k, 0]
            heading[k] = math.atan2(vy, vx)
            speed[k] = math.hypot(vx, vy)
        top = 0.0
        for k in range(n):
            hold = speed[k] < deadband
            bk = state_beta[i, k] if hold else heading[k] + np.pi / 2 - alpha[k]
            sp = speed[k]
            now = beta_meas[m, k]
            if unlimited:  # the measured angle (in ]−π, π]) on the commands' turn
                now = state_beta[i, k] + (np.mod(now - state_beta[i, k] + np.pi, 2 * np.pi) - np.pi)
            err = np.mod(bk - now + np.pi, 2 * np.pi) - np.pi  # optimize_module
            beta = now + err
            if flags[1] and abs(err) > np.pi / 2:
                beta = beta - np.sign(err) * np.pi
                sp = -sp
            while not unlimited and (beta > steer_max or beta <= steer_min):
                beta = beta - np.pi if beta > steer_max else beta + np.pi
                sp = -sp
            if hold:
                beta = state_beta[i, k]
            rphi = sp
            if flags[4]:
                rphi = rphi - k2 * b[k]
            if flags[2]:
                rphi = rphi * math.cos(beta - now)
            rate = (beta - state_beta[i, k]) / dt
            if flags[5]:
                rphi = rphi - b[k] * rate
            ph = rphi / r[k]
            beta_out[m, k], rate_out[m, k], phidot_out[m, k] = beta, rate, ph
            top = max(top, abs(ph))
        if flags[3] and top > wheel_speed_max:  # desaturate
            for k in range(n):
                phidot_out[m, k] = phidot_out[m, k] * (wheel_speed_max / top)
        for k in range(n):
            accel_out[m, k] = (rate_out[m, k] - state_rate[i, k]) / dt
            phiddot_out[m, k] = (phidot_out[m, k] - state_phidot[i, k]) / dt
            state_beta[i, k] = beta_out[m, k]
            state_rate[i, k] = rate_out[m, k]
            state_phidot[i, k] = phidot_out[m, k]


#: the step over blocks of robots (a block: at least 4 robots; :class:`estimation.threads.BlockKernel`)
SWERVE_STEP = BlockKernel(swerve_step_kernel, min_rows=4)
