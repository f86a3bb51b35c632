"""The reward of ``Azimut-v1``: its terms, their weights, and the compiled per-step computation.

The terms (:class:`RewardTerm`, :data:`REWARD_TERMS`; ``info["reward_terms"]``; the single env's
docstring, "Rewards", gives their magnitudes) for a robot at progress s with lateral error e_lat,
heading error e_θ, reference speed v_ref, top reference speed v_max of its track and control
period dt:

* progress w·clip(Δs, −v_max dt, v_ref dt)/(v_max dt) (backward jumps of the projection clipped to
  one step at full speed);
* lateral and heading −w·(1 − exp(−|e|/scale)) (bounded, steepest at zero error);
* overspeed −w·max(0, v_along − v_ref)/v_max;
* slip −min(w·P_slip, cap) and internal force −min(w·F_int, cap): the actuator antagonism that
  Clavien, Lauria, Michaud (RAS 2018) is about, the tire slip power and the internal force of the
  physics summary (``AzimutPhysics.slip_power``, ``internal_force``);
* action rate −w‖a − a_prev‖² (the normalised set-point actions);
* off track −penalty on the step that leaves the track; a stall pays it too
  (:func:`charge_penalty`, called by the termination stage).

The reward is their sum, in that order. Every input is the ground truth (the true track state),
whatever the observation's pose source. To add a term: a member of :class:`RewardTerm`, its
weight (a ``TaskConfig`` field and :func:`reward_weights`), its value in :func:`compute_rewards`.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numba import njit

from azimut_env.task.config import TaskConfig
from azimut_env.task.observation import speed_along
from azimut_env.tracks import TQ

__all__ = ["RewardTerm", "REWARD_TERMS", "reward_weights", "reward_scales", "compute_rewards", "charge_penalty"]


class RewardTerm(IntEnum):
    """The reward terms, the columns of ``AzimutTask.reward_terms``."""

    PROGRESS = 0
    LATERAL = 1
    HEADING = 2
    OVERSPEED = 3
    SLIP = 4
    INTERNAL_FORCE = 5
    ACTION_RATE = 6
    OFF_TRACK = 7


#: the reward terms' names, in the order of the columns of ``AzimutTask.reward_terms``
REWARD_TERMS = tuple(t.name.lower() for t in RewardTerm)


def reward_weights(config: TaskConfig) -> np.ndarray:
    """(len(RewardTerm),) the weights by term (``off_track``: the penalty), as the kernel takes them."""
    weights = config.weights
    return np.array([weights[name] for name in REWARD_TERMS])


def reward_scales(config: TaskConfig) -> np.ndarray:
    """(lateral_scale [m], heading_scale [rad], antagonism_cap) as the kernel takes them."""
    return np.array([config.lateral_scale, config.heading_scale, config.antagonism_cap])


@njit(cache=True)
def compute_rewards(rows, track_state, s_prev, vel_world, max_speeds, slip, internal, action, prev_action, off_track,
                    weights, scales, dt, v_along, terms, reward):
    """For the robots where ``rows`` is True: the speed along the path ``v_along``, the terms
    (N, len(RewardTerm)) and the reward (N,).

    ``track_state`` (N, 5) (columns :class:`~azimut_env.tracks.TQ`) and ``vel_world`` (N, 2) are
    the true ones, ``s_prev`` the progress before the step, ``max_speeds`` each track's top
    reference speed, ``slip`` [W] and ``internal`` [N] the physics' step means, ``action`` and
    ``prev_action`` (N, 2n) float32, ``off_track`` the termination flags of this step."""
    for i in range(rows.shape[0]):
        if not rows[i]:
            continue
        ts = track_state[i]
        s, lat, head, v_ref = ts[TQ.S], ts[TQ.LATERAL], ts[TQ.HEADING], ts[TQ.V_REF]
        va = speed_along(vel_world[i], ts[TQ.PSI])
        v_along[i] = va
        v_max = max(max_speeds[i], 1e-3)
        da2 = 0.0
        for j in range(action.shape[1]):
            d = action[i, j] - prev_action[i, j]  # float32, as the actions
            da2 += d * d
        ds = min(max(s - s_prev[i], -v_max * dt), v_ref * dt + 1e-3 * dt)
        t = terms[i]
        t[RewardTerm.PROGRESS] = weights[RewardTerm.PROGRESS] * ds / (v_max * dt)
        t[RewardTerm.LATERAL] = -weights[RewardTerm.LATERAL] * (1.0 - math.exp(-abs(lat) / scales[0]))
        t[RewardTerm.HEADING] = -weights[RewardTerm.HEADING] * (1.0 - math.exp(-abs(head) / scales[1]))
        t[RewardTerm.OVERSPEED] = -weights[RewardTerm.OVERSPEED] * max(0.0, va - v_ref) / v_max
        t[RewardTerm.SLIP] = -min(weights[RewardTerm.SLIP] * slip[i], scales[2])
        t[RewardTerm.INTERNAL_FORCE] = -min(weights[RewardTerm.INTERNAL_FORCE] * internal[i], scales[2])
        t[RewardTerm.ACTION_RATE] = -weights[RewardTerm.ACTION_RATE] * da2
        t[RewardTerm.OFF_TRACK] = -weights[RewardTerm.OFF_TRACK] if off_track[i] else 0.0
        total = 0.0  # the sum in the order of RewardTerm
        for j in range(t.shape[0]):
            total += t[j]
        reward[i] = total


def charge_penalty(mask: np.ndarray, penalty: float, reward: np.ndarray, terms: np.ndarray) -> None:
    """The robots of ``mask`` pay the off-track ``penalty`` once (a stall): their off-track term
    becomes −penalty and their reward changes by the difference."""
    col = RewardTerm.OFF_TRACK
    reward[mask] += -penalty - terms[mask, col]
    terms[mask, col] = -penalty
