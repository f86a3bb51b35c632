"""The path follower of :mod:`control.follow.path_follower` for N robots in one compiled call.

:class:`BatchFollower` holds one follower state per robot (progress, integral of the cross-track
error, farthest progress) and each robot's track as packed arrays; :meth:`BatchFollower.step`
runs :meth:`control.follow.path_follower.PathFollower.step`'s arithmetic for all robots in one numba
kernel (the same projection, feed-forward with preview, corner and curvature speed caps, feedback
with anti-windup, rotation into the chassis frame), and returns the chassis-frame twist targets.
The stop points (sharp corners, and with a stop mask the reference ICR's stops) are computed once
per track by ``PathFollower`` itself. It is what the residual action space of
:mod:`control.action_spaces.vector` uses instead of a Python follower per robot (its cost:
``docs/results/bench-env.md``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.typed import List as NumbaList

from azimut_env.tracks import Track, interp1, project_window_kernel, wrap_pi, wrap_progress
from control.follow.path_follower import PathFollower, PathFollowerConfig, check_start_progress

__all__ = ["BatchFollower"]


@njit(cache=True)
def _follow_kernel(packs, stops, closed, length, rho, poses, rows, state, cfg, dt, out):
    """state (N, 4): progress, integral, farthest progress, has-farthest flag; cfg: the
    PathFollowerConfig fields in :data:`_CFG` order; out (N, 3): chassis twists of ``rows``."""
    (k_pos, k_heading, k_int, max_integral, moving_speed, max_correction, max_heading_correction, preview,
     preview_min, corner_angle, corner_decel, corner_window, corner_speed, max_lateral_accel, speed_scale) = (
        cfg[0], cfg[1], cfg[2], cfg[3], cfg[4], cfg[5], cfg[6], cfg[7], cfg[8], cfg[9], cfg[10], cfg[11], cfg[12],
        cfg[13], cfg[14])
    for r in range(rows.shape[0]):
        i = rows[r]
        P = packs[i]
        S = P[0]
        cl = closed[i]
        L = length[i]
        px, py, pth = poses[i, 0], poses[i, 1], poses[i, 2]
        s = project_window_kernel(S, P[1], P[2], P[3], cl, L, rho[i], px, py, pth, state[i, 0], 0.5, 1.0, True)
        state[i, 0] = s
        finished = s >= L - 1e-6
        sw = wrap_progress(s, cl, L)
        x_r = interp1(S, P[1], sw)
        y_r = interp1(S, P[2], sw)
        th_r = interp1(S, P[3], sw)
        v_r = interp1(S, P[4], sw) * speed_scale
        s_ff = s + max(v_r * preview, preview_min)
        if not cl:
            s_ff = min(s_ff, L)
        psi_ff = interp1(S, P[5], wrap_progress(s_ff, cl, L))
        psi_s = interp1(S, P[5], sw)
        if abs(wrap_pi(psi_ff - psi_s)) > corner_angle:
            s_ff = min(s + preview_min, L) if not cl else s + preview_min
        sffw = wrap_progress(s_ff, cl, L)
        v_ff = interp1(S, P[4], sffw) * speed_scale
        kappa = 0.0
        stop = s_ff + 0.05
        step = (stop - s) / 5.0
        for k in range(6):
            x = s + k * step if k < 5 else stop
            x = x % L if cl else min(max(x, 0.0), L)
            kappa = max(kappa, abs(interp1(S, P[9], x)))
        if 1e-6 < kappa < 20.0:
            v_ff = min(v_ff, math.sqrt(max_lateral_accel / kappa))
        st = stops[i]
        if st.shape[0] > 0:
            s_loc = s % L if cl else s
            d = -1.0
            for k in range(st.shape[0]):
                if st[k] > s_loc:
                    d = st[k] - s_loc
                    break
            if d < 0 and cl:
                for k in range(st.shape[0]):
                    if st[k] + L > s_loc:
                        d = st[k] + L - s_loc
                        break
            if d >= 0 and d <= corner_window:
                v_ff = min(v_ff, math.sqrt(2.0 * corner_decel * d) + corner_speed)
        v_ff = max(v_ff, corner_speed)
        if finished:
            tw0 = 0.0
            tw1 = 0.0
            tw2 = 0.0
        else:
            tw0 = interp1(S, P[6], sffw) * v_ff
            tw1 = interp1(S, P[7], sffw) * v_ff
            tw2 = interp1(S, P[8], sffw) * v_ff
        ex = x_r - px
        ey = y_r - py
        nx = -math.sin(psi_s)
        ny = math.cos(psi_s)
        moved = state[i, 3] > 0 and s - state[i, 2] > moving_speed * dt
        state[i, 2] = s if state[i, 3] == 0 else max(state[i, 2], s)
        state[i, 3] = 1.0
        if moved and not finished:
            lim = max_integral / k_int if k_int > 0 else 0.0
            state[i, 1] = min(max(state[i, 1] + (ex * nx + ey * ny) * dt, -lim), lim)
        cx = k_pos * ex + k_int * state[i, 1] * nx
        cy = k_pos * ey + k_int * state[i, 1] * ny
        norm = math.sqrt(cx * cx + cy * cy)
        if norm > max_correction:
            cx *= max_correction / norm
            cy *= max_correction / norm
        w_corr = min(max(k_heading * wrap_pi(th_r - pth), -max_heading_correction), max_heading_correction)
        vx = tw0 + cx
        vy = tw1 + cy
        c = math.cos(pth)
        sn = math.sin(pth)
        out[r, 0] = c * vx + sn * vy
        out[r, 1] = -sn * vx + c * vy
        out[r, 2] = tw2 + w_corr


_CFG = ("k_pos", "k_heading", "k_int", "max_integral", "moving_speed", "max_correction", "max_heading_correction",
        "preview", "preview_min", "corner_angle", "corner_decel", "corner_window", "corner_speed", "max_lateral_accel",
        "speed_scale")


def _pack(track: Track) -> np.ndarray:
    """(10, m): s, x, y, heading, speed, tangent, dx/ds, dy/ds, dθ/ds, curvature."""
    return np.ascontiguousarray(np.vstack([track.packed(), track.dxy_ds[:, 0], track.dxy_ds[:, 1], track.dth_ds,
                                           track.curvature]).astype(np.float64))


class BatchFollower:
    """N path followers (see the module docstring).

    Args:
        num: N. config: the followers' gains. stop_mask: as :class:`~control.follow.path_follower.PathFollower`.
        dt: control period [s].
    """

    def __init__(self, num: int, config: PathFollowerConfig | None = None, stop_mask=None, dt: float = 0.02) -> None:
        self.config = config or PathFollowerConfig()
        self.stop_mask, self.dt = stop_mask, float(dt)
        self._cfg = np.array([float(getattr(self.config, k)) for k in _CFG])
        self.state = np.zeros((num, 4))
        dummy = np.zeros((10, 2))
        dummy[0] = [0.0, 1.0]
        self._packs = NumbaList([dummy] * num)
        self._stops = NumbaList([np.zeros(0)] * num)
        self.closed = np.zeros(num, dtype=np.bool_)
        self.length = np.ones(num)
        self.rho = np.ones(num)
        self._tracks: list[Track | None] = [None] * num
        self._cache: dict[int, tuple[Track, np.ndarray, np.ndarray]] = {}

    def reset(self, i: int, track: Track, progress: float) -> None:
        """Robot i starts on ``track`` at ``progress`` [m] (integral and farthest progress cleared);
        ``progress`` as :meth:`PathFollower.reset` takes it (checked before any state changes).
        Tracks with holds (``Track.holds``) are refused: this follower has no clock to hold with
        (:class:`~control.follow.path_follower.PathFollower` has)."""
        if track.holds:
            raise ValueError(f"track {track.name!r} has holds, which the batched follower does not support "
                             "(use PathFollower)")
        progress = check_start_progress(track, progress)
        key = id(track)
        hit = self._cache.get(key)
        if hit is None or hit[0] is not track:
            stops = PathFollower(track, self.config, stop_mask=self.stop_mask, dt=self.dt).stops
            hit = (track, _pack(track), np.ascontiguousarray(stops, dtype=np.float64))
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = hit
        self._packs[i] = hit[1]
        self._stops[i] = hit[2]
        self._tracks[i] = track
        self.closed[i], self.length[i], self.rho[i] = track.closed, track.length, track.progress_radius
        self.state[i] = (float(progress), 0.0, 0.0, 0.0)

    def step(self, poses: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Chassis-frame twist targets (len(rows), 3) for the robots ``rows`` at ``poses`` (N, 3)."""
        out = np.zeros((rows.size, 3))
        _follow_kernel(self._packs, self._stops, self.closed, self.length, self.rho,
                       np.ascontiguousarray(poses, dtype=np.float64), np.asarray(rows, dtype=np.int64), self.state,
                       self._cfg, self.dt, out)
        return out

    @property
    def progress(self) -> np.ndarray:
        """Each robot's progress along its track [m]."""
        return self.state[:, 0].copy()
