"""Simple polygons for obstacles: the simplicity check and the convex decomposition.

pymunk's polygon shapes are convex (a ``pymunk.Poly`` of concave vertices is their convex hull),
so a concave polygon is split into convex parts whose union is the polygon: triangulated by ear
clipping (Meisters, "Polygons have ears", American Mathematical Monthly 82(6), 1975; O'Rourke,
*Computational Geometry in C*, 2nd ed., 1998, §1.6), then triangles merged across their diagonals
while the union stays convex (Hertel and Mehlhorn, "Fast triangulation of simple polygons",
FCT 1983: at most four times the fewest convex parts), checked to cover the polygon's area.
pymunk's ``autogeometry.convex_decomposition`` was used before: Chipmunk's C code crashed the
process (a segmentation fault) on some simple polygons with collinear or nearly touching
vertices. A self-intersecting or degenerate (zero-area, repeated-vertex, near-repeated-vertex)
vertex list is refused.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["signed_area", "convex_parts"]


#: the shortest edge of an obstacle polygon, relative to its size (its largest distance from the
#: vertices' mean): a shorter one is a repeated vertex in all but rounding
MIN_EDGE = 1e-9


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
        v = _cross(a, b, c)
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
    winding): the polygon itself if it is convex, else its ear-clipping triangles merged while
    convex (the module docstring), checked to cover the polygon's area (relative 1e−9). ``ValueError`` for a
    self-intersecting or zero-area polygon."""
    v = np.asarray(vertices, dtype=np.float64)
    _check_simple(v)
    area = signed_area(v)
    scale = float(np.max(np.abs(v - v.mean(axis=0)))) or 1.0
    edges = np.hypot(*(np.roll(v, -1, axis=0) - v).T)
    if float(edges.min()) <= MIN_EDGE * scale:
        k = int(np.argmin(edges))
        raise ValueError(f"Obstacle polygon edge {k} is {float(edges[k]):.3g} m long, shorter than {MIN_EDGE:g} of the "
                         "polygon's size: merge those vertices")
    if abs(area) <= 1e-12 * scale**2:
        raise ValueError("Obstacle polygon has zero area (collinear vertices)")
    ccw = v if area > 0 else v[::-1]
    if _is_convex(ccw):
        return (tuple(map(tuple, ccw.tolist())),)
    pts = [(float(x), float(y)) for x, y in ccw.tolist()]
    parts = [tuple(pts[i] for i in part) for part in _merge_convex(pts, _ear_clip(pts))]
    covered = sum(abs(signed_area(np.array(p))) for p in parts if len(p) >= 3)
    if not math.isclose(covered, abs(area), rel_tol=1e-9):
        raise ValueError(f"Obstacle polygon: its convex decomposition covers {covered:.6g} m² of its "
                         f"{abs(area):.6g} m²; split it into convex obstacles yourself")
    return tuple(p for p in parts if len(p) >= 3)


def _cross(o, a, b) -> float:
    """z of (a − o) × (b − o): > 0 when o, a, b turn left."""
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _ear_clip(pts: list) -> list[list[int]]:
    """Triangles (counter-clockwise index triples) whose union is the simple counter-clockwise
    polygon ``pts``: a vertex that turns left and whose triangle with its neighbours holds no other
    remaining vertex (on its boundary included) is an ear and is cut off; a vertex collinear with
    its neighbours is dropped (the region is unchanged). ``ValueError`` if no ear is left (only
    for numerically degenerate input: every simple polygon has two ears)."""
    idx, tris = list(range(len(pts))), []
    while len(idx) > 3:
        m = len(idx)
        for k in range(m):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % m]
            a, b, c = pts[i0], pts[i1], pts[i2]
            turn = _cross(a, b, c)
            if turn == 0.0:
                del idx[k]
                break
            if turn < 0.0:
                continue
            if any(_cross(a, b, pts[j]) >= 0.0 and _cross(b, c, pts[j]) >= 0.0 and _cross(c, a, pts[j]) >= 0.0
                   for j in idx if j not in (i0, i1, i2)):
                continue
            tris.append([i0, i1, i2])
            del idx[k]
            break
        else:
            raise ValueError("Obstacle polygon: no ear left to cut (numerically degenerate vertices); split it into "
                             "convex obstacles yourself")
    if _cross(pts[idx[0]], pts[idx[1]], pts[idx[2]]) > 0.0:
        tris.append(idx)
    return tris


def _merge_convex(pts: list, parts: list[list[int]]) -> list[list[int]]:
    """Hertel–Mehlhorn: merge two parts across a shared edge (a diagonal) while their union stays
    convex (every vertex turning left or straight), until no pair merges."""
    parts = [list(p) for p in parts]
    merged = True
    while merged:
        merged = False
        for x in range(len(parts)):
            edges = {(parts[x][k], parts[x][(k + 1) % len(parts[x])]): k for k in range(len(parts[x]))}
            for y in range(x + 1, len(parts)):
                q = parts[y]
                for k in range(len(q)):
                    v, u = q[k], q[(k + 1) % len(q)]  # y has v → u, so x has u → v
                    if (u, v) not in edges:
                        continue
                    kx = edges[(u, v)]
                    px = parts[x][kx + 1:] + parts[x][:kx + 1]  # v ... u
                    qy = q[k + 1:] + q[:k + 1]  # u ... v
                    cand = px + qy[1:-1]
                    if all(_cross(pts[cand[i - 1]], pts[cand[i]], pts[cand[(i + 1) % len(cand)]]) >= 0.0
                           for i in range(len(cand))):
                        parts[x] = cand
                        del parts[y]
                        merged = True
                        break
                if merged:
                    break
            if merged:
                break
    return parts
