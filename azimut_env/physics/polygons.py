"""Simple polygons for obstacles: the simplicity check and the convex decomposition.

pymunk's polygon shapes are convex (a ``pymunk.Poly`` of concave vertices is their convex hull),
so a concave polygon is split into convex parts whose union is the polygon: pymunk's
``autogeometry.convex_decomposition`` (the approximate convex decomposition of Lien and Amato,
"Approximate convex decomposition of polygons", Computational Geometry 35(1–2), 2006) at
tolerance 0, checked to cover the polygon's area. A self-intersecting or degenerate (zero-area,
repeated-vertex) vertex list is refused.
"""

from __future__ import annotations

import math

import numpy as np
from pymunk import autogeometry

__all__ = ["signed_area", "convex_parts"]


def signed_area(v: np.ndarray) -> float:
    """Signed area [m²] of the closed polygon ``v`` (m, 2) (shoelace formula; > 0 counter-clockwise)."""
    x, y = v[:, 0], v[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _is_convex(v: np.ndarray) -> bool:
    """True if the counter-clockwise polygon ``v`` (m, 2) turns left (or goes straight) at every vertex."""
    d = np.roll(v, -1, axis=0) - v
    cross = d[:, 0] * np.roll(d, -1, axis=0)[:, 1] - d[:, 1] * np.roll(d, -1, axis=0)[:, 0]
    return bool(np.all(cross >= -1e-12 * float(np.max(np.abs(v))) ** 2))


def _segments_cross(p1, p2, q1, q2) -> bool:
    """True if the closed segments p1p2 and q1q2 share a point."""
    def orient(a, b, c):
        v = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        return (v > 0) - (v < 0)

    def on(a, b, c):  # c on segment ab, given collinear
        return min(a[0], b[0]) <= c[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= c[1] <= max(a[1], b[1])

    o1, o2, o3, o4 = orient(p1, p2, q1), orient(p1, p2, q2), orient(q1, q2, p1), orient(q1, q2, p2)
    if o1 != o2 and o3 != o4:
        return True
    return (o1 == 0 and on(p1, p2, q1)) or (o2 == 0 and on(p1, p2, q2)) or (o3 == 0 and on(q1, q2, p1)) \
        or (o4 == 0 and on(q1, q2, p2))


def _check_simple(v: np.ndarray) -> None:
    """``ValueError`` unless the closed polygon ``v`` (m, 2) is simple: no two edges meet except
    neighbours at their shared vertex (O(m²), obstacles have few vertices)."""
    m = len(v)
    pts = [tuple(map(float, p)) for p in v]
    for i in range(m):
        for j in range(i + 1, m):
            if j == i + 1 or (i == 0 and j == m - 1):
                continue  # neighbours share a vertex (a repeated vertex is caught by the area/edges below)
            if _segments_cross(pts[i], pts[(i + 1) % m], pts[j], pts[(j + 1) % m]):
                raise ValueError(f"Obstacle polygon edges {i} and {j} intersect: give a simple polygon (its "
                                 "boundary must not cross itself)")
    if np.any(np.all(np.roll(v, -1, axis=0) == v, axis=1)):
        raise ValueError("Obstacle polygon repeats a vertex (a zero-length edge)")


def convex_parts(vertices) -> tuple[tuple[tuple[float, float], ...], ...]:
    """Convex polygons whose union is the simple polygon ``vertices`` [(x, y), ...] (either
    winding): the polygon itself if it is convex, else pymunk's convex decomposition at
    tolerance 0, checked to cover the polygon's area (relative 1e−9). ``ValueError`` for a
    self-intersecting or zero-area polygon."""
    v = np.asarray(vertices, dtype=np.float64)
    _check_simple(v)
    area = signed_area(v)
    scale = float(np.max(np.abs(v - v.mean(axis=0)))) or 1.0
    if abs(area) <= 1e-12 * scale**2:
        raise ValueError("Obstacle polygon has zero area (collinear vertices)")
    ccw = v if area > 0 else v[::-1]
    if _is_convex(ccw):
        return (tuple(map(tuple, ccw.tolist())),)
    closed = [tuple(p) for p in ccw.tolist()] + [tuple(ccw[0].tolist())]
    parts = []
    for hull in autogeometry.convex_decomposition(closed, 0.0):
        pts = [(float(p[0]), float(p[1])) for p in hull]
        if len(pts) > 1 and pts[0] == pts[-1]:
            pts = pts[:-1]
        parts.append(tuple(pts))
    covered = sum(abs(signed_area(np.array(p))) for p in parts if len(p) >= 3)
    if not math.isclose(covered, abs(area), rel_tol=1e-9):
        raise ValueError(f"Obstacle polygon: its convex decomposition covers {covered:.6g} m² of its "
                         f"{abs(area):.6g} m²; split it into convex obstacles yourself")
    return tuple(p for p in parts if len(p) >= 3)
