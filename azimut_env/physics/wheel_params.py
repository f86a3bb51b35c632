"""The per-wheel parameter arrays of :class:`~azimut_env.physics.engine.AzimutPhysics` (columns
:class:`~azimut_env.physics.layout.WP`): built from :class:`~azimut_env.params.RobotParams`, with
the robot's geometric imperfections, and drawn anew per robot under domain randomisation.

A robot's wheels are what the parameter classes say, except two columns that hold the *true*
wheel where the controller and the estimators use the nominal geometry
(:class:`~azimut_env.params.ImperfectionParams`): ALPHA = α_k + δ_k (steering-axis zero offset)
and R = r_k (1 + ε_k) (rolling-radius error).
"""

from __future__ import annotations

import numpy as np

from azimut_env.params import RobotParams
from azimut_env.physics.layout import WP

__all__ = ["default_wheel_params", "randomized_wheel_params", "RANDOMIZED"]

#: what domain randomisation scales by a factor uniform in [1 − d, 1 + d], in the order of the draws
RANDOMIZED = ("friction", "stiffness", "damping", "chassis_mass", "tire_slip_stiffness", "contact_half_length")


def default_wheel_params(params: RobotParams, n_robots: int = 1) -> np.ndarray:
    """(n_robots, n, len(WP)) per-wheel parameters of ``params`` (the same for every robot):
    each column of :class:`WP` from its parameter class, ALPHA and R with the imperfections."""
    g, st, wh, t, lim, m = params.geometry, params.steering, params.wheel, params.tire, params.limits, \
        params.steer_motor
    imp = params.imperfections
    alpha = g.alpha + imp.offsets(g.n) if imp.steer_offset else g.alpha
    radius = g.r * (1.0 + imp.radius_errors(g.n)) if imp.radius_error else g.r
    columns = {
        WP.B: g.b, WP.R: radius, WP.ALPHA: alpha, WP.LOAD: params.static_normal_loads(), WP.MU: t.friction,
        WP.K_S: st.stiffness, WP.C_S: st.damping, WP.KP: st.position_gain, WP.I_MOD: st.module_inertia,
        WP.I_W: wh.inertia, WP.KV: wh.velocity_gain, WP.BEARING: wh.bearing_damping,
        WP.RR_TORQUE: t.rolling_resistance, WP.RR_KNEE: t.rolling_knee,
        WP.STEER_RATE: lim.steer_rate_max, WP.STEER_ACCEL: lim.steer_accel_max, WP.STEER_TORQUE: lim.steer_torque_max,
        WP.WHEEL_ACCEL: lim.wheel_accel_max, WP.WHEEL_TORQUE: lim.wheel_torque_max, WP.STEER_MIN: lim.steer_min,
        WP.STEER_MAX: lim.steer_max,
        WP.C_KAPPA: t.longitudinal_stiffness, WP.C_ALPHA: t.cornering_stiffness,
        WP.SIGMA_LONG: t.longitudinal_relaxation_length, WP.SIGMA_LAT: t.relaxation_length,
        WP.HALF_LEN: t.contact_half_length, WP.DAMP_TIME: t.damping_time,
        WP.MOTOR_STALL: m.stall_torque, WP.MOTOR_NO_LOAD: m.no_load_speed, WP.MOTOR_INERTIA: m.rotor_inertia,
        WP.FRIC_C: st.friction_coulomb, WP.FRIC_S: st.friction_static, WP.STRIBECK: st.stribeck_speed,
        WP.M_MOD: st.module_mass, WP.COM: st.com_offset,
        WP.DRIVE_STALL: wh.drive_stall_torque, WP.DRIVE_NO_LOAD: wh.drive_no_load_speed,
    }
    assert set(columns) == set(WP), "every wheel parameter column has its source"
    wp = np.zeros((n_robots, params.n, len(WP)))
    for col, value in columns.items():
        wp[..., col] = value
    return wp


def _clipped_normal(rng: np.random.Generator, std: float, n: int) -> np.ndarray:
    return np.clip(rng.normal(0.0, std, size=n), -3.0 * std, 3.0 * std)


def randomized_wheel_params(base: np.ndarray, params: RobotParams, spread: float,
                            rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """One robot's wheel parameters (n, len(WP)) and chassis mass [kg] for an episode under domain
    randomisation of relative spread d = ``spread`` (``base``: its default rows; d = 0 returns
    them and the default mass, drawing nothing).

    Drawn from ``rng``, in this order: six factors uniform in [1 − d, 1 + d] (:data:`RANDOMIZED`:
    tire friction μ, spring k_s, damper c_s, chassis mass, tire slip stiffness with its relaxation
    lengths, contact half-length); then, when ``params.imperfections`` has a spread, a new robot's
    imperfections: δ_k ~ N(0, σ_δ) and ε_k ~ N(0, σ_ε), clipped at 3σ, replacing the fixed ones;
    then, when the steering has friction, one more factor in [1 − d, 1 + d] on τ_c and τ_s.
    (Robots without imperfection spread or friction draw exactly the six factors of physics v2.)

    The tire's cornering and longitudinal stiffness coefficients and its relaxation lengths
    take the same factor: σ = C/k with k the carcass (contact) stiffness (Pacejka 2012, Ch. 7),
    so a stiffer or softer tread changes the slip stiffness and the distance to build force,
    and leaves the contact stiffness k, hence the stability budget, as it is. The contact
    half-length scales the aligning trail, the scrub torque limit and the twist stiffness."""
    wp = base.copy()
    mass = params.chassis.mass
    if spread <= 0:
        return wp, mass
    d = spread
    f = rng.uniform(1 - d, 1 + d, size=6)
    wp[..., WP.MU] *= f[0]
    wp[..., WP.K_S] *= f[1]
    wp[..., WP.C_S] *= f[2]
    mass *= f[3]
    for col in (WP.C_KAPPA, WP.C_ALPHA, WP.SIGMA_LONG, WP.SIGMA_LAT):
        wp[..., col] *= f[4]
    wp[..., WP.HALF_LEN] *= f[5]
    imp, g = params.imperfections, params.geometry
    if imp.randomised:
        wp[..., WP.ALPHA] = g.alpha + _clipped_normal(rng, imp.steer_offset_std, g.n)
        wp[..., WP.R] = g.r * (1.0 + _clipped_normal(rng, imp.radius_error_std, g.n))
    if params.steering.has_friction:
        ff = rng.uniform(1 - d, 1 + d)
        wp[..., WP.FRIC_C] *= ff
        wp[..., WP.FRIC_S] *= ff
    return wp, mass
