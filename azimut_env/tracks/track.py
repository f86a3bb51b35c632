"""A reference track for an omnidirectional robot: a path, a heading profile independent of the
path direction, and a speed profile.

A :class:`Track` is a dense polyline of reference poses (x, y, θ) in the world with a speed v per
sample. Because the robot can turn in place, progress along a track is not the path length alone:
the progress coordinate s grows by ``ds = sqrt(dℓ² + (ρ dθ)²)`` between samples, where dℓ is the path
length and ρ (``progress_radius``, [m]) converts heading change to length. A pure rotation in place
therefore still has progress, and ``v`` [m/s] is the rate of s.

:meth:`Track.from_waypoints` builds one from user waypoints; :mod:`azimut_env.tracks.library` holds
the built-in ones; the compiled queries are in :mod:`azimut_env.tracks.query`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from azimut_env.tracks.query import query_batch_kernel, query_one_kernel, segment_step, wrap_angle
from azimut_env.validation import check_bool, check_nonnegative, check_positive, check_real_array
from estimation.libm import atan2

__all__ = ["Track"]


#: the largest |heading| a track takes [rad]: an angle unwrapped along a track stays far below it;
#: beyond it an angle has no digits left for its fraction of a turn
_MAX_HEADING = 1e6


def _checked_samples(xy, heading, speed, closed: bool):
    """The track's samples checked (finite, speed >= 0), heading and speed broadcast to (M,), the
    heading unwrapped; a closed track gets its closing sample appended, so that interpolation runs
    over the full loop."""
    xy = check_real_array("Track.xy", xy)
    th = check_real_array("Track.heading", heading)
    v = check_real_array("Track.speed", speed)
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
    if closed:
        # append the closing sample so that interpolation runs over the full loop
        xy = np.vstack([xy, xy[:1]])
        th = np.append(th, th[0] + 2 * np.pi * np.round((th[-1] - th[0]) / (2 * np.pi)))
        v = np.append(v, v[0])
    return xy, th, v


def _tangent(xy: np.ndarray, th: np.ndarray, dl: np.ndarray) -> np.ndarray:
    """The path direction per sample [rad], carried through zero-length segments (the heading
    where the whole track is a rotation in place); not unwrapped."""
    seg_dir = atan2(np.diff(xy[:, 1]), np.diff(xy[:, 0]))
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
    return tangent


def _derivatives(xy: np.ndarray, th: np.ndarray, s: np.ndarray, closed: bool):
    """d(x, y)/ds and dθ/ds at the samples."""
    # derivatives at the samples: central differences (one-sided at the ends; across the
    # closing sample of a loop), interpolated linearly in between by reference_twist
    if closed and xy.shape[0] > 3:
        ext_s = np.concatenate([[-(s[-1] - s[-2])], s, [s[-1] + s[1]]])
        ext_xy = np.vstack([xy[-2:-1], xy, xy[1:2]])
        ext_th = np.concatenate([[th[-2] - (th[-1] - th[0])], th, [th[1] + (th[-1] - th[0])]])
        dxy_ds = np.gradient(ext_xy, ext_s, axis=0)[1:-1]
        dth_ds = np.gradient(ext_th, ext_s)[1:-1]
    else:
        dxy_ds = np.gradient(xy, s, axis=0)
        dth_ds = np.gradient(th, s)
    return dxy_ds, dth_ds


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
        holds: ((s, duration), ...): stops where the reference holds the robot still for
            ``duration`` [s] once it reaches progress s [m] (open tracks; the speed profile should
            come to rest there). A path follower commands exactly zero while holding
            (``control.follow.path_follower.PathFollower``); the scenario ``hold`` uses it.

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
    holds: tuple = ()
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
        xy, th, v = _checked_samples(self.xy, self.heading, self.speed, self.closed)
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
        tangent = np.unwrap(_tangent(xy, th, dl))
        curv = np.zeros(xy.shape[0])
        dpsi = np.diff(tangent)
        curv[1:] = np.where(dl > 1e-6, dpsi / np.maximum(dl, 1e-6), 0.0)
        dxy_ds, dth_ds = _derivatives(xy, th, s, self.closed)
        for name, value in dict(xy=xy, heading=th, speed=v, s=s, path_length=path, tangent=tangent,
                                curvature=curv, dxy_ds=dxy_ds, dth_ds=dth_ds).items():
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "length", float(s[-1]))
        object.__setattr__(self, "holds", self._check_holds(self.holds))
        object.__setattr__(self, "_x", np.ascontiguousarray(xy[:, 0]))
        object.__setattr__(self, "_y", np.ascontiguousarray(xy[:, 1]))

    def _check_holds(self, holds) -> tuple[tuple[float, float], ...]:
        """``holds`` as a tuple of (s [m], duration [s]) floats: on an open track, s in [0, length]
        and increasing, durations in ]0, 3600]."""
        try:
            pairs = [(float(s), float(d)) for s, d in holds]
        except (TypeError, ValueError):
            raise ValueError(f"Track.holds must be a sequence of (s, duration) pairs, got {holds!r}") from None
        if pairs and self.closed:
            raise ValueError("Track.holds: holds need an open track")
        for s, d in pairs:
            if not (math.isfinite(s) and 0.0 <= s <= self.length):
                raise ValueError(f"Track.holds: progress {s!r} outside [0, {self.length:.6g}] m")
            if not (math.isfinite(d) and 0.0 < d <= 3600.0):
                raise ValueError(f"Track.holds: duration {d!r} must be in ]0, 3600] s")
        if any(b[0] <= a[0] for a, b in zip(pairs, pairs[1:])):
            raise ValueError("Track.holds: progress values must increase")
        return tuple(pairs)

    @property
    def hold_time(self) -> float:
        """Total time [s] of the holds."""
        return float(sum(d for _, d in self.holds))

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_waypoints(cls, waypoints, heading=None, speed=0.5, closed: bool = False, spacing: float = 0.02,
                       name: str = "waypoints", progress_radius: float = 0.3, ramp: float = 0.3) -> Track:
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
        if np.ptp(wp[:, :2], axis=0).max() > 1e7 * spacing:  # (no division: a subnormal spacing overflowed it)
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
            hd = check_real_array("heading", heading, finite=True, broadcast=(w,))
        sp = check_real_array("speed", speed, finite=True, broadcast=(w,))
        if np.any(sp < 0):
            raise ValueError("speed must be >= 0 [m/s]")
        if hd is not None and np.any(np.abs(hd) > _MAX_HEADING):  # 7e306 rad overflowed the heading's gradient
            raise ValueError(f"heading must lie within ±{_MAX_HEADING:g} rad (an angle, unwrapped along the track)")
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
            th = np.unwrap(atan2(d[:, 1], d[:, 0]))
            if not closed:
                th = np.append(th, th[-1])
        else:
            th = np.concatenate(hs)
        track = cls(name, xy, th, v, closed=closed, progress_radius=progress_radius)
        if not closed and ramp > 0:
            track = track.with_ramps(ramp)
        return track

    def with_ramps(self, ramp: float) -> Track:
        """A copy whose speed rises from 0 over the first and falls to 0 over the last ``ramp`` m."""
        ramp = check_positive("ramp", ramp)
        with np.errstate(over="ignore"):  # a subnormal ramp: inf, clipped to 1 (no ramp)
            scale = np.clip(np.minimum(self.s, self.length - self.s) / ramp, 0.0, 1.0)
        v = self.speed * np.sqrt(scale)
        v[0] = min(self.speed[0], 0.05)  # let the robot start
        xy, th = self.xy, self.heading
        if self.closed:
            xy, th, v = xy[:-1], th[:-1], v[:-1]
        return Track(self.name, xy, th, v, closed=self.closed, progress_radius=self.progress_radius, holds=self.holds)

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
        # sums written out, not einsum or BLAS dot products, whose SIMD or FMA kernels round
        # differently on some CPUs: the compiled follower (control.follow.batch) repeats these bits
        cost = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + (self.progress_radius * dth) ** 2
        j = int(np.argmin(cost))
        i = int(wrapped[j])
        s = self.s[i] + offsets[j] + base
        # refine along the segments at the sample in (x, y, ρθ) space (the compiled refinement, one
        # rule for every projection: azimut_env.tracks.query.segment_step)
        moved, step = segment_step(self._x, self._y, self.heading, float(self.progress_radius), i, m,
                                   bool(self.closed), float(pose[0]), float(pose[1]), float(pose[2]))
        if moved:
            s += step
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
        out = np.empty(5)
        look = np.empty((int(lookahead_count), 3))
        query_one_kernel(self.packed(), self.closed, self.length, self.progress_radius, float(pose[0]), float(pose[1]),
                         float(pose[2]), float(s_hint), back, ahead, spacing, out, look)
        s, lat, head, v, psi = out.tolist()
        return s, lat, head, v, psi, look

    def query_batch(self, poses, s_hints, lookahead_count: int, spacing: float, back: float = 0.5,
                    ahead: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`query` for N robots on this track in one compiled call.

        Returns ``(scalars (N, 5) = (s, lateral error, heading error, v_ref, ψ), lookahead (N, K, 3))``."""
        poses = np.ascontiguousarray(np.asarray(poses, dtype=np.float64).reshape(-1, 3))
        hints = np.ascontiguousarray(np.asarray(s_hints, dtype=np.float64).reshape(-1))
        n = poses.shape[0]
        if hints.shape[0] != n:
            raise ValueError("query_batch needs one s_hint per pose")
        out = np.empty((n, 5))
        look = np.empty((n, int(lookahead_count), 3))
        pack, closed, length, rho = self._kernel_track()
        query_batch_kernel(pack, np.zeros(n, dtype=np.int64), closed, length, rho, poses, hints, back, ahead, spacing,
                           out, look)
        return out, look

    def query_many(self, poses, s_hints, lookahead_count: int, spacing: float, back: float = 0.5,
                   ahead: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Deprecated name of :meth:`query_batch` (the project spells batched calls ``*_batch``)."""
        warnings.warn("Track.query_many is deprecated; use Track.query_batch", DeprecationWarning, stacklevel=2)
        return self.query_batch(poses, s_hints, lookahead_count, spacing, back, ahead)

    def packed(self) -> np.ndarray:
        """(6, m) C-contiguous rows (s, x, y, heading, speed, tangent), what the compiled queries
        read (built once per track and cached)."""
        cached = self.__dict__.get("_packed")
        if cached is None:
            cached = np.ascontiguousarray(np.stack([self.s, self._x, self._y, self.heading, self.speed,
                                                    self.tangent]).astype(np.float64))
            object.__setattr__(self, "_packed", cached)
        return cached

    def _kernel_track(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """This track as :func:`~azimut_env.tracks.query.query_batch_kernel` reads a set of one:
        ``(packs (1, 6, m), closed (1,), length (1,), rho (1,))`` (built once and cached)."""
        cached = self.__dict__.get("_kernel_args")
        if cached is None:
            cached = (self.packed()[None], np.array([self.closed]), np.array([self.length]),
                      np.array([self.progress_radius]))
            object.__setattr__(self, "_kernel_args", cached)
        return cached

    def finished(self, s: float) -> bool:
        """Whether progress s has reached the end (one lap on a closed track)."""
        return s >= self.length - 1e-6

    @property
    def max_speed(self) -> float:
        """Largest reference speed [m/s]."""
        return float(np.max(self.speed))
