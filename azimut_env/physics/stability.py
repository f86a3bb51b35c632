"""The stability budget of the substep integration (:mod:`azimut_env.physics.kernels`): the
dimensionless figures that bound the substep for given robot parameters.

:class:`~azimut_env.physics.engine.AzimutPhysics` enforces it at construction with :func:`check_stability`
(``ValueError`` past a bound; the figures are :func:`stability_figures`). With the default
parameters, 8 substeps of 2.5 ms at the 20 ms control period:

* the tire's contact is a spring k = C/σ with bristle damper c = k τ_d, integrated by symplectic
  Euler with explicit damping (``tire.stability_numbers``): for the effective mass m it drives,
  stable iff a = c dt/m < 2 and b + 2a < 4 with b = k dt²/m. Along the rolling direction d the
  contact moves the wheel spin (r²/I_w), the module about its axis (b²/I_m) and the chassis:
  m = 1.6 kg, margin b + 2a = 1.25; across (e) only the chassis: 0.15; the patch twist on I_m:
  0.004. Refused above 3 (the margins grow with the load: room for 2.4× the nominal load, for
  randomised masses and load transfer; :meth:`AzimutPhysics.set_chassis_mass` refuses a mass
  that would take a margin to :data:`LOADED_MARGIN_MAX`, :func:`check_load_scale`). The
  relaxation itself (|v_x| dt/σ) is implicit: no bound;
* the series spring on the module: ω = sqrt(k_s / I_m) = 55 rad/s, ω·dt = 0.14 (symplectic Euler
  is stable below 2; refused above 0.5), its damper c_s dt / I_m = 0.075 (refused above 1);
* the propulsion velocity loop and bearing are implicit in the spin, and the DC steering motor's
  rotor (``SteeringMotorParams.model = "dc"``) on the spring is implicit: no bound on dt;
* the hard stops are exact projections (no stiffness, no bound on dt); the steering joint's
  friction is a velocity-level impulse that stops the joint at most (``modules.py``: no
  stiffness, no bound on dt, no energy added, no chattering);
* a module whose centre of mass is off its axis (``SteeringParams.com_offset`` > 0) couples to
  the chassis through the mass matrix: the tire and spring figures then use the exact inverse
  effective masses J M⁻¹ Jᵀ (worst wheel, worst module angle on a grid) instead of the bounds above;
* the drive's torque–speed line (``WheelParams.drive_model = "dc"``) is explicit in the spin: a
  damping τ_stall/ω₀ on I_w, refused at dt τ_stall/(ω₀ I_w) >= 1 (0.22 for the "dc" defaults);
* load transfer (h > 0) closes a loop N → F → a → N; its gain is at most 2 μ h / ℓ (ℓ the
  shorter wheelbase, between the axes along x or y; the worst case has the front and rear wheels
  saturated in opposite directions). It is explicit with a one-substep lag: refused at gain ≥ 1
  (h ≥ 0.27 m for the default robot).

The default 8 substeps pass with room; 5 is the fewest the budget accepts.
"""

from __future__ import annotations

import math

import numpy as np

from azimut_env.params import RobotParams
from azimut_env.physics.modules import mass_matrix
from azimut_env.physics.tire import stability_numbers

__all__ = ["stability_figures", "check_stability", "check_substeps", "check_load_scale", "stability_hint",
           "LOADED_MARGIN_MAX"]

#: the largest tire stability margin (b + 2a) a changed load may take (symplectic Euler diverges at 4)
LOADED_MARGIN_MAX = 4.0


def stability_figures(params: RobotParams, dt: float) -> dict[str, tuple[float, float]]:
    """The dimensionless figures of the stability budget (module docstring) for ``params`` and
    the substep ``dt`` [s], each with its bound: ``{name: (value, bound)}``."""
    p, g = params, params.geometry
    load = float(p.static_normal_loads().max())
    i_m = p.steering.module_inertia
    mass, inertia = (float(v) for v in p.body_inertia())
    reach2 = float(np.max((g.l + np.abs(g.b)) ** 2))
    # the effective mass each contact direction sees at P, 1/m = Σ ℓ²/I over the DOFs it
    # moves: along d the wheel spin (r²/I_w), the module about its axis (b²/I_m) and the
    # chassis; along e the chassis only (the module's rotation moves P along d)
    chassis_inv = 1.0 / mass + reach2 / inertia
    m_long = 1.0 / (float(np.max(g.r ** 2 / p.wheel.inertia)) + float(np.max(g.b ** 2)) / i_m + chassis_inv)
    m_lat = 1.0 / chassis_inv
    tire = stability_numbers(p.tire, load, dt, m_long, m_lat, i_m)
    ext = [float(np.ptp(g.axis_xy[:, 0])), float(np.ptp(g.axis_xy[:, 1]))]
    half = min(e for e in ext if e > 0) / 2.0
    out = {}
    for d in ("long", "lat", "twist"):
        out[f"tire_{d}_damping"] = (tire[f"{d}_a"], 1.5)
        out[f"tire_{d}_margin"] = (tire[f"{d}_margin"], 3.0)
    i_spring = i_m
    if p.steering.com_offset > 0:  # the coupled module (modules.py): exact effective inertias
        tire, i_spring = _coupled_budget(p, load, dt)
        for d in ("long", "lat", "twist"):
            out[f"tire_{d}_damping"] = (tire[f"{d}_a"], 1.5)
            out[f"tire_{d}_margin"] = (tire[f"{d}_margin"], 3.0)
    out["spring_omega_dt"] = (math.sqrt(p.steering.stiffness / i_spring) * dt, 0.5)
    out["spring_damping_dt"] = (p.steering.damping / i_spring * dt, 1.0)
    out["load_transfer_gain"] = (p.tire.friction * p.chassis.com_height / half, 1.0)
    if p.wheel.is_dc:  # the drive's torque–speed line, explicit in the spin: a damping τ_stall/ω₀
        out["drive_line_dt"] = (p.wheel.drive_stall_torque / p.wheel.drive_no_load_speed / p.wheel.inertia * dt, 1.0)
    return out


def _coupled_budget(p: RobotParams, load: float, dt: float) -> tuple[dict[str, float], float]:
    """The tire figures and the spring's effective inertia of modules whose centre of mass is off
    the axis: the inverse effective masses J M⁻¹ Jᵀ of the mass matrix (modules.mass_matrix), the
    worst over the wheels and over every module angle on a grid (all modules at the same angle)."""
    g, st = p.geometry, p.steering
    mass, inertia = (float(v) for v in p.body_inertia())
    n = g.n
    inv_long = inv_lat = inv_twist = inv_spring = 0.0
    lo, hi = (-math.pi, math.pi) if g.unlimited_steering else (g.steer_min, g.steer_max)
    for beta in np.linspace(lo, hi, 13):
        gam = g.alpha + beta
        M_inv = np.linalg.inv(mass_matrix(mass, inertia, g.axis_xy, gam, np.full(n, st.module_mass),
                                          np.full(n, st.com_offset), np.full(n, st.module_inertia)))
        for k in range(n):
            u = np.array([math.cos(gam[k]), math.sin(gam[k])])
            d = np.array([u[1], -u[0]])
            arm_perp = np.array([-g.axis_xy[k, 1], g.axis_xy[k, 0]])  # J w_k
            j_d = np.zeros(3 + n)
            j_d[:2], j_d[2], j_d[3 + k] = d, arm_perp @ d, -g.b[k]
            j_e = np.zeros(3 + n)
            j_e[:2], j_e[2] = u, arm_perp @ u
            j_s = np.zeros(3 + n)
            j_s[3 + k], j_s[2] = 1.0, -1.0
            inv_long = max(inv_long, float(j_d @ M_inv @ j_d) + float(g.r[k] ** 2 / p.wheel.inertia))
            inv_lat = max(inv_lat, float(j_e @ M_inv @ j_e))
            inv_twist = max(inv_twist, float(M_inv[3 + k, 3 + k]))
            inv_spring = max(inv_spring, float(j_s @ M_inv @ j_s))
    return stability_numbers(p.tire, load, dt, 1.0 / inv_long, 1.0 / inv_lat, 1.0 / inv_twist), 1.0 / inv_spring


def check_stability(params: RobotParams, dt: float) -> None:
    """Raise ``ValueError`` if ``params`` with the substep ``dt`` [s] are outside the budget."""
    bad = {k: v for k, v in stability_figures(params, dt).items() if not v[0] < v[1] * (1 + 1e-12)}
    if bad:
        what = ", ".join(f"{k} = {v:.3g} (must be <= {b})" for k, (v, b) in bad.items())
        hint = "lower com_height" if set(bad) == {"load_transfer_gain"} else "raise substeps"
        raise ValueError(f"substep {dt:.4g} s with these parameters is outside the stability budget: "
                         f"{what}: {hint}")


def check_substeps(substeps: int, params: RobotParams | None = None, control_period: float = 0.02,
                   flag: str = "--substeps") -> None:
    """Command-line form of :func:`check_stability`: refuse ``substeps`` per ``control_period``
    [s] outside the budget for ``params`` (default :class:`RobotParams`) before any work, in one
    line that names the flag and the smallest count that passes (``ValueError``)."""
    p = params if params is not None else RobotParams()
    try:
        check_stability(p, control_period / substeps)
    except ValueError as exc:
        least = next((k for k in range(substeps + 1, 4097) if _stable(p, control_period / k)), None)
        need = f"use at least {least}" if least else "no count up to 4096 passes"
        raise ValueError(f"{flag} {substeps}: {exc} ({need} at the {control_period:g} s control period)") from None


def _stable(params: RobotParams, dt: float) -> bool:
    try:
        check_stability(params, dt)
        return True
    except ValueError:
        return False


def check_load_scale(params: RobotParams, dt: float, chassis_mass: float) -> None:
    """Raise ``ValueError`` if a chassis of ``chassis_mass`` [kg] loads the tires so much that a
    contact's stability margin reaches :data:`LOADED_MARGIN_MAX` at the substep ``dt`` (the loads,
    so the tire's contact stiffness and the margins, scale with the robot's mass)."""
    scale = params.body_inertia(chassis_mass)[0] / params.total_mass
    worst = max(v for k, (v, _) in stability_figures(params, dt).items() if k.endswith("_margin"))
    if worst * scale >= LOADED_MARGIN_MAX:
        raise ValueError(f"chassis mass {chassis_mass} kg loads the tires {scale:.2f}x the nominal: the contact's "
                         f"stability margin {worst * scale:.2f} would reach 4 at this substep: raise substeps")


def stability_hint(params: RobotParams, dt: float) -> str:
    """The parameters most likely behind a failed stability budget at the substep ``dt`` [s], named
    as a robot file's keys (``docs/robots.md``), for a one-line refusal: each figure past its
    bound with the dominant term of what it depends on (module docstring)."""
    p, g = params, params.geometry
    figures = stability_figures(p, dt)
    bad = [k for k, (v, b) in figures.items() if not v < b * (1 + 1e-12)]
    load = float(p.static_normal_loads().max())
    mass, inertia = (float(v) for v in p.body_inertia())
    i_m = p.steering.module_inertia
    terms = {f"[wheel] inertia = {p.wheel.inertia:g} kg·m² for r_m = {float(np.max(g.r)):g} m":
             float(np.max(g.r ** 2 / p.wheel.inertia)),
             f"b_m = {float(np.max(np.abs(g.b))):g} m for [steering] module_inertia = {i_m:g} kg·m²":
             float(np.max(g.b ** 2)) / i_m,
             f"a {mass:g} kg robot ([chassis] mass, [steering] module_mass)":
             1.0 / mass + float(np.max((g.l + np.abs(g.b)) ** 2)) / inertia}
    hints = []
    for name in bad:
        if name.startswith("tire_long"):
            hints.append(max(terms, key=terms.get))
        elif name.startswith("tire_lat"):
            hints.append(f"a {mass:g} kg robot ([chassis] mass, [steering] module_mass)")
        elif name.startswith("tire_twist"):
            hints.append(f"[steering] module_inertia = {i_m:g} kg·m²")
        elif name.startswith("spring"):
            hints.append(f"[steering] stiffness = {p.steering.stiffness:g}, damping = {p.steering.damping:g} for "
                         f"module_inertia = {i_m:g} kg·m²")
        elif name == "load_transfer_gain":
            hints.append(f"[chassis] com_height = {p.chassis.com_height:g} m")
        else:
            hints.append(f"[wheel] drive_stall_torque = {p.wheel.drive_stall_torque:g} N·m for inertia = "
                         f"{p.wheel.inertia:g} kg·m²")
    if any(name.startswith("tire") for name in bad):
        hints.append(f"a static wheel load of {load:.4g} N (the tire's stiffness grows with it)")
    what = ", ".join(f"{k} = {figures[k][0]:.3g} (must be <= {figures[k][1]:g})" for k in bad)
    return f"{what}; look at {'; '.join(dict.fromkeys(hints))}" if bad else ""
