"""IT: the iterative joint-space ICR estimator, Algorithm 1 of §3.1.

Given measured steering angles q ∈ T^n, IT looks for the point S(λ) of the constraining surface,
eq. (9), closest to q: the orthogonal projection of q onto the surface.

* Starting points (§3.1.4): the intersections λ = c_i × c_j of the great circles of every pair of
  propulsion axes (c_k = s⊥1,k(q_k), eq. (8), (27)), collinear pairs skipped, ordered by their
  joint-space distance ‖q − S(λ)‖, the closest ``n_starts`` kept.
* Iteration (Lines 9–12): in the chart of λ (§2.1), a Gauss–Newton step on the two chart
  parameters, eq. (10)–(13), solved by Cramer's rule, with the chart derivatives
  S_p = ∇F · ∂λ/∂p, eq. (19), and ∇F from :mod:`estimation.kinematics`.
* Invalid parameters (§3.1.2): parameters outside the unit disc are multiplied by the norm of the
  previous ones until they are inside; a step that increases the distance is halved
  (backtracking) down to ``min_step``; below it the start fails and the next one is tried.
* Singularities (§3.1.3): a wheel whose steering axis holds λ gets a zero row in S_u, S_v and takes
  the input angle (zero distance term).
* Result (Lines 22–26): the first start that converges (‖λ − λ_t‖ ≤ ε_λ, or ‖q − S(λ₀)‖ ≤ ε_δ
  at the start itself); if none does, the closest λ found.

``race_iter`` set (not ``None``) is the improved variant, IT+ (not in the paper). Algorithm 1
read literally returns the first start that converges, even when another start would come
closer, and its backtracking stops a descent wherever a step crosses a steering stop, where the
surface jumps by π, although the distance may still decrease along that stop. IT+

* slides along the stop's boundary (the great circle s⊥1,k(β_max)·λ = 0) instead of stopping
  there (:func:`_slide`); the minima of D3 often lie on such boundaries;
* finishes the closest start, and only if the result is still far from the surface
  (``accept_rms``), races every pairwise intersection for ``race_iter`` iterations and finishes
  the leader.

The kernel is numba-compiled; the same code serves one point and a batch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from estimation.kinematics import (
    SINGULAR_TOL,
    _beta_grad_wheel,
    _beta_wheel,
    _grad_wheel,
    _steering_dist2,
    _steering_dist2_upto,
)
from estimation.validation import check_fields

__all__ = ["ITParams", "it_kernel_batch"]


@dataclass(frozen=True)
class ITParams:
    """Thresholds of Algorithm 1.

    Attributes:
        eps_delta: ε_δ [rad], joint-space distance ‖q − S(λ₀)‖ under which a starting point is
            accepted without iterating (a well-defined ICR, Line 4).
        eps_lambda: ε_λ, step ‖λ − λ_t‖ on the unit sphere under which the iteration has
            converged (Line 17).
        max_iter: maxIter, iterations per starting point (Line 20).
        min_step: backtracking floor: the smallest fraction of the Newton step tried before
            declaring a backtracking failure (§3.1.2, item 4).
        n_starts: number of starting points kept (§3.1.4; the paper uses 3).
        race_iter: ``None`` for the paper's Algorithm 1. An integer selects the improved variant
            IT+: the closest start descends to convergence (even through backtracking failures,
            which mostly stop it on a wrap of the surface, a good point); if the result is
            farther than ``accept_rms`` per wheel, every other kept start descends ``race_iter``
            iterations and the closest racer descends to convergence if it leads.
        accept_rms: IT+ only: RMS per-wheel distance [rad] under which the first result is kept
            without racing (the measured configuration is then close to the surface, in the
            first start's basin).
    """

    eps_delta: float = 1e-6
    eps_lambda: float = 1e-6
    max_iter: int = 50
    min_step: float = 1.0 / 1024
    n_starts: int = 3
    race_iter: int | None = None
    accept_rms: float = 0.05

    def accept_d2(self, n_wheels: int) -> float:
        """IT+'s squared-distance acceptance threshold for n wheels."""
        return n_wheels * self.accept_rms**2

    @property
    def race_iter_or_paper(self) -> int:
        """``race_iter`` for the kernel: −1 means the paper's Algorithm 1."""
        return -1 if self.race_iter is None else int(self.race_iter)

    def __post_init__(self) -> None:
        check_fields(self)
        for name in ("eps_delta", "eps_lambda", "min_step"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"ITParams.{name} must be finite and > 0, got {value}")
        if self.min_step > 1:
            raise ValueError(f"ITParams.min_step must be <= 1, got {self.min_step}")
        if not (np.isfinite(self.accept_rms) and self.accept_rms >= 0):
            raise ValueError(f"ITParams.accept_rms must be finite and >= 0, got {self.accept_rms}")
        for name in ("max_iter", "n_starts") + (("race_iter",) if self.race_iter is not None else ()):
            value = getattr(self, name)
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"ITParams.{name} must be an integer, got {value!r}")
        if int(self.max_iter) < 1 or int(self.n_starts) < 1:
            raise ValueError("ITParams.max_iter and n_starts must be >= 1")
        if self.race_iter is not None and not (0 <= int(self.race_iter) <= int(self.max_iter)):
            raise ValueError(f"ITParams.race_iter must be None or in [0, max_iter], got {self.race_iter}")


@njit(cache=True)
def _starting_points(q, E, P, steer_max, keep, starts, start_d2, start_beta, c, lam, scratch, periodic=False):
    """Pairwise propulsion-axis intersections, the ``keep`` closest sorted by joint-space distance.

    Fills ``starts`` (≥keep, 3), ``start_d2`` and ``start_beta`` (S of each start); ``c`` (n, 3),
    ``lam`` (3,) and ``scratch`` (n,) are work arrays. Returns how many were kept."""
    n = q.shape[0]
    for k in range(n):
        sb = math.sin(q[k])
        cb = math.cos(q[k])
        for i in range(3):
            c[k, i] = sb * E[k, i] - cb * P[k, i]  # s⊥1,k(q_k), eq. (27)
    m = 0
    for i in range(n):
        for j in range(i + 1, n):
            lam[0] = c[i, 1] * c[j, 2] - c[i, 2] * c[j, 1]
            lam[1] = c[i, 2] * c[j, 0] - c[i, 0] * c[j, 2]
            lam[2] = c[i, 0] * c[j, 1] - c[i, 1] * c[j, 0]
            nrm = math.sqrt(lam[0] * lam[0] + lam[1] * lam[1] + lam[2] * lam[2])
            if nrm <= 1e-12:
                continue  # collinear propulsion axes: no intersection
            lam[0] /= nrm
            lam[1] /= nrm
            lam[2] /= nrm
            bound = start_d2[keep - 1] if m == keep else np.inf
            d2 = _steering_dist2_upto(lam, q, E, P, steer_max, scratch, bound, periodic)
            if d2 > bound:
                continue  # farther than every start kept
            # insertion into the sorted list of kept starts
            pos = m if m < keep else keep - 1
            while pos > 0 and start_d2[pos - 1] > d2:
                start_d2[pos] = start_d2[pos - 1]
                for t in range(3):
                    starts[pos, t] = starts[pos - 1, t]
                for t in range(n):
                    start_beta[pos, t] = start_beta[pos - 1, t]
                pos -= 1
            start_d2[pos] = d2
            for t in range(3):
                starts[pos, t] = lam[t]
            for t in range(n):
                start_beta[pos, t] = scratch[t]
            if m < keep:
                m += 1
    return m


@njit(cache=True)
def _boundary_d2(x, q, E, P, steer_max, k, fixed):
    """Squared distance with wheel k's term held at ``fixed`` (wheel k at its stop)."""
    tot = fixed
    for w in range(q.shape[0]):
        if w == k:
            continue
        b, r2 = _beta_wheel(x[0], x[1], x[2], E, P, w, steer_max)
        if r2 >= SINGULAR_TOL * SINGULAR_TOL:
            tot += (q[w] - b) * (q[w] - b)
    return tot


@njit(cache=True)  # long on purpose: one compiled loop, state in locals (a split costs a call per step)
def _slide(q, E, P, steer_max, lam, d2, k, beta_lim, max_iter, min_step, grad, lam_t, scratch):
    """IT+ only: descend along the wrap boundary of wheel k, where β_k reaches a stop.

    The surface S(λ) jumps by π where a wheel's β crosses its stop; the boundary is the great
    circle of normal n_k = s⊥1,k(β_max), eq. (27). A Gauss–Newton step that keeps crossing it fails
    by backtracking although the distance still decreases along the boundary. Here λ is projected
    on that circle and moved along it (wheel k held at its stop ``beta_lim``, the limit on λ's
    side), with the same Gauss–Newton step and backtracking in one parameter. The result is
    nudged back inside λ's side. Returns the new squared distance (λ updated) or d2 unchanged."""
    n = q.shape[0]
    sm = math.sin(steer_max)
    cm = math.cos(steer_max)
    nk0 = sm * E[k, 0] - cm * P[k, 0]
    nk1 = sm * E[k, 1] - cm * P[k, 1]
    nk2 = sm * E[k, 2] - cm * P[k, 2]
    nn = nk0 * nk0 + nk1 * nk1 + nk2 * nk2
    dot = nk0 * lam[0] + nk1 * lam[1] + nk2 * lam[2]
    base = np.empty(3)
    base[0] = lam[0] - dot * nk0 / nn
    base[1] = lam[1] - dot * nk1 / nn
    base[2] = lam[2] - dot * nk2 / nn
    nb = math.sqrt(base[0] * base[0] + base[1] * base[1] + base[2] * base[2])
    if nb < 1e-12:
        return d2
    for m in range(3):
        base[m] /= nb
    fixed = (q[k] - beta_lim) * (q[k] - beta_lim)
    cur = np.empty(3)
    for m in range(3):
        cur[m] = base[m]

    f = _boundary_d2(cur, q, E, P, steer_max, k, fixed)
    t = np.empty(3)
    for _ in range(max_iter):
        # unit tangent of the boundary circle at cur
        t[0] = nk1 * cur[2] - nk2 * cur[1]
        t[1] = nk2 * cur[0] - nk0 * cur[2]
        t[2] = nk0 * cur[1] - nk1 * cur[0]
        tn = math.sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2])
        if tn < 1e-12:
            break
        for m in range(3):
            t[m] /= tn
        jj = 0.0
        jr = 0.0
        for w in range(n):
            if w == k:
                continue
            b, singular = _beta_grad_wheel(cur, E, P, w, steer_max, grad)
            if singular:
                continue
            g = grad[0] * t[0] + grad[1] * t[1] + grad[2] * t[2]
            jj += g * g
            jr += g * (q[w] - b)
        if jj <= 1e-300:
            break
        ds = jr / jj
        step = 1.0
        accepted = False
        ft = f
        while step >= min_step:
            a = step * ds
            ca = math.cos(a)
            sa = math.sin(a)
            for m in range(3):
                lam_t[m] = ca * cur[m] + sa * t[m]
            ft = _boundary_d2(lam_t, q, E, P, steer_max, k, fixed)
            if ft <= f:
                accepted = True
                break
            step *= 0.5
        if not accepted:
            break
        for m in range(3):
            cur[m] = lam_t[m]
        moved = abs(step * ds)
        f = ft
        if moved <= 1e-10:
            break
    # nudge off the boundary to λ's side of it (the side where wheel k sits at beta_lim)
    best = d2
    for sgn in (-1.0, 1.0):
        for m in range(3):
            lam_t[m] = cur[m] + sgn * 1e-9 * (nk0 if m == 0 else (nk1 if m == 1 else nk2)) / math.sqrt(nn)
        dt = _steering_dist2(lam_t, q, E, P, steer_max, scratch)
        if dt < best:
            best = dt
            nrm = math.sqrt(lam_t[0] * lam_t[0] + lam_t[1] * lam_t[1] + lam_t[2] * lam_t[2])
            for m in range(3):
                lam[m] = lam_t[m] / nrm
    return best


@njit(cache=True)  # long on purpose: Algorithm 1's loop compiled whole, state in locals, no call per step
def _descend(q, E, P, steer_max, lam, d2, beta_cur, eps_lambda, max_iter, min_step, grad, lam_t, beta_t,
             slide=False, periodic=False):
    """Lines 7–20 of Algorithm 1 from λ (modified in place), given d2 = ‖q − S(λ)‖² and
    ``beta_cur`` = S(λ) (updated in place, so F is evaluated once per point).

    With ``slide`` (IT+), a backtracking failure next to a stop continues along the stop's
    boundary (:func:`_slide`) instead of ending the descent. ``beta_t`` is a work array of n.
    ``periodic`` (unlimited steering): the distance is taken modulo π per wheel
    (:func:`~estimation.kinematics._steering_dist2_upto`), continuous where F wraps, so there is
    no stop to slide along. Returns (d2, iterations, converged)."""
    n = q.shape[0]
    count = 0
    kmax = -1
    while count < max_iter:
        # Chart selection (§2.1): largest |λ_c|, representative with λ_c > 0.
        c = 0
        if abs(lam[1]) > abs(lam[c]):
            c = 1
        if abs(lam[2]) > abs(lam[c]):
            c = 2
        if lam[c] < 0:
            lam[0] = -lam[0]
            lam[1] = -lam[1]
            lam[2] = -lam[2]
        i = (c + 1) % 3
        j = (c + 2) % 3
        # COMPUTEDERIVATIVES (Line 9): S_u, S_v, and the residual q − S(λ).
        a11 = 0.0
        a12 = 0.0
        a22 = 0.0
        b1 = 0.0
        b2 = 0.0
        kmax = -1
        beta_near = 0.0
        for k in range(n):
            if _grad_wheel(lam, E, P, k, grad):
                continue  # §3.1.3: zero row, wheel discarded from (13)
            beta = beta_cur[k]
            edge = min(steer_max - beta, beta - (steer_max - math.pi))
            if kmax < 0 or edge < beta_near:
                kmax = k
                beta_near = edge
            su_k = grad[i] - grad[c] * lam[i] / lam[c]  # eq. (19)
            sv_k = grad[j] - grad[c] * lam[j] / lam[c]
            res = q[k] - beta
            a11 += su_k * su_k
            a12 += su_k * sv_k
            a22 += sv_k * sv_k
            b1 += res * su_k
            b2 += res * sv_k
        # SOLVE (Line 10): eq. (13) by Cramer's rule.
        det = a11 * a22 - a12 * a12
        if not (det > 1e-14 * (a11 * a22 + 1e-300)):
            return d2, count, False
        du = (b1 * a22 - b2 * a12) / det
        dv = (a11 * b2 - a12 * b1) / det
        # UPDATEPARAMETERS with backtracking (Line 11, §3.1.2).
        old_norm = math.sqrt(lam[i] * lam[i] + lam[j] * lam[j])
        step = 1.0
        accepted = False
        dt = d2
        while step >= min_step:
            x = lam[i] + step * du
            y = lam[j] + step * dv
            rho2 = x * x + y * y
            shrink = 0
            while rho2 > 1.0 and shrink < 64:
                x *= old_norm
                y *= old_norm
                rho2 = x * x + y * y
                shrink += 1
            if rho2 > 1.0:
                x /= math.sqrt(rho2)
                y /= math.sqrt(rho2)
                rho2 = 1.0
            lam_t[i] = x
            lam_t[j] = y
            lam_t[c] = math.sqrt(max(0.0, 1.0 - rho2))
            dt = _steering_dist2(lam_t, q, E, P, steer_max, beta_t, periodic)
            if dt <= d2:
                accepted = True
                break
            step *= 0.5
        if not accepted:
            if slide and not periodic and kmax >= 0 and beta_near < 0.3:
                beta_k, _ = _beta_wheel(lam[0], lam[1], lam[2], E, P, kmax, steer_max)
                lim = steer_max if steer_max - beta_k < beta_k - (steer_max - math.pi) else steer_max - math.pi
                ds2 = _slide(q, E, P, steer_max, lam, d2, kmax, lim, max_iter, min_step, grad, lam_t, beta_t)
                if ds2 < d2 * (1.0 - 1e-12):
                    d2 = _steering_dist2(lam, q, E, P, steer_max, beta_cur)
                    count += 1
                    continue
                return d2, count, True  # a minimum on the stop's boundary
            return d2, count, False  # backtracking failure: keep λ, try the next start
        moved2 = 0.0
        for m in range(3):
            diff = lam[m] - lam_t[m]
            moved2 += diff * diff
            lam[m] = lam_t[m]
        for k in range(n):
            beta_cur[k] = beta_t[k]
        d2 = dt
        count += 1
        if moved2 <= eps_lambda * eps_lambda:
            return d2, count, True
    return d2, count, False


@njit(cache=True)  # long on purpose: one point in one compiled call on the workspace ws, no allocation
def _it_point(q, E, P, steer_max, eps_delta, eps_lambda, max_iter, min_step, n_starts, race_iter, accept_d2, ws,
              out, periodic=False):
    """One point: fills out[0:3] with λ. Returns (d2, iterations, starts tried, converged).

    ``race_iter`` < 0 runs the paper's Algorithm 1. ``race_iter`` >= 0 runs the improved variant:
    the closest start descends to convergence; if it ends farther than sqrt(accept_d2) from q,
    every other kept start descends ``race_iter`` iterations and the closest racer is finished.
    ``ws`` holds the work arrays (:func:`_workspace`)."""
    starts, start_d2, start_beta, c, grad, lam, lam_t, beta_cur, beta_t, race_lam, race_it = ws
    n = q.shape[0]
    m = _starting_points(q, E, P, steer_max, n_starts, starts, start_d2, start_beta, c, lam, beta_t, periodic)
    if m == 0:
        # No pair of propulsion axes intersects (cannot happen with non-collinear steering axes
        # and finite input); fall back to the rotation about the chassis centre.
        out[0] = 0.0
        out[1] = 0.0
        out[2] = 1.0
        return _steering_dist2(out, q, E, P, steer_max, beta_t, periodic), 0, 0, False
    if math.sqrt(start_d2[0]) <= eps_delta:
        # Line 4: the closest intersection lies on the surface: a well-defined ICR.
        for i in range(3):
            out[i] = starts[0, i]
        return start_d2[0], 0, 1, True
    total_iter = 0
    if race_iter < 0:
        best_d2 = np.inf
        best_conv = False
        tried = 0
        for s in range(m):
            tried += 1
            for i in range(3):
                lam[i] = starts[s, i]
            for k in range(n):
                beta_cur[k] = start_beta[s, k]
            d2, it, conv = _descend(q, E, P, steer_max, lam, start_d2[s], beta_cur, eps_lambda, max_iter, min_step,
                                    grad, lam_t, beta_t, False, periodic)
            total_iter += it
            if conv or d2 < best_d2:
                # Line 23 returns the first start that converges; Line 26 the closest otherwise.
                best_d2 = d2
                best_conv = conv
                for i in range(3):
                    out[i] = lam[i]
            if conv:
                break
        return best_d2, total_iter, tried, best_conv
    # Improved variant. First the closest start descends to convergence, as in Algorithm 1.
    for i in range(3):
        out[i] = starts[0, i]
    for k in range(n):
        beta_cur[k] = start_beta[0, k]
    best_d2, it, best_conv = _descend(q, E, P, steer_max, out, start_d2[0], beta_cur, eps_lambda, max_iter,
                                      min_step, grad, lam_t, beta_t, True, periodic)
    total_iter += it
    if best_d2 <= accept_d2 or m == 1:
        return best_d2, total_iter, 1, best_conv
    # Far from the surface, other basins may hold closer points: a short race between the other
    # starts, then the closest racer, if it beats the first result, descends to convergence.
    lead = -1
    lead_d2 = best_d2
    lead_done = False
    for s in range(1, m):
        for i in range(3):
            race_lam[s, i] = starts[s, i]
        for k in range(n):
            beta_cur[k] = start_beta[s, k]
        d2, it, conv = _descend(q, E, P, steer_max, race_lam[s], start_d2[s], beta_cur, eps_lambda, race_iter,
                                min_step, grad, lam_t, beta_t, True, periodic)
        total_iter += it
        race_it[s] = it
        if d2 < lead_d2:
            lead = s
            lead_d2 = d2
            lead_done = conv or it < race_iter  # converged, or stopped by a backtracking failure
    if lead < 0:
        return best_d2, total_iter, m, best_conv
    for i in range(3):
        lam[i] = race_lam[lead, i]
    d2 = lead_d2
    conv = lead_done
    if not conv:
        d2 = _steering_dist2(lam, q, E, P, steer_max, beta_cur, periodic)
        d2, it, conv = _descend(q, E, P, steer_max, lam, d2, beta_cur, eps_lambda, max_iter - race_it[lead],
                                min_step, grad, lam_t, beta_t, True, periodic)
        total_iter += it
    if d2 < best_d2:
        best_d2 = d2
        best_conv = conv
        for i in range(3):
            out[i] = lam[i]
    return best_d2, total_iter, m, best_conv


@njit(cache=True)
def _workspace(n):
    """Work arrays of one IT evaluation for n wheels, allocated once per batch."""
    m_max = n * (n - 1) // 2
    return (np.empty((m_max, 3)), np.empty(m_max), np.empty((m_max, n)), np.empty((n, 3)), np.empty(3),
            np.empty(3), np.empty(3), np.empty(n), np.empty(n), np.empty((m_max, 3)),
            np.empty(m_max, dtype=np.int64))


@njit(cache=True)
def it_kernel_batch(q, E, P, steer_max, eps_delta, eps_lambda, max_iter, min_step, n_starts,
                    race_iter, accept_d2, lam_out, d2_out, iters_out, starts_out, conv_out, periodic=False):
    """Algorithm 1 over a batch q (N, n). Writes λ (N, 3) and diagnostics. ``periodic``:
    unlimited steering (the joint-space distance modulo π per wheel)."""
    n = q.shape[1]
    m_max = n * (n - 1) // 2
    keep = min(max(n_starts, 1), m_max)
    ws = _workspace(n)
    out = np.empty(3)
    for p in range(q.shape[0]):
        d2, it, tried, conv = _it_point(q[p], E, P, steer_max, eps_delta, eps_lambda, max_iter, min_step, keep,
                                        race_iter, accept_d2, ws, out, periodic)
        lam_out[p, 0] = out[0]
        lam_out[p, 1] = out[1]
        lam_out[p, 2] = out[2]
        d2_out[p] = d2
        iters_out[p] = it
        starts_out[p] = tried
        conv_out[p] = conv
