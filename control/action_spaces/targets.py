"""The RL action spaces' targets compiled: policy action -> ICR target (λ_d, μ_d) for N robots
in one numba call per step.

Each kernel is the NumPy reference of :mod:`control.action_spaces.shaping` (and of
``ActionController._targets`` in :mod:`control.action_spaces.controller`) written row by row,
with the same operations in the same order (the building blocks and their conventions are
those of :mod:`control.icr.kernels`), so that it returns the same bits
(``tests/control/test_targets_compiled.py`` compares them on random batches). ``unlimited``:
the robot's ``RobotGeometry.unlimited_steering`` (no stop to cross, only the axis caps block):

* :func:`residual_targets`: the follower's twist as (λ_f, μ_f), turned on the sphere by the
  residual (:func:`~control.action_spaces.shaping.exp_step` in the
  :func:`~control.action_spaces.shaping.initial_frame` of λ_f) unless that crosses a steering
  stop or enters an axis cap (:func:`~control.action_spaces.shaping.advance_target`);
* :func:`rate_targets`: the ICR-rate action space's integrated target (λ_s, μ_s) and its
  tangent frame (:func:`~control.action_spaces.shaping.transport_frame`), updated in place;
* :func:`shaped_targets`: :func:`~control.action_spaces.shaping.shape_target` (absolute targets
  through the ICR controller).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from control.icr.kernels import dot3, norm3, sphere_angle3, steering_row
from estimation.threads import BlockKernel

__all__ = ["residual_targets", "rate_targets", "shaped_targets", "RESIDUAL_TARGETS", "RATE_TARGETS", "SHAPED_TARGETS"]


@njit(cache=True)
def _initial_frame(lam, out) -> None:
    """:func:`~control.action_spaces.shaping.initial_frame` of one λ into ``out``."""
    j = 0
    for k in (1, 2):
        if abs(lam[k]) < abs(lam[j]):
            j = k
    a = np.zeros(3)
    a[j] = 1.0
    d = dot3(a, lam)
    for k in range(3):
        out[k] = a[k] - d * lam[k]
    nrm = norm3(out)
    for k in range(3):
        out[k] = out[k] / nrm


@njit(cache=True)
def _exp_step(lam, e1, r1, r2, dt, out) -> None:
    """:func:`~control.action_spaces.shaping.exp_step` of one row (tangent rates r1, r2 [rad/s])."""
    e2 = np.empty(3)
    e2[0] = lam[1] * e1[2] - lam[2] * e1[1]
    e2[1] = lam[2] * e1[0] - lam[0] * e1[2]
    e2[2] = lam[0] * e1[1] - lam[1] * e1[0]
    v = np.empty(3)
    for k in range(3):
        v[k] = dt * (r1 * e1[k] + r2 * e2[k])
    nv = norm3(v)
    safe = nv if nv > 0 else 1.0
    c, s = math.cos(nv), math.sin(nv)
    for k in range(3):
        out[k] = c * lam[k] + s * v[k] / safe
    nrm = norm3(out)
    for k in range(3):
        out[k] = out[k] / nrm


@njit(cache=True)
def _advance(lam, prop, push, cross_push, E, P, steer_max, s_unit, cos_margin, unlimited, out):
    """:func:`~control.action_spaces.shaping.advance_target` of one row: writes λ_s into ``out``;
    returns (push, held)."""
    n = E.shape[0]
    b0, b1, scratch = np.empty(n), np.empty(n), np.empty(3)
    steering_row(lam, E, P, steer_max, b0, False, b0, scratch)
    steering_row(prop, E, P, steer_max, b1, False, b1, scratch)
    crosses = False
    in_cap = False
    for k in range(n):
        crosses = crosses or (abs(b1[k] - b0[k]) > 0.5 * np.pi and not unlimited)
        in_cap = in_cap or abs(dot3(prop, s_unit[k])) > cos_margin
    step = sphere_angle3(lam, prop)
    push = push + step if crosses and not in_cap else 0.0
    accept = not (crosses or in_cap) or (crosses and not in_cap and push > cross_push)
    if accept:
        push = 0.0
    src = prop if accept else lam
    out[0], out[1], out[2] = src[0], src[1], src[2]
    return push, not accept


@njit(cache=True)
def residual_targets(twists, actions, residual_angle, residual_mu, E, P, steer_max, s_unit, cos_margin, unlimited,
                     lam_out, mu_out, held_out, lo, hi) -> None:
    """The residual action space's targets of robots ``lo`` to ``hi - 1`` of M (a block of
    :class:`estimation.threads.BlockKernel`): the follower's chassis twists (M, 3) and the clipped
    actions (M, 3) -> λ_d (M, 3), μ_d (M,), held (M,)."""
    lam_f, frame, prop = np.empty(3), np.empty(3), np.empty(3)
    for m in range(lo, hi):
        v0, v1, v2 = -twists[m, 1], twists[m, 0], twists[m, 2]  # estimation.hrep.eta_from_twist
        mu = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        if mu > 0:
            lam_f[0], lam_f[1], lam_f[2] = v0 / mu, v1 / mu, v2 / mu
        else:
            lam_f[0], lam_f[1], lam_f[2] = 0.0, 0.0, 1.0
        _initial_frame(lam_f, frame)
        _exp_step(lam_f, frame, actions[m, 0] * residual_angle, actions[m, 1] * residual_angle, 1.0, prop)
        _, held = _advance(lam_f, prop, 0.0, np.inf, E, P, steer_max, s_unit, cos_margin, unlimited, lam_out[m])
        held_out[m] = held
        mu_out[m] = mu + actions[m, 2] * residual_mu


@njit(cache=True)
def rate_targets(rows, actions, lam_s, e1, push, mu_s, lambda_rate_max, mu_accel, mu_max, dt, cross_push, E, P,
                 steer_max, s_unit, cos_margin, unlimited, lam_out, mu_out, held_out, lo, hi) -> None:
    """The ICR-rate action space's step for the robots ``rows[lo:hi]`` (a block; ``rows``
    distinct): the clipped actions (M, 3) move each robot's (λ_s, μ_s) and tangent frame e₁
    ((N, …), updated in place); λ_d (M, 3), μ_d (M,), held (M,) out."""
    prop, e = np.empty(3), np.empty(3)
    for m in range(lo, hi):
        i = rows[m]
        lam = lam_s[i]
        _exp_step(lam, e1[i], actions[m, 0] * lambda_rate_max, actions[m, 1] * lambda_rate_max, dt, prop)
        p, held = _advance(lam, prop, push[i], cross_push, E, P, steer_max, s_unit, cos_margin, unlimited, lam_out[m])
        push[i] = p
        held_out[m] = held
        new = lam_out[m]
        d = dot3(e1[i], new)  # transport_frame
        for k in range(3):
            e[k] = e1[i, k] - d * new[k]
        nrm = norm3(e)
        if nrm < 1e-9:
            _initial_frame(new, e)
            nrm = 1.0
        for k in range(3):
            e1[i, k] = e[k] / nrm
            lam_s[i, k] = new[k]
        mu_s[i] = min(max(mu_s[i] + actions[m, 2] * mu_accel * dt, -mu_max), mu_max)
        mu_out[m] = mu_s[i]


@njit(cache=True)
def shaped_targets(rows, lam_ref, lam_t, mu_t, push, nearer, max_angle, cross_push, E, P, steer_max, s_unit,
                   cos_margin, unlimited, lam_out, mu_out, held_out, lo, hi) -> None:
    """:func:`~control.action_spaces.shaping.shape_target` for the robots ``rows[lo:hi]`` (a block): the
    controller's reference λ (N, 3), the absolute targets (M, 3), (M,) and each robot's push
    (N,, updated in place) -> λ_s (M, 3), μ_t (M,), held (M,)."""
    tgt, prop = np.empty(3), np.empty(3)
    for m in range(lo, hi):
        i = rows[m]
        lam = lam_ref[i]
        mu = mu_t[m]
        sign = -1.0 if nearer and dot3(lam, lam_t[m]) < 0 else 1.0
        for k in range(3):
            tgt[k] = lam_t[m, k] * sign
        mu = mu * sign
        d = min(max(dot3(lam, tgt), -1.0), 1.0)  # step_toward
        for k in range(3):
            prop[k] = tgt[k] - d * lam[k]
        tn = norm3(prop)
        if tn > 1e-15:
            ang = min(math.atan2(tn, d), max_angle)
            c, s = math.cos(ang), math.sin(ang)
            for k in range(3):
                prop[k] = c * lam[k] + s * (prop[k] / tn)
            nrm = norm3(prop)
            for k in range(3):
                prop[k] = prop[k] / nrm
        else:
            prop[0], prop[1], prop[2] = lam[0], lam[1], lam[2]
        p, held = _advance(lam, prop, push[i], cross_push, E, P, steer_max, s_unit, cos_margin, unlimited, lam_out[m])
        push[i] = p
        held_out[m] = held
        mu_out[m] = mu


#: the three target stages over blocks of robots (a block: at least 32 robots, ~20 µs)
RESIDUAL_TARGETS = BlockKernel(residual_targets, min_rows=32)
RATE_TARGETS = BlockKernel(rate_targets, min_rows=32)
SHAPED_TARGETS = BlockKernel(shaped_targets, min_rows=32)
