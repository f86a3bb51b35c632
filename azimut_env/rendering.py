"""Top-down rendering of one robot with pygame (imported lazily).

:meth:`Renderer.draw` takes what it draws as explicit inputs (the track, the robot's pose, twist
and steering angles, its estimated ICR, its trail, the obstacles, the chassis size and the wheel
geometry); both envs gather them in ``AzimutFrontEnd.render``. :class:`Trail` keeps the drawn
robot's recent positions.

The view shows the track (grey), the trail (blue), obstacles, the chassis, the wheels at their real
steering angles, each wheel's propulsion axis as a long line (if the axes concur, they meet at the
ICR), the estimated ICR λ̂ (red dot; off-screen when the motion is almost a translation) and the
true ICR (green ring).

Headless-safe: ``rgb_array`` draws on an off-screen surface and needs no display; ``human`` uses
SDL's dummy video driver when no display is available.
"""

from __future__ import annotations

import math
import os

import numpy as np

__all__ = ["Renderer", "Trail"]

_SIZE = 640


class Trail:
    """The recent chassis positions (x, y) [m] of the drawn robot: at most ``max_points``, the
    oldest half dropped when full."""

    def __init__(self, max_points: int = 2000) -> None:
        self.max_points = int(max_points)
        self.points: list[tuple[float, float]] = []

    def start(self, x: float, y: float) -> None:
        """A new episode: the trail is the starting position only."""
        self.points = [(float(x), float(y))]

    def add(self, x: float, y: float) -> None:
        self.points.append((float(x), float(y)))
        if len(self.points) > self.max_points:
            del self.points[: self.max_points // 2]


class Renderer:
    """Draws one robot on its track; :meth:`draw` returns an (H, W, 3) uint8 array for
    ``rgb_array`` and None for ``human``."""

    def __init__(self, render_mode: str, fps: int = 50, size: int = _SIZE) -> None:
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        if render_mode == "human" and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY") \
                and os.name != "nt":
            os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
        try:
            import pygame
        except ImportError as exc:  # pragma: no cover - depends on the installation
            from gymnasium.error import DependencyNotInstalled

            raise DependencyNotInstalled('pygame is not installed: pip install "azimut[render]"') from exc
        self.pygame = pygame
        self.mode = render_mode
        self.fps = fps
        self.size = size
        self.window = None
        self.clock = None
        self.surface = pygame.Surface((size, size))
        self._view_key = None
        self._scale = 1.0
        self._origin = np.zeros(2)

    def _fit_view(self, track) -> None:
        key = id(track)
        if key == self._view_key:
            return
        xy = track.xy
        lo, hi = xy.min(axis=0) - 1.0, xy.max(axis=0) + 1.0
        span = max(hi[0] - lo[0], hi[1] - lo[1])
        self._scale = self.size / span
        self._origin = (lo + hi) / 2 - span / 2
        self._view_key = key

    def _px(self, p) -> tuple[int, int]:
        x = (p[0] - self._origin[0]) * self._scale
        y = self.size - (p[1] - self._origin[1]) * self._scale
        return int(round(x)), int(round(y))

    def draw(self, track, pose, twist, beta, lam_hat, trail, obstacles, chassis, geometry):
        """Draw one robot.

        Args:
            track: its :class:`~azimut_env.tracks.Track`.
            pose: chassis pose (x, y, θ) [m, m, rad]. twist: chassis-frame twist (ẋ, ẏ, θ̇)
                (the true ICR). beta: (n,) true steering angles [rad].
            lam_hat: (3,) the estimated ICR λ̂. trail: sequence of (x, y) positions [m].
            obstacles: :class:`~azimut_env.physics.engine.Obstacle` sequence.
            chassis: ``ChassisParams`` (length, width [m]). geometry: ``RobotGeometry``.
        """
        pg = self.pygame
        self._fit_view(track)
        surf = self.surface
        surf.fill((250, 250, 250))
        pts = [self._px(p) for p in track.xy[:: max(1, len(track.xy) // 400)]]
        if len(pts) > 1:
            pg.draw.lines(surf, (180, 180, 180), track.closed, pts, 3)
        for ob in obstacles:
            if ob.vertices:
                pg.draw.polygon(surf, (90, 90, 90), [self._px(v) for v in ob.vertices])
            else:
                pg.draw.circle(surf, (90, 90, 90), self._px((ob.x, ob.y)), max(1, int(ob.radius * self._scale)))
        if len(trail) > 1:
            pg.draw.lines(surf, (60, 120, 220), False, [self._px(p) for p in trail[-1000:]], 2)
        x, y, th = (float(v) for v in pose)
        c, s = math.cos(th), math.sin(th)

        def world(p):
            return (x + c * p[0] - s * p[1], y + s * p[0] + c * p[1])

        L, W = chassis.length / 2, chassis.width / 2
        pg.draw.polygon(surf, (200, 200, 215), [self._px(world(p)) for p in ((L, W), (-L, W), (-L, -W), (L, -W))])
        pg.draw.polygon(surf, (60, 60, 80), [self._px(world(p)) for p in ((L, W), (-L, W), (-L, -W), (L, -W))], 2)
        pg.draw.line(surf, (60, 60, 80), self._px(world((0, 0))), self._px(world((L, 0))), 2)
        g = geometry
        reach = 4.0 * max(L, W) + 10.0
        for k in range(g.n):
            gam = th + g.alpha[k] + beta[k]
            a = world(g.axis_xy[k])
            p = (a[0] + g.b[k] * math.cos(gam), a[1] + g.b[k] * math.sin(gam))
            e = (math.cos(gam), math.sin(gam))
            d = (math.sin(gam), -math.cos(gam))
            # propulsion axis: the line through P_k along e_k
            pg.draw.line(surf, (230, 150, 60), self._px((p[0] - reach * e[0], p[1] - reach * e[1])),
                         self._px((p[0] + reach * e[0], p[1] + reach * e[1])), 1)
            r, hw = g.r[k], 0.025
            corners = [(p[0] + sx * r * d[0] + sy * hw * e[0], p[1] + sx * r * d[1] + sy * hw * e[1])
                       for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
            pg.draw.polygon(surf, (20, 20, 20), [self._px(q) for q in corners])
            pg.draw.line(surf, (20, 20, 20), self._px(a), self._px(p), 2)
        lam = lam_hat
        if abs(lam[2]) > 1e-3:
            icr = world((lam[0] / lam[2], lam[1] / lam[2]))
            if abs(icr[0]) < 1e4 and abs(icr[1]) < 1e4:
                pg.draw.circle(surf, (220, 30, 30), self._px(icr), 5)
        tw = twist
        if abs(tw[2]) > 1e-3:
            icr = world((-tw[1] / tw[2], tw[0] / tw[2]))
            if abs(icr[0]) < 1e4 and abs(icr[1]) < 1e4:
                pg.draw.circle(surf, (30, 170, 60), self._px(icr), 8, 2)
        if self.mode == "human":
            if self.window is None:
                pg.display.init()  # display only: pygame.init() would also open audio
                self.window = pg.display.set_mode((self.size, self.size))
                pg.display.set_caption("Azimut-v2")
                self.clock = pg.time.Clock()
            pg.event.pump()
            self.window.blit(surf, (0, 0))
            pg.display.flip()
            self.clock.tick(self.fps)
            return None
        return np.transpose(np.array(pg.surfarray.pixels3d(surf)), (1, 0, 2)).copy()

    def close(self) -> None:
        if self.window is not None:
            self.pygame.display.quit()
            self.window = None
