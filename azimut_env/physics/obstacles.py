"""Static obstacles of the robots' world (circles and convex polygons), as :class:`Obstacle`, and
their pymunk shapes: the collision shapes of obstacles and robots (robots collide with obstacles
only, never with each other) and the overlap query.

:class:`~azimut_env.physics.engine.AzimutPhysics` gives its robots collision shapes (the chassis
box; the wheels lie within its footprint up to 2 cm) only when there are obstacles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pymunk

from azimut_env.validation import check_fields

__all__ = ["Obstacle", "add_obstacle_shape", "add_robot_shape", "overlapping_shapes"]

#: Collision categories: robots collide with obstacles only, never with each other.
_CAT_ROBOT = 0b01
_CAT_OBSTACLE = 0b10


@dataclass(frozen=True)
class Obstacle:
    """A static obstacle: a circle (``radius`` > 0, centre ``(x, y)``) or a convex polygon
    (``vertices`` in world coordinates [m]).

    Attributes:
        x, y: centre of a circle [m]. radius: circle radius [m] (0 for a polygon).
        vertices: polygon vertices [(x, y), ...] [m] (empty for a circle).
    """

    x: float = 0.0
    y: float = 0.0
    radius: float = 0.0
    vertices: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        check_fields(self)
        if self.vertices:
            if len(self.vertices) < 3 or not np.all(np.isfinite(np.asarray(self.vertices, dtype=float))):
                raise ValueError("Obstacle polygon needs >= 3 finite vertices")
            object.__setattr__(self, "vertices", tuple((float(a), float(b)) for a, b in self.vertices))
        elif not (self.radius > 0 and math.isfinite(self.radius) and math.isfinite(self.x) and math.isfinite(self.y)):
            raise ValueError(f"Obstacle circle needs a finite centre and radius > 0, got {self}")

    @classmethod
    def coerce(cls, spec) -> Obstacle:
        """Accept an Obstacle, an ``(x, y, radius)`` triple, a dict of fields, or a vertex list."""
        if isinstance(spec, Obstacle):
            return spec
        if isinstance(spec, dict):
            return cls(**spec)
        arr = np.asarray(spec, dtype=float)
        if arr.shape == (3,):
            return cls(float(arr[0]), float(arr[1]), float(arr[2]))
        if arr.ndim == 2 and arr.shape[1] == 2:
            return cls(vertices=tuple(map(tuple, arr)))
        raise ValueError(f"cannot interpret {spec!r} as an obstacle: give (x, y, radius) or [(x, y), ...]")


def add_obstacle_shape(space: pymunk.Space, ob: Obstacle) -> pymunk.Shape:
    """Add obstacle ``ob`` to ``space`` as a static shape (friction 0.5, restitution 0.2); return it."""
    body = space.static_body
    shape = pymunk.Poly(body, ob.vertices) if ob.vertices else pymunk.Circle(body, ob.radius, (ob.x, ob.y))
    shape.filter = pymunk.ShapeFilter(categories=_CAT_OBSTACLE, mask=_CAT_ROBOT)
    shape.friction = 0.5
    shape.elasticity = 0.2
    space.add(shape)
    return shape


def add_robot_shape(space: pymunk.Space, body: pymunk.Body, length: float, width: float) -> None:
    """Give a robot's body its collision shape: the chassis box ``length`` × ``width`` [m]."""
    box = pymunk.Poly.create_box(body, (length, width))
    box.filter = pymunk.ShapeFilter(categories=_CAT_ROBOT, mask=_CAT_OBSTACLE)
    box.friction = 0.5
    space.add(box)


def overlapping_shapes(space: pymunk.Space, body: pymunk.Body, shapes: list[pymunk.Shape]) -> list[int]:
    """Indices in ``shapes`` of those that overlap ``body``'s shapes now."""
    hits = set()
    for own in body.shapes:
        for info in space.shape_query(own):
            if info.shape in shapes:
                hits.add(shapes.index(info.shape))
    return sorted(hits)
