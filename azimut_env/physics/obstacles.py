"""Static obstacles of the robots' world (circles and simple polygons, convex or not), as
:class:`Obstacle`, and their pymunk shapes: the collision shapes of obstacles (one per convex part
of a polygon, :mod:`azimut_env.physics.polygons`) and robots (robots collide with obstacles only,
never with each other) and the overlap query.

:class:`~azimut_env.physics.engine.AzimutPhysics` gives its robots collision shapes (the chassis
box; the wheels lie within its footprint up to 2 cm) only when there are obstacles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pymunk

from azimut_env.physics.polygons import convex_parts
from azimut_env.validation import check_fields, check_real_array, show

__all__ = ["Obstacle", "add_obstacle_shape", "add_robot_shape", "overlapping_shapes", "WORLD_REACH"]

#: the farthest an obstacle may reach from the origin [m]: far beyond the world a robot can reach
#: (``BlowUpLimits.position``, 1e4 m by default), near enough that areas and pymunk's collision
#: arithmetic stay exact to many digits (1e300 overflowed them)
WORLD_REACH = 1e6

#: Collision categories: robots collide with obstacles only, never with each other.
_CAT_ROBOT = 0b01
_CAT_OBSTACLE = 0b10


@dataclass(frozen=True)
class Obstacle:
    """A static obstacle: a circle (``radius`` > 0, centre ``(x, y)``) or a simple polygon,
    convex or not (``vertices`` in world coordinates [m], either winding).

    Attributes:
        x, y: centre of a circle [m]. radius: circle radius [m] (0 for a polygon).
        vertices: polygon vertices [(x, y), ...] [m] (empty for a circle).
        parts: the polygon's convex parts (:func:`convex_parts`; one for a convex polygon, none
            for a circle), the shapes the engine adds.
    """

    x: float = 0.0
    y: float = 0.0
    radius: float = 0.0
    vertices: tuple[tuple[float, float], ...] = ()
    parts: tuple[tuple[tuple[float, float], ...], ...] = field(init=False, repr=False, compare=False, default=())

    def __post_init__(self) -> None:
        check_fields(self)
        if len(self.vertices) if isinstance(self.vertices, (tuple, list, np.ndarray)) else self.vertices:
            v = check_real_array("Obstacle.vertices", self.vertices, (None, 2), finite=True)
            if len(v) < 3:
                raise ValueError("Obstacle polygon needs >= 3 finite vertices")
            if np.max(np.abs(v)) > WORLD_REACH:
                raise ValueError(f"Obstacle.vertices must lie within ±{WORLD_REACH:g} m, got {show(self.vertices)}")
            object.__setattr__(self, "vertices", tuple(map(tuple, v.tolist())))
            object.__setattr__(self, "parts", convex_parts(v))
        elif not (self.radius > 0 and math.isfinite(self.radius) and math.isfinite(self.x) and math.isfinite(self.y)):
            raise ValueError(f"Obstacle circle needs a finite centre and radius > 0, got {self}")
        elif max(abs(self.x), abs(self.y)) + self.radius > WORLD_REACH:
            raise ValueError(f"Obstacle circle must lie within ±{WORLD_REACH:g} m, got {self}")

    @classmethod
    def coerce(cls, spec) -> Obstacle:
        """Accept an Obstacle, an ``(x, y, radius)`` triple, a dict of fields, or a vertex list."""
        if isinstance(spec, Obstacle):
            return spec
        if isinstance(spec, dict):
            return cls(**spec)
        arr = check_real_array("obstacle", spec)
        if arr.shape == (3,):
            return cls(float(arr[0]), float(arr[1]), float(arr[2]))
        if arr.ndim == 2 and arr.shape[1] == 2:
            return cls(vertices=tuple(map(tuple, arr)))
        raise ValueError(f"cannot interpret {spec!r} as an obstacle: give (x, y, radius) or [(x, y), ...]")


def add_obstacle_shape(space: pymunk.Space, ob: Obstacle) -> tuple[pymunk.Shape, ...]:
    """Add obstacle ``ob`` to ``space`` as static shapes (friction 0.5, restitution 0.2): a circle,
    or one convex polygon per part of :attr:`Obstacle.parts` (a single ``pymunk.Poly`` is the
    convex hull of its vertices: a concave obstacle filled its notches). Return them."""
    body = space.static_body
    shapes = tuple(pymunk.Poly(body, part) for part in ob.parts) if ob.vertices else \
        (pymunk.Circle(body, ob.radius, (ob.x, ob.y)),)
    for shape in shapes:
        shape.filter = pymunk.ShapeFilter(categories=_CAT_OBSTACLE, mask=_CAT_ROBOT)
        shape.friction = 0.5
        shape.elasticity = 0.2
    space.add(*shapes)
    return shapes


def add_robot_shape(space: pymunk.Space, body: pymunk.Body, length: float, width: float) -> None:
    """Give a robot's body its collision shape: the chassis box ``length`` × ``width`` [m]."""
    box = pymunk.Poly.create_box(body, (length, width))
    box.filter = pymunk.ShapeFilter(categories=_CAT_ROBOT, mask=_CAT_OBSTACLE)
    box.friction = 0.5
    space.add(box)


def overlapping_shapes(space: pymunk.Space, body: pymunk.Body, shapes: list[tuple[pymunk.Shape, ...]]) -> list[int]:
    """Indices in ``shapes`` (each obstacle's shapes, :func:`add_obstacle_shape`) of the
    obstacles that overlap ``body``'s shapes now."""
    owner = {id(shape): k for k, group in enumerate(shapes) for shape in group}
    hits = set()
    for own in body.shapes:
        for info in space.shape_query(own):
            if id(info.shape) in owner:
                hits.add(owner[id(info.shape)])
    return sorted(hits)
