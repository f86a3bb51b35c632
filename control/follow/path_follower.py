"""Path follower: a :class:`~azimut_env.tracks.Track` and the robot's pose -> a chassis twist target.

The same follower feeds every controller (the ICR controller through (λ_d, μ_d), the twist
baseline through ξ̇_d), so a comparison isolates how the wheels are coordinated.

Per step, with the pose (x, y, θ) in the world:

1. progress s = the nearest reference pose (``Track.project``, windowed around the last s, so it
   is continuous and waits for the robot when it stops); within one segment of a cusp (the path
   turning back on itself), the projection onto the nearer of the cusp's two legs
   (:mod:`control.follow.cusps`);
2. feed-forward: the reference world twist at s + max(v_ref·τ, d_min), the preview shrinking
   to d_min before a sharp corner, and the speed capped so the robot can slow down for it
   (``Track.reference_twist``; τ is a short preview that compensates the controllers' lag);
3. feedback on the pose error, position and heading separately (the robot is omnidirectional, so
   the heading follows its own profile, independent of the path direction):
   v = v_ref + k_p (p_ref − p) + k_i n ∫ e_n dt and ω = θ̇_ref + k_θ wrap(θ_ref − θ), with the
   corrections capped (n: the path normal, e_n the cross-track error, integrated while the robot
   makes progress along the track);
4. the world twist is rotated into the chassis frame; ``eta_from_twist`` gives (λ_d, μ_d), using
   ξ̇ = μ (v, −u, w) (§2).

A track's holds (``Track.holds``: (s, duration) pairs) stop this: once the progress reaches a
hold's s (within ``hold_reach``), the follower outputs exactly zero (twist 0, μ_d = 0, no
feedback) for the hold's duration, counted in control periods of ``dt``, then follows on
(``FollowerOutput.holding``). This is the command "stand still" of the ``hold`` scenario.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from azimut_env.tracks import Track, wrap_angle
from azimut_env.validation import check_fields, check_finite
from control.follow.cusps import cusp_feed_forward, cusp_progress, cusp_table
from estimation.hrep import eta_from_twist

__all__ = ["PathFollowerConfig", "PathFollower", "FollowerOutput", "check_start_progress"]


def check_start_progress(track: Track, progress) -> float:
    """A follower's starting progress [m] on ``track`` as ``float``: a finite number (not a bool)
    within [0, length] on an open track, within [−length, length] on a closed one (progress is
    counted over laps there: a start beyond one lap would report the lap finished at once, one
    just before the start line is slightly negative). ``ValueError``/``TypeError`` naming it."""
    s = check_finite("progress", progress)
    lo = -track.length if track.closed else 0.0
    if not lo <= s <= track.length:
        raise ValueError(f"progress = {s!r} m is off the track: it must lie in [{lo:.6g}, {track.length:.6g}] m")
    return s


@dataclass(frozen=True)
class PathFollowerConfig:
    """Gains of the path follower.

    Attributes:
        k_pos: position error gain [1/s].
        k_heading: heading error gain [1/s].
        k_int: integral gain on the cross-track error [1/s²] (removes the steady offset that tire
            slip and steering compliance leave in curves); integrated only while the robot makes
            progress along the track.
        max_integral: cap on the integral correction speed [m/s].
        moving_speed: rate of progress along the track [m/s] above which the robot counts as moving
            (for the integral).
        max_correction: cap on the position correction speed [m/s].
        max_heading_correction: cap on the heading correction rate [rad/s].
        preview: feed-forward preview time τ [s].
        preview_min: smallest feed-forward preview distance [m]: at a sharp corner, where the
            reference slows to a crawl, it makes the reference direction switch as the robot
            arrives (with none, the feed-forward along the old side and the feedback back to the
            corner cancel and the robot stalls).
        corner_angle: if the path direction turns by more than this [rad] between s and the
            preview point (a sharp corner), the preview shrinks to ``preview_min``, so the robot
            reaches the corner before the reference direction switches.
        corner_decel: deceleration [m/s²] used to slow down before a sharp corner (a turn of the
            path direction by more than ``corner_angle`` within ``corner_window`` of progress):
            the feed-forward speed is capped at sqrt(2 a d) + ``corner_speed``, d the distance to
            the corner. Both controllers get it; it is what lets any of them take a corner that
            needs the wheels turned in place.
        corner_window: how far ahead corners are looked for [m].
        corner_speed: speed floor at a corner, and everywhere before the end of the track [m/s].
        max_lateral_accel: cap on the path's centripetal acceleration [m/s²]: the feed-forward
            speed is at most sqrt(a / κ) where the path curvature κ is high (a speed profile that
            ignores curvature is scaled down in tight curves).
        speed_scale: multiplies the track's speed profile [-] (1: the track's nominal speed).
        hold_reach: progress [m] short of a hold's s at which the hold starts (the reference
            speed falls to ``corner_speed`` there, so the robot arrives slowly).
        rotation_cusps: also treat as cusps the points where the path turns back in the
            projection's metric (x, y, ρθ) but not in the plane (:func:`control.follow.cusps.cusp_table`),
            as where ``spin``'s drive-and-rotate leg ends in a spin in place the other way (False
            by default; the ICR path controller turns it on: without it the progress can stall a
            few millimetres before such a junction, the heading feedback balancing the spin's
            feed-forward; the twist baselines blend through it; ``docs/control.md``).
    """

    k_pos: float = 3.0
    k_heading: float = 3.0
    k_int: float = 2.0
    max_integral: float = 0.1
    moving_speed: float = 0.02
    max_correction: float = 0.3
    max_heading_correction: float = 0.6
    preview: float = 0.1
    preview_min: float = 0.001
    corner_angle: float = 0.35
    corner_decel: float = 1.0
    corner_window: float = 1.0
    corner_speed: float = 0.02
    max_lateral_accel: float = 1.0
    speed_scale: float = 1.0
    hold_reach: float = 0.01
    rotation_cusps: bool = False

    @classmethod
    def for_robot(cls, params, speed_scale: float = 1.0) -> PathFollowerConfig:
        """The gains scaled to a robot (``azimut_env.params.RobotParams``), for tracks whose
        speeds are the robot's own (the scenarios, ``azimut_env.tracks.scenarios``): curves are
        capped at the friction limit μ g (not 1 m/s²), sharp corners and stops are braked for at
        half the wheels' acceleration limit r φ̈_max, looked for far enough ahead to brake from
        the top wheel speed, and the position correction is capped at 0.3 m/s or 20% of the top
        wheel speed. The other gains are the defaults."""
        import numpy as np

        r = float(np.min(params.geometry.r))
        v_max, accel = r * params.limits.wheel_speed_max, r * params.limits.wheel_accel_max
        decel = 0.5 * accel
        return cls(max_lateral_accel=params.tire.friction * params.gravity, corner_decel=decel,
                   corner_window=max(1.0, v_max * v_max / (2.0 * decel) + 0.2),
                   max_correction=max(0.3, 0.2 * v_max), speed_scale=speed_scale)

    def __post_init__(self) -> None:
        check_fields(self)
        for name in ("k_int", "moving_speed", "preview", "preview_min", "hold_reach"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"PathFollowerConfig.{name} must be finite and >= 0, got {value!r}")
        for name in ("k_pos", "k_heading", "max_correction", "max_integral", "max_heading_correction", "speed_scale",
                     "corner_angle", "corner_decel", "corner_window", "corner_speed", "max_lateral_accel"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"PathFollowerConfig.{name} must be finite and > 0, got {value!r}")
        for name in ("preview", "preview_min"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"PathFollowerConfig.{name} must be finite and >= 0, got {value!r}")


@dataclass(frozen=True)
class FollowerOutput:
    """One step of the follower.

    Attributes:
        twist: (3,) chassis-frame twist target (ẋ, ẏ, θ̇) [m/s, m/s, rad/s].
        lam: (3,) target λ_d; mu: target μ_d ≥ 0 [m/s] (from ``eta_from_twist``).
        progress: s [m]; finished: whether the track's end (or one lap) is reached.
        holding: the track holds the robot still at this step (the twist is exactly zero).
    """

    twist: np.ndarray
    lam: np.ndarray
    mu: float
    progress: float
    finished: bool
    holding: bool = False


def reference_lambdas(track: Track, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reference's chassis-frame ICR λ (M, 3) at progress ``s`` (M,) and the twist's norm at
    unit progress speed (M,) (0 where the reference does not move; λ does not depend on the speed)."""
    tw = track.reference_twist(s, speed=np.ones_like(s))
    th = track.sample(s)[:, 2]
    c, sn = np.cos(th), np.sin(th)
    body = np.stack([c * tw[:, 0] + sn * tw[:, 1], -sn * tw[:, 0] + c * tw[:, 1], tw[:, 2]], axis=1)
    return eta_from_twist(body)


def merge_stops(stops: np.ndarray, extra, track: Track) -> np.ndarray:
    """The sorted union of ``stops`` and ``extra`` progress values [m] (None: none; wrapped into one
    lap on a closed track); ``ValueError`` if an extra one is not finite."""
    if extra is None or np.size(extra) == 0:
        return stops
    extra = np.asarray(extra, dtype=np.float64).ravel()
    if not np.all(np.isfinite(extra)):
        raise ValueError("extra_stops must be finite")
    if track.closed:
        extra = np.mod(extra, track.length)
    return np.unique(np.concatenate([stops, extra]))


class PathFollower:
    """Stateful (only the progress hint) path follower; see the module docstring.

    Args:
        track: the reference.
        config: gains.
        stop_mask: optional ``f(λ (M, 3)) -> (M − 1,) bool``: whether the controller must stop
            between consecutive reference ICRs (for the ICR controller:
            :func:`control.icr.controller.reference_stop_mask`, a steering stop or axis on the
            way). The follower then slows down to reach those points at ``corner_speed``, as for
            sharp corners. None: only sharp corners of the path count.
        extra_stops: progress values [m] to arrive slowly at as well (a look-ahead plan's changes
            of configuration; :func:`merge_stops`).
    """

    def __init__(self, track: Track, config: PathFollowerConfig | None = None,
                 stop_mask: Callable[[np.ndarray], np.ndarray] | None = None, dt: float = 0.02,
                 extra_stops=None) -> None:
        if not isinstance(track, Track):
            raise ValueError(f"track must be an azimut_env.tracks.Track, got {type(track).__name__}")
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {dt!r}")
        self.track = track
        self.config = config or PathFollowerConfig()
        self.dt = float(dt)
        self.progress: float | None = None
        self._integral = 0.0
        self._max_progress: float | None = None
        self._hold_next = 0  # index of the next hold of the track
        self._hold_left = 0  # control periods left in the current hold (0: not holding)
        self.stops = merge_stops(self._find_stops(stop_mask), extra_stops, track)
        self._cusps = cusp_table(track, self.config.rotation_cusps)

    def reset(self, progress: float | None = None) -> None:
        """Forget the progress (the next step searches the whole track unless given) and the
        integral of the cross-track error. ``progress`` [m]: None, or a start along the track
        (:func:`check_start_progress`); ``ValueError``/``TypeError`` otherwise, changing nothing
        (NaN, inf or 1e9 were accepted and the next step reported the lap finished; ``True`` was
        taken as 1)."""
        if progress is not None:
            progress = check_start_progress(self.track, progress)
        self.progress = progress
        self._integral = 0.0
        self._max_progress = None
        holds = self.track.holds
        self._hold_next = 0 if progress is None else sum(1 for s, _ in holds if s < progress - self.config.hold_reach)
        self._hold_left = 0

    def _find_stops(self, stop_mask) -> np.ndarray:
        """Sorted progress values [m] where the robot should arrive slowly: sharp path corners
        (the direction turns by more than ``corner_angle``/2 within 1 cm) and, with ``stop_mask``,
        the points where the reference ICR needs a stop and reconfiguration."""
        tr, cfg = self.track, self.config
        grid = np.arange(0.0, tr.length, 0.01)
        psi = np.asarray(tr.tangent_at(grid))
        mask = np.abs(wrap_angle(np.diff(psi))) > 0.5 * cfg.corner_angle
        if stop_mask is not None:
            lam, unit_mu = reference_lambdas(tr, grid)
            moving = unit_mu > 1e-9
            lam = lam[moving]
            sub = np.asarray(stop_mask(lam), dtype=bool)
            idx = np.flatnonzero(moving)
            extra = np.zeros(grid.size - 1, dtype=bool)
            extra[idx[:-1][sub]] = True
            mask |= extra
        return grid[1:][mask]

    def _holding(self, s: float) -> bool:
        """Whether this step is one of a hold's (starting it when s reaches the next hold)."""
        holds = self.track.holds
        if self._hold_left == 0 and self._hold_next < len(holds):
            s_hold, duration = holds[self._hold_next]
            if s >= s_hold - self.config.hold_reach:
                self._hold_left = max(1, int(round(duration / self.dt)))
                self._hold_next += 1
        if self._hold_left > 0:
            self._hold_left -= 1
            return True
        return False

    def _distance_to_stop(self, s: float) -> float | None:
        """Progress [m] from s to the next stop point within ``corner_window``, or None."""
        tr, cfg = self.track, self.config
        if self.stops.size == 0:
            return None
        stops = np.concatenate([self.stops, self.stops + tr.length]) if tr.closed else self.stops
        s_loc = s % tr.length if tr.closed else s
        ahead = stops[stops > s_loc]
        if ahead.size == 0 or ahead[0] - s_loc > cfg.corner_window:
            return None
        return float(ahead[0] - s_loc)

    def step(self, pose) -> FollowerOutput:
        """The twist target for the robot at ``pose`` = (x, y, θ) [m, m, rad] in the world."""
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise ValueError(f"pose must be a finite (3,) array, got {pose!r}")
        cfg, tr = self.config, self.track
        s = tr.project(pose, s_hint=self.progress)
        if self._cusps.shape[0]:  # a cusp: the nearer of its two legs (control.follow.cusps)
            s = float(cusp_progress(tr.s, tr.xy[:, 0], tr.xy[:, 1], tr.heading, tr.progress_radius, tr.closed,
                                    tr.length, self._cusps, pose[0], pose[1], pose[2], s))
        self.progress = s
        finished = tr.finished(s)
        if self._holding(s):
            zero = np.zeros(3)
            lam, mu = eta_from_twist(zero)
            return FollowerOutput(twist=zero, lam=lam, mu=float(mu), progress=float(s), finished=bool(finished),
                                  holding=True)
        x_r, y_r, th_r, v_r = tr.sample(s)
        v_r *= cfg.speed_scale
        s_ff = s + max(v_r * cfg.preview, cfg.preview_min)
        if not tr.closed:
            s_ff = min(s_ff, tr.length)
        if abs(float(wrap_angle(tr.tangent_at(s_ff) - tr.tangent_at(s)))) > cfg.corner_angle:
            s_ff = min(s + cfg.preview_min, tr.length) if not tr.closed else s + cfg.preview_min
        v_ff = float(tr.sample(s_ff)[3]) * cfg.speed_scale
        kappa = float(np.max(np.abs(np.interp(np.linspace(s, s_ff + 0.05, 6) % tr.length if tr.closed else
                                              np.clip(np.linspace(s, s_ff + 0.05, 6), 0, tr.length),
                                              tr.s, tr.curvature))))
        if 1e-6 < kappa < 20.0:  # sharper turns (radius < 5 cm) are corners, handled as stops
            v_ff = min(v_ff, math.sqrt(cfg.max_lateral_accel / kappa))
        d_corner = self._distance_to_stop(s)
        if d_corner is not None:
            v_ff = min(v_ff, math.sqrt(2.0 * cfg.corner_decel * d_corner) + cfg.corner_speed)
        v_ff = max(v_ff, cfg.corner_speed)  # never stall short of the end (speed ramps reach 0)
        tw_ref = tr.reference_twist(s_ff, speed=v_ff)
        if finished:
            tw_ref = np.zeros(3)
        elif self._cusps.shape[0]:  # at a cusp, along its legs (control.follow.cusps)
            tw_ref = np.array(tw_ref, dtype=np.float64)
            reached = s if self._max_progress is None else max(self._max_progress, s)
            cusp_feed_forward(tr.s, self._cusps, tr.progress_radius, tr.closed, tr.length, s_ff, reached, v_ff,
                              tw_ref)
        err = np.array([x_r - pose[0], y_r - pose[1]])
        psi = float(tr.tangent_at(s))
        normal = np.array([-math.sin(psi), math.cos(psi)])
        # anti-windup: integrate the cross-track error only while the robot makes new progress along
        # the track, not while it stands off the path turning its wheels in place (after a knock, at
        # a reconfiguration): the chassis still shakes then, but an error it cannot reduce there
        # would wind the integral up, and the robot would overshoot the path once it drives on
        # (progress past the farthest reached so far, so shaking back and forth does not count)
        moved = self._max_progress is not None and s - self._max_progress > cfg.moving_speed * self.dt
        self._max_progress = s if self._max_progress is None else max(self._max_progress, s)
        if moved and not finished:
            lim = cfg.max_integral / cfg.k_int if cfg.k_int > 0 else 0.0
            # the dot product and norm written out (a BLAS call may round differently on some
            # CPUs): the compiled follower, control.follow.batch, computes these same bits
            e_n = float(err[0] * normal[0] + err[1] * normal[1])
            self._integral = float(np.clip(self._integral + e_n * self.dt, -lim, lim))
        corr = cfg.k_pos * err + cfg.k_int * self._integral * normal
        norm = math.sqrt(corr[0] * corr[0] + corr[1] * corr[1])
        if norm > cfg.max_correction:
            corr *= cfg.max_correction / norm
        w_corr = float(np.clip(cfg.k_heading * float(wrap_angle(th_r - pose[2])),
                               -cfg.max_heading_correction, cfg.max_heading_correction))
        vx, vy = tw_ref[0] + corr[0], tw_ref[1] + corr[1]
        c, sn = math.cos(pose[2]), math.sin(pose[2])
        twist = np.array([c * vx + sn * vy, -sn * vx + c * vy, tw_ref[2] + w_corr])
        lam, mu = eta_from_twist(twist)
        return FollowerOutput(twist=twist, lam=lam, mu=float(mu), progress=float(s), finished=bool(finished))
