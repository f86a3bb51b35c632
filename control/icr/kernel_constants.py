"""What the compiled ICR controller step reads besides the robots' state: one named struct per
controller (:class:`ICRConstants`, a numba ``StructRef``), built once by :func:`compiled_constants`,
and the work space of one step (:data:`WS` rows of one (len(WS), max(n, 3)) array).

The struct holds the robot's geometry (the arrays of :class:`~estimation.geometry.RobotGeometry`
and its stop circles' normals), the limit constants and the tuning as float arrays (indices
``L_*`` and ``C_*`` of :mod:`control.icr.kernels`), the κ grid and the control period, so that the
step and its motion primitives take one argument for all of them instead of a dozen positional
ones. Every constant is computed here once, in Python floats. Without JIT
(``NUMBA_DISABLE_JIT=1``) the struct is a named tuple of the same fields.

The work space replaces the small arrays the row functions used to allocate for every robot and
step: its rows are named (:class:`WS`), a function reads the rows it needs.
"""

from __future__ import annotations

import hashlib
from enum import IntEnum

import numpy as np
from numba import types
from numba.experimental import structref

from control.icr.config import ICRControllerConfig
from control.icr.kernels import (
    L_A_DT,
    L_ACCEL_LAM,
    L_BRAKE_DT,
    L_CO_C1,
    L_HEADROOM_WSM,
    L_MU_ACCEL,
    L_NEG_WSM_SLACK,
    L_RC_A,
    L_RC_BRAKE,
    L_RC_C1,
    L_RC_VMAX,
    L_SAM,
    L_SAT_C1,
    L_SRM,
    L_STEER_LO,
    L_UNLIMITED,
    L_WA_DT,
    L_WA_DT_SLACK,
    L_WAM,
    L_WSM,
    L_WSM_SLACK,
    N_LIM,
    stop_normals,
)
from control.limits import ActuatorLimits
from estimation.geometry import RobotGeometry
from estimation.numba_cache import structref_constructor

__all__ = ["ICRConstants", "compiled_constants", "private_constants", "WS", "N_WS"]


@structref.register
class ICRConstantsType(types.StructRef):
    """The numba type of :class:`ICRConstants`."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class ICRConstants(structref.StructRefProxy):
    """An opaque handle on the struct, for compiled code (build it with :func:`compiled_constants`)."""


structref.define_boxing(ICRConstantsType, ICRConstants)

_F1, _F2 = types.float64[::1], types.float64[:, ::1]

#: the struct's fields: name, numba type, meaning
FIELDS = (
    ("E", _F2, "RobotGeometry.a_minus_l (n, 3)"),
    ("P", _F2, "RobotGeometry.a_perp (n, 3)"),
    ("b", _F1, "RobotGeometry.b (n,) [m]"),
    ("r", _F1, "RobotGeometry.r (n,) [m]"),
    ("steer_min", types.float64, "RobotGeometry.steer_min [rad]"),
    ("steer_max", types.float64, "RobotGeometry.steer_max [rad]"),
    ("s_unit", _F2, "RobotGeometry.s_unit (n, 3): the steering axes"),
    ("normals", _F2, "the stop circles' unit normals (n, 3) (control.icr.kernels.stop_normals)"),
    ("lim", _F1, "the limit constants (N_LIM,), indices L_*"),
    ("tune", _F1, "the tuning (21,), indices C_*"),
    ("kappa", _F1, "the κ grid (n_kappa,)"),
    ("dt", types.float64, "the control period [s]"),
)

_TYPE = ICRConstantsType([(name, typ) for name, typ, _ in FIELDS])
_NAMES = [name for name, _, _ in FIELDS]


#: the cached compiled constructor, ``new(*fields)`` in :data:`FIELDS` order
_NEW = structref_constructor(_TYPE, _NAMES, __file__, __name__)


def _private_copy():
    """``private(c)``: the struct with copies of its arrays, compiled (cached under a name that
    hashes its source, generated from :data:`FIELDS`)."""
    from numba import njit

    args = ", ".join(f"c.{name}.copy()" if isinstance(typ, types.Array) else f"c.{name}" for name, typ, _ in FIELDS)
    src = f"def _private(c):\n    return _new({args})\n"
    name = "_private_" + hashlib.sha256(src.encode()).hexdigest()[:16]
    scope = {"_new": _NEW, "__name__": __name__}
    exec(compile(src.replace("def _private(", f"def {name}("), __file__, "exec"), scope)
    return njit(cache=True)(scope[name])


#: ``private_constants(c)``: the struct with arrays of its own. Each block of a step on several
#: threads takes one: the step passes these arrays to a function per robot, and the shared struct's
#: arrays carry one reference count that the threads would contend for (estimation/threads.py)
private_constants = _private_copy()


def stop_circle_normals(geom: RobotGeometry) -> np.ndarray:
    """(n, 3) the unit normals of the wheels' stop circles (:func:`control.icr.kernels.stop_normals`)."""
    normals = np.empty((geom.n, 3))
    stop_normals(np.ascontiguousarray(geom.a_minus_l, dtype=np.float64),
                 np.ascontiguousarray(geom.a_perp, dtype=np.float64), float(geom.steer_max), normals)
    return normals


def compiled_constants(geom: RobotGeometry, limits: ActuatorLimits, config: ICRControllerConfig,
                       dt: float) -> ICRConstants:
    """The struct of (geom, limits, config, dt): every constant the step reads, computed in Python
    floats."""
    sam, srm, wsm, wam = (float(limits.steer_accel_max), float(limits.steer_rate_max), float(limits.wheel_speed_max),
                          float(limits.wheel_accel_max))
    lim = np.zeros(N_LIM)

    def stop_speed(at: int, accel: float) -> None:
        lim[at], lim[at + 1], lim[at + 2] = -0.5 * accel * dt, (0.5 * accel * dt) ** 2, 2.0 * accel

    lim[L_SAM], lim[L_SRM], lim[L_WSM], lim[L_WAM] = sam, srm, wsm, wam
    lim[L_A_DT], lim[L_WA_DT], lim[L_STEER_LO] = sam * dt, wam * dt, geom.steer_min + 1e-9
    stop_speed(L_SAT_C1, 0.95 * sam)
    stop_speed(L_CO_C1, 0.8 * sam)
    lim[L_ACCEL_LAM] = 0.8 * sam
    a = sam * config.reconfig_accel_fraction
    lim[L_RC_A], lim[L_RC_VMAX] = a, srm * config.reconfig_rate_fraction
    stop_speed(L_RC_C1, 0.85 * a)
    lim[L_RC_BRAKE] = float(np.maximum(a, 0.95 * sam))
    lim[L_MU_ACCEL] = config.mu_accel_fraction * wam
    slack = 1.0 - 1e-9
    lim[L_WSM_SLACK], lim[L_WA_DT_SLACK], lim[L_NEG_WSM_SLACK] = wsm * slack, wam * dt * slack, -wsm * slack
    lim[L_HEADROOM_WSM] = config.mu_headroom * wsm
    lim[L_BRAKE_DT] = sam * dt
    lim[L_UNLIMITED] = 1.0 if geom.unlimited_steering else 0.0
    tune = np.array([config.zero_mu_tol, config.axis_margin, config.arc_step, np.sin(0.5 * config.axis_margin),
                     config.stop_hysteresis, config.stop_hold_distance, config.kick_tol, config.stop_mu_tol,
                     config.stop_timeout, config.reconfig_freeze, config.reconfig_tol, config.reconfig_hold_tol,
                     config.reconfig_still_tol, config.reconfig_timeout, config.k_lambda,
                     float(config.coupling_from_measurement), float(config.mu_own_scale), config.stop_hold_speed,
                     config.stop_hold_angle, config.stop_hold_margin, config.planned_hold_distance],
                    dtype=np.float64)
    E, P = np.ascontiguousarray(geom.a_minus_l, dtype=np.float64), np.ascontiguousarray(geom.a_perp, dtype=np.float64)
    normals = stop_circle_normals(geom)
    values = dict(E=E, P=P, b=np.ascontiguousarray(geom.b, dtype=np.float64),
                  r=np.ascontiguousarray(geom.r, dtype=np.float64), steer_min=float(geom.steer_min),
                  steer_max=float(geom.steer_max), s_unit=np.ascontiguousarray(geom.s_unit, dtype=np.float64),
                  normals=normals, lim=lim, tune=tune, kappa=np.linspace(0.0, 1.0, config.n_kappa), dt=float(dt))
    return _NEW(*[values[name] for name in _NAMES])


class WS(IntEnum):
    """The rows of a step's work space (3-vectors in the first three columns, per-wheel values in
    the first n)."""

    # the motion primitives (control.icr.kernels_motion)
    U = 0  # a candidate λ, normalised twice
    G = 1  # a wheel's steering gradient
    SCRATCH = 2
    V_DES = 3  # the desired λ̇ (tangent)
    V_PREV = 4  # the previous λ̇ (tangent)
    LAM_NEW = 5  # the chosen candidate's λ
    V = 6  # the chosen candidate's λ̇
    C_NOW = 7  # the wheel speed coefficients at λ
    BETA_WORK = 8
    BETA_NEW = 9  # the chosen candidate's β, β̇, φ̇, c
    BETA_RATE = 10
    PHIDOT = 11
    C = 12
    WANT_BETA = 13  # saturate's wanted β, φ̇
    WANT_PHIDOT = 14
    SAT_BETA = 15
    SAT_RATE = 16
    # the step (control.icr.compiled)
    LAM = 17  # the robot's reference λ before the step
    LAM_D = 18  # the feasible target
    TARGET = 19  # the unit target before the axis caps
    HOLD = 20  # the hold point at a steering stop
    CELL = 21
    S_LAM = 22  # the reference (λ, λ̇) the commands start from
    S_LAM_RATE = 23
    BETA0 = 24  # the robot's β_c, β̇_c, φ̇_c before the step
    RATE0 = 25
    PHIDOT0 = 26
    BETA_TARGET = 27  # RECONFIGURING: the steering target
    MEASURED_RATE = 28
    ARC = 29  # arc_check_row's work space
    LAM1 = 30  # the robot's λ, λ̇, β_c, β̇_c, φ̇_c after the step
    LAM_RATE1 = 31
    BETA1 = 32
    RATE1 = 33
    PHIDOT1 = 34
    RECONFIG_LAM = 35  # the λ the wheels are being reconfigured for


#: the number of rows of the work space
N_WS = len(WS)
