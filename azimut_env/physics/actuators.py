"""Actuator models: the series-elastic steering motor and the velocity-controlled propulsion motor.

Steering (per wheel), two models (``params.SteeringMotorParams.model``):

* ``"kinematic"`` (default): the motor angle θ_m follows the set-point β_cmd under a position loop
  with rate and acceleration limits (the desired rate is ``min(gain·|e|, rate_max,
  sqrt(2·accel_max·|e|))`` toward the set-point, so it brakes in time). It drives the module
  through a spring and damper, ``τ_s = k_s (θ_m − β) + c_s (θ̇_m − β̇)``, clipped to the motor's
  torque limit; when the spring would need more torque the motor stalls (θ_m stays within
  τ_max / k_s of β) (:func:`steer_motor_kernel`, :func:`spring_torque_kernel`).
* ``"dc"``: the same rate profile asked of a DC motor with reflected rotor inertia J, whose torque
  is limited by its torque–speed line τ_stall (1 − |ω|/ω₀) (back-EMF) and its current limit
  (:func:`steer_dc_motor_kernel`, :func:`dc_torque_limits_kernel`); under load it slows down.

:func:`steer_actuator_kernel` runs either one.

Propulsion (per wheel): the set-point φ̇_cmd is ramped at ``wheel_accel_max`` into φ̇_ref; the
motor torque is ``clip(K_v (φ̇_ref − φ̇), ±τ_max)``, implicit in the spin; the tire force of
:func:`azimut_env.physics.tire.tire_step_kernel` and the rolling resistance load the spin
(:func:`wheel_spin_step_kernel`).

Command latency (k control periods of transport delay) lives in the task
(``TaskConfig.action_latency``), where the actions enter.

These are numba scalar kernels inlined into the physics substep loop.
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["steer_rate_step_kernel", "steer_motor_kernel", "spring_torque_kernel", "rolling_resistance_kernel",
           "wheel_spin_step_kernel", "dc_torque_limits_kernel", "steer_dc_motor_kernel", "steer_actuator_kernel"]


@njit(cache=True, inline="always")
def clamp_sym(x: float, lim: float) -> float:
    """x clipped to [−lim, lim] (lim >= 0)."""
    if x > lim:
        return lim
    if x < -lim:
        return -lim
    return x


@njit(cache=True, inline="always")
def steer_rate_step_kernel(theta: float, omega: float, target: float, gain: float, rate_max: float,
                           accel_max: float, dt: float) -> float:
    """The change of the steering motor's rate over one substep [rad/s] that its position loop
    asks: toward the rate ``sgn(e) min(gain |e|, rate_max, 0.9 √(2 accel_max |e|))`` (e = target −
    θ_m; the square root brakes in time), by at most ``accel_max dt``. Both motor models use it."""
    e = target - theta
    ae = abs(e)
    v = min(gain * ae, rate_max, math.sqrt(2.0 * accel_max * ae) * 0.9)
    if e < 0:
        v = -v
    dv = v - omega
    return clamp_sym(dv, accel_max * dt)


@njit(cache=True, inline="always")
def steer_motor_kernel(theta: float, omega: float, target: float, beta: float, enabled: bool,
                       gain: float, rate_max: float, accel_max: float, torque_max: float,
                       stiffness: float, dt: float):
    """One substep of the steering motor. Returns the new (θ_m, θ̇_m)."""
    if enabled:
        omega = omega + steer_rate_step_kernel(theta, omega, target, gain, rate_max, accel_max, dt)
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
    return clamp_sym(tau, torque_max) if enabled else tau


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
                           kv: float, torque_lo: float, torque_hi: float, bearing: float, rr_torque: float,
                           rr_knee: float, dt: float) -> float:
    """One substep of the wheel spin driven by its velocity-controlled motor and loaded by the
    tire force ``f_long`` [N] (on the robot, along d) of :func:`azimut_env.physics.tire.tire_step_kernel`.

    ``I φ̇' = I φ̇ + dt (τ_m + τ_rr − b φ̇' − r F_long)`` with ``τ_m = clip(K_v (φ̇_ref − φ̇'), τ_lo, τ_hi)``:
    the motor gain and bearing are implicit (no bound on dt from K_v/I), the rolling resistance
    and the tire force explicit. The torque range is ±τ_max (the current limit), or with the DC
    drive model :func:`dc_torque_limits_kernel` at the substep's starting speed (the torque–speed
    line explicit: its slope τ_stall/ω₀ acts as a damping with the bound dt τ_stall/(ω₀ I) < 1 of
    the stability budget). The tire is a spring-damper on the spin: its bound is
    :func:`azimut_env.physics.tire.stability_numbers` with the mass I/r² (longitudinal direction). The
    tire force reacts on the spin with torque −r F_long (F_long > 0 pushes the robot forward and
    brakes the wheel). Returns φ̇' [rad/s]."""
    tau_rr = rolling_resistance_kernel(phidot, r, rr_torque, rr_knee)
    load = tau_rr - r * f_long
    if enabled:
        new = (inertia * phidot + dt * (kv * ref + load)) / (inertia + dt * (kv + bearing))
        tau_m = kv * (ref - new)
        if tau_m > torque_hi or tau_m < torque_lo:
            tau_m = torque_hi if tau_m > torque_hi else torque_lo
            new = (inertia * phidot + dt * (tau_m + load)) / (inertia + dt * bearing)
        return new
    return (inertia * phidot + dt * load) / (inertia + dt * bearing)


@njit(cache=True, inline="always")
def dc_torque_limits_kernel(omega: float, stall_torque: float, no_load_speed: float, torque_max: float):
    """Torque range (τ_lo, τ_hi) [N·m] of a voltage- and current-limited DC motor at output speed
    ω [rad/s].

    A DC motor at its supply voltage ±U gives ``τ = τ_stall (±1 − ω/ω₀)`` (back-EMF: the torque
    falls linearly from the stall torque τ_stall at rest to 0 at the no-load speed ω₀; Hughes &
    Drury, *Electric Motors and Drives*, 5th ed., Ch. 3), and its driver limits the current to
    ``|τ| ≤ τ_max``. Motoring (τ ω > 0) the available torque is τ_stall (1 − |ω|/ω₀); braking it
    is larger (the back-EMF helps), up to τ_max."""
    x = omega / no_load_speed
    hi = stall_torque * (1.0 - x)
    lo = -stall_torque * (1.0 + x)
    if hi > torque_max:
        hi = torque_max
    if lo < -torque_max:
        lo = -torque_max
    if hi < lo:  # beyond the no-load speed: driven by the load, the motor brakes at its limit
        hi = lo = max(min(hi, torque_max), -torque_max)
    return lo, hi


@njit(cache=True, inline="always")
def steer_dc_motor_kernel(theta: float, omega: float, target: float, beta: float, beta_dot: float, enabled: bool,
                          gain: float, rate_max: float, accel_max: float, torque_max: float, stiffness: float,
                          damping: float, stall_torque: float, no_load_speed: float, inertia: float, dt: float):
    """One substep of the steering motor as a torque source with inertia (the "dc" model).

    The rate profile is that of :func:`steer_motor_kernel` (position loop, rate and acceleration
    limits): it gives the rate v the motor should have after the substep. The drive asks the
    torque that reaches it, and gets it only within :func:`dc_torque_limits_kernel` at the
    current speed; the rotor (reflected inertia J at the output) carries the series spring and
    damper::

        J θ̇_m' = J θ̇_m + dt (τ − τ_s'),   θ_m' = θ_m + dt θ̇_m',   τ_s' = k_s (θ_m' − β) + c_s (θ̇_m' − β̇),
        τ = clip(J (v − θ̇_m)/dt + τ_s'(v), τ_lo(θ̇_m), τ_hi(θ̇_m)).

    The rotor feels the same spring torque τ_s' that the module receives over the substep
    (action = reaction, no O(dt) offset between the two).

    Unloaded it follows the kinematic model's profile exactly; under a load τ_L it slows to
    ω₀ (1 − τ_L/τ_stall) where that is below the rate limit; against a stop it stalls at the
    current limit. Spring and damper are implicit on the rotor side (the module side keeps its
    bound √(k_s/I_mod) dt, the physics' stability budget). Motors off: braked (θ̇_m = 0).

    Returns (θ_m', θ̇_m', τ_s), τ_s = k_s (θ_m' − β) + c_s (θ̇_m' − β̇) the torque on the module
    (not clipped: the motor's torque limit is its own)."""
    if enabled:
        dv = steer_rate_step_kernel(theta, omega, target, gain, rate_max, accel_max, dt)
        v = omega + dv
        spring = stiffness * (theta - beta) - damping * beta_dot
        tau = inertia * dv / dt + spring + (damping + dt * stiffness) * v
        lo, hi = dc_torque_limits_kernel(omega, stall_torque, no_load_speed, torque_max)
        if tau > hi or tau < lo:
            tau = hi if tau > hi else lo
            v = (inertia * omega + dt * (tau - spring)) / (inertia + dt * (damping + dt * stiffness))
        omega = v
        theta = theta + dt * omega
    else:
        omega = 0.0
    return theta, omega, stiffness * (theta - beta) + damping * (omega - beta_dot)


@njit(cache=True, inline="always")
def steer_actuator_kernel(dc: bool, theta: float, omega: float, target: float, beta: float, beta_dot: float,
                          enabled: bool, gain: float, rate_max: float, accel_max: float, torque_max: float,
                          stiffness: float, damping: float, stall_torque: float, no_load_speed: float,
                          inertia: float, dt: float):
    """One substep of the series-elastic steering actuator, either model. Returns (θ_m', θ̇_m', τ_s).

    ``dc`` False: the kinematic position source (:func:`steer_motor_kernel`, spring torque clipped
    to τ_max by :func:`spring_torque_kernel`; the last three motor parameters are unused). True:
    the DC motor with back-EMF (:func:`steer_dc_motor_kernel`)."""
    if dc:
        return steer_dc_motor_kernel(theta, omega, target, beta, beta_dot, enabled, gain, rate_max, accel_max,
                                     torque_max, stiffness, damping, stall_torque, no_load_speed, inertia, dt)
    theta, omega = steer_motor_kernel(theta, omega, target, beta, enabled, gain, rate_max, accel_max, torque_max,
                                      stiffness, dt)
    return theta, omega, spring_torque_kernel(theta, omega, beta, beta_dot, enabled, stiffness, damping, torque_max)
