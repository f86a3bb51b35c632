"""Look-ahead for the ICR controller: which configuration cell to be in along a track, and where
to change it (:func:`plan_cells`, :class:`CellPlan`).

The stop circles of the wheels cut Λ into *cells* (``docs/icr-controller.md`` §5): inside one,
no wheel passes its steering stop, so the controller moves λ freely; leaving one means stopping
the robot and turning some wheels by up to π (1–2 s at rest). Without look-ahead the controller
decides from the current arc λ → λ_d only: it stops wherever the target leaves λ's cell by more
than a hold takes (``stop_hold_distance``, 1 cm of missed motion), even for a short excursion of
the reference that comes straight back, and it picks the cell after a stop from the target of
that moment, not from where the reference goes next.

The plan looks at the whole reference instead. Along the track, sampled every ``spacing`` [m]
of progress, the reference motion is (λ_j, μ_j) at the track's speed v_j (× the speed scale). A
cell sequence c_0 … c_M costs, in seconds,

    J = Σ_j w · m_j(c_j)  +  Σ_{j: c_j ≠ c_{j−1}} T_j(c_{j−1} → c_j)

* m_j(c) = μ_j ‖λ_j − p_c(λ_j)‖ Δt_j, the motion [m] missed while the controller holds λ at
  p_c(λ_j), the point of cell c nearest to λ_j (the hold point of §5; 0 when λ_j is in c;
  Δt_j = spacing / v_j), with w = ``miss_cost`` [s/m]; a hold farther from a moving reference
  than the controller holds (its ``stop_hold_angle``) is not allowed;
* T_j, the time a stop and reconfiguration costs there: the speed lost braking to rest and
  accelerating again, v_j / a (a = the follower's ``corner_decel``), plus the slowest wheel's turn
  from its angle in c_{j−1} to its angle in c_j (a trapezoidal profile at the reconfiguration rate
  and acceleration), plus ``switch_overhead`` (detecting rest, settling).

The cheapest sequence is found exactly by dynamic programming over (sample, cell) (Viterbi; the
candidate cells are those the reference visits, and both sides of a circle it runs along). So a
short excursion whose hold misses a few millimetres stays in its cell (held on the boundary,
§5), an unavoidable change of cell lands where the reference is slow (a cusp, a corner, a stop
of the speed profile, a spin in place), and the cell after a stop and the first cell are those
the reference ahead needs.

The plan is a table over progress: :attr:`CellPlan.start` [m] where each segment begins and its
cell's sign pattern :attr:`CellPlan.side` (±1 per stop circle). The path follower slows down to
arrive slowly at the switch points (:attr:`CellPlan.switches`); the controller gets, every step,
the cell planned at the robot's progress (:func:`plan_sides`) and holds λ in it rather than stop,
or stops and reconfigures into it when the plan changes cell (``docs/icr-controller.md`` §6).

Why a dynamic program over cells, not an MPC over (λ, μ) or a time-optimal speed profile: the
choice that costs time is discrete (which cell, where to change it) and is fixed by the
reference's geometry alone (λ(s) does not depend on the speed), so it is solved once per track,
exactly, in milliseconds; the continuous motion inside a cell is already time-scaled within the
actuator limits by the controller's κ search (§7.1). Measurements are in ``docs/icr-controller.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from control.follow.path_follower import reference_lambdas
from control.icr.config import ICRControllerConfig
from control.icr.kernel_constants import stop_circle_normals
from control.icr.kernels import EXCURSION_END, EXCURSION_NONE, EXCURSION_PLANNED, in_cell, nearest_in_cell, steering_row
from control.limits import ActuatorLimits
from estimation.geometry import RobotGeometry
from estimation.validation import check_fields, check_positive_fields, check_range

__all__ = ["LookaheadConfig", "CellPlan", "PlanTable", "plan_cells", "plan_table", "plan_sides", "capped_track"]

_INF = 1e18
_ICR = ICRControllerConfig()  # the controller's defaults, the plan's holds'


@dataclass(frozen=True)
class LookaheadConfig:
    """Tuning of the cell plan (module docstring).

    Attributes:
        miss_cost: w, seconds a metre of motion missed while holding costs [s/m] (40: a 5 cm
            miss weighs as much as a 2 s stop).
        switch_overhead: fixed time of a stop and reconfiguration besides braking and turning
            (detecting rest, settling the wheels) [s].
        spacing: progress between reference samples [m].
        swing_window, steer_rate_fraction: the planned steering β(s) is differenced over
            ``swing_window`` [m] of progress, and the reference speed capped where the wheels would
            need more than ``steer_rate_fraction`` of their steering rate limit to keep up.
        excursion_margin: [m] how far before and after an expected excursion of the reference
            the controller may hold for it (the robot's progress and the follower's preview are
            not the reference's).
        stall_distance, stall_time: a robot whose progress grows by less than ``stall_distance``
            [m] in ``stall_time`` [s] (outside the track's holds) is steered without its plan for
            the rest of its episode: near a change of cell, a reference neither cell follows can
            hold it still (the safety net).
        corner_speed: the path follower's speed floor at its stop points [m/s] (corners, the
            plan's changes of cell; the follower's own default is 0.02). At 2 cm/s the target's
            direction at a corner is the position feedback's, which swings as the robot settles
            on the corner, and the controller reconfigured after it without end (``spin`` stalled
            on 2 of 5 seeds on azimut3, 3 of 5 on hex); at 7 cm/s the reference's direction
            dominates and the controller stops and reconfigures once, where the reference turns
            (at 10 cm/s tri's ``square`` stalled at a corner on 2 of 5 seeds, at 5 cm/s hex's on 1).
        end_hold: [m] on an open track, the last ``end_hold`` of progress is the approach to the
            end, where the controller holds λ in the last planned cell whatever the target's angle
            (within ``planned_hold_distance``; 0: no such approach). The follower's target slows to
            zero there against the robot's steady offset from the reference, so its direction
            becomes the position feedback's and swings; a stop and reconfiguration for it (over a
            second) would buy the last centimetres (``docs/icr-controller.md`` §9).
    """

    miss_cost: float = 40.0
    switch_overhead: float = 0.5
    spacing: float = 0.01
    swing_window: float = 0.05
    steer_rate_fraction: float = 0.8
    excursion_margin: float = 0.1
    stall_distance: float = 0.02
    stall_time: float = 3.0
    corner_speed: float = 0.07
    end_hold: float = 0.1

    def __post_init__(self) -> None:
        check_fields(self)
        check_positive_fields(self, "spacing", "swing_window", "steer_rate_fraction", "stall_time",
                              "corner_speed")
        check_positive_fields(self, "miss_cost", "switch_overhead", "excursion_margin", "stall_distance",
                              "end_hold", allow_zero=True)
        for name, lo, hi in (("spacing", 0.001, 0.1), ("steer_rate_fraction", 0.0, 1.0),
                             ("swing_window", 0.0, 1.0), ("corner_speed", 0.0, 1.0), ("end_hold", 0.0, 1.0)):
            check_range(f"LookaheadConfig.{name}", getattr(self, name), lo, hi)


@dataclass(frozen=True)
class CellPlan:
    """Where the ICR controller should be in which cell along a track (module docstring).

    Attributes:
        start: (K,) progress [m] where each segment begins (the first at the plan's start).
        side: (K, n) the segment's cell: the side (±1) of each stop circle (a cell and its
            negation are the same cell of Λ).
        cost: the plan's cost J [s].
        holds_missed: the motion [m] the plan expects to miss while holding, in total.
        excursions: (E, 2) the progress intervals [m] where the reference leaves the planned cell
            (the plan holds there), widened by ``excursion_margin``.
        s: (M,) the progress samples [m]; speed_cap: (M,) the speed [m/s] at which the wheels, at
            ``steer_rate_fraction`` of their steering rate limit, keep up with the planned
            configuration's steering β(s) over a ``swing_window`` (module docstring), braked
            and accelerated within the follower's deceleration.
        end_from: the progress [m] where the approach to the end begins (``end_hold`` before an
            open track's end; inf on a closed track).
    """

    start: np.ndarray
    side: np.ndarray
    cost: float
    holds_missed: float
    excursions: np.ndarray
    s: np.ndarray
    speed_cap: np.ndarray
    end_from: float = math.inf

    @property
    def switches(self) -> np.ndarray:
        """(K − 1,) the progress values [m] where the plan changes cell."""
        return self.start[1:]


def _signature(lam: np.ndarray, N: np.ndarray, tol: float = 1e-3) -> list[tuple[int, ...]]:
    """The cells λ lies in or on the rim of: its sign pattern (first entry +1, the canonical one
    of the pair ±pattern), with both signs for circles it is within ``tol`` of."""
    d = N @ lam
    options = [[1.0, -1.0] if abs(x) < tol else [1.0 if x >= 0 else -1.0] for x in d]
    cells = [()]
    for opt in options:
        cells = [c + (o,) for c in cells for o in opt]
    return [tuple(int(v * c[0]) for v in c) for c in cells]


@njit(cache=True)
def _hold_costs(lams, mus, dts, sides, N, margin, max_angle, E, P, steer_max, cost, betas):
    """Per sample j and cell c: the motion missed holding in c (``cost`` (M, C), inf when the
    hold is farther than ``max_angle``) and the wheels' angles there (``betas`` (M, C, n))."""
    M, C, n = lams.shape[0], sides.shape[0], N.shape[0]
    p = np.empty(3)
    neg = np.empty(3)
    scratch = np.empty(3)
    fill = np.zeros(n)
    for j in range(M):
        for c in range(C):
            angle = nearest_in_cell(sides[c], lams[j], N, margin, p, neg, scratch)
            if angle < 0.0 or (angle > max_angle and abs(mus[j]) > 0.05):
                cost[j, c] = np.inf
                continue
            cost[j, c] = abs(mus[j]) * (2.0 * math.sin(0.5 * angle)) * dts[j]  # μ ‖λ − p‖ Δt
            steering_row(p, E, P, steer_max, fill, False, betas[j, c], scratch)


@njit(cache=True, inline="always")
def _turn_time(delta, rate, accel) -> float:
    """A trapezoidal turn by ``delta`` [rad] at ``rate`` and ``accel`` [s]."""
    if delta * accel >= rate * rate:
        return delta / rate + rate / accel
    return 2.0 * math.sqrt(delta / accel)


@njit(cache=True)
def _viterbi(hold, betas, speeds, w, decel, overhead, rate, accel, choice):
    """The cheapest cell per sample into ``choice`` (M,); returns the cost J [s]."""
    M, C = hold.shape
    n = betas.shape[2]
    cost = np.empty(C)
    new = np.empty(C)
    back = np.zeros((M, C), dtype=np.int64)
    for c in range(C):
        cost[c] = w * hold[0, c]
    for j in range(1, M):
        brake = speeds[j] / decel + overhead
        for c in range(C):
            if not hold[j, c] < np.inf:  # no hold in c here: c is not a state of sample j
                new[c] = _INF
                back[j, c] = c
                continue
            best = cost[c]
            arg = c
            for d in range(C):
                if d == c or cost[d] >= _INF:
                    continue
                # the wheels turn from their angles in d at the previous sample (where the robot stopped)
                turn = 0.0
                for k in range(n):
                    turn = max(turn, _turn_time(abs(betas[j, c, k] - betas[j - 1, d, k]), rate, accel))
                total = cost[d] + brake + turn
                if total < best:
                    best, arg = total, d
            new[c] = best + w * hold[j, c]
            back[j, c] = arg
        for c in range(C):
            cost[c] = new[c]
    last = 0
    for c in range(C):
        if cost[c] < cost[last]:
            last = c
    total = cost[last]
    for j in range(M - 1, -1, -1):
        choice[j] = last
        last = back[j, last]
    return total


def plan_cells(track, geom: RobotGeometry, limits: ActuatorLimits, *, speed_scale: float = 1.0,
               start: float = 0.0, decel: float = 1.0, rate_fraction: float = 1.0, accel_fraction: float = 1.0,
               hold_margin: float = _ICR.stop_hold_margin, hold_angle: float = _ICR.stop_hold_angle, corners=(),
               corner_speed: float = 0.02,
               config: LookaheadConfig | None = None) -> CellPlan | None:
    """The cell plan of ``track`` from progress ``start`` to its end (a closed track: one lap)
    for the robot ``geom`` (module docstring). None without steering stops (one cell).

    Args:
        speed_scale: multiplies the track's speed profile. decel: the follower's braking [m/s²].
        corners, corner_speed: the progress values [m] the follower brakes to arrive at at
            ``corner_speed`` [m/s] (sharp corners of the path); the plan counts the time there at
            that speed.
        rate_fraction, accel_fraction: the reconfiguration's share of the steering limits.
        hold_margin: how far inside its cell a hold point is [rad] (the controller's
            ``stop_hold_margin``).
        hold_angle: the farthest a hold may be from the reference λ [rad] while the reference
            moves (|μ| > 0.05 m/s): the controller's own ``stop_hold_angle``, so the plan counts
            only on holds the controller makes (a plan holding farther stops where it planned not
            to: ``docs/icr-controller.md`` §9).
        config: the plan's tuning (default :class:`LookaheadConfig`).
    """
    hold_margin = check_range("hold_margin", hold_margin, 0.0, 0.1)
    hold_angle = check_range("hold_angle", hold_angle, 0.0, math.pi, lo_open=True)
    if geom.unlimited_steering:
        return None
    cfg = config or LookaheadConfig()
    length = track.length
    s = start + np.arange(0.0, length - start if not track.closed else length, cfg.spacing)
    lam, unit_mu = reference_lambdas(track, s)
    speed = track.sample(s)[:, 3] * speed_scale
    corners = np.asarray(corners, dtype=np.float64).ravel()
    if corners.size:
        ahead = np.concatenate([corners, corners + length]) if track.closed else corners
        nxt = np.searchsorted(ahead, s, side="left")
        dist = np.where(nxt < ahead.size, ahead[np.minimum(nxt, ahead.size - 1)] - s, np.inf)
        speed = np.minimum(speed, np.sqrt(2.0 * decel * np.maximum(dist, 0.0)) + corner_speed)
    moving = unit_mu > 1e-9
    if not moving.any():
        return None
    # a sample that does not move keeps the last moving λ (the first moving one before that)
    idx = np.where(moving, np.arange(s.size), -1)
    idx = np.maximum.accumulate(idx)
    idx[idx < 0] = np.flatnonzero(moving)[0]
    lam = lam[idx]
    mus = np.where(moving, unit_mu * speed, 0.0)
    dts = cfg.spacing / np.maximum(speed, 1e-3)
    N = stop_circle_normals(geom)
    E, P = np.ascontiguousarray(geom.a_minus_l, dtype=np.float64), np.ascontiguousarray(geom.a_perp, dtype=np.float64)
    cells = sorted({c for row in lam[::max(1, int(0.05 / cfg.spacing))] for c in _signature(row, N)}
                   | {c for row in lam for c in _signature(row, N, tol=0.0)})
    sides = np.array(cells, dtype=np.float64)
    hold = np.empty((s.size, sides.shape[0]))
    betas = np.zeros((s.size, sides.shape[0], geom.n))  # read only where the hold is finite
    _hold_costs(lam, mus, dts, sides, N, hold_margin, hold_angle, E, P, float(geom.steer_max), hold, betas)
    choice = np.empty(s.size, dtype=np.int64)
    cost = _viterbi(hold, betas, speed, cfg.miss_cost, decel, cfg.switch_overhead,
                    rate_fraction * limits.steer_rate_max, accel_fraction * limits.steer_accel_max, choice)
    first = np.concatenate([[0], np.flatnonzero(np.diff(choice)) + 1])
    held = hold[np.arange(s.size), choice]
    beta = betas[np.arange(s.size), choice]
    cap = _speed_cap(beta, choice, cfg, cfg.steer_rate_fraction * limits.steer_rate_max, decel)
    out = (held > 0).astype(np.int8)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], out, [0]])))
    excursions = np.stack([s[edges[0::2]] - cfg.excursion_margin,
                           s[np.minimum(edges[1::2], s.size) - 1] + cfg.excursion_margin], axis=1)
    end_from = math.inf if track.closed or cfg.end_hold == 0.0 else length - cfg.end_hold
    return CellPlan(start=s[first].copy(), side=sides[choice[first]].copy(), cost=float(cost),
                    holds_missed=float(np.sum(held[np.isfinite(held)])), excursions=excursions, s=s, speed_cap=cap,
                    end_from=end_from)


def _speed_cap(beta: np.ndarray, choice: np.ndarray, cfg: LookaheadConfig, rate: float, decel: float) -> np.ndarray:
    """(M,) v ≤ rate / |Δβ/Δs| over ``swing_window`` of the planned steering (a change of cell is a
    stop: not counted), then braked and accelerated at ``decel`` between samples."""
    M = beta.shape[0]
    h = max(1, int(round(0.5 * cfg.swing_window / cfg.spacing)))
    lo, hi = np.maximum(np.arange(M) - h, 0), np.minimum(np.arange(M) + h, M - 1)
    same = choice[lo] == choice[hi]
    turn = np.mod(beta[hi] - beta[lo] + 0.5 * np.pi, np.pi) - 0.5 * np.pi  # a wheel at its stop: ±π/2 alike
    slope = np.max(np.abs(turn), axis=1) / np.maximum((hi - lo) * cfg.spacing, 1e-12)
    cap = np.where(same & (slope > 0), rate / np.maximum(slope, 1e-12), np.inf)
    step = 2.0 * decel * cfg.spacing
    for j in range(M - 2, -1, -1):  # brake before
        cap[j] = min(cap[j], math.sqrt(cap[j + 1] ** 2 + step))
    for j in range(1, M):  # accelerate after
        cap[j] = min(cap[j], math.sqrt(cap[j - 1] ** 2 + step))
    return cap


def capped_track(track, plan: CellPlan, speed_scale: float):
    """A copy of ``track`` whose speed profile (scaled by ``speed_scale``) stays within the plan's
    :attr:`CellPlan.speed_cap`: the reference a path follower should follow."""
    from dataclasses import replace

    cap = np.interp(track.s, plan.s, plan.speed_cap, left=np.inf, right=np.inf)
    if track.closed:
        cap = np.minimum(cap, np.interp(track.s + track.length, plan.s, plan.speed_cap, left=np.inf, right=np.inf))
    speed = np.minimum(track.speed, cap / speed_scale)
    return replace(track, speed=speed)


@njit(cache=True)
def _lookup(starts, sides, counts, exc, exc_counts, end_from, closed, lengths, progress, lam_d, N, lead, segment,
            out, out_exc):
    for i in range(progress.shape[0]):
        K = counts[i]
        out[i, :] = 0.0
        out_exc[i] = EXCURSION_NONE
        if K == 0 or not math.isfinite(progress[i]):
            continue
        s = progress[i]
        if closed[i]:  # one lap from the plan's start (a progress just short of it is the start)
            s = starts[i, 0] + ((s - starts[i, 0] + 0.05) % lengths[i]) - 0.05
        k = min(max(segment[i], 0), K - 1)
        while k + 1 < K and starts[i, k + 1] <= s:
            k += 1
        if k + 1 < K and starts[i, k + 1] - s < lead and not in_cell(lam_d[i], sides[i, k], N) \
                and in_cell(lam_d[i], sides[i, k + 1], N):
            k += 1
        segment[i] = k
        for q in range(sides.shape[2]):
            out[i, q] = sides[i, k, q]
        for e in range(exc_counts[i]):
            if exc[i, e, 0] <= s <= exc[i, e, 1]:
                out_exc[i] = EXCURSION_PLANNED
        if s >= end_from[i]:
            out_exc[i] = EXCURSION_END


class PlanTable(NamedTuple):
    """N robots' plans packed for the compiled lookup (:func:`plan_table`)."""

    starts: np.ndarray  #: (N, K) segment starts [m]
    sides: np.ndarray  #: (N, K, n) segment cells
    counts: np.ndarray  #: (N,) segments per robot (0: no plan)
    excursions: np.ndarray  #: (N, E, 2) expected excursions [m]
    excursion_counts: np.ndarray  #: (N,)
    end_from: np.ndarray  #: (N,) where the approach to the end begins [m] (inf: nowhere)
    closed: np.ndarray  #: (N,) bool: the robot's track is a loop
    lengths: np.ndarray  #: (N,) its length [m]


def plan_table(plans: list[CellPlan | None], tracks, n: int) -> PlanTable:
    """The plans of N robots (None: no plan) on their ``tracks``, packed once per reset."""
    num = len(plans)
    K = max([1] + [p.start.size for p in plans if p is not None])
    E = max([1] + [p.excursions.shape[0] for p in plans if p is not None])
    table = PlanTable(np.zeros((num, K)), np.zeros((num, K, n)), np.zeros(num, dtype=np.int64), np.zeros((num, E, 2)),
                      np.zeros(num, dtype=np.int64), np.full(num, np.inf),
                      np.array([bool(t.closed) for t in tracks], dtype=np.bool_),
                      np.array([float(t.length) for t in tracks]))
    for i, p in enumerate(plans):
        if p is not None:
            table.counts[i], table.excursion_counts[i] = p.start.size, p.excursions.shape[0]
            table.starts[i, :p.start.size], table.sides[i, :p.start.size] = p.start, p.side
            table.excursions[i, :p.excursions.shape[0]] = p.excursions
            table.end_from[i] = p.end_from
    return table


def plan_sides(table: PlanTable, progress: np.ndarray, lam_d: np.ndarray, normals: np.ndarray, segment: np.ndarray,
               lead: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """(N, n) the cell each robot's plan (``table``, :func:`plan_table`) has at its ``progress``
    [m] (zeros: no plan), or already the next one when the change is less than ``lead`` [m] ahead
    and the target λ_d (N, 3) has left the planned cell for it (the robot arrives slowly at a
    change of cell, and the reference there may already ask for the next cell a few centimetres
    early: holding it in the old cell would make no progress). ``normals``: the stop circles'
    (n, 3). ``segment`` (N,) int: each robot's current segment of its plan, updated in place (it
    never goes back: a target that swings back and forth at rest does not swing the plan; 0 after
    a reset). Also (N,) the excursion flag: ``EXCURSION_PLANNED`` (1.0) where the progress is in one
    of the plan's expected excursions, ``EXCURSION_END`` (2.0) on the approach to the track's end
    (:attr:`CellPlan.end_from`), 0.0 elsewhere."""
    num, n = table.counts.shape[0], normals.shape[0]
    out = np.empty((num, n))
    out_exc = np.empty(num)
    _lookup(table.starts, table.sides, table.counts, table.excursions, table.excursion_counts, table.end_from,
            table.closed,
            table.lengths, np.asarray(progress, dtype=np.float64), np.ascontiguousarray(lam_d, dtype=np.float64),
            np.ascontiguousarray(normals, dtype=np.float64), float(lead), segment, out, out_exc)
    return out, out_exc
