"""The ICR controller's step compiled: :func:`compiled_control_step_batch`, one numba call for all robots.

It is the ICR controller's step, the only implementation (what
:func:`control.icr.controller.icr_control_step_batch`, ``ICRController`` and ``BatchICRController``
run), row by row: the feasible target, the mode transitions and each mode's commands (the
building blocks are in :mod:`control.icr.kernels` and :mod:`control.icr.kernels_motion`). The time
scaling tries κ from 1 down and stops at the first feasible one, and an arc check stops at its
first blocked sample. The tests' reference is this code run as plain Python
(``NUMBA_DISABLE_JIT=1``): ``tests/control/test_icr_compiled.py`` replays recorded episodes through
both and requires the same commands, modes, events and state to the bit.

The kernel takes the robot's constants as one named struct (:func:`compiled_constants`), the
state before and after the step as the fields of :class:`~control.icr.state.ICRBatchState` (two
tuples), the step's inputs and its outputs (two tuples); each robot's row is copied into a work
space (:class:`~control.icr.kernel_constants.WS`) and its results copied out, so that no row
function allocates or takes a view.

Input checks are those of ``icr_control_step_batch``, with the same messages (the finiteness
checks run inside the kernel, before anything is written). A step may cover a subset of the
robots (``rows``): the other rows of the state are carried over unchanged.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from control.commands import WheelCommand
from control.icr.config import ICRControllerConfig
from control.icr.kernel_constants import N_WS, WS, compiled_constants, private_constants
from control.icr.kernels import (
    ARC_AXIS,
    ARC_NONE,
    ARC_STOP,
    C_ARC_STEP,
    C_AXIS_MARGIN,
    C_COUPLING_MEAS,
    C_FREEZE,
    C_HOLD_ANGLE,
    C_HOLD_DIST,
    C_HOLD_MARGIN,
    C_HOLD_SPEED,
    C_HOLD_TOL,
    C_KICK,
    C_PLAN_HOLD_DIST,
    C_RECONFIG_TIMEOUT,
    C_RECONFIG_TOL,
    C_SIN_HALF_MARGIN,
    C_STILL_TOL,
    C_STOP_HYST,
    C_STOP_MU,
    C_STOP_TIMEOUT,
    C_ZERO_MU,
    EXCURSION_END,
    EXCURSION_NONE,
    EXCURSION_PLANNED,
    L_BRAKE_DT,
    L_HEADROOM_WSM,
    L_UNLIMITED,
    arc_check_row,
    dot3,
    in_cell,
    nearest1,
    nearest_in_cell,
    norm3,
    project_off_axes_row,
    slerp3,
    speed_coefs_row,
    steering_difference1,
    steering_row,
    stop_hold_row,
    unit_xyz,
    wrap_half1,
)
from control.icr.kernels_motion import coordinated_row, reconfigure_row
from control.icr.state import ICRBatchState
from control.limits import ActuatorLimits
from estimation.geometry import RobotGeometry
from estimation.threads import BlockKernel

__all__ = ["compiled_control_step_batch", "compiled_constants"]

_RUNNING, _STOPPING, _RECONFIGURING = 0, 1, 2  # Mode
_EV_NONE, _EV_KICK = 0, 1  # Event (STOP and AXIS are the arc reason + 1)

_ERRORS = ("lam_hat contains NaN or inf", "lam_hat is the zero vector, not a point of Λ", "mu_hat contains NaN or inf",
           "beta_meas contains NaN or inf", "phidot_meas contains NaN or inf", "lam_d contains NaN or inf",
           "lam_d is the zero vector, not a point of Λ", "mu_d contains NaN or inf")


@njit(cache=True)
def _validate(lam_hat, mu_hat, beta_meas, phidot_meas, lam_d, mu_d) -> int:
    """0, or 1 + the index of the first failed check in :data:`_ERRORS` (in the order of
    ``icr_control_step_batch``'s checks)."""
    for i in range(lam_hat.shape[0]):
        for j in range(3):
            if not math.isfinite(lam_hat[i, j]):
                return 1
    for i in range(lam_hat.shape[0]):
        if norm3(lam_hat[i]) == 0:
            return 2
    for i in range(mu_hat.shape[0]):
        if not math.isfinite(mu_hat[i]):
            return 3
    for arr, code in ((beta_meas, 4), (phidot_meas, 5)):
        for i in range(arr.shape[0]):
            for k in range(arr.shape[1]):
                if not math.isfinite(arr[i, k]):
                    return code
    for i in range(lam_d.shape[0]):
        for j in range(3):
            if not math.isfinite(lam_d[i, j]):
                return 6
    for i in range(lam_d.shape[0]):
        if norm3(lam_d[i]) == 0:
            return 7
    for i in range(mu_d.shape[0]):
        if not math.isfinite(mu_d[i]):
            return 8
    return 0


@njit(cache=True)
def _must_stop(c, ws, lam, lam_d) -> bool:
    """Whether reaching λ_d from λ needs a stop and reconfiguration: the arc passes a steering axis,
    or goes past a steering stop by more than ``stop_hysteresis``."""
    tune = c.tune
    reason, free, theta = arc_check_row(lam, lam_d, c.E, c.P, c.steer_max, c.s_unit, tune[C_SIN_HALF_MARGIN],
                                        tune[C_ARC_STEP], c.lim[L_UNLIMITED] != 0.0, ws[WS.ARC, :c.b.shape[0]])
    return reason == ARC_AXIS or (reason == ARC_STOP and theta - free >= tune[C_STOP_HYST])


@njit(cache=True)
def _differs(rlam, ld, md, speed) -> bool:
    """Whether the motion (λ_d, μ_d) differs from one at ``rlam`` by ``speed`` or more: |μ_d| times
    the chord between ``rlam`` and the nearer of ±λ_d (the retargeting test of RECONFIGURING)."""
    a0, a1, a2 = rlam[0] - ld[0], rlam[1] - ld[1], rlam[2] - ld[2]
    b0, b1, b2 = rlam[0] + ld[0], rlam[1] + ld[1], rlam[2] + ld[2]
    chord = min(math.sqrt(a0 * a0 + a1 * a1 + a2 * a2), math.sqrt(b0 * b0 + b1 * b1 + b2 * b2))
    return abs(md) * chord >= speed


@njit(cache=True)
def _clamp_mu(c, ws, lam_d, mu_d) -> float:
    """μ_d clamped to the wheel-speed limits at λ_d, with ``mu_headroom``: |μ| ≤ h r_k φ̇_max / |c_k|
    for every wheel."""
    r, lim = c.r, c.lim
    n = r.shape[0]
    coef = ws[WS.C_NOW, :n]
    speed_coefs_row(lam_d, coef, False, c.E, c.P, c.b, c.steer_max, coef, ws[WS.SCRATCH, :3], ws[WS.BETA_WORK, :n])
    bound = np.inf
    for k in range(n):
        ck = abs(coef[k])
        bound = min(bound, lim[L_HEADROOM_WSM] * r[k] / (ck if ck > 0 else np.inf))
    return min(max(mu_d, -bound), bound)


@njit(cache=True)
def _plan_target(c, side, ld, out, neg, other) -> None:
    """The point of the planned cell ``side`` nearest to ±λ_d (:func:`nearest_in_cell`; λ_d itself
    when none is found) into ``out``: where a reconfiguration into that cell aims. ``neg``,
    ``other``: (3,) work space."""
    if nearest_in_cell(side, ld, c.normals, c.tune[C_HOLD_MARGIN], out, neg, other) < 0.0:
        out[0], out[1], out[2] = ld[0], ld[1], ld[2]


@njit(cache=True)
def _step_kernel(rows, c, state0, state1, inputs, outputs, lo, hi) -> None:
    """The step of the robots ``rows[lo:hi]`` (a block of :class:`estimation.threads.BlockKernel`;
    its work space its own; the inputs checked by :func:`_validate` first): ``c`` the constants;
    ``state0`` and ``state1`` the fields of
    the state before and after the step, in :class:`~control.icr.state.ICRBatchState`'s order
    ((N, …) arrays, ``state1`` already a copy of ``state0``); ``inputs`` (λ̂, μ̂, β, φ̇, λ_d, μ_d,
    planned cell (M, n): ±1 per stop circle, all 0 without a plan; planned excursion (M,):
    ``EXCURSION_PLANNED`` where the plan expects the target outside that cell, ``EXCURSION_END`` on
    the approach to the track's end) and ``outputs`` (β_c, β̇_c, φ̇_c, β̈_c, φ̈_c,
    λ_target, μ_target, axis_cap, event, κ, saturated, held) are (M, …), row m of them is robot
    rows[m] (distinct robots)."""
    # One long function on purpose: the whole step of a robot (target, modes, commands) reads and
    # writes one work space row by row in a single compiled call, with no allocation per robot;
    # the building blocks it calls (kernels.py, kernels_motion.py) are the named stages, and
    # splitting the mode logic further would pass the same dozen per-robot scalars back and forth.
    (mode0, lam0, mu0, lam_rate0, beta0, rate0, phidot0, mode_time0, rlam0, has_rl0, events0, bmeas0, has_bmeas0,
     held_miss0) = state0
    (mode1, lam1, mu1, lam_rate1, beta1, rate1, phidot1, mode_time1, rlam1, has_rl1, events1, bmeas1, has_bmeas1,
     held_miss1) = state1
    lam_hat, mu_hat, beta_meas, phidot_meas, lam_d_in, mu_d_in, plan, excursion = inputs
    beta_c, rate_c, phidot_c, accel, phiddot, lam_target, mu_target, axis_cap, event_out, kappa_out, saturated, \
        held_out = outputs
    c = private_constants(c)  # a block's own arrays: no reference count shared between threads
    E, P, s_unit, normals, lim, tune, dt = c.E, c.P, c.s_unit, c.normals, c.lim, c.tune, c.dt
    steer_max = c.steer_max
    n = E.shape[0]
    unlimited = lim[L_UNLIMITED] != 0.0
    ws = np.zeros((N_WS, max(n, 3)))
    lam, ld, target, hp, cell = ws[WS.LAM, :3], ws[WS.LAM_D, :3], ws[WS.TARGET, :3], ws[WS.HOLD, :3], ws[WS.CELL, :3]
    s_lam, s_lam_rate, rlam, scratch = ws[WS.S_LAM, :3], ws[WS.S_LAM_RATE, :3], ws[WS.RECONFIG_LAM, :3], \
        ws[WS.SCRATCH, :3]
    b0, r0, p0 = ws[WS.BETA0, :n], ws[WS.RATE0, :n], ws[WS.PHIDOT0, :n]
    lam_o, lam_rate_o, b1, r1, p1 = ws[WS.LAM1, :3], ws[WS.LAM_RATE1, :3], ws[WS.BETA1, :n], ws[WS.RATE1, :n], \
        ws[WS.PHIDOT1, :n]
    bt, measured_rate, arc = ws[WS.BETA_TARGET, :n], ws[WS.MEASURED_RATE, :n], ws[WS.ARC, :n]
    for m in range(lo, hi):
        i = rows[m]
        for j in range(3):
            lam[j], rlam[j], s_lam[j], s_lam_rate[j] = lam0[i, j], rlam0[i, j], lam0[i, j], lam_rate0[i, j]
        for k in range(n):
            b0[k], r0[k], p0[k] = beta0[i, k], rate0[i, k], phidot0[i, k]
        # ---- feasible target
        target[0], target[1], target[2] = unit_xyz(lam_d_in[m, 0], lam_d_in[m, 1], lam_d_in[m, 2])
        md = mu_d_in[m]
        zero = abs(md) < tune[C_ZERO_MU]
        if zero:
            target[0], target[1], target[2] = lam[0], lam[1], lam[2]
            md = 0.0
        sign = -1.0 if dot3(lam, target) < 0 else 1.0
        for j in range(3):
            target[j] = target[j] * sign
        md = md * sign
        axis_k = project_off_axes_row(target, lam, s_unit, tune[C_AXIS_MARGIN], ld)
        sign = -1.0 if dot3(lam, ld) < 0 else 1.0
        for j in range(3):
            ld[j] = ld[j] * sign
        md = _clamp_mu(c, ws, ld, md * sign)
        lam_target[m, 0], lam_target[m, 1], lam_target[m, 2] = ld[0], ld[1], ld[2]
        mu_target[m] = md
        axis_cap[m] = axis_k
        # ---- mode transitions
        mode = mode0[i]
        mode_time = mode_time0[i] + dt
        events = events0[i]
        has_rl = has_rl0[i]
        s_mu = mu0[i]
        held = False
        held_miss = 0.0
        kicked = False
        for k in range(n):
            kicked = kicked or abs(wrap_half1(beta_meas[m, k] - b0[k])) > tune[C_KICK]
        running = mode == _RUNNING
        blocked = ARC_NONE
        planned = False
        for k in range(n):
            planned = planned or plan[m, k] != 0.0
        if running and not zero:
            reason, free, theta = arc_check_row(lam, ld, E, P, steer_max, s_unit, tune[C_SIN_HALF_MARGIN],
                                                tune[C_ARC_STEP], unlimited, arc)
            hold = False
            near = math.sin(tune[C_STOP_HYST])  # a path along a stop circle is on both of its sides
            if planned and not in_cell(lam, plan[m], normals, near) and in_cell(ld, plan[m], normals):
                reason = ARC_STOP  # the plan changes cell and the target is there: stop, reconfigure into it
            elif reason == ARC_STOP:
                # the hold point: the nearest point of λ's cell, else the arc's last sample
                slerp3(lam, ld, free, hp)
                beyond = theta - free
                angle = stop_hold_row(lam, ld, normals, tune[C_HOLD_MARGIN], cell)
                if angle >= 0.0:
                    ok, _, _ = arc_check_row(lam, cell, E, P, steer_max, s_unit, tune[C_SIN_HALF_MARGIN],
                                             tune[C_ARC_STEP], unlimited, arc)
                    if ok == ARC_NONE:
                        hp[0], hp[1], hp[2] = cell[0], cell[1], cell[2]
                        beyond = angle
                d0, d1, d2 = hp[0] - ld[0], hp[1] - ld[1], hp[2] - ld[2]
                miss = max(abs(md), abs(mu0[i])) * math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                grazing = beyond < tune[C_STOP_HYST] and miss < tune[C_HOLD_SPEED]
                missed = held_miss0[i] + (0.0 if grazing else miss * dt)
                # in the planned cell, hold through the target's excursions (the plan has weighed them)
                # unless one goes beyond the hold angle (the follower's feedback after a disturbance);
                # on the approach to the track's end at any angle: the target slowing to the end
                # swings with the follower's feedback, and no change of cell pays off there
                planned_hold = planned and excursion[m] != EXCURSION_NONE and in_cell(lam, plan[m], normals, near) \
                    and missed <= tune[C_PLAN_HOLD_DIST] \
                    and (beyond < tune[C_HOLD_ANGLE] or miss < tune[C_HOLD_SPEED] or excursion[m] == EXCURSION_END)
                hold = planned_hold or (beyond < tune[C_HOLD_ANGLE] and missed <= tune[C_HOLD_DIST])
                if hold:
                    ld[0], ld[1], ld[2] = hp[0], hp[1], hp[2]
                    reason = ARC_NONE
                    held_miss = missed
            blocked = reason
            held = hold
        trig = running and (kicked or blocked != ARC_NONE)
        event = (_EV_KICK if kicked else blocked + 1) if trig else _EV_NONE
        if trig:
            events += 1
            mode = _STOPPING
            mode_time = 0.0
        if mode == _STOPPING and mu0[i] == 0.0 and norm3(s_lam_rate) < 1e-9 and (
                abs(mu_hat[m]) < tune[C_STOP_MU] or mode_time > tune[C_STOP_TIMEOUT]):
            mode = _RECONFIGURING
            mode_time = 0.0
        recon = mode == _RECONFIGURING
        if recon and not has_rl:
            if planned and not in_cell(s_lam, plan[m], normals, math.sin(tune[C_STOP_HYST])):  # the plan's change
                _plan_target(c, plan[m], ld, rlam, hp, cell)
            else:
                rlam[0], rlam[1], rlam[2] = ld[0], ld[1], ld[2]
            has_rl = True
        for k in range(n):
            bt[k] = 0.0
        if recon:
            if not zero:
                steering_row(rlam, E, P, steer_max, b0, True, bt, scratch)
                far = 0.0
                for k in range(n):
                    far = max(far, abs(steering_difference1(b0[k], bt[k], unlimited)))
                if planned and in_cell(rlam, plan[m], normals):
                    pass  # going where the plan wants
                elif planned and in_cell(ld, plan[m], normals):
                    if far > tune[C_FREEZE]:
                        _plan_target(c, plan[m], ld, rlam, hp, cell)
                elif far > tune[C_FREEZE] and _must_stop(c, ws, rlam, ld) and _differs(rlam, ld, md,
                                                                                      tune[C_HOLD_SPEED]):
                    rlam[0], rlam[1], rlam[2] = ld[0], ld[1], ld[2]
            steering_row(rlam, E, P, steer_max, b0, True, bt, scratch)
            for k in range(n):  # unlimited steering: the nearer angle of each axis
                bt[k] = nearest1(bt[k], b0[k], unlimited)
            settled_cmd = True
            settled_meas = True
            for k in range(n):
                settled_cmd = settled_cmd and abs(b0[k] - bt[k]) < 1e-6 and abs(r0[k]) < 1e-9
                err = abs(wrap_half1(beta_meas[m, k] - bt[k]))
                still = has_bmeas0[i] and abs(wrap_half1(beta_meas[m, k] - bmeas0[i, k])) < tune[C_STILL_TOL]
                settled_meas = settled_meas and (err < tune[C_RECONFIG_TOL] or (err < tune[C_HOLD_TOL] and still))
            if settled_cmd and (settled_meas or mode_time > tune[C_RECONFIG_TIMEOUT]) and not zero:
                s_lam[0], s_lam[1], s_lam[2] = rlam[0], rlam[1], rlam[2]
                s_mu = 0.0
                s_lam_rate[:] = 0.0
                mode = _RUNNING
                mode_time = 0.0
                has_rl = False
                sign = -1.0 if dot3(s_lam, ld) < 0 else 1.0
                for j in range(3):
                    ld[j] = ld[j] * sign
                md = md * sign
        # ---- each mode's commands
        kap = 0.0
        sat = False
        mu_new = 0.0
        if mode == _RECONFIGURING:
            if zero:
                for k in range(n):
                    br = r0[k]
                    bt[k] = b0[k] + np.sign(br) * max(abs(br) - lim[L_BRAKE_DT], 0.0) * dt
            use_meas = False
            if tune[C_COUPLING_MEAS] != 0.0:
                use_meas = has_bmeas0[i]
                for k in range(n):
                    measured_rate[k] = wrap_half1(beta_meas[m, k] - bmeas0[i, k]) / dt
            reconfigure_row(c, ws, b0, r0, p0, bt, zero, measured_rate, use_meas, b1, r1, p1)
            lam_o[0], lam_o[1], lam_o[2] = s_lam[0], s_lam[1], s_lam[2]
            lam_rate_o[:] = 0.0
        else:
            stopping = mode == _STOPPING
            tgt = s_lam if stopping else ld
            mn, kap, sat = coordinated_row(c, ws, s_lam, s_mu, s_lam_rate, b0, r0, p0, tgt, 0.0 if stopping else md,
                                           stopping, lam_o, lam_rate_o, b1, r1, p1)
            if stopping and abs(mn) < 1e-9:
                mn = 0.0
            if stopping and abs(mn) < 1e-6 * max(1.0, abs(s_mu)) and norm3(lam_rate_o) < 1e-6:
                mn = 0.0
                lam_rate_o[:] = 0.0
            mu_new = mn
        mu1[i] = mu_new
        for j in range(3):
            lam1[i, j], lam_rate1[i, j], rlam1[i, j] = lam_o[j], lam_rate_o[j], rlam[j] if has_rl else 0.0
        for k in range(n):
            beta1[i, k], rate1[i, k], phidot1[i, k] = b1[k], r1[k], p1[k]
            beta_c[m, k] = b1[k]
            rate_c[m, k] = r1[k]
            phidot_c[m, k] = p1[k]
            accel[m, k] = (r1[k] - r0[k]) / dt
            phiddot[m, k] = (p1[k] - p0[k]) / dt
            bmeas1[i, k] = beta_meas[m, k]
        mode1[i] = mode
        mode_time1[i] = mode_time
        events1[i] = events
        has_rl1[i] = has_rl
        has_bmeas1[i] = True
        held_miss1[i] = held_miss
        event_out[m] = event
        kappa_out[m] = kap
        saturated[m] = sat
        held_out[m] = held


#: the step over blocks of robots (a block: at least 4 robots)
_STEP = BlockKernel(_step_kernel, min_rows=4)


def _rows_array(rows, num: int) -> np.ndarray:
    return np.arange(num, dtype=np.int64) if rows is None else np.asarray(rows, dtype=np.int64)


def _plan_rows(x, name: str, shape: tuple[int, ...], allowed: tuple[float, ...]) -> np.ndarray:
    """A plan input: numbers of ``shape``, each one of ``allowed`` (a cell's sides, a flag)."""
    try:
        arr = np.ascontiguousarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an array of numbers of shape {shape}") from None
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isin(arr, allowed)):
        bad = arr[~np.isin(arr, allowed)][0]
        raise ValueError(f"{name} must hold only {', '.join(f'{a:g}' for a in allowed)}; got {bad!r}")
    return arr


def _float_rows(x, name: str, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.ascontiguousarray(x, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    return arr


def compiled_control_step_batch(state: ICRBatchState, lam_hat, mu_hat, beta_meas, phidot_meas, lam_d, mu_d,
                                geom: RobotGeometry, limits: ActuatorLimits, config: ICRControllerConfig, dt: float,
                                rows=None, constants=None, plan_side=None, plan_excursion=None,
                                num_threads: int = 1) -> tuple[ICRBatchState, WheelCommand]:
    """One control period of the robots ``rows``: the ICR controller's step (see the module docstring).

    Args:
        state: the N robots' state; rows: the robots to step (integer indices; None: all). The
            other arguments are those of ``icr_control_step_batch``, for the M stepped robots in the
            order of ``rows``. constants: :func:`compiled_constants` of (geom, limits, config,
            dt), when the caller keeps them (else computed here). plan_side: (M, n) the cell a
            look-ahead plan wants each robot in (±1 per stop circle; a row of zeros, or None: no
            plan; :func:`control.icr.lookahead.plan_sides`): the controller stops and reconfigures
            into it when λ is elsewhere and the target is in it. plan_excursion: (M,) 1.0
            (``EXCURSION_PLANNED``) where the plan expects the target to leave that cell for a while,
            2.0 (``EXCURSION_END``) on the approach to an open track's end, 0.0 elsewhere (None:
            nowhere): there a target beyond a stop is held at the cell's rim for up to
            ``planned_hold_distance`` of missed motion, not ``stop_hold_distance``, and on the
            approach to the end at any angle (``docs/icr-controller.md`` §6). num_threads: the
            robots in blocks on this many threads (:mod:`estimation.threads`; checked where it
            entered; the same bits for any count).

    Returns:
        (the new state of all N robots, the (M, n) commands with their ``info``: λ_target, μ_target,
        axis_cap, mode, events, kappa, saturated, event, held_at_stop).

    Raises:
        ValueError: as ``icr_control_step_batch`` (non-finite input, wrong shapes, a zero λ_d,
            dt <= 0), changing nothing.
    """
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0, got {dt!r}")
    idx = _rows_array(rows, state.num)
    M, n = idx.shape[0], geom.n
    lam_hat = np.ascontiguousarray(lam_hat, dtype=np.float64)
    if lam_hat.ndim != 2 or lam_hat.shape[1] != 3:
        raise ValueError(f"lam_hat must have shape (N, 3), got {lam_hat.shape}")
    if lam_hat.shape[0] != M:
        raise ValueError(f"lam_hat must have shape ({M}, 3)")
    mu_hat = _float_rows(mu_hat, "mu_hat", (M,))
    beta_meas = _float_rows(beta_meas, "beta_meas", (M, n))
    phidot_meas = _float_rows(phidot_meas, "phidot_meas", (M, n))
    lam_d = np.ascontiguousarray(lam_d, dtype=np.float64)
    if lam_d.ndim != 2 or lam_d.shape[1] != 3:
        raise ValueError(f"lam_d must have shape (N, 3), got {lam_d.shape}")
    if lam_d.shape[0] != M:
        raise ValueError(f"lam_d must have shape ({M}, 3)")
    mu_d = _float_rows(mu_d, "mu_d", (M,))
    plan = np.zeros((M, n)) if plan_side is None else _plan_rows(plan_side, "plan_side", (M, n), (-1.0, 0.0, 1.0))
    excursion = np.zeros(M) if plan_excursion is None else _plan_rows(plan_excursion, "plan_excursion", (M,),
                                                                      (EXCURSION_NONE, EXCURSION_PLANNED,
                                                                       EXCURSION_END))
    c = constants if constants is not None else compiled_constants(geom, limits, config, dt)
    fields = state.__dataclass_fields__
    state0 = tuple(getattr(state, name) for name in fields)
    state1 = tuple(arr.copy() for arr in state0)
    outputs = (np.empty((M, n)), np.empty((M, n)), np.empty((M, n)), np.empty((M, n)), np.empty((M, n)),
               np.empty((M, 3)), np.empty(M), np.empty(M, dtype=np.int64), np.empty(M, dtype=np.int64), np.empty(M),
               np.empty(M, dtype=np.bool_), np.empty(M, dtype=np.bool_))
    code = _validate(lam_hat, mu_hat, beta_meas, phidot_meas, lam_d, mu_d)
    if code:
        raise ValueError(_ERRORS[code - 1])
    if num_threads > 1 and rows is not None and np.unique(idx).size != M:
        raise ValueError("rows must be distinct robots")
    _STEP.run(num_threads, M, idx, c, state0, state1,
              (lam_hat, mu_hat, beta_meas, phidot_meas, lam_d, mu_d, plan, excursion), outputs)
    new = ICRBatchState(*state1)
    beta_c, rate_c, phidot_c, accel, phiddot, lam_target, mu_target, axis_cap, event, kap, saturated, held = outputs
    info = {"lam_target": lam_target, "mu_target": mu_target, "axis_cap": axis_cap, "mode": new.mode[idx],
            "events": new.events[idx], "kappa": kap, "saturated": saturated, "event": event, "held_at_stop": held}
    return new, WheelCommand(beta=beta_c, phidot=phidot_c, beta_rate=rate_c, beta_accel=accel, phiddot=phiddot,
                             info=info)
