"""Path follower: a :class:`~azimut_env.tracks.Track` and the robot's pose -> a chassis twist target.

The same follower feeds every controller (the ICR controller through (λ_d, μ_d), the twist
baseline through ξ̇_d), so a comparison isolates how the wheels are coordinated.

Per step, with the pose (x, y, θ) in the world:

1. progress s = the nearest reference pose (``Track.project``, windowed around the last s, so it
   is continuous and waits for the robot when it stops);
2. feed-forward: the reference world twist at s + max(v_ref·τ, d_min), the preview shrinking
   to d_min before a sharp corner, and the speed capped so the robot can slow down for it (``Track.reference_twist``; τ is a
   short preview that compensates the controllers' lag);
3. feedback on the pose error, position and heading separately (the robot is omnidirectional, so
   the heading follows its own profile, independent of the path direction):
   v = v_ref + k_p (p_ref − p) and ω = θ̇_ref + k_θ wrap(θ_ref − θ), with |k_p e| capped;
4. the world twist is rotated into the chassis frame; ``eta_from_twist`` gives (λ_d, μ_d), using
   ξ̇ = μ (v, −u, w) (§2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from azimut_env.tracks import Track, wrap_angle
from estimation.hrep import eta_from_twist

__all__ = ["PathFollowerConfig", "PathFollower", "FollowerOutput"]


@dataclass(frozen=True)
class PathFollowerConfig:
    """Gains of the path follower.

    Attributes:
        k_pos: position error gain [1/s].
        k_heading: heading error gain [1/s].
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
        corner_speed: speed floor at the corner itself [m/s].
        speed_scale: multiplies the track's speed profile [-] (1: the track's nominal speed).
    """

    k_pos: float = 3.0
    k_heading: float = 3.0
    max_correction: float = 0.3
    max_heading_correction: float = 0.6
    preview: float = 0.1
    preview_min: float = 0.001
    corner_angle: float = 0.35
    corner_decel: float = 1.0
    corner_window: float = 1.0
    corner_speed: float = 0.02
    speed_scale: float = 1.0

    def __post_init__(self) -> None:
        for name in ("k_pos", "k_heading", "max_correction", "max_heading_correction", "speed_scale",
                     "corner_angle", "corner_decel", "corner_window", "corner_speed"):
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
    """

    twist: np.ndarray
    lam: np.ndarray
    mu: float
    progress: float
    finished: bool


class PathFollower:
    """Stateful (only the progress hint) path follower; see the module docstring."""

    def __init__(self, track: Track, config: PathFollowerConfig | None = None) -> None:
        if not isinstance(track, Track):
            raise ValueError(f"track must be an azimut_env.tracks.Track, got {type(track).__name__}")
        self.track = track
        self.config = config or PathFollowerConfig()
        self.progress: float | None = None

    def reset(self, progress: float | None = None) -> None:
        """Forget the progress (the next step searches the whole track unless given)."""
        self.progress = progress

    def _distance_to_corner(self, s: float) -> float | None:
        """Progress [m] from s to the first sharp turn of the path direction within the window."""
        tr, cfg = self.track, self.config
        ahead = s + np.linspace(0.0, cfg.corner_window, max(2, int(cfg.corner_window / 0.01) + 1))
        if not tr.closed:
            ahead = ahead[ahead <= tr.length]
        psi = np.asarray(tr.tangent_at(ahead))
        turned = np.abs(wrap_angle(np.diff(psi))) > 0.5 * cfg.corner_angle  # a jump within 1 cm: a corner
        if not np.any(turned):
            return None
        return float(ahead[int(np.argmax(turned))] - s)

    def step(self, pose) -> FollowerOutput:
        """The twist target for the robot at ``pose`` = (x, y, θ) [m, m, rad] in the world."""
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise ValueError(f"pose must be a finite (3,) array, got {pose!r}")
        cfg, tr = self.config, self.track
        s = tr.project(pose, s_hint=self.progress)
        self.progress = s
        finished = tr.finished(s)
        x_r, y_r, th_r, v_r = tr.sample(s)
        v_r *= cfg.speed_scale
        s_ff = s + max(v_r * cfg.preview, cfg.preview_min)
        if not tr.closed:
            s_ff = min(s_ff, tr.length)
        if abs(float(tr.tangent_at(s_ff) - tr.tangent_at(s))) > cfg.corner_angle:
            s_ff = min(s + cfg.preview_min, tr.length) if not tr.closed else s + cfg.preview_min
        v_ff = float(tr.sample(s_ff)[3]) * cfg.speed_scale
        d_corner = self._distance_to_corner(s)
        if d_corner is not None:
            v_ff = min(v_ff, math.sqrt(2.0 * cfg.corner_decel * d_corner) + cfg.corner_speed)
        tw_ref = tr.reference_twist(s_ff, speed=v_ff)
        if finished:
            tw_ref = np.zeros(3)
        err = np.array([x_r - pose[0], y_r - pose[1]])
        corr = cfg.k_pos * err
        norm = float(np.linalg.norm(corr))
        if norm > cfg.max_correction:
            corr *= cfg.max_correction / norm
        w_corr = float(np.clip(cfg.k_heading * float(wrap_angle(th_r - pose[2])),
                               -cfg.max_heading_correction, cfg.max_heading_correction))
        vx, vy = tw_ref[0] + corr[0], tw_ref[1] + corr[1]
        c, sn = math.cos(pose[2]), math.sin(pose[2])
        twist = np.array([c * vx + sn * vy, -sn * vx + c * vy, tw_ref[2] + w_corr])
        lam, mu = eta_from_twist(twist)
        return FollowerOutput(twist=twist, lam=lam, mu=float(mu), progress=float(s), finished=bool(finished))
