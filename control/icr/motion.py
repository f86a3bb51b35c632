"""The ICR controller's two motion primitives, batched over robots ((N, …) rows).

* :func:`coordinated_step`: one time-scaled step of the H state (λ, μ) toward (λ_d, μ_d) with
  every wheel on the constraining surface (RUNNING and STOPPING);
* :func:`reconfigure_step`: the wheels turned in place toward given steering angles with the
  chassis at rest (RECONFIGURING).

The derivations (the braking profile along the great circle, the discrete time scaling κ, the
steer-to-drive coupling r φ̇ = −b β̇ of a sidewise-offset wheel) are in ``docs/icr-controller.md``.
"""

from __future__ import annotations

import numpy as np

from control.icr.config import ICRControllerConfig
from control.icr.feasibility import safe_stop_speed, saturate, stop_room
from control.limits import ActuatorLimits
from estimation.geometry import RobotGeometry
from estimation.hrep import exp_map, sphere_angle
from estimation.kinematics import steering_from_lambda, steering_gradient, wheel_speed_coefficients

__all__ = ["coordinated_step", "reconfigure_step"]


def coordinated_step(lam, mu, lam_rate, beta, beta_rate, phidot, lam_d, mu_d, mu_first, geom: RobotGeometry,
                      limits: ActuatorLimits, config: ICRControllerConfig, dt: float):
    """One time-scaled step of (λ, μ) toward (λ_d, μ_d) with every wheel on the surface, for N rows
    (λ (N, 3), μ (N,), λ̇ (N, 3), β, β̇, φ̇ (N, n), λ_d (N, 3), μ_d (N,), ``mu_first`` (N,) bool).

    With ``mu_first`` (STOPPING), μ takes its full ramp step whatever κ the λ motion gets, so the
    robot brakes at once even while λ is still slowing down.

    Returns (λ, μ, λ̇, β_c, β̇_c, φ̇_c, κ, saturated), row by row.
    """
    nrows, n = beta.shape
    rows = np.arange(nrows)
    # desired λ̇: along the great circle toward λ_d, braking so that it can stop at λ_d
    theta = sphere_angle(lam, lam_d)
    grad = steering_gradient(lam, geom)  # (N, n, 3)
    gmax = np.max(np.linalg.norm(grad, axis=-1), axis=-1)
    accel_lam = 0.8 * limits.steer_accel_max / np.maximum(gmax, 1e-6)  # λ angular accel every wheel can follow
    speed = np.minimum(np.minimum(config.k_lambda * theta, np.sqrt(2.0 * accel_lam * theta)), theta / dt)
    tang = lam_d - np.sum(lam * lam_d, axis=-1)[:, None] * lam
    tn = np.linalg.norm(tang, axis=-1)
    ok = tn > 1e-15
    v_des = np.where(ok[:, None], tang / np.where(ok, tn, 1.0)[:, None] * speed[:, None], 0.0)
    v_prev = lam_rate - np.sum(lam_rate * lam, axis=-1)[:, None] * lam  # carried over, in the tangent plane
    # desired μ: a ramp toward μ_d at the acceleration every wheel can follow at λ
    c_now = np.abs(wheel_speed_coefficients(lam, geom))
    accel_mu = config.mu_accel_fraction * limits.wheel_accel_max * np.min(
        geom.r / np.where(c_now > 0, c_now, np.inf), axis=-1)
    mu_des = mu + np.clip(mu_d - mu, -accel_mu * dt, accel_mu * dt)

    kappa = np.linspace(0.0, 1.0, config.n_kappa)
    nk = kappa.size
    v = v_prev[:, None, :] + kappa[None, :, None] * (v_des - v_prev)[:, None, :]  # (N, K, 3)
    lam_new = exp_map(lam, v * dt)
    mu_new = np.where(mu_first[:, None], mu_des[:, None], mu[:, None] + kappa[None, :] * (mu_des - mu)[:, None])
    fill = np.broadcast_to(beta[:, None, :], (nrows, nk, n)).reshape(-1, n)
    beta_new = steering_from_lambda(lam_new.reshape(-1, 3), geom, singular_fill=fill).reshape(nrows, nk, n)
    if geom.unlimited_steering:  # each wheel's axis at the angle nearest its command: never a flip
        beta_new = geom.nearest_steering(beta_new, beta[:, None, :])
    dbeta = beta_new - beta[:, None, :]
    flipped = np.any(np.abs(dbeta) > np.pi / 2, axis=-1)
    b_rate = dbeta / dt
    b_acc = (b_rate - beta_rate[:, None, :]) / dt
    c = wheel_speed_coefficients(lam_new.reshape(-1, 3), geom, beta_new.reshape(-1, n)).reshape(nrows, nk, n)
    phid = (mu_new[:, :, None] * c - geom.b * b_rate) / geom.r
    phidd = (phid - phidot[:, None, :]) / dt
    # every wheel must keep the room to brake before the stop it turns toward (a wheel that runs
    # into a stop at speed would exceed the acceleration limit there)
    v_stop = safe_stop_speed(stop_room(beta_new, b_rate, geom), 0.8 * limits.steer_accel_max, dt)
    ratio = np.max(np.stack([
        np.abs(b_rate) / limits.steer_rate_max,
        np.abs(b_acc) / limits.steer_accel_max,
        np.abs(phid) / limits.wheel_speed_max,
        np.abs(phidd) / limits.wheel_accel_max,
        np.abs(b_rate) / np.maximum(v_stop, 1e-12),
    ]), axis=(0, 3))
    ratio = np.where(flipped, np.inf, ratio)
    feasible = ratio <= 1.0 - 1e-9
    any_ok = feasible.any(axis=1)
    last_ok = nk - 1 - np.argmax(feasible[:, ::-1], axis=1)
    i = np.where(any_ok, last_ok, np.argmin(ratio, axis=1))
    beta_c, rate_c, phidot_c = beta_new[rows, i], b_rate[rows, i], phid[rows, i]
    mu_c = mu_new[rows, i]
    sat = ~any_ok
    if config.mu_own_scale:
        mu_c, phidot_c = mu_own_step(mu_c, mu_des, c[rows, i], rate_c, phidot, any_ok & ~mu_first, geom, limits, dt)
    if np.any(sat):
        want = np.where(flipped[rows, i][:, None], beta, beta_c)
        sb, sr, sp = saturate(beta[sat], beta_rate[sat], phidot[sat], want[sat], phidot_c[sat], geom, limits, dt)
        beta_c, rate_c, phidot_c = beta_c.copy(), rate_c.copy(), phidot_c.copy()
        beta_c[sat], rate_c[sat], phidot_c[sat] = sb, sr, sp
    return lam_new[rows, i], mu_c, v[rows, i], beta_c, rate_c, phidot_c, kappa[i], sat


def mu_own_step(mu, mu_des, c, beta_rate, phidot_prev, rows, geom: RobotGeometry, limits: ActuatorLimits, dt: float):
    """``ICRControllerConfig.mu_own_scale``: move μ (N,) from its feasible value toward
    ``mu_des`` (N,) as far as every wheel's |φ̇| and |φ̈| limits allow, λ fixed (so are the
    coefficients c (N, n) and the steering rates β̇ (N, n)): r φ̇_k = μ c_k − b β̇_k is affine
    in μ, each wheel bounds μ to an interval holding the feasible μ, and so does their
    intersection. Rows where ``rows`` (N,) is False are left as they are. Returns (μ, φ̇_c)."""
    slack = 1.0 - 1e-9
    coupling = -geom.b * beta_rate / geom.r
    hi = np.minimum(limits.wheel_speed_max * slack, phidot_prev + limits.wheel_accel_max * dt * slack) - coupling
    lo = np.maximum(-limits.wheel_speed_max * slack, phidot_prev - limits.wheel_accel_max * dt * slack) - coupling
    k = c / geom.r  # φ̇_k = k_k μ + coupling_k
    free = np.abs(k) <= 1e-12
    safe = np.where(free, 1.0, k)
    a, b = lo / safe, hi / safe
    mu_lo = np.max(np.where(free, -np.inf, np.minimum(a, b)), axis=-1)
    mu_hi = np.min(np.where(free, np.inf, np.maximum(a, b)), axis=-1)
    # the common step's μ is feasible (up to rounding): the interval holds it
    mu_lo, mu_hi = np.minimum(mu_lo, mu), np.maximum(mu_hi, mu)
    mu_out = np.where(rows, np.clip(mu_des, mu_lo, mu_hi), mu)
    return mu_out, k * mu_out[:, None] + coupling



def reconfigure_step(beta0: np.ndarray, beta_rate0: np.ndarray, phidot0: np.ndarray, beta_target: np.ndarray,
                      geom: RobotGeometry, limits: ActuatorLimits, dt: float, exact: np.ndarray,
                      measured_rate: np.ndarray, use_measured: np.ndarray, rate_fraction: float = 0.95,
                      accel_fraction: float = 0.95):
    """Turn each wheel in place toward ``beta_target`` (μ = 0), rate- and accel-limited; (N, n) rows.

    Where ``exact`` (N,), ``beta_target`` is taken as the next set-point as it is (the caller made it
    feasible). Where ``use_measured`` (N,), the coupling uses the wheels' measured steering rate
    ``measured_rate``: the compliant steering lags its set-point, and it is the actual contact
    point that must roll.

    Each wheel follows a discrete trapezoidal profile. The propulsion set-point is the pure
    steer-to-drive coupling r φ̇ = −b β̇, so the contact point rolls on its circle about A_k
    instead of scrubbing, and the chassis stays put.
    """
    err = beta_target - beta0  # both inside the range (or, unlimited, the target nearest beta0): never a stop
    a, vmax = limits.steer_accel_max * accel_fraction, limits.steer_rate_max * rate_fraction
    # discrete braking profile: moving v for one period, then braking at a_plan, covers
    # v²/(2 a_plan) + v dt/2; planning with less deceleration than allowed leaves margin
    a_plan = 0.85 * a
    vstop = -0.5 * a_plan * dt + np.sqrt((0.5 * a_plan * dt) ** 2 + 2.0 * a_plan * np.abs(err))
    want = np.sign(err) * np.minimum(vmax, np.minimum(vstop, np.abs(err) / dt))
    # speeding up follows the gentle profile; braking (less speed, or a reversal) may use the
    # full limit, so a wheel still turning toward a stop when the reconfiguration starts
    # stops short of it instead of being clipped there
    braking = (want * beta_rate0 < 0) | (np.abs(want) < np.abs(beta_rate0) - 1e-12)
    a_step = np.where(braking, np.maximum(a, 0.95 * limits.steer_accel_max), a) * dt
    rate = np.clip(want, beta_rate0 - a_step, beta_rate0 + a_step)
    rate = np.where(exact[:, None], err / dt, rate)  # ``beta_target`` is already a feasible next set-point
    beta = beta0 + rate * dt
    if not geom.unlimited_steering:
        beta = np.clip(beta, geom.steer_min + 1e-9, geom.steer_max)
    rate = (beta - beta0) / dt
    phidot_want = -geom.b * np.where(use_measured[:, None], measured_rate, rate) / geom.r
    _, _, phidot = saturate(beta0, beta_rate0, phidot0, beta, phidot_want, geom, limits, dt)
    return beta, rate, phidot

