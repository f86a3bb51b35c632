"""The stages of a step after the physics in one compiled call (:meth:`AzimutTask.observe
<azimut_env.task.core.AzimutTask.observe>`'s fast path).

:class:`TaskArrays` is a named struct (a numba ``StructRef``) that holds references to the task's
per-robot arrays (the same buffers: the kernel writes them in place, the task reads them as
usual) and its constants, so that a step crosses into compiled code once, with two arguments
(the struct and the step's clipped action), instead of once per stage with their own argument
lists. :func:`observe_kernel` then runs the stages in :meth:`AzimutTask.observe`'s order, one
compiled function per stage, each calling the same compiled building blocks as the stage-by-stage
path:

1. :func:`sense`: the sensor models on the physics' true state (the noise normals are drawn
   before the call, from each robot's generator, as in the stage-by-stage path);
2. :func:`estimate`: the IT estimate (λ̂, μ̂, S(λ̂), qua) of the readings;
3. :func:`track`: each robot's track state and look-ahead from its progress before the step;
4. termination (``check_track_limits``), then the reward (the table's compiled kernel,
   :func:`azimut_env.task.reward.reward_kernel`), then :func:`remember_action`;
5. :func:`observe`: the observation rows;
6. :func:`stalls`: the stall check and its penalty.

The same functions in the same order give the same bits as the stage-by-stage path
(``tests/azimut_env/test_compiled_step.py`` steps both side by side). The fast path covers a step
of every robot with the true pose as the pose source; the task falls back to the stages one by one
otherwise (a subset of robots, ``pose_source="odometry"``).
"""

from __future__ import annotations

import hashlib

import numpy as np
from numba import njit, types
from numba.core.caching import NullCache
from numba.experimental import structref

from azimut_env.physics.layout import MS, RS, WS
from azimut_env.task.observation import fill_observation
from azimut_env.task.sensors import _measure_kernel
from azimut_env.task.termination import check_track_limits
from azimut_env.tracks import TQ, query_batch_kernel
from estimation.estimate import IT_PAPER, _eta_it_rows
from estimation.numba_cache import structref_constructor
from estimation.quality import QUALITY_F

__all__ = ["TaskArrays", "FIELDS", "task_arrays", "observe_kernel", "sense", "estimate", "track",
           "remember_action", "observe", "stalls"]


@structref.register
class TaskArraysType(types.StructRef):
    """The numba type of :class:`TaskArrays`."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class TaskArrays(structref.StructRefProxy):
    """An opaque handle on the struct, for compiled code only (build it with :func:`task_arrays`)."""


structref.define_boxing(TaskArraysType, TaskArrays)

_F1, _F2, _F3 = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1]
_B1, _I1 = types.boolean[::1], types.int64[::1]
_S1, _S2 = types.float32[::1], types.float32[:, ::1]

#: the struct's fields: name, numba type, meaning (what :func:`task_arrays` reads from the task)
FIELDS = (
    ("rows", _B1, "every robot (all True): the stages' row mask"),
    # the physics (read)
    ("summary", _F2, "physics.summary (N, RS)"),
    ("wheel_summary", _F3, "physics.wheel_summary (N, n, WS)"),
    ("motor_state", _F3, "physics.motor_state (N, n, MS)"),
    # sensors
    ("normals", _F3, "sensors.normals (N, 3, n): this step's standard normals"),
    ("steer_bias", _F2, "sensors.steer_bias (N, n) [rad]"),
    ("phi_prev", _F2, "sensors.phi_prev (N, n) [rad]"),
    ("sensor_out", _F3, "sensors' scratch (N, 3, n)"),
    ("beta_m", _F2, "measured β (N, n) [rad]"),
    ("motor_m", _F2, "measured motor angles (N, n) [rad]"),
    ("phidot_m", _F2, "measured φ̇ (N, n) [rad/s]"),
    ("control_period", types.float64, "dt [s]"),
    ("steer_noise", types.float64, "SensorParams.steer_noise [rad]"),
    ("motor_noise", types.float64, "SensorParams.motor_noise [rad]"),
    ("steer_resolution", types.float64, "SensorParams.steer_resolution [rad]"),
    ("wheel_cpr", types.int64, "SensorParams.wheel_cpr"),
    ("wheel_speed_noise", types.float64, "SensorParams.wheel_speed_noise [rad/s]"),
    ("wrap_angles", types.boolean, "angle readings modulo 2π (unlimited steering)"),
    # the IT estimate
    ("a_minus_l", _F2, "RobotGeometry.a_minus_l"),
    ("a_perp", _F2, "RobotGeometry.a_perp"),
    ("b", _F1, "RobotGeometry.b [m]"),
    ("r", _F1, "RobotGeometry.r [m]"),
    ("steer_min", types.float64, "RobotGeometry.steer_min [rad]"),
    ("steer_max", types.float64, "RobotGeometry.steer_max [rad]"),
    ("unlimited", types.boolean, "RobotGeometry.unlimited_steering"),
    ("eps_delta", types.float64, "ITParams.eps_delta"),
    ("eps_lambda", types.float64, "ITParams.eps_lambda"),
    ("max_iter", types.int64, "ITParams.max_iter"),
    ("min_step", types.float64, "ITParams.min_step"),
    ("n_starts", types.int64, "ITParams.n_starts"),
    ("race", types.int64, "ITParams.race_iter_or_paper"),
    ("accept_d2", types.float64, "ITParams.accept_d2(n)"),
    ("lam_hat", _F2, "λ̂ (N, 3)"),
    ("mu_hat", _F1, "μ̂ (N,) [m/s]"),
    ("beta_est", _F2, "S(λ̂) (N, n) [rad]"),
    ("qua", _F1, "qua (N,)"),
    # the track state
    ("packs", types.ListType(_F2), "the robots' Track.packed() arrays"),
    ("which", _I1, "0..N−1: robot i on packs[i]"),
    ("track_closed", _B1, "(N,)"),
    ("track_length", _F1, "(N,) [m]"),
    ("track_rho", _F1, "(N,) [m]"),
    ("lookahead_spacing", types.float64, "[m]"),
    ("s_prev", _F1, "progress before the step (N,) [m]"),
    ("track_out", _F2, "track state (N, len(TQ))"),
    ("look", _F3, "look-ahead (N, K, 3)"),
    ("s", _F1, "(N,) [m]"),
    ("lat", _F1, "(N,) [m]"),
    ("head", _F1, "(N,) [rad]"),
    ("v_ref", _F1, "(N,) [m/s]"),
    # termination and reward
    ("max_lateral_error", types.float64, "[m]"),
    ("off_track", _B1, "(N,)"),
    ("finished", _B1, "(N,)"),
    ("track_max_speed", _F1, "(N,) [m/s]"),
    ("v_along", _F1, "(N,) [m/s]"),
    ("reward_inputs", _F2, "(N, len(RewardInput))"),
    ("reward_constants", _F1, "(len(RewardConstant),)"),
    ("weights", _F1, "the reward weights, in the table's order"),
    ("reward_terms", _F2, "(N, T)"),
    ("reward", _F1, "(N,)"),
    ("prev_action", _S2, "(N, 2n) float32"),
    # observation
    ("obs_offsets", _I1, "field_offsets"),
    ("obs_low", _S1, "observation bounds"),
    ("obs_high", _S1, ""),
    ("obs", _S2, "(N, D) float32"),
    # stalls
    ("s_best", _F1, "(N,) [m]"),
    ("best_step", _I1, "(N,)"),
    ("steps", _I1, "(N,)"),
    ("stalled", _B1, "(N,)"),
    ("stall_time", types.float64, "[s]"),
    ("stall_distance", types.float64, "[m]"),
    ("off_track_penalty", types.float64, ""),
    ("off_track_column", types.int64, "the off-track term's column of reward_terms"),
)

_TYPE = TaskArraysType([(name, typ) for name, typ, _ in FIELDS])
_NAMES = [name for name, _, _ in FIELDS]


#: the cached compiled constructor, ``new(*fields)`` in :data:`FIELDS` order
_NEW = structref_constructor(_TYPE, _NAMES, __file__, __name__)

# plain-int columns (numba folds them; the IntEnums stay the names)
_WS_BETA, _MS_THETA, _MS_PHI, _MS_PHIDOT = int(WS.BETA), int(MS.THETA), int(MS.PHI), int(MS.PHIDOT)
_RS_X, _RS_TH, _RS_VX, _RS_VY = int(RS.X), int(RS.TH), int(RS.VX), int(RS.VY)
_RS_SLIP, _RS_ANTAGONISM, _RS_NULLSPACE = int(RS.SLIP), int(RS.ANTAGONISM), int(RS.NULLSPACE)
_TQ_S, _TQ_LATERAL, _TQ_HEADING, _TQ_V_REF = int(TQ.S), int(TQ.LATERAL), int(TQ.HEADING), int(TQ.V_REF)


def task_arrays(task) -> TaskArrays:
    """The struct of an :class:`~azimut_env.task.core.AzimutTask`: references to its arrays
    (which the task must then only write in place) and copies of its constants."""
    sensors, geom, cfg, phys = task.sensors, task.params.geometry, task.config, task.physics
    sp = sensors.params
    it = IT_PAPER
    values = dict(
        rows=task._all, summary=phys.summary, wheel_summary=phys.wheel_summary, motor_state=phys.motor_state,
        normals=sensors.normals, steer_bias=sensors.steer_bias, phi_prev=sensors.phi_prev, sensor_out=sensors._out,
        beta_m=task.beta_m, motor_m=task.motor_m, phidot_m=task.phidot_m, control_period=float(cfg.control_period),
        steer_noise=float(sp.steer_noise), motor_noise=float(sp.motor_noise),
        steer_resolution=float(sp.steer_resolution), wheel_cpr=int(sp.wheel_cpr),
        wheel_speed_noise=float(sp.wheel_speed_noise), wrap_angles=bool(sensors.wrap_angles),
        a_minus_l=np.array(geom.a_minus_l), a_perp=np.array(geom.a_perp), b=np.array(geom.b), r=np.array(geom.r),
        steer_min=float(geom.steer_min), steer_max=float(geom.steer_max), unlimited=bool(geom.unlimited_steering),
        eps_delta=float(it.eps_delta), eps_lambda=float(it.eps_lambda), max_iter=int(it.max_iter),
        min_step=float(it.min_step), n_starts=int(it.n_starts), race=int(it.race_iter_or_paper),
        accept_d2=float(it.accept_d2(geom.n)), lam_hat=task.lam_hat, mu_hat=task.mu_hat, beta_est=task.beta_est,
        qua=task.qua, packs=task._packs, which=np.arange(task.n_robots, dtype=np.int64),
        track_closed=task.track_closed, track_length=task.track_length, track_rho=task.track_rho,
        lookahead_spacing=float(cfg.lookahead_spacing), s_prev=np.zeros(task.n_robots), track_out=task.track_out,
        look=task.look, s=task.s, lat=task.lat, head=task.head, v_ref=task.v_ref,
        max_lateral_error=float(cfg.max_lateral_error), off_track=task.off_track, finished=task.finished,
        track_max_speed=task.track_max_speed, v_along=task.v_along, reward_inputs=task.reward_inputs,
        reward_constants=task._reward_constants, weights=task._weights, reward_terms=task.reward_terms,
        reward=task.reward, prev_action=task.prev_action, obs_offsets=task._obs_offsets, obs_low=task.obs_low,
        obs_high=task.obs_high, obs=task.obs, s_best=task.s_best, best_step=task.best_step, steps=task.steps,
        stalled=task.stalled, stall_time=float(cfg.stall_time), stall_distance=float(cfg.stall_distance),
        off_track_penalty=float(cfg.off_track_penalty), off_track_column=int(task._off_track_column))
    return _NEW(*[values[name] for name in _NAMES])


# ----------------------------------------------------------------------------------- stages


@njit(cache=True)
def sense(ta) -> None:
    """:meth:`SensorState.measure <azimut_env.task.sensors.SensorState.measure>` of every robot."""
    phi = ta.motor_state[:, :, _MS_PHI]
    _measure_kernel(ta.wheel_summary[:, :, _WS_BETA] + ta.steer_bias, ta.motor_state[:, :, _MS_THETA], phi,
                    ta.phi_prev, ta.motor_state[:, :, _MS_PHIDOT], ta.control_period, ta.steer_noise, ta.motor_noise,
                    ta.steer_resolution, ta.wheel_cpr, ta.wheel_speed_noise, ta.normals, ta.sensor_out,
                    ta.wrap_angles)
    ta.phi_prev[:] = phi
    ta.beta_m[:] = ta.sensor_out[:, 0]
    ta.motor_m[:] = ta.sensor_out[:, 1]
    ta.phidot_m[:] = ta.sensor_out[:, 2]


@njit(cache=True)
def estimate(ta) -> None:
    """``estimation.estimate.estimate_eta_rows`` (IT) of every robot's readings."""
    _eta_it_rows(ta.beta_m, ta.phidot_m, ta.a_minus_l, ta.a_perp, ta.b, ta.r, ta.steer_min, ta.steer_max,
                 ta.unlimited, ta.eps_delta, ta.eps_lambda, ta.max_iter, ta.min_step, ta.n_starts, ta.race,
                 ta.accept_d2, 1e-3, QUALITY_F, ta.lam_hat, ta.mu_hat, ta.beta_est, ta.qua)


@njit(cache=True)
def track(ta) -> None:
    """Every robot's track state (``query_tracks`` from the progress before the step)."""
    ta.s_prev[:] = ta.s
    query_batch_kernel(ta.packs, ta.which, ta.track_closed, ta.track_length, ta.track_rho,
                       ta.summary[:, _RS_X:_RS_TH + 1], ta.s_prev, 0.5, 1.0, ta.lookahead_spacing, ta.track_out,
                       ta.look)
    ta.s[:] = ta.track_out[:, _TQ_S]
    ta.lat[:] = ta.track_out[:, _TQ_LATERAL]
    ta.head[:] = ta.track_out[:, _TQ_HEADING]
    ta.v_ref[:] = ta.track_out[:, _TQ_V_REF]


@njit(cache=True)
def remember_action(ta, action) -> None:
    """``prev_action`` takes the step's clipped action."""
    ta.prev_action[:] = action


@njit(cache=True)
def observe(ta) -> None:
    """The observation rows (``fill_observation`` with the true track state)."""
    fill_observation(ta.rows, ta.obs_offsets, ta.lam_hat, ta.mu_hat, ta.beta_m, ta.phidot_m, ta.motor_m,
                     ta.track_out, ta.look, ta.summary[:, _RS_VX:_RS_VY + 1], ta.prev_action, ta.obs_low, ta.obs_high,
                     ta.obs)


@njit(cache=True)
def stalls(ta) -> None:
    """``termination.check_stalls`` and, for the robots that stalled, ``reward.charge_penalty``."""
    for i in range(ta.rows.shape[0]):
        if ta.rows[i] and ta.s[i] > ta.s_best[i] + ta.stall_distance:
            ta.s_best[i] = ta.s[i]
            ta.best_step[i] = ta.steps[i]
    if ta.stall_time <= 0:
        return
    col = ta.off_track_column
    for i in range(ta.rows.shape[0]):
        stalled = ta.rows[i] and not ta.off_track[i] and (ta.steps[i] - ta.best_step[i]) * ta.control_period >= \
            ta.stall_time
        ta.stalled[i] = stalled
        if stalled:
            ta.reward[i] += -ta.off_track_penalty - ta.reward_terms[i, col]
            ta.reward_terms[i, col] = -ta.off_track_penalty


_KERNELS: dict = {}


def observe_kernel(reward_kernel):
    """The compiled step after the physics, ``kernel(task_arrays, action)``, for the reward table
    whose compiled kernel is ``reward_kernel``: the stages of the module docstring in their order.
    Its source is generated (the reward kernel is a compiled function of its own, named after
    its table), so numba caches one per table under a name that hashes it."""
    kernel = _KERNELS.get(reward_kernel)
    if kernel is not None:
        return kernel
    src = f"""def _observe(ta, action):
    sense(ta)
    estimate(ta)
    track(ta)
    check_track_limits(ta.rows, ta.track_out, ta.track_length, ta.max_lateral_error, ta.off_track, ta.finished)
    # the reward: {reward_kernel.__name__}
    _reward(ta.rows, ta.track_out, ta.s_prev, ta.summary[:, {_RS_VX}:{_RS_VY + 1}], ta.track_max_speed,
            ta.summary[:, {_RS_SLIP}], ta.summary[:, {_RS_ANTAGONISM}], ta.summary[:, {_RS_NULLSPACE}], action,
            ta.prev_action, ta.off_track, ta.v_along, ta.reward_inputs, ta.reward_constants, ta.weights,
            ta.reward_terms, ta.reward)
    remember_action(ta, action)
    observe(ta)
    stalls(ta)
"""
    name = "_observe_" + hashlib.sha256(src.encode()).hexdigest()[:16]
    namespace = {"sense": sense, "estimate": estimate, "track": track, "check_track_limits": check_track_limits,
                 "_reward": reward_kernel, "remember_action": remember_action, "observe": observe, "stalls": stalls,
                 "__name__": __name__}
    exec(compile(src.replace("def _observe(", f"def {name}("), __file__, "exec"), namespace)
    cached = not isinstance(getattr(reward_kernel, "_cache", None), NullCache)  # as the reward kernel is
    kernel = _KERNELS[reward_kernel] = njit(cache=cached)(namespace[name])
    return kernel
