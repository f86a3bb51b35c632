"""The path follower of :mod:`control.follow.path_follower` for N robots in one compiled call.

:class:`BatchFollower` holds one follower state per robot (progress, integral of the cross-track
error, farthest progress, hold counters) and each robot's track, gains and holds as packed arrays;
:meth:`BatchFollower.step` runs :meth:`PathFollower.step
<control.follow.path_follower.PathFollower.step>` for all robots in one numba call and returns
every robot's :class:`~control.follow.path_follower.FollowerOutput` fields as arrays
(:class:`FollowerBatchOutput`).

The kernel is ``PathFollower.step`` written row by row with the same operations in the same
order, one compiled function per stage of the step: projection (``Track.project``, and at a cusp
the same compiled :func:`~control.follow.cusps.cusp_progress` as the follower's), holds,
feed-forward (preview point, curvature and stop speed caps, ``Track.reference_twist``), feedback
(anti-windup integral, capped corrections), rotation into the chassis frame and
``estimation.hrep.eta_from_twist``. Track lookups use :func:`~azimut_env.tracks.np_interp1`
(``np.interp``'s own formula), and the reference's dot products and norms are written out as
sums (not BLAS calls), so the two return the same bits on every CPU:
``tests/control/test_follower_batch.py`` replays recorded episodes through both. The stop points
(sharp corners, and with a stop mask the reference ICR's stops) are computed once per track and
configuration by ``PathFollower`` itself.

It is what the path controllers of ``azimut eval`` (:mod:`control.path_controllers`) and the
residual action space (:mod:`control.action_spaces.controller`) step.
"""

from __future__ import annotations

import math
from enum import IntEnum
from typing import NamedTuple

import numpy as np
from numba import njit

from azimut_env.tracks import Track, np_interp1, project_window_kernel, wrap_pi
from azimut_env.tracks.query import refined_progress
from azimut_env.typed_lists import array_list, set_item
from control.follow.cusps import cusp_feed_forward, cusp_progress, cusp_table
from control.follow.path_follower import PathFollower, PathFollowerConfig, check_start_progress, merge_stops
from estimation.threads import BlockKernel, check_threads

__all__ = ["BatchFollower", "FollowerBatchOutput", "FC", "FS", "FT", "FO"]


class FC(IntEnum):
    """Columns of a robot's gains (:class:`PathFollowerConfig`'s fields, by the same names)."""

    K_POS = 0
    K_HEADING = 1
    K_INT = 2
    MAX_INTEGRAL = 3
    MOVING_SPEED = 4
    MAX_CORRECTION = 5
    MAX_HEADING_CORRECTION = 6
    PREVIEW = 7
    PREVIEW_MIN = 8
    CORNER_ANGLE = 9
    CORNER_DECEL = 10
    CORNER_WINDOW = 11
    CORNER_SPEED = 12
    MAX_LATERAL_ACCEL = 13
    SPEED_SCALE = 14
    HOLD_REACH = 15


class FS(IntEnum):
    """Columns of a robot's follower state (``PathFollower``'s attributes)."""

    PROGRESS = 0  #: ``progress`` [m]
    HAS_PROGRESS = 1  #: 1: ``progress`` is set (the projection is windowed around it), 0: None
    INTEGRAL = 2  #: ``_integral`` [m·s]
    MAX_PROGRESS = 3  #: ``_max_progress`` [m]
    HAS_MAX = 4  #: 1: ``_max_progress`` is set
    HOLD_NEXT = 5  #: ``_hold_next``: index of the track's next hold
    HOLD_LEFT = 6  #: ``_hold_left``: control periods left in the current hold


class FT(IntEnum):
    """Columns of a robot's track scalars."""

    CLOSED = 0  #: 1.0 for a closed track
    LENGTH = 1  #: ``Track.length`` [m]
    RHO = 2  #: ``Track.progress_radius`` [m]


class FO(IntEnum):
    """Columns of one step's output rows (:class:`~control.follow.path_follower.FollowerOutput`)."""

    TWIST_X = 0  #: chassis-frame twist target ẋ [m/s]
    TWIST_Y = 1  #: ẏ [m/s]
    TWIST_W = 2  #: θ̇ [rad/s]
    LAM_U = 3  #: λ_d (3 columns)
    LAM_V = 4
    LAM_W = 5
    MU = 6  #: μ_d [m/s]
    PROGRESS = 7  #: s [m]
    FINISHED = 8  #: 1.0: the track's end (or one lap) is reached
    HOLDING = 9  #: 1.0: a track hold keeps the robot still


class TP(IntEnum):
    """Rows of a track as the followers read it (:func:`_pack`): the six of
    :meth:`azimut_env.tracks.Track.packed`, then the path derivatives the feed-forward needs."""

    S = 0  #: progress s [m]
    X = 1  #: reference x [m]
    Y = 2  #: reference y [m]
    TH = 3  #: reference heading θ [rad]
    V = 4  #: reference speed [m/s]
    PSI = 5  #: path direction ψ [rad]
    DX = 6  #: dx/ds
    DY = 7  #: dy/ds
    DTH = 8  #: dθ/ds [rad/m]
    KAPPA = 9  #: path curvature [1/m]


# ----------------------------------------------------------------------------- compiled stages


@njit(cache=True)
def _project(P, closed, length, rho, px, py, pth, hint, has_hint):
    """``Track.project(pose, s_hint)`` (back 0.5 m, ahead 1 m); the whole track without a hint."""
    if has_hint:
        return project_window_kernel(P[TP.S], P[TP.X], P[TP.Y], P[TP.TH], closed, length, rho, px, py, pth, hint,
                                     0.5, 1.0, True)
    S, X, Y, TH = P[TP.S], P[TP.X], P[TP.Y], P[TP.TH]
    m = S.shape[0]
    best = 1e300
    bi = 0
    for i in range(m - 1 if closed else m):
        dx = X[i] - px
        dy = Y[i] - py
        dth = wrap_pi(TH[i] - pth)
        c = dx * dx + dy * dy + (rho * dth) ** 2
        if c < best:
            best = c
            bi = i
    return refined_progress(S, X, Y, TH, rho, closed, length, bi, 0.0, 0.0, px, py, pth)


@njit(cache=True, inline="always")
def _wrap_s(s, closed, length):
    """``Track._wrap_s``: modulo the length on a closed track, clipped to [0, length] on an open one."""
    return s % length if closed else min(max(s, 0.0), length)


@njit(cache=True)
def _holding(holds, state, s, hold_reach):
    """``PathFollower._holding``: whether this step is one of a hold's (starting it when s reaches
    the next hold); ``holds`` (2, h): each hold's s [m] and its duration in control periods."""
    nxt = int(state[FS.HOLD_NEXT])
    if state[FS.HOLD_LEFT] == 0 and nxt < holds.shape[1]:
        if s >= holds[0, nxt] - hold_reach:
            state[FS.HOLD_LEFT] = holds[1, nxt]
            state[FS.HOLD_NEXT] = nxt + 1
    if state[FS.HOLD_LEFT] > 0:
        state[FS.HOLD_LEFT] -= 1
        return True
    return False


@njit(cache=True)
def _distance_to_stop(stops, closed, length, s, window):
    """``PathFollower._distance_to_stop``: progress [m] from s to the next stop within ``window``, or −1."""
    if stops.shape[0] == 0:
        return -1.0
    s_loc = s % length if closed else s
    d = -1.0
    for k in range(stops.shape[0]):
        if stops[k] > s_loc:
            d = stops[k] - s_loc
            break
    if d < 0 and closed:
        for k in range(stops.shape[0]):
            if stops[k] + length > s_loc:
                d = stops[k] + length - s_loc
                break
    if d < 0 or d > window:
        return -1.0
    return d


@njit(cache=True)
def _feed_forward(P, stops, cusps, closed, length, rho, c, s, reached, finished, ref):
    """The preview point s_ff, its capped speed v_ff and the reference world twist there into
    ``ref`` (3,) (zero once finished); also the reference pose and ψ at s into ``ref[3:7]``
    (x_r, y_r, θ_r, ψ)."""
    S = P[TP.S]
    sw = _wrap_s(s, closed, length)
    x_r, y_r, th_r = np_interp1(S, P[TP.X], sw), np_interp1(S, P[TP.Y], sw), np_interp1(S, P[TP.TH], sw)
    v_r = np_interp1(S, P[TP.V], sw) * c[FC.SPEED_SCALE]
    s_ff = s + max(v_r * c[FC.PREVIEW], c[FC.PREVIEW_MIN])
    if not closed:
        s_ff = min(s_ff, length)
    psi = np_interp1(S, P[TP.PSI], sw)
    if abs(wrap_pi(np_interp1(S, P[TP.PSI], _wrap_s(s_ff, closed, length)) - psi)) > c[FC.CORNER_ANGLE]:
        s_ff = min(s + c[FC.PREVIEW_MIN], length) if not closed else s + c[FC.PREVIEW_MIN]
    sffw = _wrap_s(s_ff, closed, length)
    v_ff = np_interp1(S, P[TP.V], sffw) * c[FC.SPEED_SCALE]
    stop = s_ff + 0.05  # np.linspace(s, s_ff + 0.05, 6): k·step + s, the last one the end itself
    step = (stop - s) / 5.0
    kappa = 0.0
    for k in range(6):
        x = k * 1.0 * step + s if k < 5 else stop
        kappa = max(kappa, abs(np_interp1(S, P[TP.KAPPA], _wrap_s(x, closed, length))))
    if 1e-6 < kappa < 20.0:  # sharper turns (radius < 5 cm) are corners, handled as stops
        v_ff = min(v_ff, math.sqrt(c[FC.MAX_LATERAL_ACCEL] / kappa))
    d = _distance_to_stop(stops, closed, length, s, c[FC.CORNER_WINDOW])
    if d >= 0:
        v_ff = min(v_ff, math.sqrt(2.0 * c[FC.CORNER_DECEL] * d) + c[FC.CORNER_SPEED])
    v_ff = max(v_ff, c[FC.CORNER_SPEED])
    if finished:
        ref[0], ref[1], ref[2] = 0.0, 0.0, 0.0
    else:
        ref[0] = np_interp1(S, P[TP.DX], sffw) * v_ff
        ref[1] = np_interp1(S, P[TP.DY], sffw) * v_ff
        ref[2] = np_interp1(S, P[TP.DTH], sffw) * v_ff
        if cusps.shape[0]:
            cusp_feed_forward(S, cusps, rho, closed, length, s_ff, max(reached, s), v_ff, ref)
    ref[3], ref[4], ref[5], ref[6] = x_r, y_r, th_r, psi


@njit(cache=True)
def _feedback(c, state, s, finished, px, py, pth, ref, dt, out):
    """The pose feedback (anti-windup integral of the cross-track error, capped position and
    heading corrections) on the reference twist ``ref``, rotated into the chassis frame: the
    twist target into ``out[TWIST_*]``."""
    ex = ref[3] - px
    ey = ref[4] - py
    nx = -math.sin(ref[6])
    ny = math.cos(ref[6])
    has_max = state[FS.HAS_MAX] != 0
    moved = has_max and s - state[FS.MAX_PROGRESS] > c[FC.MOVING_SPEED] * dt
    state[FS.MAX_PROGRESS] = max(state[FS.MAX_PROGRESS], s) if has_max else s
    state[FS.HAS_MAX] = 1.0
    k_int = c[FC.K_INT]
    if moved and not finished:
        lim = c[FC.MAX_INTEGRAL] / k_int if k_int > 0 else 0.0
        state[FS.INTEGRAL] = min(max(state[FS.INTEGRAL] + (ex * nx + ey * ny) * dt, -lim), lim)
    gain = k_int * state[FS.INTEGRAL]
    cx = c[FC.K_POS] * ex + gain * nx
    cy = c[FC.K_POS] * ey + gain * ny
    norm = math.sqrt(cx * cx + cy * cy)
    if norm > c[FC.MAX_CORRECTION]:
        scale = c[FC.MAX_CORRECTION] / norm
        cx *= scale
        cy *= scale
    w_max = c[FC.MAX_HEADING_CORRECTION]
    w_corr = min(max(c[FC.K_HEADING] * wrap_pi(ref[5] - pth), -w_max), w_max)
    vx = ref[0] + cx
    vy = ref[1] + cy
    cs, sn = math.cos(pth), math.sin(pth)
    out[FO.TWIST_X] = cs * vx + sn * vy
    out[FO.TWIST_Y] = -sn * vx + cs * vy
    out[FO.TWIST_W] = ref[2] + w_corr


@njit(cache=True)
def _eta(out):
    """``estimation.hrep.eta_from_twist`` of the twist in ``out``: (λ_d, μ_d) into ``out``, with
    ``unit_and_norm``'s power-of-two prescaling."""
    v0, v1, v2 = -out[FO.TWIST_Y], out[FO.TWIST_X], out[FO.TWIST_W]
    _, e = math.frexp(max(abs(v0), abs(v1), abs(v2)))
    s0, s1, s2 = math.ldexp(v0, -e), math.ldexp(v1, -e), math.ldexp(v2, -e)
    norm = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    mu = math.ldexp(norm, e)
    if mu > 0:
        out[FO.LAM_U], out[FO.LAM_V], out[FO.LAM_W] = s0 / norm, s1 / norm, s2 / norm
    else:
        out[FO.LAM_U], out[FO.LAM_V], out[FO.LAM_W] = 0.0, 0.0, 1.0
    out[FO.MU] = mu


@njit(cache=True)
def follow_kernel(packs, stops, holds, cusps, tracks, cfg, state, poses, rows, dt, out, lo, hi):
    """``PathFollower.step`` of the robots ``rows[lo:hi]`` (a block of
    :class:`estimation.threads.BlockKernel`; ``rows`` (M,) distinct) at ``poses`` (N, 3): robot i's packed
    track ``packs[i]`` (10, m), stop points ``stops[i]``, holds ``holds[i]`` (2, h), cusps ``cusps[i]``
    (:func:`~control.follow.cusps.cusp_table`), track scalars
    ``tracks[i]`` (columns :class:`FT`), gains ``cfg[i]`` (:class:`FC`) and state ``state[i]``
    (:class:`FS`, updated in place); one output row per robot of ``rows`` into ``out`` (M, len(FO))."""
    ref = np.empty(7)
    for r in range(lo, hi):
        i = rows[r]
        P, c, st, o = packs[i], cfg[i], state[i], out[r]
        closed, length = tracks[i, FT.CLOSED] != 0, tracks[i, FT.LENGTH]
        px, py, pth = poses[i, 0], poses[i, 1], poses[i, 2]
        s = _project(P, closed, length, tracks[i, FT.RHO], px, py, pth, st[FS.PROGRESS], st[FS.HAS_PROGRESS] != 0)
        if cusps[i].shape[0]:
            s = cusp_progress(P[TP.S], P[TP.X], P[TP.Y], P[TP.TH], tracks[i, FT.RHO], closed, length, cusps[i], px,
                              py, pth, s)
        st[FS.PROGRESS] = s
        st[FS.HAS_PROGRESS] = 1.0
        finished = s >= length - 1e-6  # Track.finished
        o[FO.PROGRESS] = s
        o[FO.FINISHED] = 1.0 if finished else 0.0
        if _holding(holds[i], st, s, c[FC.HOLD_REACH]):
            o[FO.TWIST_X], o[FO.TWIST_Y], o[FO.TWIST_W] = 0.0, 0.0, 0.0
            o[FO.HOLDING] = 1.0
        else:
            reached = st[FS.MAX_PROGRESS] if st[FS.HAS_MAX] != 0 else s
            _feed_forward(P, stops[i], cusps[i], closed, length, tracks[i, FT.RHO], c, s, reached, finished, ref)
            _feedback(c, st, s, finished, px, py, pth, ref, dt, o)
            o[FO.HOLDING] = 0.0
        _eta(o)


# ----------------------------------------------------------------------------- Python side

#: the followers' step over blocks of robots (a block: at least 8 robots)
_FOLLOW = BlockKernel(follow_kernel, min_rows=8)


class FollowerBatchOutput(NamedTuple):
    """One step of M followers (the fields of :class:`~control.follow.path_follower.FollowerOutput`
    with a leading robot axis)."""

    twist: np.ndarray  #: (M, 3) chassis-frame twist targets [m/s, m/s, rad/s]
    lam: np.ndarray  #: (M, 3) λ_d
    mu: np.ndarray  #: (M,) μ_d [m/s]
    progress: np.ndarray  #: (M,) s [m]
    finished: np.ndarray  #: (M,) bool
    holding: np.ndarray  #: (M,) bool


def _pack(track: Track) -> np.ndarray:
    """(10, m): the rows :class:`TP` names."""
    return np.ascontiguousarray(np.vstack([track.packed(), track.dxy_ds[:, 0], track.dxy_ds[:, 1], track.dth_ds,
                                           track.curvature]).astype(np.float64))


def _config_row(config: PathFollowerConfig) -> np.ndarray:
    return np.array([float(getattr(config, name.lower())) for name in FC.__members__])


class BatchFollower:
    """N path followers (see the module docstring).

    Args:
        num: N. config: the followers' gains (each robot's may be replaced at its reset).
        stop_mask: as :class:`~control.follow.path_follower.PathFollower`. dt: control period [s].
        num_threads: threads of the compiled step (None: the cores this process may use; any
            count gives the same bits).
    """

    def __init__(self, num: int, config: PathFollowerConfig | None = None, stop_mask=None, dt: float = 0.02,
                 num_threads: int | None = None) -> None:
        self.config = config or PathFollowerConfig()
        if not isinstance(self.config, PathFollowerConfig):
            raise TypeError(f"config must be a PathFollowerConfig or None, got {type(config).__name__}")
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {dt!r}")
        self.stop_mask, self.dt = stop_mask, float(dt)
        self.num = int(num)
        #: threads of the compiled step (blocks of robots; None given: the cores this process may use)
        self.num_threads = check_threads(num_threads)
        self.cfg = np.tile(_config_row(self.config), (num, 1))
        self.state = np.zeros((num, len(FS)))
        self.tracks = np.zeros((num, len(FT)))
        self.tracks[:, FT.LENGTH] = 1.0
        dummy = np.zeros((10, 2))
        dummy[TP.S] = [0.0, 1.0]
        self._packs = array_list([dummy] * num)
        self._stops = array_list([np.zeros(0)] * num)
        self._holds = array_list([np.zeros((2, 0))] * num)
        self._cusps = array_list([np.zeros((0, 9))] * num)
        self._track_of: list[Track | None] = [None] * num
        self._cache: dict[tuple[int, PathFollowerConfig], tuple] = {}

    def _track_arrays(self, track: Track, config: PathFollowerConfig) -> tuple:
        """(track, pack, stops, holds) of a track under ``config``, cached (the stop points cost a
        scan of the track)."""
        key = (id(track), config)
        hit = self._cache.get(key)
        if hit is None or hit[0] is not track:
            stops = PathFollower(track, config, stop_mask=self.stop_mask, dt=self.dt).stops
            holds = np.array([[s for s, _ in track.holds],
                              [max(1, int(round(d / self.dt))) for _, d in track.holds]], dtype=np.float64)
            hit = (track, _pack(track), np.ascontiguousarray(stops, dtype=np.float64), holds.reshape(2, -1))
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = hit
        return hit

    def reset(self, i: int, track: Track, progress: float | None, config: PathFollowerConfig | None = None,
              extra_stops=None) -> None:
        """Robot i starts on ``track`` at ``progress`` [m] (None: the next step searches the whole
        track), with ``config`` (default: the follower's); the integral, farthest progress and
        holds start afresh, as :meth:`PathFollower.reset` (``progress`` checked the same way,
        before any state changes). ``extra_stops``: progress values [m] to arrive slowly at besides
        those the follower finds itself (a look-ahead plan's changes of configuration)."""
        if not isinstance(track, Track):
            raise ValueError(f"track must be an azimut_env.tracks.Track, got {type(track).__name__}")
        config = self.config if config is None else config
        if not isinstance(config, PathFollowerConfig):
            raise TypeError(f"config must be a PathFollowerConfig or None, got {type(config).__name__}")
        if progress is not None:
            progress = check_start_progress(track, progress)
        _, pack, stops, holds = self._track_arrays(track, config)
        stops = merge_stops(stops, extra_stops, track)
        for lst, value in ((self._packs, pack), (self._stops, stops), (self._holds, holds),
                           (self._cusps, cusp_table(track, config.rotation_cusps))):
            set_item(lst, i, value)
        self._track_of[i] = track
        self.tracks[i] = (1.0 if track.closed else 0.0, track.length, track.progress_radius)
        self.cfg[i] = _config_row(config)
        hold_next = 0 if progress is None else sum(1 for s, _ in track.holds if s < progress - config.hold_reach)
        st = self.state[i]
        st[:] = 0.0
        st[FS.PROGRESS], st[FS.HAS_PROGRESS] = (0.0, 0.0) if progress is None else (progress, 1.0)
        st[FS.HOLD_NEXT] = hold_next

    def _run(self, poses: np.ndarray, rows: np.ndarray | None) -> np.ndarray:
        """The kernel's (len(rows), len(FO)) outputs of the robots ``rows`` (default all)."""
        if rows is None:
            rows = np.arange(self.num)
        else:
            rows = np.asarray(rows, dtype=np.int64)
            if self.num_threads > 1 and np.unique(rows).size != rows.size:
                raise ValueError("rows must be distinct robots")
        out = np.empty((rows.size, len(FO)))
        _FOLLOW.run(self.num_threads, rows.size, self._packs, self._stops, self._holds, self._cusps, self.tracks,
                    self.cfg, self.state, np.ascontiguousarray(poses, dtype=np.float64), rows, self.dt, out)
        return out

    def step_all(self, poses: np.ndarray, rows: np.ndarray | None = None) -> FollowerBatchOutput:
        """Every output of the robots ``rows`` (default all) at ``poses`` (N, 3) [m, m, rad]."""
        return self.outputs(self._run(poses, rows))

    @staticmethod
    def outputs(out: np.ndarray) -> FollowerBatchOutput:
        """The named outputs of the kernel's (M, len(FO)) array."""
        return FollowerBatchOutput(out[:, FO.TWIST_X:FO.TWIST_W + 1].copy(), out[:, FO.LAM_U:FO.LAM_W + 1].copy(),
                                   out[:, FO.MU].copy(), out[:, FO.PROGRESS].copy(), out[:, FO.FINISHED] != 0,
                                   out[:, FO.HOLDING] != 0)

    def step(self, poses: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Chassis-frame twist targets (len(rows), 3) for the robots ``rows`` at ``poses`` (N, 3)
        (:meth:`step_all`'s ``twist``, without building its other outputs)."""
        return self._run(poses, rows)[:, FO.TWIST_X:FO.TWIST_W + 1].copy()

    @property
    def progress(self) -> np.ndarray:
        """Each robot's progress along its track [m] (NaN where none is set yet)."""
        return np.where(self.state[:, FS.HAS_PROGRESS] != 0, self.state[:, FS.PROGRESS], np.nan)
