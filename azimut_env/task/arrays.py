"""The task's per-robot arrays and constants: one struct, one field table.

:data:`FIELDS` lists every array and constant the stages of the pipeline
(:mod:`azimut_env.task.pipeline`) read or write: its name, its numba type, how it is made from the
:class:`~azimut_env.task.core.AzimutTask`, and what it holds. :func:`task_arrays` builds them
once per task: the arrays the task owns (``own``: allocated here, leading axis N, and set as the
task's attributes of the same names: ``task.lam_hat``, ``task.obs``...) and references to those of
the physics, the sensors and the pose source, plus the settings as constants. It returns the same
values twice: as a numba ``StructRef`` (:class:`TaskArrays`, what the compiled stages take: one
argument instead of fifty) and as a plain namespace (what Python stages and the reference path,
the stages' ``py_func``, take). Both hold the same buffers: the stages write them in place.

**To add a quantity** a stage reads or writes: a row here (a new sensor's readings, a new
condition's state); every stage then reads it as ``ta.<name>``.
"""

from __future__ import annotations

from collections.abc import Callable
from types import SimpleNamespace
from typing import Any, NamedTuple

import numpy as np
from numba import types
from numba.experimental import structref

from azimut_env.physics.layout import RS_VEL_WORLD
from azimut_env.tracks import TQ
from estimation.estimate import IT_PAPER
from estimation.numba_cache import structref_constructor

__all__ = ["Field", "FIELDS", "TaskArrays", "task_arrays"]


@structref.register
class TaskArraysType(types.StructRef):
    """The numba type of :class:`TaskArrays`."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class TaskArrays(structref.StructRefProxy):
    """An opaque handle on the struct, for compiled code only (build it with :func:`task_arrays`)."""


structref.define_boxing(TaskArraysType, TaskArrays)


class Field(NamedTuple):
    """One field of the struct: a row of :data:`FIELDS`."""

    name: str
    type: Any
    #: ``make(task)``: the value (an array the task owns, a reference, or a constant)
    make: Callable[[Any], Any]
    doc: str
    #: allocated here and set as the task's attribute ``name``
    own: bool = False


_F1, _F2, _F3, _FA = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1], types.float64[:, :]
_B1, _B2, _I1 = types.boolean[::1], types.boolean[:, ::1], types.int64[::1]
_S1, _S2 = types.float32[::1], types.float32[:, ::1]
_f, _i, _b = types.float64, types.int64, types.boolean


def _zeros(*shape: Callable, dtype=np.float64) -> Callable:
    return lambda t: np.zeros(tuple(s(t) for s in shape), dtype=dtype)


def _N(t):
    return t.n_robots


def _n(t):
    return t.n


def _K(t):
    return t.config.lookahead_count


def _c(k):
    return lambda t: k


def _pose_source(name: str, true: Callable) -> Callable:
    return lambda t: getattr(t.odometry, name) if t.odometry is not None else true(t)


_IT = IT_PAPER
_Fd = Field
#: the struct's fields, in order: name, numba type, maker, meaning, owned by the task
FIELDS: tuple[Field, ...] = (
    # the physics (read)
    _Fd("summary", _F2, lambda t: t.physics.summary, "physics.summary (N, RS)"),
    _Fd("wheel_summary", _F3, lambda t: t.physics.wheel_summary, "physics.wheel_summary (N, n, WS)"),
    _Fd("motor_state", _F3, lambda t: t.physics.motor_state, "physics.motor_state (N, n, MS)"),
    _Fd("steps", _I1, _zeros(_N, dtype=np.int64), "steps since each robot's reset (N,)", True),
    # sensors (azimut_env.task.sensors)
    _Fd("normals", _F3, lambda t: t.sensors.normals, "sensors.normals (N, 3, n): this step's standard normals"),
    _Fd("steer_bias", _F2, lambda t: t.sensors.steer_bias, "sensors.steer_bias (N, n) [rad]"),
    _Fd("phi_prev", _F2, lambda t: t.sensors.phi_prev, "sensors.phi_prev (N, n) [rad]"),
    _Fd("beta_m", _F2, lambda t: t.sensors.beta, "measured β (N, n) [rad]"),
    _Fd("motor_m", _F2, lambda t: t.sensors.motor, "measured motor angles (N, n) [rad]"),
    _Fd("phidot_m", _F2, lambda t: t.sensors.phidot, "measured φ̇ (N, n) [rad/s]"),
    _Fd("control_period", _f, lambda t: float(t.config.control_period), "dt [s]"),
    _Fd("steer_noise", _f, lambda t: float(t.params.sensors.steer_noise), "SensorParams.steer_noise [rad]"),
    _Fd("motor_noise", _f, lambda t: float(t.params.sensors.motor_noise), "SensorParams.motor_noise [rad]"),
    _Fd("steer_resolution", _f, lambda t: float(t.params.sensors.steer_resolution),
        "SensorParams.steer_resolution [rad]"),
    _Fd("wheel_cpr", _i, lambda t: int(t.params.sensors.wheel_cpr), "SensorParams.wheel_cpr"),
    _Fd("wheel_speed_noise", _f, lambda t: float(t.params.sensors.wheel_speed_noise),
        "SensorParams.wheel_speed_noise [rad/s]"),
    _Fd("wrap_angles", _b, lambda t: bool(t.sensors.wrap_angles), "angle readings modulo 2π (unlimited steering)"),
    # the IT estimate (azimut_env.task.icr_estimate)
    _Fd("a_minus_l", _F2, lambda t: np.array(t.params.geometry.a_minus_l), "RobotGeometry.a_minus_l"),
    _Fd("a_perp", _F2, lambda t: np.array(t.params.geometry.a_perp), "RobotGeometry.a_perp"),
    _Fd("b", _F1, lambda t: np.array(t.params.geometry.b), "RobotGeometry.b [m]"),
    _Fd("r", _F1, lambda t: np.array(t.params.geometry.r), "RobotGeometry.r [m]"),
    _Fd("steer_min", _f, lambda t: float(t.params.geometry.steer_min), "RobotGeometry.steer_min [rad]"),
    _Fd("steer_max", _f, lambda t: float(t.params.geometry.steer_max), "RobotGeometry.steer_max [rad]"),
    _Fd("unlimited", _b, lambda t: bool(t.params.geometry.unlimited_steering), "RobotGeometry.unlimited_steering"),
    _Fd("eps_delta", _f, _c(float(_IT.eps_delta)), "ITParams.eps_delta"),
    _Fd("eps_lambda", _f, _c(float(_IT.eps_lambda)), "ITParams.eps_lambda"),
    _Fd("max_iter", _i, _c(int(_IT.max_iter)), "ITParams.max_iter"),
    _Fd("min_step", _f, _c(float(_IT.min_step)), "ITParams.min_step"),
    _Fd("n_starts", _i, _c(int(_IT.n_starts)), "ITParams.n_starts"),
    _Fd("race", _i, _c(int(_IT.race_iter_or_paper)), "ITParams.race_iter_or_paper"),
    _Fd("accept_d2", _f, lambda t: float(_IT.accept_d2(t.n)), "ITParams.accept_d2(n)"),
    _Fd("lam_hat", _F2, lambda t: np.tile(np.array([0.0, 0.0, 1.0]), (t.n_robots, 1)), "λ̂ (N, 3)", True),
    _Fd("mu_hat", _F1, _zeros(_N), "μ̂ (N,) [m/s]", True),
    _Fd("beta_est", _F2, _zeros(_N, _n), "S(λ̂) (N, n) [rad]", True),
    _Fd("qua", _F1, lambda t: np.ones(t.n_robots), "qua (N,)", True),
    # the true track state (azimut_env.task.track_state)
    _Fd("packs", types.ListType(_F2), lambda t: t._packs, "the robots' Track.packed() arrays"),
    _Fd("track_closed", _B1, lambda t: np.array([k.closed for k in t.tracks], dtype=np.bool_), "(N,)", True),
    _Fd("track_length", _F1, lambda t: np.array([k.length for k in t.tracks]), "(N,) [m]", True),
    _Fd("track_rho", _F1, lambda t: np.array([k.progress_radius for k in t.tracks]), "(N,) [m]", True),
    _Fd("track_max_speed", _F1, lambda t: np.array([k.max_speed for k in t.tracks]), "(N,) [m/s]", True),
    _Fd("lookahead_spacing", _f, lambda t: float(t.config.lookahead_spacing), "[m]"),
    _Fd("s_prev", _F1, _zeros(_N), "progress before the step (N,) [m]", True),
    _Fd("track_out", _F2, _zeros(_N, _c(len(TQ))), "track state (N, len(TQ))", True),
    _Fd("look", _F3, _zeros(_N, _K, _c(3)), "look-ahead (N, K, 3)", True),
    _Fd("s", _F1, _zeros(_N), "progress (N,) [m]", True),
    _Fd("lat", _F1, _zeros(_N), "lateral error (N,) [m]", True),
    _Fd("head", _F1, _zeros(_N), "heading error (N,) [rad]", True),
    _Fd("v_ref", _F1, _zeros(_N), "reference speed (N,) [m/s]", True),
    _Fd("v_along", _F1, _zeros(_N), "chassis speed along the path (N,) [m/s]", True),
    # what the observation sees: the true track state or the odometry's (azimut_env.task.localisation)
    _Fd("obs_track", _F2, _pose_source("track_state", lambda t: t.track_out), "(N, len(TQ))"),
    _Fd("obs_look", _F3, _pose_source("look", lambda t: t.look), "(N, K, 3)"),
    _Fd("obs_vel", _FA, _pose_source("vel", lambda t: t.physics.summary[:, RS_VEL_WORLD]), "world velocity (N, 2)"),
    # termination (azimut_env.task.termination)
    _Fd("max_lateral_error", _f, lambda t: float(t.config.max_lateral_error), "[m]"),
    _Fd("stall_time", _f, lambda t: float(t.config.stall_time), "[s]"),
    _Fd("stall_distance", _f, lambda t: float(t.config.stall_distance), "[m]"),
    _Fd("s_best", _F1, _zeros(_N), "best progress (N,) [m]", True),
    _Fd("best_step", _I1, _zeros(_N, dtype=np.int64), "the step of s_best (N,)", True),
    _Fd("ended", _B2, lambda t: np.zeros((t.n_robots, len(t.termination_table)), dtype=np.bool_),
        "each end condition's flag of the last step (N, T)", True),
    _Fd("failed", _B1, _zeros(_N, dtype=np.bool_), "the last step ended by a failure (N,)", True),
    # reward (azimut_env.task.reward)
    _Fd("reward_inputs", _F2, lambda t: np.zeros((t.n_robots, t.reward_input_count)), "(N, len(RewardInput))", True),
    _Fd("reward_constants", _F1, lambda t: t.reward_constant_values, "(len(RewardConstant),)"),
    _Fd("weights", _F1, lambda t: t.weight_values, "the reward weights, in the table's order"),
    _Fd("reward_terms", _F2, lambda t: np.zeros((t.n_robots, len(t.reward_table))), "(N, T)", True),
    _Fd("reward", _F1, _zeros(_N), "(N,)", True),
    _Fd("prev_action", _S2, lambda t: np.zeros((t.n_robots, 2 * t.n), dtype=np.float32), "(N, 2n) float32", True),
    # observation (azimut_env.task.observation)
    _Fd("obs_offsets", _I1, lambda t: t.obs_offsets, "each field's start, then the length"),
    _Fd("obs_low", _S1, lambda t: t.obs_low, "observation bounds"),
    _Fd("obs_high", _S1, lambda t: t.obs_high, ""),
    _Fd("obs", _S2, lambda t: np.zeros((t.n_robots, t.obs_low.shape[0]), dtype=np.float32), "(N, D) float32", True),
)
del _Fd

_CONSTRUCTORS: dict[tuple, Callable] = {}


def _constructor(fields: tuple[Field, ...]) -> Callable:
    key = tuple((f.name, f.type) for f in fields)
    new = _CONSTRUCTORS.get(key)
    if new is None:
        new = _CONSTRUCTORS[key] = structref_constructor(TaskArraysType(list(key)), [k for k, _ in key], __file__,
                                                         __name__)
    return new


def allocate(task: Any) -> None:
    """The arrays the task owns (the rows of :data:`FIELDS` with ``own``), set as its attributes."""
    for f in FIELDS:
        if f.own:
            setattr(task, f.name, f.make(task))


def task_arrays(task: Any, jit: bool = True) -> tuple[Any, SimpleNamespace]:
    """(the struct, the namespace) of a task's fields (:func:`allocate` first): the struct a
    compiled :class:`TaskArrays` (None with ``jit=False``), the namespace the same values by name."""
    fields = FIELDS
    values = {f.name: getattr(task, f.name) if f.own else f.make(task) for f in fields}
    ns = SimpleNamespace(**values)
    if not jit:
        return None, ns
    return _constructor(fields)(*values.values()), ns
