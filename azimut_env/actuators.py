"""Actuator models: the series-elastic steering motor and the velocity-controlled propulsion motor.

Steering (per wheel): the motor angle θ_m follows the set-point β_cmd under a position loop with
rate and acceleration limits (the desired rate is ``min(gain·|e|, rate_max, sqrt(2·accel_max·|e|))``
toward the set-point, so it brakes in time). It drives the module through a spring and damper,
``τ_s = k_s (θ_m − β) + c_s (θ̇_m − β̇)``, clipped to the motor's torque limit; when the spring
would need more torque the motor stalls (θ_m stays within τ_max / k_s of β). The spring torque is
computed here, in closed form, rather than with pymunk's explicit ``DampedRotarySpring``.

Propulsion (per wheel): the set-point φ̇_cmd is ramped at ``wheel_accel_max`` into φ̇_ref; the
motor torque is ``clip(K_v (φ̇_ref − φ̇), ±τ_max)``. The spin is integrated implicitly in the
tire's linear range (see :func:`wheel_spin_kernel`), which keeps a light wheel on a stiff tire
stable at the default substep.

These are numba scalar kernels inlined into the physics substep loop.
"""

from __future__ import annotations

import math

from numba import njit

from .tire import tire_force_kernel

__all__ = ["steer_motor_kernel", "spring_torque_kernel", "wheel_spin_kernel", "rolling_resistance_kernel",
           "wheel_spin_step_kernel"]


@njit(cache=True, inline="always")
def steer_motor_kernel(theta: float, omega: float, target: float, beta: float, enabled: bool,
                       gain: float, rate_max: float, accel_max: float, torque_max: float,
                       stiffness: float, dt: float):
    """One substep of the steering motor. Returns the new (θ_m, θ̇_m)."""
    if enabled:
        e = target - theta
        ae = abs(e)
        v = min(gain * ae, rate_max, math.sqrt(2.0 * accel_max * ae) * 0.9)
        if e < 0:
            v = -v
        dv = v - omega
        lim = accel_max * dt
        if dv > lim:
            dv = lim
        elif dv < -lim:
            dv = -lim
        omega = omega + dv
        theta = theta + omega * dt
        # torque limit: the motor stalls rather than wind the spring beyond τ_max
        band = torque_max / stiffness
        if theta > beta + band:
            theta = beta + band
            if omega > 0.0:
                omega = 0.0
        elif theta < beta - band:
            theta = beta - band
            if omega < 0.0:
                omega = 0.0
    else:
        omega = 0.0  # motor off: it brakes and holds its angle
    return theta, omega


@njit(cache=True, inline="always")
def spring_torque_kernel(theta: float, omega: float, beta: float, beta_dot: float, enabled: bool,
                         stiffness: float, damping: float, torque_max: float) -> float:
    """Torque [N·m] of the series spring + damper on the module (the chassis gets the opposite)."""
    tau = stiffness * (theta - beta) + damping * (omega - beta_dot)
    if enabled:
        if tau > torque_max:
            tau = torque_max
        elif tau < -torque_max:
            tau = -torque_max
    return tau


@njit(cache=True, inline="always")
def wheel_spin_kernel(phidot: float, ref: float, v_roll: float, v_lat: float, enabled: bool,
                      r: float, inertia: float, kv: float, torque_max: float, bearing: float,
                      rr_torque: float, rr_knee: float, mu_n: float, knee: float, dt: float):
    """One substep of the wheel spin and its tire.

    Solves the spin implicitly in the motor gain and the linear tire:
    ``I φ̇' = I φ̇ + dt (τ_m(φ̇') + τ_rr − b φ̇' − r F_long(φ̇'))``; if the motor torque saturates
    it is held at its limit; if the tire force leaves the friction circle the saturated force is
    used explicitly. Returns (φ̇', F_long, F_lat, slip_long).
    """
    # rolling resistance, fading linearly near zero spin so that the robot can come to rest
    x = phidot * r / rr_knee
    if x > 1.0:
        x = 1.0
    elif x < -1.0:
        x = -1.0
    tau_rr = -rr_torque * x
    c = mu_n / knee
    cr2 = c * r * r
    if enabled:
        den = inertia + dt * (kv + cr2 + bearing)
        new = (inertia * phidot + dt * (kv * ref + tau_rr + r * c * v_roll)) / den
        tau_m = kv * (ref - new)
        if tau_m > torque_max or tau_m < -torque_max:
            tau_m = torque_max if tau_m > 0 else -torque_max
            new = (inertia * phidot + dt * (tau_m + tau_rr + r * c * v_roll)) / (inertia + dt * (cr2 + bearing))
    else:
        tau_m = 0.0
        new = (inertia * phidot + dt * (tau_rr + r * c * v_roll)) / (inertia + dt * (cr2 + bearing))
    s_long = v_roll - r * new
    f_long, f_lat, sat = tire_force_kernel(s_long, v_lat, mu_n, knee)
    if sat:
        if enabled:
            tau_m = kv * (ref - phidot)
            if tau_m > torque_max:
                tau_m = torque_max
            elif tau_m < -torque_max:
                tau_m = -torque_max
        new = phidot + dt * (tau_m + tau_rr - bearing * phidot - r * f_long) / inertia
        s_long = v_roll - r * new
    return new, f_long, f_lat, s_long


@njit(cache=True, inline="always")
def rolling_resistance_kernel(phidot: float, r: float, rr_torque: float, rr_knee: float) -> float:
    """Rolling resistance torque on the spin [N·m]: ``−C_rr N r · sat(r φ̇ / v_knee)``, i.e. the
    Coulomb-like resistance C_rr N r faded linearly below the surface speed v_knee so that the
    wheel can come to rest (rr_torque = C_rr N r)."""
    x = phidot * r / rr_knee
    if x > 1.0:
        x = 1.0
    elif x < -1.0:
        x = -1.0
    return -rr_torque * x


@njit(cache=True, inline="always")
def wheel_spin_step_kernel(phidot: float, ref: float, f_long: float, enabled: bool, r: float, inertia: float,
                           kv: float, torque_max: float, bearing: float, rr_torque: float, rr_knee: float,
                           dt: float) -> float:
    """One substep of the wheel spin driven by its velocity-controlled motor and loaded by the
    tire force ``f_long`` [N] (on the robot, along d) of :func:`azimut_env.tire.tire_step_kernel`.

    ``I φ̇' = I φ̇ + dt (τ_m + τ_rr − b φ̇' − r F_long)`` with ``τ_m = clip(K_v (φ̇_ref − φ̇'), ±τ_max)``:
    the motor gain and bearing are implicit (no bound on dt from K_v/I), the rolling resistance
    and the tire force explicit. The tire is a spring-damper on the spin: its bound is
    :func:`azimut_env.tire.stability_numbers` with the mass I/r² (longitudinal direction). The
    tire force reacts on the spin with torque −r F_long (F_long > 0 pushes the robot forward and
    brakes the wheel). Returns φ̇' [rad/s]."""
    tau_rr = rolling_resistance_kernel(phidot, r, rr_torque, rr_knee)
    load = tau_rr - r * f_long
    if enabled:
        new = (inertia * phidot + dt * (kv * ref + load)) / (inertia + dt * (kv + bearing))
        tau_m = kv * (ref - new)
        if tau_m > torque_max or tau_m < -torque_max:
            tau_m = torque_max if tau_m > 0 else -torque_max
            new = (inertia * phidot + dt * (tau_m + load)) / (inertia + dt * bearing)
        return new
    return (inertia * phidot + dt * load) / (inertia + dt * bearing)
