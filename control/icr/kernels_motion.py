"""The ICR controller's motion primitives compiled, one robot at a time: the numba twins of
:func:`control.icr.motion.coordinated_step` (with :func:`~control.icr.motion.mu_own_step`) and
:func:`control.icr.motion.reconfigure_step`, with the same operations in the same order (see
:mod:`control.icr.kernels`). The step that calls them is :mod:`control.icr.compiled`.

One difference in how, not in what: the time scaling tries κ from 1 down and stops at the first
feasible one, the largest (the NumPy version evaluates the whole grid and takes the last feasible
one: the same κ); when none is, it takes the smallest limit ratio, the lowest κ among equals
(NumPy's ``argmin``), and a candidate stops being computed once its wheels so far exceed both
the feasibility bound and the best ratio found (:func:`kappa_ratio`); the chosen candidate is then
computed in full (:func:`kappa_candidate`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from control.icr.kernels import (
    C_K_LAMBDA,
    C_MU_OWN,
    L_ACCEL_LAM,
    L_CO_C1,
    L_CO_C2,
    L_CO_C3,
    L_MU_ACCEL,
    L_NEG_WSM_SLACK,
    L_RC_A,
    L_RC_BRAKE,
    L_RC_C1,
    L_RC_C2,
    L_RC_C3,
    L_RC_VMAX,
    L_SAM,
    L_SRM,
    L_STEER_LO,
    L_UNLIMITED,
    L_WA_DT_SLACK,
    L_WAM,
    L_WSM,
    L_WSM_SLACK,
    dot3,
    gradient_norm_max,
    nearest1,
    norm3,
    safe_stop_speed1,
    saturate_row,
    speed_coefs_row,
    sphere_angle3,
    steering_row,
    stop_room1,
    unit3,
)
from estimation.kinematics import SINGULAR_TOL, _beta_wheel, _speed_coef

__all__ = ["coordinated_row", "reconfigure_row", "kappa_candidate", "kappa_ratio", "mu_own_row"]


@njit(cache=True)
def reconfigure_row(beta0, rate0, phidot0, target, exact, measured_rate, use_measured, b, r, steer_min, steer_max, lim,
                 dt, beta_out, rate_out, phidot_out) -> None:
    """:func:`control.icr.motion.reconfigure_step` of one robot."""
    n = beta0.shape[0]
    want_phidot = np.empty(n)
    for k in range(n):
        err = target[k] - beta0[k]
        vstop = lim[L_RC_C1] + math.sqrt(lim[L_RC_C2] + lim[L_RC_C3] * abs(err))
        want = np.sign(err) * min(lim[L_RC_VMAX], min(vstop, abs(err) / dt))
        braking = (want * rate0[k] < 0) or (abs(want) < abs(rate0[k]) - 1e-12)
        a_step = (lim[L_RC_BRAKE] if braking else lim[L_RC_A]) * dt
        rate = min(max(want, rate0[k] - a_step), rate0[k] + a_step)
        if exact:
            rate = err / dt
        beta = beta0[k] + rate * dt
        if lim[L_UNLIMITED] == 0.0:
            beta = min(max(beta, lim[L_STEER_LO]), steer_max)
        rate = (beta - beta0[k]) / dt
        beta_out[k] = beta
        rate_out[k] = rate
        want_phidot[k] = -b[k] * (measured_rate[k] if use_measured else rate) / r[k]
    sat_beta, sat_rate = np.empty(n), np.empty(n)
    saturate_row(beta0, rate0, phidot0, beta_out, want_phidot, steer_min, steer_max, lim, dt, sat_beta, sat_rate,
                 phidot_out)


@njit(cache=True)
def kappa_candidate(q, kappa, lam, mu, mu_des, mu_first, v_prev, v_des, beta, beta_rate, phidot, E, P, b, r,
                     steer_min, steer_max, lim, dt, lam_new, v, beta_new, b_rate, phid, c) -> tuple[float, float, bool]:
    """One κ of :func:`control.icr.motion.coordinated_step`: the candidate (λ, λ̇, β, β̇, φ̇, c
    written into the arrays) and (μ, its limit ratio, flipped)."""
    n = beta.shape[0]
    kq = kappa[q]
    vd = np.empty(3)
    for j in range(3):
        v[j] = v_prev[j] + kq * (v_des[j] - v_prev[j])
        vd[j] = v[j] * dt
    nv = norm3(vd)
    safe = nv if nv > 0 else 1.0
    cn, sn = math.cos(nv), math.sin(nv)
    for j in range(3):
        lam_new[j] = cn * lam[j] + sn * vd[j] / safe
    unit3(lam_new, lam_new)
    mu_new = mu_des if mu_first else mu + kq * (mu_des - mu)
    steering_row(lam_new, E, P, steer_max, beta, True, beta_new, vd)
    unlimited = lim[L_UNLIMITED] != 0.0
    if unlimited:  # each wheel's axis at the angle nearest its command: never a flip
        for k in range(n):
            beta_new[k] = nearest1(beta_new[k], beta[k], True)
    speed_coefs_row(lam_new, beta_new, True, E, P, b, steer_max, c, vd, c)
    flipped = False
    ratio = 0.0
    for k in range(n):
        db = beta_new[k] - beta[k]
        flipped = flipped or abs(db) > np.pi / 2
        br = db / dt
        b_rate[k] = br
        ba = (br - beta_rate[k]) / dt
        ph = (mu_new * c[k] - b[k] * br) / r[k]
        phid[k] = ph
        phdd = (ph - phidot[k]) / dt
        room = stop_room1(beta_new[k], br, steer_min, steer_max, unlimited)
        v_stop = safe_stop_speed1(room, lim[L_CO_C1], lim[L_CO_C2], lim[L_CO_C3])
        ratio = max(ratio, abs(br) / lim[L_SRM], abs(ba) / lim[L_SAM], abs(ph) / lim[L_WSM], abs(phdd) / lim[L_WAM],
                    abs(br) / max(v_stop, 1e-12))
    return mu_new, (np.inf if flipped else ratio), flipped


@njit(cache=True)
def kappa_ratio(q, kappa, lam, v_prev, v_des, mu, mu_des, mu_first, beta, beta_rate, phidot, E, P, b, r, steer_min,
                steer_max, lim, dt, threshold, u) -> float:
    """The limit ratio of :func:`kappa_candidate`'s candidate q (inf where a wheel flips), or,
    as soon as the wheels seen so far put it above ``threshold``, that partial maximum (a lower
    bound above the threshold: the candidate is neither feasible nor a better fallback, and the
    other wheels need not be computed). The same arithmetic as :func:`kappa_candidate`."""
    kq = kappa[q]
    vd = np.empty(3)
    for j in range(3):
        vd[j] = (v_prev[j] + kq * (v_des[j] - v_prev[j])) * dt
    nv = norm3(vd)
    safe = nv if nv > 0 else 1.0
    cn, sn = math.cos(nv), math.sin(nv)
    for j in range(3):
        u[j] = cn * lam[j] + sn * vd[j] / safe
    unit3(u, u)  # λ of the candidate
    unit3(u, u)  # normalised again, as steering_from_lambda and wheel_speed_coefficients do
    mu_new = mu_des if mu_first else mu + kq * (mu_des - mu)
    unlimited = lim[L_UNLIMITED] != 0.0
    ratio = 0.0
    for k in range(beta.shape[0]):
        bk, r2 = _beta_wheel(u[0], u[1], u[2], E, P, k, steer_max)
        if r2 < SINGULAR_TOL * SINGULAR_TOL:
            bk = beta[k]
        bk = nearest1(bk, beta[k], unlimited)
        db = bk - beta[k]
        if abs(db) > np.pi / 2:
            return np.inf
        br = db / dt
        ba = (br - beta_rate[k]) / dt
        ph = (mu_new * _speed_coef(u, E, P, b, k, bk) - b[k] * br) / r[k]
        phdd = (ph - phidot[k]) / dt
        room = stop_room1(bk, br, steer_min, steer_max, unlimited)
        v_stop = safe_stop_speed1(room, lim[L_CO_C1], lim[L_CO_C2], lim[L_CO_C3])
        ratio = max(ratio, abs(br) / lim[L_SRM], abs(ba) / lim[L_SAM], abs(ph) / lim[L_WSM], abs(phdd) / lim[L_WAM],
                    abs(br) / max(v_stop, 1e-12))
        if ratio > threshold:
            return ratio
    return ratio


@njit(cache=True)
def coordinated_row(lam, mu, lam_rate, beta, beta_rate, phidot, lam_d, mu_d, mu_first, E, P, b, r, steer_min, steer_max,
                 lim, tune, kappa, dt, lam_out, lam_rate_out, beta_out, rate_out, phidot_out):
    """:func:`control.icr.motion.coordinated_step` of one robot: writes λ, λ̇, β_c, β̇_c, φ̇_c;
    returns (μ, κ, saturated)."""
    n = beta.shape[0]
    theta = sphere_angle3(lam, lam_d)
    gmax = gradient_norm_max(lam, E, P)
    accel_lam = lim[L_ACCEL_LAM] / max(gmax, 1e-6)
    speed = min(min(tune[C_K_LAMBDA] * theta, math.sqrt(2.0 * accel_lam * theta)), theta / dt)
    d = dot3(lam, lam_d)
    v_des = np.empty(3)
    for j in range(3):
        v_des[j] = lam_d[j] - d * lam[j]
    tn = norm3(v_des)
    for j in range(3):
        v_des[j] = v_des[j] / tn * speed if tn > 1e-15 else 0.0
    dv = dot3(lam_rate, lam)
    v_prev = np.empty(3)
    for j in range(3):
        v_prev[j] = lam_rate[j] - dv * lam[j]
    c_now = np.empty(n)
    speed_coefs_row(lam, c_now, False, E, P, b, steer_max, c_now, np.empty(3), np.empty(n))
    inv = np.inf
    for k in range(n):
        ck = abs(c_now[k])
        inv = min(inv, r[k] / (ck if ck > 0 else np.inf))
    accel_mu = lim[L_MU_ACCEL] * inv
    mu_des = mu + min(max(mu_d - mu, -accel_mu * dt), accel_mu * dt)
    # κ from 1 down: the first feasible one is the largest (NumPy: the last feasible of the grid);
    # none feasible: the smallest ratio, the lowest κ among equals (NumPy's argmin)
    nk = kappa.shape[0]
    lam_new, v, beta_new, b_rate, phid, c = np.empty(3), np.empty(3), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    best_q, best_ratio, found = -1, np.inf, False
    u = np.empty(3)
    for q in range(nk - 1, -1, -1):
        # a candidate above both the feasibility bound and the best fallback so far cannot be chosen
        threshold = np.inf if best_q < 0 else max(1.0 - 1e-9, best_ratio)
        ratio = kappa_ratio(q, kappa, lam, v_prev, v_des, mu, mu_des, mu_first, beta, beta_rate, phidot, E, P, b, r,
                            steer_min, steer_max, lim, dt, threshold, u)
        if ratio <= 1.0 - 1e-9:
            best_q, found = q, True
            break
        if best_q < 0 or ratio <= best_ratio:
            best_q, best_ratio = q, ratio
    mu_c, ratio, flipped = kappa_candidate(best_q, kappa, lam, mu, mu_des, mu_first, v_prev, v_des, beta, beta_rate,
                                            phidot, E, P, b, r, steer_min, steer_max, lim, dt, lam_new, v, beta_new,
                                            b_rate, phid, c)
    for j in range(3):
        lam_out[j] = lam_new[j]
        lam_rate_out[j] = v[j]
    for k in range(n):
        beta_out[k], rate_out[k], phidot_out[k] = beta_new[k], b_rate[k], phid[k]
    if tune[C_MU_OWN] != 0.0:
        mu_c = mu_own_row(mu_c, mu_des, c, rate_out, phidot, found and not mu_first, b, r, lim, phidot_out)
    if not found:
        want = beta if flipped else beta_out.copy()
        saturate_row(beta, beta_rate, phidot, want, phidot_out.copy(), steer_min, steer_max, lim, dt, beta_out,
                     rate_out, phidot_out)
    return mu_c, kappa[best_q], not found


@njit(cache=True)
def mu_own_row(mu, mu_des, c, beta_rate, phidot_prev, move, b, r, lim, phidot_out) -> float:
    """:func:`control.icr.motion.mu_own_step` of one robot: returns μ, writes φ̇_c."""
    n = c.shape[0]
    mu_lo, mu_hi = -np.inf, np.inf
    for k in range(n):
        coupling = -b[k] * beta_rate[k] / r[k]
        hi = min(lim[L_WSM_SLACK], phidot_prev[k] + lim[L_WA_DT_SLACK]) - coupling
        lo = max(lim[L_NEG_WSM_SLACK], phidot_prev[k] - lim[L_WA_DT_SLACK]) - coupling
        kk = c[k] / r[k]
        if abs(kk) > 1e-12:
            a, bb = lo / kk, hi / kk
            mu_lo = max(mu_lo, min(a, bb))
            mu_hi = min(mu_hi, max(a, bb))
    mu_lo, mu_hi = min(mu_lo, mu), max(mu_hi, mu)
    mu_out = min(max(mu_des, mu_lo), mu_hi) if move else mu
    for k in range(n):
        phidot_out[k] = c[k] / r[k] * mu_out + (-b[k] * beta_rate[k] / r[k])
    return mu_out
