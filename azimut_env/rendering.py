"""Top-down rendering of :class:`~azimut_env.env.AzimutEnv` with pygame (imported lazily).

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

from .physics_layout import RS_POSE, RS_TWIST_BODY, WS

__all__ = ["Renderer"]

_SIZE = 640


class Renderer:
    """Draws an env's current state; ``draw(env)`` returns an (H, W, 3) uint8 array for
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

    def _fit_view(self, env) -> None:
        track = env.track
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

    def draw(self, env, robot: int = 0):
        """Draw robot ``robot`` of ``env`` (its physics, track, trail and estimated ICR)."""
        pg = self.pygame
        self._fit_view(env)
        surf = self.surface
        surf.fill((250, 250, 250))
        track = env.track
        pts = [self._px(p) for p in track.xy[:: max(1, len(track.xy) // 400)]]
        if len(pts) > 1:
            pg.draw.lines(surf, (180, 180, 180), track.closed, pts, 3)
        phys = env.physics
        for ob in phys.obstacles:
            if ob.vertices:
                pg.draw.polygon(surf, (90, 90, 90), [self._px(v) for v in ob.vertices])
            else:
                pg.draw.circle(surf, (90, 90, 90), self._px((ob.x, ob.y)), max(1, int(ob.radius * self._scale)))
        if len(env._trail) > 1:
            pg.draw.lines(surf, (60, 120, 220), False, [self._px(p) for p in env._trail[-1000:]], 2)
        x, y, th = phys.summary[robot, RS_POSE]
        c, s = math.cos(th), math.sin(th)

        def world(p):
            return (x + c * p[0] - s * p[1], y + s * p[0] + c * p[1])

        L, W = env.params.chassis.length / 2, env.params.chassis.width / 2
        pg.draw.polygon(surf, (200, 200, 215), [self._px(world(p)) for p in ((L, W), (-L, W), (-L, -W), (L, -W))])
        pg.draw.polygon(surf, (60, 60, 80), [self._px(world(p)) for p in ((L, W), (-L, W), (-L, -W), (L, -W))], 2)
        pg.draw.line(surf, (60, 60, 80), self._px(world((0, 0))), self._px(world((L, 0))), 2)
        g = env.geometry
        beta = phys.wheel_summary[robot, :, WS.BETA]
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
        lam = env._lam_hat
        if abs(lam[2]) > 1e-3:
            icr = world((lam[0] / lam[2], lam[1] / lam[2]))
            if abs(icr[0]) < 1e4 and abs(icr[1]) < 1e4:
                pg.draw.circle(surf, (220, 30, 30), self._px(icr), 5)
        tw = phys.summary[robot, RS_TWIST_BODY]
        if abs(tw[2]) > 1e-3:
            icr = world((-tw[1] / tw[2], tw[0] / tw[2]))
            if abs(icr[0]) < 1e4 and abs(icr[1]) < 1e4:
                pg.draw.circle(surf, (30, 170, 60), self._px(icr), 8, 2)
        if self.mode == "human":
            if self.window is None:
                pg.display.init()  # display only: pygame.init() would also open audio
                self.window = pg.display.set_mode((self.size, self.size))
                pg.display.set_caption("Azimut-v1")
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
