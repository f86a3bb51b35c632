"""Progress at a cusp of the reference path: where the path reverses its direction.

A track's progress s is the nearest reference pose, found at a sample and refined along the
segment that starts there, clipped to ± one segment (:meth:`azimut_env.tracks.Track.project`).
On a smooth path that is the nearest point of the polyline. At a *cusp* (the path turns back on
itself: the ``reverse`` scenario's reversals, in which the direction turns by 160°), it is not: a
robot that runs a few millimetres past the cusp along the incoming leg is nearest to the cusp
sample, and the refinement along the *outgoing* leg, which points back, moves s up to one segment
(2 cm) *before* the cusp, onto the incoming leg. The follower then asks for the incoming direction
(interpolated toward the cusp's) and pulls the robot back to that point: the feed-forward and
the feedback balance and the robot stalls there (seen with the ICR controller on ``reverse``:
``azimut eval --tracks reverse``, seed 0, the default robot standing 4–8 mm past the second cusp
for the last 27 s of the episode; the ideal robot 4.3 cm past the first one).

Here the progress within one segment of a cusp is the projection onto the nearer of the cusp's
two legs, in the projection's metric (x, y, ρθ): a robot past the cusp along the incoming leg is
*at* the cusp (s = s_cusp). And the feed-forward direction there is the leg's own: the track's
reference velocity interpolates its sample derivatives linearly, and the central differences at
a cusp point along the bisector of its legs, so over the last and first segments the reference
direction sweeps through the bisector (80° from both legs on ``reverse``), a direction the path
never takes and the ICR controller may need a stop to turn to; within one segment of a cusp the
preview's direction is the incoming leg's until the robot has reached the cusp and the outgoing
leg's from then on (the speed the follower chose, unchanged). Elsewhere, and on tracks without a cusp, the follower is
unchanged, to the bit.

One compiled function (:func:`cusp_progress`) serves the follower
(:class:`~control.follow.path_follower.PathFollower`) and its compiled twin
(:class:`~control.follow.batch.BatchFollower`), so the two agree to the bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from azimut_env.tracks import Track, wrap_pi

__all__ = ["CUSP_MIN_STEP", "cusp_row", "cusp_table", "cusp_progress", "cusp_feed_forward"]

#: [m] steps of the path shorter than this are bridged when the legs of a cusp are found (the
#: ``reverse`` scenario joins its legs through a 1 µm step along their bisector)
CUSP_MIN_STEP = 1e-3


def cusp_table(track: Track, rotation: bool = False) -> np.ndarray:
    """The cusps of ``track``: (K, 9) rows (sample index, s-length of the incoming leg's last
    segment, of the outgoing leg's first segment, unit incoming direction (3), unit outgoing
    direction (3)), directions in (x, y, ρθ). A sample is a cusp where the *path* turns back: its
    incoming and outgoing directions in the plane, each taken to the nearest sample at least
    :data:`CUSP_MIN_STEP` away, make an angle of more than 90° (a negative dot product); a
    rotation in place that reverses the turn is not one. With ``rotation``
    (``PathFollowerConfig.rotation_cusps``) the directions are those in the projection's own
    metric (x, y, ρθ): a path that turns back there is a cusp too, as where ``spin``'s
    drive-and-rotate leg (turning by −π) ends in a spin in place by +π/2 (118°). Interior samples
    only (the ends of an open track, and a closed track's seam, are not examined). Cached on the
    track."""
    key = "_cusp_table_rotation" if rotation else "_cusp_table"
    cached = track.__dict__.get(key)
    if cached is not None:
        return cached
    pts = np.stack([track.xy[:, 0], track.xy[:, 1], track.progress_radius * track.heading], axis=1)
    test = pts if rotation else pts[:, :2]
    # only samples that may be cusps go through the exact test (cusp_row): a neighbour closer than twice
    # the bridging step, or a turn not clearly under 90° (a superset of the test's hits, so the
    # table is the loop's over every sample; a reset of a random track ran ~1,200 norms before)
    da_all, db_all = test[1:-1] - test[:-2], test[2:] - test[1:-1]
    na, nb = np.linalg.norm(da_all, axis=1), np.linalg.norm(db_all, axis=1)
    dots = np.sum(da_all * db_all, axis=1)
    maybe = (na < 2 * CUSP_MIN_STEP) | (nb < 2 * CUSP_MIN_STEP) | (dots <= 1e-9 * na * nb)
    rows = [row for i in (np.flatnonzero(maybe) + 1).tolist()
            if (row := cusp_row(track, pts, i, rotation)) is not None]
    table = np.ascontiguousarray(np.array(rows, dtype=np.float64).reshape(-1, 9))
    object.__setattr__(track, key, table)
    return table


def cusp_row(track: Track, pts: np.ndarray, i: int, rotation: bool = False) -> list[float] | None:
    """The exact test of :func:`cusp_table` at interior sample ``i`` (``pts``: the samples' (x, y,
    ρθ); ``rotation``: the test in (x, y, ρθ), else in the plane): its row if the sample is a
    cusp, else None."""
    test, m = (pts if rotation else pts[:, :2]), pts.shape[0]
    j = i - 1
    while j > 0 and np.linalg.norm(test[i] - test[j]) < CUSP_MIN_STEP:
        j -= 1
    k = i + 1
    while k < m - 1 and np.linalg.norm(test[k] - test[i]) < CUSP_MIN_STEP:
        k += 1
    da, db = test[i] - test[j], test[k] - test[i]
    if min(np.linalg.norm(da), np.linalg.norm(db)) < CUSP_MIN_STEP or float(da @ db) >= 0.0:
        return None
    a, b = pts[i] - pts[j], pts[k] - pts[i]
    return [float(i), float(track.s[i] - track.s[j]), float(track.s[k] - track.s[i]),
            *(a / np.linalg.norm(a)), *(b / np.linalg.norm(b))]


@njit(cache=True, inline="always")
def _cusp_at(S, cusps, closed, length, s, include_end) -> tuple[int, float]:
    """The first cusp (its row of ``cusps``) within one segment of which the progress ``s`` lies
    (the outgoing leg's end included with ``include_end``), or −1; and the progress where ``s``'s
    lap starts (a closed track's ``s`` counts laps)."""
    if cusps.shape[0] == 0:
        return -1, 0.0
    base = math.floor(s / length) * length if closed else 0.0
    s_loc = s - base
    for c in range(cusps.shape[0]):
        i = int(cusps[c, 0])
        if include_end:
            outside = s_loc < S[i] - cusps[c, 1] or s_loc > S[i] + cusps[c, 2]
        else:
            outside = s_loc < S[i] - cusps[c, 1] or s_loc >= S[i] + cusps[c, 2]
        if not outside:
            return c, base
    return -1, base


@njit(cache=True)
def cusp_progress(S, X, Y, TH, rho, closed, length, cusps, px, py, pth, s0) -> float:
    """The progress at pose (px, py, pth) given the projection's ``s0``: within one segment of a
    cusp (``cusps``: :func:`cusp_table`), the projection onto the nearer of its two legs (the
    incoming one on a tie); ``s0`` elsewhere. ``S``, ``X``, ``Y``, ``TH``: the track's samples;
    ``rho``: its progress radius; a closed track's ``s0`` counts laps (kept)."""
    c, base = _cusp_at(S, cusps, closed, length, s0, True)
    if c < 0:
        return s0
    i = int(cusps[c, 0])
    lin, lout = cusps[c, 1], cusps[c, 2]
    r0 = px - X[i]
    r1 = py - Y[i]
    r2 = rho * wrap_pi(pth - TH[i])
    t_in = min(max(r0 * cusps[c, 3] + r1 * cusps[c, 4] + r2 * cusps[c, 5], -lin), 0.0)
    t_out = min(max(r0 * cusps[c, 6] + r1 * cusps[c, 7] + r2 * cusps[c, 8], 0.0), lout)
    e0, e1, e2 = r0 - t_in * cusps[c, 3], r1 - t_in * cusps[c, 4], r2 - t_in * cusps[c, 5]
    f0, f1, f2 = r0 - t_out * cusps[c, 6], r1 - t_out * cusps[c, 7], r2 - t_out * cusps[c, 8]
    if e0 * e0 + e1 * e1 + e2 * e2 <= f0 * f0 + f1 * f1 + f2 * f2:
        return base + S[i] + t_in
    return base + S[i] + t_out


@njit(cache=True)
def cusp_feed_forward(S, cusps, rho, closed, length, s_ff, reached, v_ff, ref) -> bool:
    """Within one segment of a cusp (``cusps``: :func:`cusp_table`), the reference velocity at
    the preview progress ``s_ff`` along one of its legs, at ``v_ff`` [m/s of progress], into
    ``ref[0:3]`` (ẋ, ẏ, θ̇ in the world; θ̇ = v_ff u_θ/ρ, the direction's third component being
    ρθ): the incoming leg's direction until the robot has reached the cusp (``reached``, the
    farthest progress so far, counting this step's), the outgoing leg's from then on, so that a
    robot jittering about the cusp does not flip its direction every period. Returns whether it
    did (``ref`` is untouched otherwise)."""
    c, base = _cusp_at(S, cusps, closed, length, s_ff, False)
    if c < 0:
        return False
    j = 6 if reached >= base + S[int(cusps[c, 0])] else 3
    ref[0] = v_ff * cusps[c, j]
    ref[1] = v_ff * cusps[c, j + 1]
    ref[2] = v_ff * cusps[c, j + 2] / rho
    return True
