"""The ICR controller's state machine, batched over robots: the mode transitions of one control
period (:func:`mode_transitions`), then each mode's commands (:func:`mode_commands`).

RUNNING -> STOPPING when a wheel is knocked out of place, the arc to the target crosses a
steering axis, or the target lies beyond a steering stop farther than a hold takes (a target just
beyond is held at the nearest point of the current cell, until the hold has missed
``stop_hold_distance`` of motion); STOPPING -> RECONFIGURING once the reference is at rest and μ̂ ≈ 0 (or after
``stop_timeout``); RECONFIGURING -> RUNNING once the steering commands have reached the new
configuration and the measured wheels are within ``reconfig_tol`` of it (or after
``reconfig_timeout``). The modes are per-row masks; see ``docs/icr-controller.md``, "Modes".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from control.commands import WheelCommand
from control.icr.config import Event, ICRControllerConfig, Mode
from control.icr.feasibility import ArcReason, arc_check_batch, must_stop, stop_hold_point_batch, wrap_half
from control.icr.motion import coordinated_step, reconfigure_step
from control.icr.state import ICRBatchState
from control.limits import ActuatorLimits
from estimation.geometry import RobotGeometry
from estimation.hrep import nearer_representative, slerp
from estimation.kinematics import steering_from_lambda

__all__ = ["ModeUpdate", "mode_transitions", "mode_commands"]


@dataclass(frozen=True)
class ModeUpdate:
    """The outcome of :func:`mode_transitions` for N robots ((N, …) arrays).

    Attributes:
        mode, mode_time, events, reconfig_lam, has_reconfig_lam, held_miss: the new values of
            those :class:`~control.icr.state.ICRBatchState` fields.
        lam, mu, lam_rate: the reference H state the commands start from (the reconfigured λ at
            rest where RECONFIGURING has just ended, else the state's).
        lam_d, mu_d: the target (held at the steering stop where ``held``; the nearer
            representative again where RECONFIGURING has just ended).
        held: (N,) the target is held at a steering stop this period.
        event: (N,) :class:`~control.icr.config.Event` code of a sequence started this period.
        beta_target: (N, n) the steering angles being reconfigured to (RECONFIGURING rows).
    """

    mode: np.ndarray
    mode_time: np.ndarray
    events: np.ndarray
    reconfig_lam: np.ndarray
    has_reconfig_lam: np.ndarray
    held_miss: np.ndarray
    lam: np.ndarray
    mu: np.ndarray
    lam_rate: np.ndarray
    lam_d: np.ndarray
    mu_d: np.ndarray
    held: np.ndarray
    event: np.ndarray
    beta_target: np.ndarray


def mode_transitions(state: ICRBatchState, mu_hat: np.ndarray, beta_meas: np.ndarray, lam_d: np.ndarray,
                     mu_d: np.ndarray, zero_cmd: np.ndarray, geom: RobotGeometry, config: ICRControllerConfig,
                     dt: float) -> ModeUpdate:
    """The mode of each robot for this period (see the module docstring).

    Args:
        state: the controllers' state; mu_hat: (N,) estimated μ̂ [m/s]; beta_meas: (N, n)
            measured steering angles [rad].
        lam_d, mu_d, zero_cmd: the feasible target (:func:`control.icr.feasibility.feasible_target`).
    """
    nrows, n = state.num, geom.n
    lam_d, mu_d = lam_d.copy(), mu_d.copy()
    mode, mode_time, events = state.mode.copy(), state.mode_time + dt, state.events.copy()
    reconfig_lam, has_rl = state.reconfig_lam.copy(), state.has_reconfig_lam.copy()
    s_lam, s_mu, s_lam_rate = state.lam.copy(), state.mu.copy(), state.lam_rate.copy()
    held = np.zeros(nrows, dtype=np.bool_)
    held_miss = np.zeros(nrows)

    # RUNNING -> STOPPING: a wheel knocked out of place (measured far from commanded), or an arc
    # to the target that crosses a steering axis, or a steering stop beyond what a hold takes
    kicked = np.max(np.abs(wrap_half(beta_meas - state.beta)), axis=-1) > config.kick_tol
    running = mode == Mode.RUNNING
    blocked = np.zeros(nrows, dtype=np.int64)
    check = running & ~zero_cmd
    if np.any(check):
        r = np.flatnonzero(check)
        reason, free, theta = arc_check_batch(state.lam[r], lam_d[r], geom, config.axis_margin, config.arc_step)
        stop = reason == ArcReason.STOP
        # the hold point: the nearest point of λ's cell (sliding along a stop circle), else the
        # last sample of the arc before the stop
        point = slerp(state.lam[r], lam_d[r], free)
        beyond = theta - free
        if np.any(stop):
            rs = np.flatnonzero(stop)
            cell, angle = stop_hold_point_batch(state.lam[r[rs]], lam_d[r[rs]], geom, config.stop_hold_margin)
            found = angle >= 0.0
            if np.any(found):
                ok, _, _ = arc_check_batch(state.lam[r[rs[found]]], cell[found], geom, config.axis_margin,
                                           config.arc_step)
                found[found] = ok == ArcReason.NONE
            point[rs[found]] = cell[found]
            beyond[rs[found]] = angle[found]
        # the motion the hold misses: the twist difference's speed, the robot's own μ counted
        # while it is still faster than the target
        miss = np.maximum(np.abs(mu_d[r]), np.abs(state.mu[r])) * np.linalg.norm(point - lam_d[r], axis=-1)
        grazing = (beyond < config.stop_hysteresis) & (miss < config.stop_hold_speed)
        missed = state.held_miss[r] + np.where(grazing, 0.0, miss * dt)
        hold = stop & (beyond < config.stop_hold_angle) & (missed <= config.stop_hold_distance)
        if np.any(hold):
            lam_d[r[hold]] = point[hold]
        reason = np.where(hold, ArcReason.NONE, reason)
        blocked[r] = reason
        held[r] = hold
        held_miss[r] = np.where(hold, missed, 0.0)
    trig = running & (kicked | (blocked != ArcReason.NONE))
    # an arc's reason code + 1 is its Event code (STOP 1 -> 2, AXIS 2 -> 3)
    event = np.where(trig, np.where(kicked, Event.KICK, blocked + 1), Event.NONE)
    events = events + trig
    mode = np.where(trig, int(Mode.STOPPING), mode)
    mode_time = np.where(trig, 0.0, mode_time)

    # STOPPING -> RECONFIGURING: the reference at rest and the robot stopped (or timed out)
    stopping = mode == Mode.STOPPING
    stopped = stopping & (state.mu == 0.0) & (np.linalg.norm(state.lam_rate, axis=-1) < 1e-9) & (
        (np.abs(mu_hat) < config.stop_mu_tol) | (mode_time > config.stop_timeout))
    mode = np.where(stopped, int(Mode.RECONFIGURING), mode)
    mode_time = np.where(stopped, 0.0, mode_time)

    # RECONFIGURING: the configuration to reach; -> RUNNING once it is reached
    recon = mode == Mode.RECONFIGURING
    fresh = recon & ~has_rl
    reconfig_lam[fresh] = lam_d[fresh]
    has_rl |= fresh
    beta_target = np.zeros((nrows, n))
    if np.any(recon):
        r = np.flatnonzero(recon)
        cand = ~zero_cmd[r] & (np.max(np.abs(geom.steering_difference(state.beta[r], steering_from_lambda(
            reconfig_lam[r], geom, singular_fill=state.beta[r]))), axis=-1) > config.reconfig_freeze)
        if np.any(cand):
            rc = r[cand]
            # retarget only if the latest target could not be reached continuously from the
            # configuration being reached (RUNNING does the rest); no chasing a jittery target
            # a target whose motion differs from the one being reached by less than
            # stop_hold_speed is not worth another reconfiguration either (a slow target's λ_d
            # points anywhere)
            chord = np.minimum(np.linalg.norm(reconfig_lam[rc] - lam_d[rc], axis=-1),
                               np.linalg.norm(reconfig_lam[rc] + lam_d[rc], axis=-1))
            differs = np.abs(mu_d[rc]) * chord >= config.stop_hold_speed
            rt = rc[must_stop(reconfig_lam[rc], lam_d[rc], geom, config) & differs]
            reconfig_lam[rt] = lam_d[rt]
        bt = steering_from_lambda(reconfig_lam[r], geom, singular_fill=state.beta[r])
        bt = geom.nearest_steering(bt, state.beta[r])  # unlimited steering: the nearer angle of each axis
        beta_target[r] = bt
        settled_cmd = (np.max(np.abs(state.beta[r] - bt), axis=-1) < 1e-6) & (
            np.max(np.abs(state.beta_rate[r]), axis=-1) < 1e-9)
        err = np.abs(wrap_half(beta_meas[r] - bt))
        # a wheel within reconfig_tol, or stopped near its target where stiction and the tread hold it
        still = state.has_beta_meas[r, None] & (np.abs(wrap_half(beta_meas[r] - state.beta_meas[r]))
                                                < config.reconfig_still_tol)
        held_at_rest = (err < config.reconfig_hold_tol) & still
        settled_meas = np.all((err < config.reconfig_tol) | held_at_rest, axis=-1)
        resume = settled_cmd & (settled_meas | (mode_time[r] > config.reconfig_timeout)) & ~zero_cmd[r]
        if np.any(resume):
            rr = r[resume]
            s_lam[rr], s_mu[rr], s_lam_rate[rr] = reconfig_lam[rr], 0.0, 0.0
            mode[rr], mode_time[rr], has_rl[rr] = int(Mode.RUNNING), 0.0, False
            lam_d[rr], mu_d[rr] = nearer_representative(s_lam[rr], lam_d[rr], mu_d[rr])
    return ModeUpdate(mode=mode, mode_time=mode_time, events=events, reconfig_lam=reconfig_lam,
                      has_reconfig_lam=has_rl, held_miss=held_miss, lam=s_lam, mu=s_mu, lam_rate=s_lam_rate,
                      lam_d=lam_d, mu_d=mu_d, held=held, event=event, beta_target=beta_target)


def mode_commands(state: ICRBatchState, upd: ModeUpdate, beta_meas: np.ndarray, zero_cmd: np.ndarray,
                  geom: RobotGeometry, limits: ActuatorLimits, config: ICRControllerConfig, dt: float
                  ) -> tuple[ICRBatchState, WheelCommand]:
    """Each robot's commands in its new mode: RECONFIGURING turns the wheels in place
    (:func:`~control.icr.motion.reconfigure_step`; a stop command brakes them where they are),
    RUNNING and STOPPING take a coordinated step (:func:`~control.icr.motion.coordinated_step`;
    STOPPING toward μ = 0 with λ held). Returns the new state and the (N, n) commands (``info``
    holds mode, events, kappa, saturated, event, held_at_stop)."""
    nrows, n = state.num, geom.n
    mode, s_lam, s_mu, s_lam_rate = upd.mode, upd.lam, upd.mu, upd.lam_rate
    lam_new, mu_new, lam_rate = s_lam.copy(), np.zeros(nrows), np.zeros((nrows, 3))
    beta_c, rate_c, phidot_c = state.beta.copy(), state.beta_rate.copy(), state.phidot.copy()
    kappa, saturated = np.zeros(nrows), np.zeros(nrows, dtype=np.bool_)
    recon = mode == Mode.RECONFIGURING
    if np.any(recon):
        r = np.flatnonzero(recon)
        bt = upd.beta_target[r]
        zr = zero_cmd[r]
        if np.any(zr):
            # hold: brake the steering to rest where it is (at full deceleration, so it stops
            # short of where the reconfiguration was heading, inside the range); do not swing
            br = state.beta_rate[r]
            rate = np.sign(br) * np.maximum(np.abs(br) - limits.steer_accel_max * dt, 0.0)
            bt = np.where(zr[:, None], state.beta[r] + rate * dt, bt)
        use_meas = np.zeros(r.size, dtype=np.bool_)
        measured_rate = np.zeros((r.size, n))
        if config.coupling_from_measurement:
            use_meas = state.has_beta_meas[r].copy()
            measured_rate = wrap_half(beta_meas[r] - state.beta_meas[r]) / dt
        beta_c[r], rate_c[r], phidot_c[r] = reconfigure_step(
            state.beta[r], state.beta_rate[r], state.phidot[r], bt, geom, limits, dt, exact=zr,
            measured_rate=measured_rate, use_measured=use_meas, rate_fraction=config.reconfig_rate_fraction,
            accel_fraction=config.reconfig_accel_fraction)
    moving = ~recon
    if np.any(moving):
        r = np.flatnonzero(moving)
        stop_r = mode[r] == Mode.STOPPING
        tgt_lam = np.where(stop_r[:, None], s_lam[r], upd.lam_d[r])
        tgt_mu = np.where(stop_r, 0.0, upd.mu_d[r])
        ln, mn, lr, bc, rcm, pc, kp, sat = coordinated_step(
            s_lam[r], s_mu[r], s_lam_rate[r], state.beta[r], state.beta_rate[r], state.phidot[r], tgt_lam, tgt_mu,
            stop_r, geom, limits, config, dt)
        mn = np.where(stop_r & (np.abs(mn) < 1e-9), 0.0, mn)
        rest = stop_r & (np.abs(mn) < 1e-6 * np.maximum(1.0, np.abs(s_mu[r]))) & (np.linalg.norm(lr, axis=-1) < 1e-6)
        mn = np.where(rest, 0.0, mn)
        lr = np.where(rest[:, None], 0.0, lr)
        lam_new[r], mu_new[r], lam_rate[r] = ln, mn, lr
        beta_c[r], rate_c[r], phidot_c[r] = bc, rcm, pc
        kappa[r], saturated[r] = kp, sat

    accel = (rate_c - state.beta_rate) / dt
    phiddot = (phidot_c - state.phidot) / dt
    info = {"mode": mode.copy(), "events": upd.events.copy(), "kappa": kappa, "saturated": saturated,
            "event": upd.event, "held_at_stop": upd.held}
    has_rl = upd.has_reconfig_lam
    new_state = ICRBatchState(mode=mode, lam=lam_new, mu=mu_new, lam_rate=lam_rate, beta=beta_c, beta_rate=rate_c,
                              phidot=phidot_c, mode_time=upd.mode_time,
                              reconfig_lam=np.where(has_rl[:, None], upd.reconfig_lam, 0.0), has_reconfig_lam=has_rl,
                              events=upd.events, beta_meas=beta_meas.copy(),
                              has_beta_meas=np.ones(nrows, dtype=np.bool_), held_miss=upd.held_miss)
    cmd = WheelCommand(beta=beta_c.copy(), phidot=phidot_c.copy(), beta_rate=rate_c.copy(), beta_accel=accel,
                       phiddot=phiddot, info=info)
    return new_state, cmd
