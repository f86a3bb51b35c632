"""Static obstacles of the robots' world (circles and convex polygons), as :class:`Obstacle`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Obstacle"]


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
