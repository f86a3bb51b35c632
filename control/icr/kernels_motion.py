"""The ICR controller's two motion primitives, compiled, one robot at a time.

* :func:`coordinated_row`: one time-scaled step of the H state (λ, μ) toward (λ_d, μ_d) with every
  wheel on the constraining surface (RUNNING and STOPPING), with :func:`mu_own_row` for
  ``ICRControllerConfig.mu_own_scale``;
* :func:`reconfigure_row`: the wheels turned in place toward given steering angles with the
  chassis at rest (RECONFIGURING).

The step that calls them is :mod:`control.icr.compiled`; the constants and the work space ``ws``
they read are :mod:`control.icr.kernel_constants`'. The derivations (the braking profile along
the great circle, the discrete time scaling κ, the steer-to-drive coupling r φ̇ = −b β̇ of a
sidewise-offset wheel) are in ``docs/icr-controller.md``.

The time scaling takes the largest κ of the grid (``n_kappa`` values in [0, 1]) whose candidate
is feasible, or, when none is, the candidate with the smallest limit ratio (the lowest κ among
equals). :func:`kappa_search` tries κ from 1 down and stops at the first feasible one; each
candidate stops at its first limit term above the bound (the ratio, a maximum of terms, is above
the bound exactly when one term is), starting with the wheel that ruled out the previous
candidate and with the steering terms, which need no cos/sin. Only when no κ is feasible does
:func:`kappa_fallback` compute the ratios, a candidate stopping once its wheels so far exceed the
best ratio found. The chosen candidate is then computed in full (:func:`kappa_candidate`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from control.icr.kernel_constants import WS
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
    safe_stop_speed1,
    saturate_row,
    speed_coefs_row,
    sphere_angle3,
    steering_row,
    stop_room1,
    unit_xyz,
)
from estimation.kinematics import SINGULAR_TOL, _beta_wheel, _speed_coef

__all__ = ["coordinated_row", "reconfigure_row", "kappa_candidate", "kappa_search", "kappa_fallback", "mu_own_row"]

#: a candidate is feasible when its limit ratio is at most this
FEASIBLE = 1.0 - 1e-9


@njit(cache=True)
def reconfigure_row(c, ws, beta0, rate0, phidot0, target, exact, measured_rate, use_measured, beta_out, rate_out,
                    phidot_out) -> None:
    """Turn one robot's wheels in place toward ``target`` (μ = 0), rate- and accel-limited (``c``:
    the constants, ``ws``: the work space).

    With ``exact``, ``target`` is taken as the next set-point as it is (the caller made it
    feasible). With ``use_measured``, the coupling uses the wheels' measured steering rate
    ``measured_rate``: the compliant steering lags its set-point, and it is the actual contact
    point that must roll. Each wheel follows a discrete trapezoidal profile planned with 0.85 of
    the allowed deceleration (speeding up follows it; braking, less speed or a reversal, may use
    0.95 of the limit, so a wheel still turning toward a stop when the reconfiguration starts stops
    short of it); the propulsion set-point is the pure steer-to-drive coupling r φ̇ = −b β̇, so
    the contact point rolls on its circle about A_k instead of scrubbing, and the chassis stays
    put. Then :func:`~control.icr.kernels.saturate_row`."""
    n = beta0.shape[0]
    b, r, lim, dt, steer_max = c.b, c.r, c.lim, c.dt, c.steer_max
    want_phidot = ws[WS.WANT_PHIDOT, :n]
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
    saturate_row(beta0, rate0, phidot0, beta_out, want_phidot, c.steer_min, steer_max, lim, dt, ws[WS.SAT_BETA, :n],
                 ws[WS.SAT_RATE, :n], phidot_out)


@njit(cache=True, inline="always")
def candidate_lambda(kq, l0, l1, l2, p0, p1, p2, d0, d1, d2, dt):
    """The λ of candidate κ = ``kq`` (normalised once) and its λ̇ (the tangent v = v_prev + κ
    (v_des − v_prev), ``p*`` and ``d*``): λ turned by v·dt (:func:`estimation.hrep.exp_map`)."""
    v0 = p0 + kq * (d0 - p0)
    v1 = p1 + kq * (d1 - p1)
    v2 = p2 + kq * (d2 - p2)
    w0, w1, w2 = v0 * dt, v1 * dt, v2 * dt
    nv = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    safe = nv if nv > 0 else 1.0
    cn, sn = math.cos(nv), math.sin(nv)
    u0, u1, u2 = unit_xyz(cn * l0 + sn * w0 / safe, cn * l1 + sn * w1 / safe, cn * l2 + sn * w2 / safe)
    return u0, u1, u2, v0, v1, v2


@njit(cache=True, inline="always")
def _candidate_steer(c, u, k, beta, beta_rate, unlimited) -> tuple[bool, float, float, float]:
    """Wheel k's steering for the candidate's axis ``u``: (flipped: its angle would turn by more
    than π/2, β, β̇, β̈); β stays where the axis is singular for the wheel, and the rates are 0
    when it flips."""
    bk, r2 = _beta_wheel(u[0], u[1], u[2], c.E, c.P, k, c.steer_max)
    if r2 < SINGULAR_TOL * SINGULAR_TOL:
        bk = beta[k]
    bk = nearest1(bk, beta[k], unlimited)
    db = bk - beta[k]
    if abs(db) > np.pi / 2:
        return True, bk, 0.0, 0.0
    br = db / c.dt
    return False, bk, br, (br - beta_rate[k]) / c.dt


@njit(cache=True, inline="always")
def _candidate_stop_speed(c, bk, br, unlimited) -> float:
    """The steering speed wheel k (at β, β̇ of the candidate) can still stop from before its stop."""
    room = stop_room1(bk, br, c.steer_min, c.steer_max, unlimited)
    return safe_stop_speed1(room, c.lim[L_CO_C1], c.lim[L_CO_C2], c.lim[L_CO_C3])


@njit(cache=True, inline="always")
def _candidate_drive(c, u, k, bk, br, mu_new, phidot) -> tuple[float, float]:
    """Wheel k's drive for the candidate (axis ``u``, its β and β̇, μ): (φ̇, φ̈)."""
    ph = (mu_new * _speed_coef(u, c.E, c.P, c.b, k, bk) - c.b[k] * br) / c.r[k]
    return ph, (ph - phidot[k]) / c.dt


@njit(cache=True, inline="always")
def _candidate_axis(c, u, q, lam, v_prev, v_des, mu, mu_des, mu_first) -> float:
    """Candidate q's axis into ``u`` (its λ, :func:`candidate_lambda`, normalised again, as
    ``steering_from_lambda`` does) and its μ: what :func:`kappa_search` and :func:`kappa_fallback`
    test of each candidate."""
    kq = c.kappa[q]
    u0, u1, u2, _, _, _ = candidate_lambda(kq, lam[0], lam[1], lam[2], v_prev[0], v_prev[1], v_prev[2], v_des[0],
                                           v_des[1], v_des[2], c.dt)
    u[0], u[1], u[2] = unit_xyz(u0, u1, u2)
    return mu_des if mu_first else mu + kq * (mu_des - mu)


@njit(cache=True)
def kappa_search(c, ws, lam, v_prev, v_des, mu, mu_des, mu_first, beta, beta_rate, phidot) -> int:
    """The largest q whose candidate (:func:`kappa_candidate`) is feasible, or −1 (see the module
    docstring: the same verdicts as the candidates' ratios, in another order)."""
    lim = c.lim
    u = ws[WS.U, :3]
    unlimited = lim[L_UNLIMITED] != 0.0
    n = beta.shape[0]
    first = 0  # the wheel that ruled out the previous candidate
    for q in range(c.kappa.shape[0] - 1, -1, -1):
        mu_new = _candidate_axis(c, u, q, lam, v_prev, v_des, mu, mu_des, mu_first)
        bad = -1
        for j in range(n):
            k = first + j
            if k >= n:
                k -= n
            flipped, bk, br, ba = _candidate_steer(c, u, k, beta, beta_rate, unlimited)
            if flipped or abs(ba) / lim[L_SAM] > FEASIBLE or abs(br) / lim[L_SRM] > FEASIBLE:
                bad = k
                break
            if abs(br) / max(_candidate_stop_speed(c, bk, br, unlimited), 1e-12) > FEASIBLE:
                bad = k
                break
            ph, phdd = _candidate_drive(c, u, k, bk, br, mu_new, phidot)
            if abs(phdd) / lim[L_WAM] > FEASIBLE or abs(ph) / lim[L_WSM] > FEASIBLE:
                bad = k
                break
        if bad < 0:
            return q
        first = bad
    return -1


@njit(cache=True)
def kappa_fallback(c, ws, lam, v_prev, v_des, mu, mu_des, mu_first, beta, beta_rate, phidot) -> int:
    """The candidate with the smallest limit ratio (inf where a wheel flips), the lowest κ among
    equals, when none is feasible. A candidate stops being computed once its wheels so far put it
    above the best ratio found (it cannot be chosen)."""
    lim = c.lim
    u = ws[WS.U, :3]
    unlimited = lim[L_UNLIMITED] != 0.0
    n = beta.shape[0]
    best_q, best_ratio = -1, np.inf
    for q in range(c.kappa.shape[0] - 1, -1, -1):
        threshold = np.inf if best_q < 0 else best_ratio
        mu_new = _candidate_axis(c, u, q, lam, v_prev, v_des, mu, mu_des, mu_first)
        ratio = 0.0
        for k in range(n):
            flipped, bk, br, ba = _candidate_steer(c, u, k, beta, beta_rate, unlimited)
            if flipped:
                ratio = np.inf
                break
            ph, phdd = _candidate_drive(c, u, k, bk, br, mu_new, phidot)
            v_stop = _candidate_stop_speed(c, bk, br, unlimited)
            ratio = max(ratio, abs(br) / lim[L_SRM], abs(ba) / lim[L_SAM], abs(ph) / lim[L_WSM],
                        abs(phdd) / lim[L_WAM], abs(br) / max(v_stop, 1e-12))
            if ratio > threshold:
                break
        if best_q < 0 or ratio <= best_ratio:
            best_q, best_ratio = q, ratio
    return best_q


@njit(cache=True)
def kappa_candidate(c, ws, q, lam, mu, mu_des, mu_first, v_prev, v_des, beta, beta_rate, phidot, lam_new, v,
                    beta_new, b_rate, phid, coef) -> tuple[float, float, bool]:
    """One κ of :func:`coordinated_row`: the candidate (λ, λ̇, β, β̇, φ̇, c
    written into the arrays) and (μ, its limit ratio, flipped)."""
    E, P, b, r, lim, kappa = c.E, c.P, c.b, c.r, c.lim, c.kappa
    steer_min, steer_max, dt = c.steer_min, c.steer_max, c.dt
    scratch = ws[WS.SCRATCH, :3]
    n = beta.shape[0]
    kq = kappa[q]
    lam_new[0], lam_new[1], lam_new[2], v[0], v[1], v[2] = candidate_lambda(
        kq, lam[0], lam[1], lam[2], v_prev[0], v_prev[1], v_prev[2], v_des[0], v_des[1], v_des[2], dt)
    mu_new = mu_des if mu_first else mu + kq * (mu_des - mu)
    steering_row(lam_new, E, P, steer_max, beta, True, beta_new, scratch)
    unlimited = lim[L_UNLIMITED] != 0.0
    if unlimited:  # each wheel's axis at the angle nearest its command: never a flip
        for k in range(n):
            beta_new[k] = nearest1(beta_new[k], beta[k], True)
    speed_coefs_row(lam_new, beta_new, True, E, P, b, steer_max, coef, scratch, coef)
    flipped = False
    ratio = 0.0
    for k in range(n):
        db = beta_new[k] - beta[k]
        flipped = flipped or abs(db) > np.pi / 2
        br = db / dt
        b_rate[k] = br
        ba = (br - beta_rate[k]) / dt
        ph = (mu_new * coef[k] - b[k] * br) / r[k]
        phid[k] = ph
        phdd = (ph - phidot[k]) / dt
        room = stop_room1(beta_new[k], br, steer_min, steer_max, unlimited)
        v_stop = safe_stop_speed1(room, lim[L_CO_C1], lim[L_CO_C2], lim[L_CO_C3])
        ratio = max(ratio, abs(br) / lim[L_SRM], abs(ba) / lim[L_SAM], abs(ph) / lim[L_WSM], abs(phdd) / lim[L_WAM],
                    abs(br) / max(v_stop, 1e-12))
    return mu_new, (np.inf if flipped else ratio), flipped


@njit(cache=True)
def coordinated_row(c, ws, lam, mu, lam_rate, beta, beta_rate, phidot, lam_d, mu_d, mu_first, lam_out, lam_rate_out,
                    beta_out, rate_out, phidot_out):
    """One time-scaled step of one robot's (λ, μ) toward (λ_d, μ_d) with every wheel on the
    surface (``c``: the constants, ``ws``: the work space): writes λ, λ̇, β_c, β̇_c, φ̇_c; returns
    (μ, κ, saturated).

    The desired λ̇ runs along the great circle toward λ_d, braking so that it can stop there; the
    desired μ is a ramp toward μ_d at the acceleration every wheel can follow at λ. With
    ``mu_first`` (STOPPING), μ takes its full ramp step whatever κ the λ motion gets, so the robot
    brakes at once even while λ is still slowing down. When no κ is feasible the chosen candidate
    is saturated wheel by wheel (:func:`~control.icr.kernels.saturate_row`)."""
    E, P, b, r, lim, tune, kappa, dt = c.E, c.P, c.b, c.r, c.lim, c.tune, c.kappa, c.dt
    n = beta.shape[0]
    theta = sphere_angle3(lam, lam_d)
    gmax = gradient_norm_max(lam, E, P, ws[WS.U, :3], ws[WS.G, :3])
    accel_lam = lim[L_ACCEL_LAM] / max(gmax, 1e-6)
    speed = min(min(tune[C_K_LAMBDA] * theta, math.sqrt(2.0 * accel_lam * theta)), theta / dt)
    d = dot3(lam, lam_d)
    v_des = ws[WS.V_DES, :3]
    for j in range(3):
        v_des[j] = lam_d[j] - d * lam[j]
    tn = math.sqrt(v_des[0] * v_des[0] + v_des[1] * v_des[1] + v_des[2] * v_des[2])
    for j in range(3):
        v_des[j] = v_des[j] / tn * speed if tn > 1e-15 else 0.0
    dv = dot3(lam_rate, lam)
    v_prev = ws[WS.V_PREV, :3]
    for j in range(3):
        v_prev[j] = lam_rate[j] - dv * lam[j]
    c_now = ws[WS.C_NOW, :n]
    speed_coefs_row(lam, c_now, False, E, P, b, c.steer_max, c_now, ws[WS.SCRATCH, :3], ws[WS.BETA_WORK, :n])
    inv = np.inf
    for k in range(n):
        ck = abs(c_now[k])
        inv = min(inv, r[k] / (ck if ck > 0 else np.inf))
    accel_mu = lim[L_MU_ACCEL] * inv
    mu_des = mu + min(max(mu_d - mu, -accel_mu * dt), accel_mu * dt)
    best_q = kappa_search(c, ws, lam, v_prev, v_des, mu, mu_des, mu_first, beta, beta_rate, phidot)
    found = best_q >= 0
    if not found:
        best_q = kappa_fallback(c, ws, lam, v_prev, v_des, mu, mu_des, mu_first, beta, beta_rate, phidot)
    coef = ws[WS.C, :n]
    mu_c, ratio, flipped = kappa_candidate(c, ws, best_q, lam, mu, mu_des, mu_first, v_prev, v_des, beta, beta_rate,
                                           phidot, lam_out, lam_rate_out, beta_out, rate_out, phidot_out, coef)
    if tune[C_MU_OWN] != 0.0:
        mu_c = mu_own_row(mu_c, mu_des, coef, rate_out, phidot, found and not mu_first, b, r, lim, phidot_out)
    if not found:
        want, want_phidot = ws[WS.WANT_BETA, :n], ws[WS.WANT_PHIDOT, :n]
        for k in range(n):
            want[k] = beta[k] if flipped else beta_out[k]
            want_phidot[k] = phidot_out[k]
        saturate_row(beta, beta_rate, phidot, want, want_phidot, c.steer_min, c.steer_max, lim, dt, beta_out,
                     rate_out, phidot_out)
    return mu_c, kappa[best_q], not found


@njit(cache=True)
def mu_own_row(mu, mu_des, c, beta_rate, phidot_prev, move, b, r, lim, phidot_out) -> float:
    """``ICRControllerConfig.mu_own_scale`` for one robot: move μ from its feasible value toward
    ``mu_des`` as far as every wheel's |φ̇| and |φ̈| limits allow, λ fixed (so are the coefficients
    c (n,) and the steering rates β̇ (n,)): r φ̇_k = μ c_k − b β̇_k is affine in μ, each wheel bounds
    μ to an interval holding the feasible μ, and so does their intersection. Without ``move`` μ
    stays. Returns μ, writes φ̇_c."""
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
