"""Compiled track queries: the windowed projection onto a track and the per-step track state
(progress, tracking errors, reference speed, look-ahead) of N robots, each on its own track.

The tracks enter as :meth:`~azimut_env.tracks.Track.packed` arrays (6, m) = rows (s, x, y, θ, v, ψ).
One kernel: :func:`query_one_kernel` for one robot (:meth:`Track.query`), and
:func:`query_batch_kernel`, its loop over robots, for N robots on one track
(:meth:`Track.query_batch`) or on N tracks (:func:`query_tracks`).
The scalar helpers :func:`interp1`, :func:`np_interp1`, :func:`wrap_pi` and :func:`wrap_progress` are
public for other compiled code that reads packed tracks (``control.follow.batch``).
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numba import njit

__all__ = ["TQ", "wrap_angle", "wrap_pi", "interp1", "np_interp1", "wrap_progress", "project_window_kernel",
           "refined_progress", "query_one_kernel", "query_batch_kernel", "query_tracks"]


class TQ(IntEnum):
    """Columns of a robot's track state, the ``out`` rows of the queries (N, 5)."""

    S = 0  #: progress s along the track [m] (unwrapped over laps)
    LATERAL = 1  #: lateral error, positive to the left of the path direction [m]
    HEADING = 2  #: heading error θ − θ_ref, wrapped [rad]
    V_REF = 3  #: reference progress speed at s [m/s]
    PSI = 4  #: path direction ψ at s [rad]


def wrap_angle(a):
    """Wrap angles to ]−π, π]."""
    a = np.asarray(a, dtype=np.float64)
    return np.pi - np.mod(np.pi - a, 2 * np.pi)


@njit(cache=True)
def interp1(S, col, s):
    """``np.interp(s, S, col)`` for a scalar s on sorted S (compiled; constant beyond the ends)."""
    m = S.shape[0]
    if s <= S[0]:
        return col[0]
    if s >= S[m - 1]:
        return col[m - 1]
    j = np.searchsorted(S, s, side="right") - 1
    t = (s - S[j]) / (S[j + 1] - S[j])
    return col[j] + t * (col[j + 1] - col[j])


@njit(cache=True)
def np_interp1(S, col, x):
    """``np.interp(x, S, col)`` for a scalar x on strictly increasing S, with NumPy's own
    arithmetic (``slope · (x − S[j]) + col[j]``, ``col[j]`` at a sample; :func:`interp1` rounds
    differently), so compiled code that must equal a NumPy reference bit for bit reads tracks with
    it (``control.follow.batch``)."""
    m = S.shape[0]
    if math.isnan(x):
        return x
    if x <= S[0]:
        return col[0]
    if x >= S[m - 1]:
        return col[m - 1]
    j = np.searchsorted(S, x, side="right") - 1
    if S[j] == x:
        return col[j]
    slope = (col[j + 1] - col[j]) / (S[j + 1] - S[j])
    y = slope * (x - S[j]) + col[j]
    if math.isnan(y):  # NumPy's fallbacks: from the other end of the interval, then the flat value
        y = slope * (x - S[j + 1]) + col[j + 1]
        if math.isnan(y) and col[j] == col[j + 1]:
            y = col[j]
    return y


@njit(cache=True)
def wrap_pi(a):
    """A scalar angle wrapped to ]−π, π] (compiled :func:`wrap_angle`)."""
    return math.pi - ((math.pi - a) % (2 * math.pi))


@njit(cache=True)
def wrap_progress(s, closed, length):
    """Progress s [m] brought onto the track: modulo the length on a closed track, clipped to
    [0, length] on an open one (compiled ``Track._wrap_s`` for a scalar)."""
    if closed:
        return s % length
    return min(max(s, 0.0), length)


#: the cosine of the smallest turn of the path at a sample [5°] that the projection treats as a
#: corner (:func:`segment_step`); the built-in tracks' arcs, sampled every 2 cm, turn by under 1°
CORNER_COS = math.cos(math.radians(5.0))


@njit(cache=True, inline="always")
def _segment(X, Y, TH, rho, a, b) -> tuple[float, float, float, float]:
    """The segment from sample ``a`` to ``b`` in (x, y, ρθ) and its length."""
    sx = X[b] - X[a]
    sy = Y[b] - Y[a]
    st = rho * (TH[b] - TH[a])
    return sx, sy, st, math.sqrt(sx * sx + sy * sy + st * st)


@njit(cache=True, inline="always")
def segment_step(X, Y, TH, rho, bi, m, closed, px, py, pth) -> tuple[bool, float]:
    """The refinement of a projection at sample ``bi`` along the segment that starts there (the
    last one at the track's end), in the metric ‖Δxy‖² + (ρ Δθ)²: (whether it moved, the step [m],
    clipped to ± the segment's length). At a corner (the path turns there by more than 5°,
    :data:`CORNER_COS`), a pose behind ``bi`` along that segment but ahead of it along the
    segment that ends there (on a closed track the last one before sample 0) is past the corner on
    its outside, and its projection is the corner itself. (Stepping back along the next segment's
    direction put a robot that overran a square's corner by 2 cm 2 cm before it, where the
    feed-forward along the old leg and the position feedback back to it balanced, and the robot
    stalled.) On a smooth path the two segments agree to first order, and the step is as ever."""
    last = bi >= m - 1  # an open track's end: its last segment
    sx, sy, st, seg = _segment(X, Y, TH, rho, m - 2 if last else bi, m - 1 if last else bi + 1)
    if not seg > 0:
        return False, 0.0
    rx = px - X[bi]
    ry = py - Y[bi]
    rt = rho * wrap_pi(pth - TH[bi])
    step = (rx * sx + ry * sy + rt * st) / seg
    if step < 0 and not last and (bi > 0 or closed):
        gx, gy, gt, seg_b = _segment(X, Y, TH, rho, bi - 1 if bi > 0 else m - 2, bi if bi > 0 else m - 1)
        if seg_b > 0 and sx * gx + sy * gy + st * gt < CORNER_COS * seg * seg_b and rx * gx + ry * gy + rt * gt >= 0:
            return False, 0.0
    return True, min(max(step, -seg), seg)


@njit(cache=True, inline="always")
def refined_progress(S, X, Y, TH, rho, closed, length, bi, lap_offset, base, px, py, pth):
    """The progress of the nearest sample ``bi`` (S[bi] + ``lap_offset`` + ``base``, in that
    order: whole laps of a closed track) moved along its segments (:func:`segment_step`) and, on an
    open track, clamped to [0, length]: the end of every windowed and whole-track projection."""
    s = S[bi] + lap_offset + base
    moved, step = segment_step(X, Y, TH, rho, bi, S.shape[0], closed, px, py, pth)
    if moved:
        s += step
    if not closed:
        s = min(max(s, 0.0), length)
    return s


@njit(cache=True)
def project_window_kernel(S, X, Y, TH, closed, length, rho, px, py, pth, s_hint, back, ahead, always_wrap):
    """Progress s of the reference pose nearest to (px, py, pth) in the window [s_hint − back,
    s_hint + ahead], metric ‖Δxy‖² + (ρ Δθ)², refined along the segment (the compiled
    :meth:`Track.project`; unwrapped on a closed track). ``always_wrap``: wrap every heading
    difference as ``Track.project`` does (``control.follow.batch`` matches ``PathFollower``
    to the last bit that way); otherwise only those outside ]−π, π] (the env's hot loop)."""
    m = S.shape[0]
    mu = m - 1
    if closed:
        lap = math.floor(s_hint / length)
        base = lap * length
        s_loc = s_hint - base
        lo_s = s_loc - back
        hi_s = s_loc + ahead
        j0 = int(math.floor(lo_s / length)) * mu + np.searchsorted(S, lo_s % length) - 1
        j1 = int(math.floor(hi_s / length)) * mu + np.searchsorted(S, hi_s % length) + 1
    else:
        base = 0.0
        j0 = max(np.searchsorted(S, s_hint - back) - 1, 0)
        j1 = min(np.searchsorted(S, s_hint + ahead, side="right") + 1, m)
    best = 1e300
    bi = 0
    boff = 0.0
    for j in range(j0, j1):
        if closed:
            i = j % mu
            off = math.floor(j / mu) * length
        else:
            i = j
            off = 0.0
        dx = X[i] - px
        dy = Y[i] - py
        dth = TH[i] - pth
        if always_wrap or dth > math.pi or dth <= -math.pi:  # the float modulo only when needed
            dth = wrap_pi(dth)
        c = dx * dx + dy * dy + (rho * dth) ** 2
        if c < best:
            best = c
            bi = i
            boff = off
    return refined_progress(S, X, Y, TH, rho, closed, length, bi, boff, base, px, py, pth)


@njit(cache=True)
def query_one_kernel(p, closed, length, rho, px, py, pth, s_hint, back, ahead, spacing, out, look):
    """One robot at pose (px, py, pth) on the packed track ``p`` (6, m), from the progress hint
    ``s_hint``: its track state into ``out`` (5,) (columns :class:`TQ`) and its K look-ahead points
    into ``look`` (K, 3); the body of :func:`query_batch_kernel` (see there)."""
    S = p[0]
    s = project_window_kernel(S, p[1], p[2], p[3], closed, length, rho, px, py, pth, s_hint, back, ahead, False)
    sw = s % length if closed else s
    xr = interp1(S, p[1], sw)
    yr = interp1(S, p[2], sw)
    thr = interp1(S, p[3], sw)
    psi = interp1(S, p[5], sw)
    out[TQ.S] = s
    out[TQ.LATERAL] = -(px - xr) * math.sin(psi) + (py - yr) * math.cos(psi)
    out[TQ.HEADING] = wrap_pi(pth - thr)
    out[TQ.V_REF] = interp1(S, p[4], sw)
    out[TQ.PSI] = psi
    c, sn = math.cos(pth), math.sin(pth)
    for k in range(look.shape[0]):
        sk = wrap_progress(s + spacing * (k + 1), closed, length)
        dx = interp1(S, p[1], sk) - px
        dy = interp1(S, p[2], sk) - py
        look[k, 0] = c * dx + sn * dy
        look[k, 1] = -sn * dx + c * dy
        look[k, 2] = wrap_pi(interp1(S, p[3], sk) - pth)


@njit(cache=True)
def query_batch_kernel(packs, which, closed, length, rho, poses, hints, back, ahead, spacing, out, look):
    """The track state of N robots: robot i is on track ``which[i]``, whose packed rows are
    ``packs[which[i]]`` (a ``numba.typed.List`` of (6, m) arrays, or a (T, 6, m) array) and whose
    flag, length [m] and progress radius [m] are ``closed``, ``length``, ``rho`` at ``which[i]``.

    Per robot: the windowed projection from ``hints[i]`` (:func:`project_window_kernel`), then at
    that progress s the lateral error (positive to the left of the path direction ψ), the heading
    error θ − θ_ref, v_ref and ψ into ``out[i]`` = (s, lateral, heading, v_ref, ψ), and the K
    look-ahead points at s + spacing·(1..K) in the robot's chassis frame into ``look[i]`` (K, 3)."""
    for i in range(poses.shape[0]):
        t = which[i]
        query_one_kernel(packs[t], closed[t], length[t], rho[t], poses[i, 0], poses[i, 1], poses[i, 2], hints[i],
                         back, ahead, spacing, out[i], look[i])


def query_tracks(packs, closed, length, rho, poses, s_hints, lookahead_count: int, spacing: float,
                 back: float = 0.5, ahead: float = 1.0, n_packs: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Track.query` for N robots on N tracks in one compiled call.

    Args:
        packs: a ``numba.typed.List`` of the robots' :meth:`Track.packed` arrays.
        closed (N,) bool, length (N,) [m], rho (N,) [m]: each track's ``closed``, ``length`` and
            ``progress_radius``. poses (N, 3), s_hints (N,): as :meth:`Track.query_batch`.
        n_packs: ``len(packs)`` when the caller keeps it (``len`` of a numba typed list is a slow
            call, on the env's per-step path); None: taken here.

    Returns ``(scalars (N, 5) = (s, lateral error, heading error, v_ref, ψ), lookahead (N, K, 3))``,
    the same numbers as :meth:`Track.query` robot by robot.
    """
    poses = np.ascontiguousarray(np.asarray(poses, dtype=np.float64).reshape(-1, 3))
    hints = np.ascontiguousarray(np.asarray(s_hints, dtype=np.float64).reshape(-1))
    n = poses.shape[0]
    if n_packs is None:
        n_packs = len(packs)
    if hints.shape[0] != n or n_packs != n or closed.shape[0] != n or length.shape[0] != n or rho.shape[0] != n:
        raise ValueError("query_tracks needs one track, flag, length, radius and s_hint per pose")
    out = np.empty((n, len(TQ)))
    look = np.empty((n, int(lookahead_count), 3))
    query_batch_kernel(packs, np.arange(n), closed, length, rho, poses, hints, back, ahead, spacing, out, look)
    return out, look
