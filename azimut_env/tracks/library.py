"""The built-in tracks (:func:`make_track`): ``paper`` (spiral, circle, rounded square, after the
paper's Fig. 9), ``circle``, ``figure8``, ``square`` (sharp corners: stop and reconfigure), ``crab``
(translation at a fixed heading, rotation in place, translation), ``random`` (seeded smooth closed
curves).

To add one: write a builder returning a :class:`~azimut_env.tracks.Track` here, add it to
``_BUILDERS`` and its name to :data:`TRACK_NAMES` (the env, ``azimut eval`` and the CLIs take their
choices from it).
"""

from __future__ import annotations

import math

import numpy as np

from azimut_env.tracks.track import Track
from estimation.libm import atan2

__all__ = ["TRACK_NAMES", "make_track", "paper_track", "circle_track", "figure8_track", "square_track",
           "crab_track", "random_track"]

TRACK_NAMES = ("paper", "circle", "figure8", "square", "crab", "random")


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
    tang = np.unwrap(atan2(d[:, 1], d[:, 0]))
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
    th = np.unwrap(atan2(dx[:, 1], dx[:, 0]))
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
        th = np.unwrap(atan2(dxy[:, 1], dxy[:, 0])) + rng.uniform(-np.pi, np.pi)
    else:
        th = rng.uniform(-np.pi, np.pi) + rng.uniform(0, 0.8) * np.sin(2 * np.pi * ss / ss[-1] * rng.integers(1, 4)
                                                                       + rng.uniform(0, 2 * np.pi))
    speed = rng.uniform(0.3, 0.7)
    return Track("random", xy - xy[0], th, speed, closed=True)


_BUILDERS = {"paper": paper_track, "circle": circle_track, "figure8": figure8_track, "square": square_track,
             "crab": crab_track, "random": random_track}


def make_track(name: str, rng: np.random.Generator | None = None, **kwargs) -> Track:
    """A built-in track by name (see ``TRACK_NAMES``); ``random`` draws from ``rng``."""
    if name == "random":
        return random_track(rng=rng if rng is not None else np.random.default_rng(), **kwargs)
    if name not in _BUILDERS:
        raise ValueError(f"unknown track {name!r}; choose from {TRACK_NAMES} or pass a Track")
    return _BUILDERS[name](**kwargs)
