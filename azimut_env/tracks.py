"""Reference tracks for an omnidirectional robot: a path, a heading profile independent of the path
direction, and a speed profile.

A :class:`Track` is a dense polyline of reference poses (x, y, θ) in the world with a speed v per
sample. Because the robot can turn in place, progress along a track is not the path length alone:
the progress coordinate s grows by ``ds = sqrt(dℓ² + (ρ dθ)²)`` between samples, where dℓ is the path
length and ρ (``progress_radius``, [m]) converts heading change to length. A pure rotation in place
therefore still has progress, and ``v`` [m/s] is the rate of s.

Built-in tracks (:func:`make_track`): ``paper`` (spiral, circle, rounded square, after the paper's
Fig. 9), ``circle``, ``figure8``, ``square`` (sharp corners: stop and reconfigure), ``crab``
(translation at a fixed heading, rotation in place, translation), ``random`` (seeded smooth closed
curves). :meth:`Track.from_waypoints` builds one from user waypoints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from .validation import check_bool, check_nonnegative, check_positive, check_real_array

__all__ = ["Track", "make_track", "query_tracks", "TRACK_NAMES", "wrap_angle"]

TRACK_NAMES = ("paper", "circle", "figure8", "square", "crab", "random")


def wrap_angle(a):
    """Wrap angles to ]−π, π]."""
    a = np.asarray(a, dtype=np.float64)
    return np.pi - np.mod(np.pi - a, 2 * np.pi)


@njit(cache=True)
def _interp1(S, col, s):
    """np.interp for a scalar on sorted S."""
    m = S.shape[0]
    if s <= S[0]:
        return col[0]
    if s >= S[m - 1]:
        return col[m - 1]
    j = np.searchsorted(S, s, side="right") - 1
    t = (s - S[j]) / (S[j + 1] - S[j])
    return col[j] + t * (col[j + 1] - col[j])


@njit(cache=True)
def _wrap_pi(a):
    return math.pi - ((math.pi - a) % (2 * math.pi))


@njit(cache=True)
def project_window_kernel(S, X, Y, TH, closed, length, rho, px, py, pth, s_hint, back, ahead, always_wrap):
    """Progress s of the reference pose nearest to (px, py, pth) in the window [s_hint − back,
    s_hint + ahead], metric ‖Δxy‖² + (ρ Δθ)², refined along the segment (the compiled
    :meth:`Track.project`; unwrapped on a closed track). ``always_wrap``: wrap every heading
    difference as ``Track.project`` does (``control.follower_batch`` matches ``PathFollower``
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
            dth = _wrap_pi(dth)
        c = dx * dx + dy * dy + (rho * dth) ** 2
        if c < best:
            best = c
            bi = i
            boff = off
    s = S[bi] + boff + base
    i2 = min(bi, m - 2)
    sx = X[i2 + 1] - X[i2]
    sy = Y[i2 + 1] - Y[i2]
    st = rho * (TH[i2 + 1] - TH[i2])
    seg = math.sqrt(sx * sx + sy * sy + st * st)
    if seg > 0:
        rx = px - X[bi]
        ry = py - Y[bi]
        rt = rho * _wrap_pi(pth - TH[bi])
        step = (rx * sx + ry * sy + rt * st) / seg
        s += min(max(step, -seg), seg)
    if not closed:
        s = min(max(s, 0.0), length)
    return s


@njit(cache=True)
def _track_query_kernel(S, X, Y, TH, V, PSI, closed, length, rho, px, py, pth, s_hint, back, ahead,
                        spacing, look):
    """Windowed projection, errors, reference speed and look-ahead in one call (see Track.query)."""
    s = project_window_kernel(S, X, Y, TH, closed, length, rho, px, py, pth, s_hint, back, ahead, False)
    sw = s % length if closed else s
    xr = _interp1(S, X, sw)
    yr = _interp1(S, Y, sw)
    thr = _interp1(S, TH, sw)
    vr = _interp1(S, V, sw)
    psi = _interp1(S, PSI, sw)
    lat = -(px - xr) * math.sin(psi) + (py - yr) * math.cos(psi)
    head = _wrap_pi(pth - thr)
    c, sn = math.cos(pth), math.sin(pth)
    for k in range(look.shape[0]):
        sk = s + spacing * (k + 1)
        sk = sk % length if closed else min(max(sk, 0.0), length)
        dx = _interp1(S, X, sk) - px
        dy = _interp1(S, Y, sk) - py
        look[k, 0] = c * dx + sn * dy
        look[k, 1] = -sn * dx + c * dy
        look[k, 2] = _wrap_pi(_interp1(S, TH, sk) - pth)
    return s, lat, head, vr, psi


@njit(cache=True)
def _track_query_many_kernel(S, X, Y, TH, V, PSI, closed, length, rho, poses, hints, back, ahead, spacing, out,
                             look):
    for i in range(poses.shape[0]):
        s, lat, head, vr, psi = _track_query_kernel(S, X, Y, TH, V, PSI, closed, length, rho, poses[i, 0],
                                                    poses[i, 1], poses[i, 2], hints[i], back, ahead, spacing,
                                                    look[i])
        out[i, 0] = s
        out[i, 1] = lat
        out[i, 2] = head
        out[i, 3] = vr
        out[i, 4] = psi


@njit(cache=True)
def _track_query_multi_kernel(packs, closed, length, rho, poses, hints, back, ahead, spacing, out, look):
    """:func:`_track_query_kernel` for N robots, each on its own track: ``packs[i]`` is robot i's
    :meth:`Track.packed` array (6, m); closed, length, rho (N,) its flags and scalars."""
    for i in range(poses.shape[0]):
        p = packs[i]
        s, lat, head, vr, psi = _track_query_kernel(p[0], p[1], p[2], p[3], p[4], p[5], closed[i], length[i],
                                                    rho[i], poses[i, 0], poses[i, 1], poses[i, 2], hints[i],
                                                    back, ahead, spacing, look[i])
        out[i, 0] = s
        out[i, 1] = lat
        out[i, 2] = head
        out[i, 3] = vr
        out[i, 4] = psi


def query_tracks(packs, closed, length, rho, poses, s_hints, lookahead_count: int, spacing: float,
                 back: float = 0.5, ahead: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Track.query` for N robots on N tracks in one compiled call.

    Args:
        packs: a ``numba.typed.List`` of the robots' :meth:`Track.packed` arrays.
        closed (N,) bool, length (N,) [m], rho (N,) [m]: each track's ``closed``, ``length`` and
            ``progress_radius``. poses (N, 3), s_hints (N,): as :meth:`Track.query_many`.

    Returns ``(scalars (N, 5) = (s, lateral error, heading error, v_ref, ψ), lookahead (N, K, 3))``,
    the same numbers as :meth:`Track.query` robot by robot.
    """
    poses = np.ascontiguousarray(np.asarray(poses, dtype=np.float64).reshape(-1, 3))
    hints = np.ascontiguousarray(np.asarray(s_hints, dtype=np.float64).reshape(-1))
    n = poses.shape[0]
    if hints.shape[0] != n or len(packs) != n or closed.shape[0] != n or length.shape[0] != n or rho.shape[0] != n:
        raise ValueError("query_tracks needs one track, flag, length, radius and s_hint per pose")
    out = np.empty((n, 5))
    look = np.empty((n, int(lookahead_count), 3))
    _track_query_multi_kernel(packs, closed, length, rho, poses, hints, back, ahead, spacing, out, look)
    return out, look


@dataclass(frozen=True, eq=False)
class Track:
    """A reference track (see the module docstring).

    Attributes:
        name: a label.
        xy: (M, 2) reference positions of the chassis centre in the world [m].
        heading: (M,) reference chassis heading θ_ref [rad] (unwrapped, independent of the path).
        speed: (M,) reference progress speed v_ref [m/s], >= 0.
        closed: whether the track is a loop (the last sample joins the first).
        progress_radius: ρ [m], the length equivalent of one radian of heading change.

    Derived (filled in ``__post_init__``): ``s`` (M,) progress [m]; ``length`` total progress [m];
    ``path_length`` (M,) path arclength [m]; ``tangent`` (M,) path direction ψ [rad] (carried over
    through rotations in place); ``curvature`` (M,) dψ/dℓ [1/m]; ``dxy_ds`` (M, 2), ``dth_ds`` (M,).
    """

    name: str
    xy: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    closed: bool = False
    progress_radius: float = 0.3
    s: np.ndarray = field(init=False, repr=False)
    path_length: np.ndarray = field(init=False, repr=False)
    tangent: np.ndarray = field(init=False, repr=False)
    curvature: np.ndarray = field(init=False, repr=False)
    dxy_ds: np.ndarray = field(init=False, repr=False)
    dth_ds: np.ndarray = field(init=False, repr=False)
    length: float = field(init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise TypeError(f"Track.name must be a str, got {type(self.name).__name__}")
        object.__setattr__(self, "closed", check_bool("Track.closed", self.closed))
        object.__setattr__(self, "progress_radius", check_positive("Track.progress_radius", self.progress_radius))
        xy = check_real_array("Track.xy", self.xy)
        th = check_real_array("Track.heading", self.heading)
        v = check_real_array("Track.speed", self.speed)
        if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] < 2:
            raise ValueError(f"Track.xy must have shape (M >= 2, 2), got {xy.shape}")
        m = xy.shape[0]
        th = np.broadcast_to(th, (m,)).copy()
        v = np.broadcast_to(v, (m,)).copy()
        if not (np.all(np.isfinite(xy)) and np.all(np.isfinite(th)) and np.all(np.isfinite(v))):
            raise ValueError("Track samples must be finite")
        if np.any(v < 0):
            raise ValueError("Track.speed must be >= 0")
        th = np.unwrap(th)
        if self.closed:
            # append the closing sample so that interpolation runs over the full loop
            xy = np.vstack([xy, xy[:1]])
            th = np.append(th, th[0] + 2 * np.pi * np.round((th[-1] - th[0]) / (2 * np.pi)))
            v = np.append(v, v[0])
        dl = np.hypot(*np.diff(xy, axis=0).T)
        dth = np.diff(th)
        ds = np.sqrt(dl**2 + (self.progress_radius * dth) ** 2)
        keep = np.concatenate([[True], ds > 1e-9])
        xy, th, v = xy[keep], th[keep], v[keep]
        dl = np.hypot(*np.diff(xy, axis=0).T)
        dth = np.diff(th)
        ds = np.sqrt(dl**2 + (self.progress_radius * dth) ** 2)
        if xy.shape[0] < 2:
            raise ValueError("Track has no extent (all samples identical)")
        s = np.concatenate([[0.0], np.cumsum(ds)])
        path = np.concatenate([[0.0], np.cumsum(dl)])
        # path direction per sample, carried through zero-length segments
        seg_dir = np.arctan2(np.diff(xy[:, 1]), np.diff(xy[:, 0]))
        valid = dl > 1e-9
        tangent = np.empty(xy.shape[0])
        if np.any(valid):
            idx = np.where(valid, np.arange(valid.size), -1)
            idx = np.maximum.accumulate(idx)
            first = int(np.argmax(valid))
            idx[idx < 0] = first
            seg = seg_dir[idx]
            tangent[:-1] = seg
            tangent[-1] = seg[-1]
        else:
            tangent[:] = th  # pure rotation: use the heading as direction
        tangent = np.unwrap(tangent)
        curv = np.zeros(xy.shape[0])
        dpsi = np.diff(tangent)
        curv[1:] = np.where(dl > 1e-6, dpsi / np.maximum(dl, 1e-6), 0.0)
        # derivatives at the samples: central differences (one-sided at the ends; across the
        # closing sample of a loop), interpolated linearly in between by reference_twist
        if self.closed and xy.shape[0] > 3:
            ext_s = np.concatenate([[-(s[-1] - s[-2])], s, [s[-1] + s[1]]])
            ext_xy = np.vstack([xy[-2:-1], xy, xy[1:2]])
            ext_th = np.concatenate([[th[-2] - (th[-1] - th[0])], th, [th[1] + (th[-1] - th[0])]])
            dxy_ds = np.gradient(ext_xy, ext_s, axis=0)[1:-1]
            dth_ds = np.gradient(ext_th, ext_s)[1:-1]
        else:
            dxy_ds = np.gradient(xy, s, axis=0)
            dth_ds = np.gradient(th, s)
        for name, value in dict(xy=xy, heading=th, speed=v, s=s, path_length=path, tangent=tangent,
                                curvature=curv, dxy_ds=dxy_ds, dth_ds=dth_ds).items():
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "length", float(s[-1]))
        object.__setattr__(self, "_x", np.ascontiguousarray(xy[:, 0]))
        object.__setattr__(self, "_y", np.ascontiguousarray(xy[:, 1]))

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_waypoints(cls, waypoints, heading=None, speed=0.5, closed: bool = False, spacing: float = 0.02,
                       name: str = "waypoints", progress_radius: float = 0.3, ramp: float = 0.3) -> "Track":
        """A track through user waypoints, linearly interpolated at ``spacing`` [m].

        Args:
            waypoints: (W, 2) positions [m], or (W, 3) with a heading per waypoint [rad].
            heading: None (use the third column, else 0), a constant [rad], ``"tangent"`` (the
                heading follows the path direction, car-like) or (W,) headings [rad].
            speed: progress speed [m/s], scalar or (W,).
            closed: whether to join the last waypoint to the first.
            ramp: for open tracks, the speed ramps up from 0 over the first and down to 0 over the
                last ``ramp`` metres of progress (0: no ramps).
        """
        wp = check_real_array("waypoints", waypoints)
        spacing = check_positive("spacing", spacing)
        ramp = check_nonnegative("ramp", ramp)
        closed = check_bool("closed", closed)
        if wp.ndim != 2 or wp.shape[1] not in (2, 3) or wp.shape[0] < 2:
            raise ValueError(f"waypoints must have shape (W >= 2, 2 or 3), got {wp.shape}")
        if not np.all(np.isfinite(wp)):
            raise ValueError("waypoints must be finite")
        if np.ptp(wp[:, :2], axis=0).max() / spacing > 1e7:
            raise ValueError(f"spacing {spacing} m is too fine for waypoints spanning {np.ptp(wp[:, :2]):.3g} m "
                             "(more than 1e7 samples)")
        w = wp.shape[0]
        if isinstance(heading, str):
            if heading != "tangent":
                raise ValueError(f"heading must be None, a number, 'tangent' or an array, got {heading!r}")
            hd = None
        elif heading is None:
            hd = wp[:, 2] if wp.shape[1] == 3 else np.zeros(w)
        else:
            hd = np.broadcast_to(check_real_array("heading", heading, finite=True), (w,))
        sp = np.broadcast_to(check_real_array("speed", speed, finite=True), (w,))
        if np.any(sp < 0):
            raise ValueError("speed must be >= 0 [m/s]")
        pts = wp[:, :2]
        if closed:
            pts = np.vstack([pts, pts[:1]])
            hd = None if hd is None else np.append(hd, hd[0])
            sp = np.append(sp, sp[0])
        xs, hs, vs = [], [], []
        for j in range(pts.shape[0] - 1):
            seg = pts[j + 1] - pts[j]
            count = max(1, int(math.ceil(np.hypot(*seg) / spacing)))
            t = np.arange(count) / count
            xs.append(pts[j] + t[:, None] * seg)
            if hd is not None:
                hs.append(hd[j] + t * (hd[j + 1] - hd[j]))
            vs.append(sp[j] + t * (sp[j + 1] - sp[j]))
        if not closed:
            xs.append(pts[-1:])
            if hd is not None:
                hs.append(hd[-1:])
            vs.append(sp[-1:])
        xy = np.vstack(xs)
        v = np.concatenate(vs)
        if hd is None:
            d = np.diff(np.vstack([xy, xy[:1]]) if closed else xy, axis=0)
            th = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
            if not closed:
                th = np.append(th, th[-1])
        else:
            th = np.concatenate(hs)
        track = cls(name, xy, th, v, closed=closed, progress_radius=progress_radius)
        if not closed and ramp > 0:
            track = track.with_ramps(ramp)
        return track

    def with_ramps(self, ramp: float) -> "Track":
        """A copy whose speed rises from 0 over the first and falls to 0 over the last ``ramp`` m."""
        ramp = check_positive("ramp", ramp)
        scale = np.clip(np.minimum(self.s, self.length - self.s) / ramp, 0.0, 1.0)
        v = self.speed * np.sqrt(scale)
        v[0] = min(self.speed[0], 0.05)  # let the robot start
        xy, th = self.xy, self.heading
        if self.closed:
            xy, th, v = xy[:-1], th[:-1], v[:-1]
        return Track(self.name, xy, th, v, closed=self.closed, progress_radius=self.progress_radius)

    # ------------------------------------------------------------------ queries

    def _wrap_s(self, s):
        s = np.asarray(s, dtype=np.float64)
        if self.closed:
            return np.mod(s, self.length)
        return np.clip(s, 0.0, self.length)

    def sample(self, s) -> np.ndarray:
        """Reference pose and speed at progress s (scalar or array): (..., 4) = (x, y, θ, v)."""
        s = self._wrap_s(s)
        return np.stack([np.interp(s, self.s, self.xy[:, 0]), np.interp(s, self.s, self.xy[:, 1]),
                         np.interp(s, self.s, self.heading), np.interp(s, self.s, self.speed)], axis=-1)

    def reference_twist(self, s, speed=None) -> np.ndarray:
        """Reference world velocity (v_x, v_y, θ̇) [m/s, m/s, rad/s] at progress s, moving at the
        track's speed profile (or at ``speed`` [m/s of progress])."""
        s = self._wrap_s(s)
        v = np.interp(s, self.s, self.speed) if speed is None else np.asarray(speed, dtype=np.float64)
        return np.stack([np.interp(s, self.s, self.dxy_ds[:, 0]) * v, np.interp(s, self.s, self.dxy_ds[:, 1]) * v,
                         np.interp(s, self.s, self.dth_ds) * v], axis=-1)

    def reference_twist_body(self, s, theta: float, speed=None) -> np.ndarray:
        """The reference twist rotated into a chassis frame of heading ``theta`` [rad]: (ẋ, ẏ, θ̇)."""
        tw = self.reference_twist(s, speed)
        c, sn = math.cos(theta), math.sin(theta)
        return np.array([c * tw[0] + sn * tw[1], -sn * tw[0] + c * tw[1], tw[2]])

    def project(self, pose, s_hint: float | None = None, back: float = 0.5, ahead: float = 1.0) -> float:
        """Progress s of the reference pose nearest to ``pose`` = (x, y, θ), with the metric
        ``‖Δxy‖² + (ρ Δθ)²``. With ``s_hint``, only [s_hint − back, s_hint + ahead] is searched
        (progress then stays continuous; on a closed track it is unwrapped: it counts laps)."""
        pose = np.asarray(pose, dtype=np.float64)
        m = self.s.size
        if s_hint is None:
            idx = np.arange(m - 1 if self.closed else m)
            base = 0.0
        else:
            lap = math.floor(s_hint / self.length) if self.closed else 0
            base = lap * self.length
            s_loc = s_hint - base
            if self.closed:
                mu = m - 1

                def unwrapped_index(sv: float) -> int:
                    return int(math.floor(sv / self.length)) * mu + int(np.searchsorted(self.s, sv % self.length))

                idx = np.arange(unwrapped_index(s_loc - back) - 1, unwrapped_index(s_loc + ahead) + 1)
            else:
                lo = np.searchsorted(self.s, s_loc - back)
                hi = np.searchsorted(self.s, s_loc + ahead, side="right")
                idx = np.arange(max(lo - 1, 0), min(hi + 1, m))
        if self.closed:
            wrapped = np.mod(idx, m - 1)
            offsets = np.floor_divide(idx, m - 1) * self.length
        else:
            wrapped = idx
            offsets = np.zeros(idx.size)
        d = self.xy[wrapped] - pose[:2]
        dth = wrap_angle(self.heading[wrapped] - pose[2])
        cost = np.einsum("ij,ij->i", d, d) + (self.progress_radius * dth) ** 2
        j = int(np.argmin(cost))
        i = int(wrapped[j])
        s = self.s[i] + offsets[j] + base
        # refine along the segment's direction in (x, y, ρθ) space
        i2 = min(i, m - 2)
        seg = np.array([self.xy[i2 + 1, 0] - self.xy[i2, 0], self.xy[i2 + 1, 1] - self.xy[i2, 1],
                        self.progress_radius * (self.heading[i2 + 1] - self.heading[i2])])
        seg_len = float(np.linalg.norm(seg))
        if seg_len > 0:
            rel = np.array([pose[0] - self.xy[i, 0], pose[1] - self.xy[i, 1],
                            self.progress_radius * float(wrap_angle(pose[2] - self.heading[i]))])
            step = float(rel @ seg) / seg_len
            s += float(np.clip(step, -seg_len, seg_len))
        if not self.closed:
            s = float(np.clip(s, 0.0, self.length))
        return float(s)

    def errors(self, pose, s: float) -> tuple[float, float]:
        """(lateral error [m], heading error [rad]) of ``pose`` relative to the reference at s.

        The lateral error is positive to the left of the path direction; the heading error is
        θ − θ_ref wrapped to ]−π, π]."""
        pose = np.asarray(pose, dtype=np.float64)
        s_w = float(self._wrap_s(s))
        x, y, th, _ = self.sample(s_w)
        psi = float(np.interp(s_w, self.s, self.tangent))
        lat = -(pose[0] - x) * math.sin(psi) + (pose[1] - y) * math.cos(psi)
        return float(lat), float(wrap_angle(pose[2] - th))

    def tangent_at(self, s) -> np.ndarray:
        """Path direction ψ [rad] at progress s."""
        return np.interp(self._wrap_s(s), self.s, self.tangent)

    def lookahead(self, pose, s: float, count: int, spacing: float) -> np.ndarray:
        """(count, 3): reference points at s + spacing·(1..count) in the chassis frame of ``pose``:
        (x_b, y_b) [m] and heading difference θ_ref − θ [rad], wrapped."""
        pose = np.asarray(pose, dtype=np.float64)
        ref = self.sample(s + spacing * np.arange(1, count + 1))
        c, sn = math.cos(pose[2]), math.sin(pose[2])
        dx, dy = ref[:, 0] - pose[0], ref[:, 1] - pose[1]
        return np.stack([c * dx + sn * dy, -sn * dx + c * dy, wrap_angle(ref[:, 2] - pose[2])], axis=1)

    def query(self, pose, s_hint: float, lookahead_count: int, spacing: float, back: float = 0.5,
              ahead: float = 1.0) -> tuple[float, float, float, float, float, np.ndarray]:
        """Everything the env needs per step, in one compiled call: ``(s, lateral error, heading
        error, v_ref, ψ, lookahead (K, 3))``, the same as :meth:`project` (windowed at ``s_hint``),
        :meth:`errors`, :meth:`sample`, :meth:`tangent_at` and :meth:`lookahead`."""
        look = np.empty((int(lookahead_count), 3))
        s, lat, head, v, psi = _track_query_kernel(
            self.s, self._x, self._y, self.heading, self.speed,
            self.tangent, self.closed, self.length, self.progress_radius, float(pose[0]), float(pose[1]),
            float(pose[2]), float(s_hint), back, ahead, spacing, look)
        return s, lat, head, v, psi, look

    def query_many(self, poses, s_hints, lookahead_count: int, spacing: float, back: float = 0.5,
                   ahead: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`query` for N robots on this track in one compiled call.

        Returns ``(scalars (N, 5) = (s, lateral error, heading error, v_ref, ψ), lookahead (N, K, 3))``."""
        poses = np.ascontiguousarray(np.asarray(poses, dtype=np.float64).reshape(-1, 3))
        hints = np.ascontiguousarray(np.asarray(s_hints, dtype=np.float64).reshape(-1))
        if hints.shape[0] != poses.shape[0]:
            raise ValueError("query_many needs one s_hint per pose")
        out = np.empty((poses.shape[0], 5))
        look = np.empty((poses.shape[0], int(lookahead_count), 3))
        _track_query_many_kernel(self.s, self._x, self._y, self.heading, self.speed, self.tangent, self.closed,
                                 self.length, self.progress_radius, poses, hints, back, ahead, spacing, out, look)
        return out, look

    def packed(self) -> np.ndarray:
        """(6, m) C-contiguous rows (s, x, y, heading, speed, tangent), what the compiled queries
        read (built once per track and cached)."""
        cached = self.__dict__.get("_packed")
        if cached is None:
            cached = np.ascontiguousarray(np.stack([self.s, self._x, self._y, self.heading, self.speed,
                                                    self.tangent]).astype(np.float64))
            object.__setattr__(self, "_packed", cached)
        return cached

    def finished(self, s: float) -> bool:
        """Whether progress s has reached the end (one lap on a closed track)."""
        return s >= self.length - 1e-6

    @property
    def max_speed(self) -> float:
        """Largest reference speed [m/s]."""
        return float(np.max(self.speed))


# ---------------------------------------------------------------------- built-in tracks


def _arc(center, radius, a0, a1, spacing):
    count = max(2, int(math.ceil(abs(a1 - a0) * radius / spacing)))
    a = np.linspace(a0, a1, count, endpoint=False)
    return np.stack([center[0] + radius * np.cos(a), center[1] + radius * np.sin(a)], axis=1), a


def _line(p0, p1, spacing):
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    count = max(1, int(math.ceil(np.hypot(*(p1 - p0)) / spacing)))
    t = np.arange(count) / count
    return p0 + t[:, None] * (p1 - p0)


def paper_track(speed: float = 1.0, spacing: float = 0.02) -> Track:
    """Spiral, then circle, then square with rounded corners (after the paper's Fig. 9), at a nominal
    ``speed`` of 1 m/s (the path follower slows for curvature and stops).

    As in the paper (§4): the spiral is a continuously moving ICR with concurrent axes, the circle a
    constant ICR, and the rounded square switches between parallel propulsion axes (straight
    sides: a translation) and concurrent ones (corners: a rotation about the corner's centre), with
    sharp transitions in between. The robot's X axis points away from the centre of the spiral and
    circle, and away from the square's side (path direction minus π/2) on the square.
    """
    R = 1.5
    # spiral: r from 0.5 to R over 1.5 turns, ending at angle 0 (point (R, 0))
    turns = 1.5
    a = np.linspace(-2 * np.pi * turns, 0.0, int(2 * np.pi * turns * 1.0 / spacing), endpoint=False)
    rad = R - (R - 0.5) * (-a) / (2 * np.pi * turns)
    spiral = np.stack([rad * np.cos(a), rad * np.sin(a)], axis=1)
    h_sp = a.copy()  # car-like as on the circle: the ICR is the spiral's centre
    # circle: one turn from angle 0, heading along the tangent (tangent = angle + π/2, minus π/2 offset)
    circ, ac = _arc((0.0, 0.0), R, 0.0, 2 * np.pi, spacing)
    h_c = ac  # heading = tangent − π/2: ICR at the circle's centre, robot's X axis pointing outward
    # rounded square, side 2R centred at the origin, entered at (R, 0) going up (tangent continuous)
    rc = 0.4
    h_end = 2 * np.pi
    pieces = []
    pieces.append(_line((R, 0.0), (R, R - rc), spacing))
    corners = [((R - rc, R - rc), 0.0), ((-R + rc, R - rc), np.pi / 2), ((-R + rc, -R + rc), np.pi),
               ((R - rc, -R + rc), 3 * np.pi / 2)]
    ends = [(-R + rc, R), (-R, -R + rc), (R - rc, -R), (R, 0.0)]
    for (c, a0), e in zip(corners, ends):
        arc, _ = _arc(c, rc, a0, a0 + np.pi / 2, spacing)
        pieces.append(arc)
        start = np.array([c[0] + rc * math.cos(a0 + np.pi / 2), c[1] + rc * math.sin(a0 + np.pi / 2)])
        pieces.append(_line(start, e, spacing))
    square = np.vstack(pieces + [np.array([[R, 0.0]])])
    d = np.diff(square, axis=0)
    tang = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    tang = np.append(tang, tang[-1])
    h_sq = tang - np.pi / 2
    h_sq += h_end - h_sq[0]  # continuous with the end of the circle
    xy = np.vstack([spiral, circ, square])
    th = np.concatenate([h_sp, h_c, h_sq])
    v = np.full(len(xy), speed)
    return Track("paper", xy, th, v, closed=False).with_ramps(0.3)


def circle_track(radius: float = 1.5, speed: float = 0.5, spacing: float = 0.02) -> Track:
    """A closed circle driven car-like (heading along the path; ICR at the centre)."""
    xy, a = _arc((0.0, 0.0), radius, -np.pi / 2, 3 * np.pi / 2, spacing)
    return Track("circle", xy + np.array([0.0, radius]), a + np.pi / 2, speed, closed=True)


def figure8_track(size: float = 2.0, speed: float = 0.5, spacing: float = 0.02) -> Track:
    """A closed lemniscate of Gerono (x = a sin t, y = a sin t cos t), heading along the path."""
    t = np.linspace(0, 2 * np.pi, 4000, endpoint=False)
    x, y = size * np.sin(t), size * np.sin(t) * np.cos(t)
    d = np.hypot(np.diff(x, append=x[0]), np.diff(y, append=y[0]))
    s = np.concatenate([[0], np.cumsum(d)])[:-1]
    ss = np.arange(0, s[-1] + d[-1], spacing)
    tt = np.interp(ss, np.append(s, s[-1] + d[-1]), np.append(t, 2 * np.pi))
    xy = np.stack([size * np.sin(tt), size * np.sin(tt) * np.cos(tt)], axis=1)
    dx = np.stack([np.cos(tt), np.cos(2 * tt)], axis=1)  # derivative direction
    th = np.unwrap(np.arctan2(dx[:, 1], dx[:, 0]))
    return Track("figure8", xy, th, speed, closed=True)


def square_track(side: float = 3.0, speed: float = 0.5, heading: float = 0.0, spacing: float = 0.02,
                 stop_ramp: float = 0.4) -> Track:
    """A closed square with sharp corners at a fixed heading: the speed falls to 0 at each corner,
    where the translation direction turns by 90°, so the robot must stop and reconfigure its wheels."""
    h = side / 2
    corners = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    pts = np.vstack([_line(corners[j], corners[(j + 1) % 4], spacing) for j in range(4)])
    # distance to the nearest corner
    dist = np.min(np.hypot(pts[:, None, 0] - corners[None, :, 0], pts[:, None, 1] - corners[None, :, 1]), axis=1)
    v = speed * np.sqrt(np.clip(dist / stop_ramp, 0.0, 1.0))
    v = np.maximum(v, 0.02)
    return Track("square", pts + np.array([h, h]), heading, v, closed=True)


def crab_track(speed: float = 0.4, heading: float = 0.5, spacing: float = 0.02) -> Track:
    """Translation at a fixed heading (diagonally), a rotation in place by π/2, then a sideways
    translation: the ICR jumps from the horizon to the chassis centre and back."""
    a = _line((0.0, 0.0), (2.0, 1.0), spacing)
    rot_n = int(math.ceil(0.3 * (np.pi / 2) / spacing))
    rot_xy = np.repeat(np.array([[2.0, 1.0]]), rot_n, axis=0)
    rot_th = heading + np.linspace(0, np.pi / 2, rot_n, endpoint=False)
    b = _line((2.0, 1.0), (2.0, 3.0), spacing)
    xy = np.vstack([a, rot_xy, b, [[2.0, 3.0]]])
    th = np.concatenate([np.full(len(a), heading), rot_th, np.full(len(b) + 1, heading + np.pi / 2)])
    # stop before and after the rotation in place
    track = Track("crab", xy, th, speed, closed=False)
    s_rot0 = track.s[len(a)]
    s_rot1 = track.s[min(len(a) + rot_n, track.s.size - 1)]
    dist = np.minimum(np.abs(track.s - s_rot0), np.abs(track.s - s_rot1))
    inside = (track.s > s_rot0) & (track.s < s_rot1)
    v = track.speed * np.where(inside, 1.0, np.sqrt(np.clip(dist / 0.3, 0.05, 1.0)))
    return Track("crab", track.xy, track.heading, v, closed=False).with_ramps(0.3)


def random_track(seed: int | None = None, rng: np.random.Generator | None = None, spacing: float = 0.02) -> Track:
    """A seeded smooth closed curve: a radius profile with a few random harmonics, a heading that
    either follows the path or stays near a fixed value with a slow oscillation, a random speed."""
    rng = np.random.default_rng(seed) if rng is None else rng
    r0 = rng.uniform(1.2, 2.5)
    harm = np.arange(2, 5)
    amp = rng.uniform(0, 0.12, size=harm.size)
    ph = rng.uniform(0, 2 * np.pi, size=harm.size)
    t = np.linspace(0, 2 * np.pi, 4000, endpoint=False)
    rad = r0 * (1 + np.sum(amp[:, None] * np.cos(harm[:, None] * t[None] + ph[:, None]), axis=0))
    x, y = rad * np.cos(t), rad * np.sin(t)
    d = np.hypot(np.diff(x, append=x[0]), np.diff(y, append=y[0]))
    s = np.concatenate([[0], np.cumsum(d)])
    ss = np.arange(0, s[-1], spacing)
    xy = np.stack([np.interp(ss, s, np.append(x, x[0])), np.interp(ss, s, np.append(y, y[0]))], axis=1)
    if rng.random() < 0.5:
        dxy = np.diff(np.vstack([xy, xy[:1]]), axis=0)
        th = np.unwrap(np.arctan2(dxy[:, 1], dxy[:, 0])) + rng.uniform(-np.pi, np.pi)
    else:
        th = rng.uniform(-np.pi, np.pi) + rng.uniform(0, 0.8) * np.sin(2 * np.pi * ss / ss[-1] * rng.integers(1, 4)
                                                                       + rng.uniform(0, 2 * np.pi))
    speed = rng.uniform(0.3, 0.7)
    return Track("random", xy - xy[0], th, speed, closed=True)


def make_track(name: str, rng: np.random.Generator | None = None, **kwargs) -> Track:
    """A built-in track by name (see ``TRACK_NAMES``); ``random`` draws from ``rng``."""
    builders = {"paper": paper_track, "circle": circle_track, "figure8": figure8_track, "square": square_track,
                "crab": crab_track}
    if name == "random":
        return random_track(rng=rng if rng is not None else np.random.default_rng(), **kwargs)
    if name not in builders:
        raise ValueError(f"unknown track {name!r}; choose from {TRACK_NAMES} or pass a Track")
    return builders[name](**kwargs)
