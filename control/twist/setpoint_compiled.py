"""The setpoint generator's step (``twist-setpoint``) for N robots in one numba call.

:func:`setpoint_step_kernel` is :meth:`control.twist.setpoint.SetpointController.step` (the NumPy
reference, one robot, where every formula is explained) row by row, with the same operations in the
same order (``atan2`` and ``hypot`` the C library's on both sides), so
:class:`~control.twist.setpoint.SetpointBatch` gives every robot the reference's commands bit for
bit (``tests/control/test_twist_setpoint.py``).

Per robot the state is the chassis setpoint (3,), the last commands β, β̇, φ̇ (n,), whether it was
stopping first, and its stop-first count. ``flags``: discretize, offset_correction,
cosine_compensation; ``params``: speed_deadband, zero_twist, β̇_max, β̈_max, φ̇_max, φ̈_max (the
planned ones, scales applied), slip_speed, stop_hysteresis; ``search``: grid, iterations.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from control.twist.compiled import discretize_twist_kernel
from estimation.threads import BlockKernel

__all__ = ["setpoint_step_kernel", "SETPOINT_STEP"]

TOL = 1e-9  # control.twist.setpoint.TOL
# columns of the per-module table P
V0X, V0Y, DVX, DVY, N0, TM, BETA0, LO, HI, BLO, BHI, FREE = range(12)
# columns of the per-module flags F
NEAR, MOVING, CROSSING, FLIP, DIRECT = range(5)
RUNNING, STOPPING, RECONFIGURING = 0, 1, 2  # control.icr.config.Mode


@njit(cache=True)
def _brake(d, a, dt):
    d = max(d, 0.0)
    if d <= a * dt * dt:
        return d
    return a * (math.sqrt(dt * dt + 2.0 * d / a) - dt) * dt


@njit(cache=True)
def _rep(beta, ref, unlimited, steer_max):
    if unlimited:
        return ref + (np.mod(beta - ref + np.pi / 2, np.pi) - np.pi / 2)
    return steer_max - np.mod(steer_max - beta, np.pi)


@njit(cache=True)
def _in_range(beta, unlimited, steer_min, steer_max):
    return unlimited or (beta > steer_min and beta <= steer_max)


@njit(cache=True)
def _prepare(i, t, state_twist, state_beta, state_rate, params, alpha, axis_xy, steer_min, steer_max, unlimited, dt,
             P, F):
    db, w, a = params[0], params[2], params[3]
    c0, c1, c2 = state_twist[i, 0], state_twist[i, 1], state_twist[i, 2]
    for k in range(alpha.shape[0]):
        x, y, bp = axis_xy[k, 0], axis_xy[k, 1], state_beta[i, k]
        v0x, v0y = c0 - c2 * y, c1 + c2 * x
        v1x, v1y = t[0] - t[2] * y, t[1] + t[2] * x
        dvx, dvy = v1x - v0x, v1y - v0y
        n0, n1 = math.hypot(v0x, v0y), math.hypot(v1x, v1y)
        dd = dvx * dvx + dvy * dvy
        tm = 0.0
        if dd > 0:
            tm = min(max(-(v0x * dvx + v0y * dvy) / dd, 0.0), 1.0)
        near = math.hypot(v0x + tm * dvx, v0y + tm * dvy) < db
        moving, goal = n0 >= db, n1 >= db
        beta0 = bp
        if moving:
            beta0 = _rep(math.atan2(v0y, v0x) + np.pi / 2 - alpha[k], bp, unlimited, steer_max)
        theta1 = math.atan2(v0x * v1y - v0y * v1x, v0x * v1x + v0y * v1y)
        aligned = abs(beta0 - bp) <= np.pi / 4
        cont = moving and not near and aligned
        if cont:
            beta_g = beta0 + theta1
        else:
            beta_g = _rep(math.atan2(v1y, v1x) + np.pi / 2 - alpha[k], bp, unlimited, steer_max)
        d = beta_g - bp
        lo = max(-w, state_rate[i, k] - a * dt) * dt
        hi = min(w, state_rate[i, k] + a * dt) * dt
        if unlimited:
            sb_lo, sb_hi = -np.inf, np.inf
        else:
            sb_lo, sb_hi = -_brake(bp - steer_min, a, dt), _brake(steer_max - bp, a, dt)
        gstep = 0.0
        if goal:
            gstep = _brake(d, a, dt) if d >= 0 else -_brake(-d, a, dt)
        gb_lo = gstep if (moving and goal and d < 0) else -np.inf
        gb_hi = gstep if (moving and goal and d >= 0) else np.inf
        b_lo, b_hi = max(sb_lo, gb_lo), min(sb_hi, gb_hi)
        P[k, V0X], P[k, V0Y], P[k, DVX], P[k, DVY], P[k, N0], P[k, TM] = v0x, v0y, dvx, dvy, n0, tm
        P[k, BETA0], P[k, LO], P[k, HI], P[k, BLO], P[k, BHI] = beta0, lo, hi, b_lo, b_hi
        P[k, FREE] = min(max(min(max(gstep, sb_lo), sb_hi), lo), hi)
        F[k, NEAR], F[k, MOVING], F[k, DIRECT] = near, moving, not (moving and aligned)
        past = min(beta_g - steer_max if beta_g > steer_max else steer_min - beta_g, np.pi / 2)
        F[k, CROSSING] = (cont and goal and not _in_range(beta_g, unlimited, steer_min, steer_max)
                          and past > params[7] and n1 * math.sin(past) > params[6])
        F[k, FLIP] = cont and goal and abs(theta1) > np.pi / 2


@njit(cache=True)
def _phidot(k, s, vx, vy, delta, bp, now, c2, dw, flags, alpha, b, r):
    beta = bp + delta
    gamma = alpha[k] + beta
    ph = vx * math.sin(gamma) - vy * math.cos(gamma)
    if flags[1]:
        ph = ph - (c2 + s * dw) * b[k]
    ph = ph / r[k]
    if flags[2]:
        ph = ph * math.cos(beta - now)
    return ph


@njit(cache=True)
def _eval(k, s, P, F, bp, now, php, c2, dw, flags, params, alpha, b, r, steer_min, steer_max, unlimited, dt, hold):
    """Module k at s: (ok, Δ, |v|, vx, vy), as SetpointController._eval."""
    db = params[0]
    vx, vy = P[k, V0X] + s * P[k, DVX], P[k, V0Y] + s * P[k, DVY]
    nv = math.hypot(vx, vy)
    free = nv < db or hold
    if F[k, DIRECT] or (F[k, NEAR] and s >= P[k, TM]):
        beta_s = _rep(math.atan2(vy, vx) + np.pi / 2 - alpha[k], bp, unlimited, steer_max)
    else:
        v0x, v0y = P[k, V0X], P[k, V0Y]
        beta_s = P[k, BETA0] + math.atan2(v0x * vy - v0y * vx, v0x * vx + v0y * vy)
    want = beta_s - bp
    step = min(max(min(max(want, P[k, BLO]), P[k, BHI]), P[k, LO]), P[k, HI])
    lag = min(abs(want - step), np.pi / 2)
    delta = P[k, FREE] if free else step
    ok = free or nv * math.sin(lag) <= params[6]
    ph = _phidot(k, s, vx, vy, delta, bp, now, c2, dw, flags, alpha, b, r)
    ok = ok and abs(ph) <= params[4] * (1.0 + TOL) and abs(ph - php) <= params[5] * dt * (1.0 + TOL)
    return ok, delta, nv, vx, vy


@njit(cache=True)
def _all_ok(s, mask, P, F, i, now, state_beta, state_phidot, c2, dw, flags, params, alpha, b, r, steer_min, steer_max,
            unlimited, dt, hold):
    for k in range(alpha.shape[0]):
        if mask[k] and not _eval(k, s, P, F, state_beta[i, k], now[k], state_phidot[i, k], c2, dw, flags, params,
                                 alpha, b, r, steer_min, steer_max, unlimited, dt, hold)[0]:
            return False
    return True


@njit(cache=True)
def _search(table, mask, G, iters, P, F, i, now, state_beta, state_phidot, c2, dw, flags, params, alpha, b, r,
            steer_min, steer_max, unlimited, dt, hold):
    for j in range(G - 1, -1, -1):
        good = True
        for k in range(alpha.shape[0]):
            if mask[k] and not table[j, k]:
                good = False
        if good:
            lo, hi = j / G, (j + 1) / G
            for _ in range(iters):
                mid = 0.5 * (lo + hi)
                if _all_ok(mid, mask, P, F, i, now, state_beta, state_phidot, c2, dw, flags, params, alpha, b, r,
                           steer_min, steer_max, unlimited, dt, hold):
                    lo = mid
                else:
                    hi = mid
            return lo
    return -1.0


# One long function on purpose: one numba call per control step for all robots, no allocation,
# each robot's state kept in locals between the stages; split, it costs calls per robot or breaks
# bit-identity with the reference path.
@njit(cache=True)
def setpoint_step_kernel(rows, twists, beta_meas, state_twist, state_beta, state_rate, state_phidot, state_stop,
                         state_events, flags, params, search, alpha, axis_xy, b, r, steer_min, steer_max, unlimited,
                         dt, beta_out, phidot_out, rate_out, accel_out, phiddot_out, twist_out, s_out, mode_out,
                         stop_out, decoupled_out, lo, hi) -> None:
    """Step the robots ``rows[lo:hi]`` (a block of :class:`estimation.threads.BlockKernel`; the
    inputs checked finite before): twist targets (M, 3) and measured β (M, n) in, the state
    (N, …) updated in place, the commands (M, n), the chassis setpoints (M, 3), s, modes, stop
    flags (M,) and decoupled modules (M, n) out."""
    n = alpha.shape[0]
    db, zero_twist, phmax, aw = params[0], params[1], params[4], params[5]
    G, iters = search[0], search[1]
    P = np.empty((n, 12))
    F = np.empty((n, 5), dtype=np.bool_)
    table = np.empty((G + 1, n), dtype=np.bool_)
    mask = np.empty(n, dtype=np.bool_)
    now = np.empty(n)
    t = np.empty(3)
    for m in range(lo, hi):
        i = rows[m]
        for k in range(n):
            now[k] = beta_meas[m, k]
            if unlimited:  # the measured angle (in ]−π, π]) on the commands' turn
                now[k] = state_beta[i, k] + (np.mod(beta_meas[m, k] - state_beta[i, k] + np.pi, 2 * np.pi) - np.pi)
        if flags[0]:
            t[0], t[1], t[2] = discretize_twist_kernel(twists[m, 0], twists[m, 1], twists[m, 2], dt)
        else:
            t[0], t[1], t[2] = twists[m, 0], twists[m, 1], twists[m, 2]
        top = 0.0  # desaturate the target
        for k in range(n):
            vx, vy = t[0] - t[2] * axis_xy[k, 1], t[1] + t[2] * axis_xy[k, 0]
            beta1 = state_beta[i, k]
            if math.hypot(vx, vy) >= db:
                beta1 = _rep(math.atan2(vy, vx) + np.pi / 2 - alpha[k], state_beta[i, k], unlimited, steer_max)
            gamma = alpha[k] + beta1
            ph = vx * math.sin(gamma) - vy * math.cos(gamma)
            if flags[1]:
                ph = ph - t[2] * b[k]
            top = max(top, abs(ph / r[k]))
        if top > phmax:
            f = phmax / top
            t[0], t[1], t[2] = t[0] * f, t[1] * f, t[2] * f
        zero = abs(t[0]) <= zero_twist and abs(t[1]) <= zero_twist and abs(t[2]) <= zero_twist
        if zero:
            t[0], t[1], t[2] = 0.0, 0.0, 0.0
        _prepare(i, t, state_twist, state_beta, state_rate, params, alpha, axis_xy, steer_min, steer_max, unlimited,
                 dt, P, F)
        any_moving, any_crossing, all_flip = False, False, True
        for k in range(n):
            any_moving = any_moving or P[k, N0] > params[6]
            any_crossing = any_crossing or F[k, CROSSING]
            all_flip = all_flip and F[k, FLIP]
        stop = (not zero) and any_moving and (any_crossing or all_flip)
        if stop:  # stop first
            t[0], t[1], t[2] = 0.0, 0.0, 0.0
            _prepare(i, t, state_twist, state_beta, state_rate, params, alpha, axis_xy, steer_min, steer_max,
                     unlimited, dt, P, F)
        c2, dw = state_twist[i, 2], t[2] - state_twist[i, 2]
        hold = zero or stop
        # the largest s
        for k in range(n):
            mask[k] = True
        if _all_ok(1.0, mask, P, F, i, now, state_beta, state_phidot, c2, dw, flags, params, alpha, b, r, steer_min,
                   steer_max, unlimited, dt, hold):
            s = 1.0
        else:
            for j in range(G + 1):
                for k in range(n):
                    table[j, k] = _eval(k, j / G, P, F, state_beta[i, k], now[k], state_phidot[i, k], c2, dw, flags,
                                        params, alpha, b, r, steer_min, steer_max, unlimited, dt, hold)[0]
            s = _search(table, mask, G, iters, P, F, i, now, state_beta, state_phidot, c2, dw, flags, params, alpha,
                        b, r, steer_min, steer_max, unlimited, dt, hold)
            if s < 0:
                for k in range(n):
                    mask[k] = False
                    for j in range(G + 1):
                        mask[k] = mask[k] or table[j, k]
                s = _search(table, mask, G, iters, P, F, i, now, state_beta, state_phidot, c2, dw, flags, params,
                            alpha, b, r, steer_min, steer_max, unlimited, dt, hold)
            if s < 0:
                best, jbest = -1, 0
                for j in range(G + 1):
                    cnt = 0
                    for k in range(n):
                        cnt += table[j, k]
                    if cnt >= best:
                        best, jbest = cnt, j
                s = jbest / G
        # the commands at s
        at_rest = True
        for k in range(n):
            bp, php = state_beta[i, k], state_phidot[i, k]
            ok, delta, nv, vx, vy = _eval(k, s, P, F, bp, now[k], php, c2, dw, flags, params, alpha, b, r, steer_min,
                                          steer_max, unlimited, dt, hold)
            at_rest = at_rest and nv < db
            ph = _phidot(k, s, vx, vy, delta, bp, now[k], c2, dw, flags, alpha, b, r)
            ph = min(max(ph, php - aw * dt), php + aw * dt)
            ph = min(max(ph, -phmax), phmax)
            beta = bp + delta
            rate = (beta - bp) / dt
            beta_out[m, k], phidot_out[m, k], rate_out[m, k] = beta, ph, rate
            accel_out[m, k] = (rate - state_rate[i, k]) / dt
            phiddot_out[m, k] = (ph - php) / dt
            decoupled_out[m, k] = not ok
        for j in range(3):
            twist_out[m, j] = state_twist[i, j] + s * (t[j] - state_twist[i, j])
        if stop and not state_stop[i]:
            state_events[i] += 1
        state_stop[i] = stop
        if stop:
            mode_out[m] = STOPPING
        elif (not zero) and at_rest:
            mode_out[m] = RECONFIGURING
        else:
            mode_out[m] = RUNNING
        stop_out[m], s_out[m] = stop, s
        for j in range(3):
            state_twist[i, j] = twist_out[m, j]
        for k in range(n):
            state_beta[i, k] = beta_out[m, k]
            state_rate[i, k] = rate_out[m, k]
            state_phidot[i, k] = phidot_out[m, k]


#: the step over blocks of robots (a block: at least 4 robots; :class:`estimation.threads.BlockKernel`)
SETPOINT_STEP = BlockKernel(setpoint_step_kernel, min_rows=4)
