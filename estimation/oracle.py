"""ORACLE: the true orthogonal projection of q onto the constraining surface (the yardstick).

Not a practical estimator: it searches a dense grid of Λ exhaustively, in joint space, then
refines the best grid points, every steering axis ŝ_k and every IT starting point with the same
local descent as IT (:func:`estimation.it._descend`), and keeps the closest result. It is what any
estimator could at best achieve for the metric of eq. (28)–(29).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from estimation.geometry import RobotGeometry
from estimation.it import _descend, _starting_points, _workspace
from estimation.kinematics import _steering_dist2, _wrap_half_pi, steering_from_lambda
from estimation.validation import check_fields

__all__ = ["OracleParams", "oracle_grid", "oracle_kernel_batch"]


@dataclass(frozen=True)
class OracleParams:
    """Search density of ORACLE.

    Attributes:
        grid_points: points of the Fibonacci grid on the hemisphere (spacing about
            sqrt(2π / grid_points) rad).
        ring_radii: radii [rad] of extra rings of points around each steering axis ŝ_k, where F
            turns fast (β_k sweeps π around the axis).
        ring_points: points per ring.
        refine: number of best grid points refined by local descent.
    """

    grid_points: int = 20000
    ring_radii: tuple[float, ...] = (1e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1)
    ring_points: int = 72
    refine: int = 12

    def __post_init__(self) -> None:
        check_fields(self)
        for name, low in (("grid_points", 2), ("ring_points", 0), ("refine", 1)):
            value = getattr(self, name)
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"OracleParams.{name} must be an integer, got {value!r}")
            if not low <= value <= 10_000_000:
                raise ValueError(f"OracleParams.{name} must be in [{low}, 1e7], got {value}")
        radii = np.asarray(self.ring_radii)
        if radii.dtype.kind not in "iuf" or radii.ndim != 1 or not np.all(np.isfinite(radii) & (radii > 0)):
            raise ValueError(f"OracleParams.ring_radii must be finite radii > 0 [rad], got {self.ring_radii!r}")


def oracle_grid(geom: RobotGeometry, params: OracleParams = OracleParams()) -> np.ndarray:
    """Dense search grid of Λ: a Fibonacci hemisphere plus rings around each steering axis."""
    m = int(params.grid_points)
    i = np.arange(m) + 0.5
    w = 1.0 - i / m  # uniform in w ∈ ]0, 1[: uniform area on the hemisphere
    rho = np.sqrt(1 - w**2)
    phi = math.pi * (3 - math.sqrt(5)) * i
    pts = [np.stack([rho * np.cos(phi), rho * np.sin(phi), w], axis=1)]
    t = 2 * math.pi * np.arange(params.ring_points) / params.ring_points
    for s in geom.s_unit:
        e1 = np.cross(s, [0.0, 0.0, 1.0] if abs(s[2]) < 0.9 else [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(s, e1)
        for rad in params.ring_radii:
            ring = (np.cos(rad) * s[None, :]
                    + np.sin(rad) * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2))
            pts.append(ring)
    return np.ascontiguousarray(np.concatenate(pts, axis=0))


@njit(cache=True)
def oracle_kernel_batch(q, E, P, steer_max, grid, grid_beta, s_unit, refine, lam_out, d2_out, periodic=False):
    n = q.shape[1]
    m = grid.shape[0]
    best_idx = np.empty(refine, dtype=np.int64)
    best_val = np.empty(refine)
    m_max = n * (n - 1) // 2
    starts, start_d2, start_beta, cw, grad, lam, lam_t, beta_cur, beta_t, _, _ = _workspace(n)
    for p in range(q.shape[0]):
        qp = q[p]
        # exhaustive search of the grid, keeping the `refine` closest points
        cnt = 0
        for g in range(m):
            d2 = 0.0
            for k in range(n):
                diff = qp[k] - grid_beta[g, k]
                if periodic:
                    diff = _wrap_half_pi(diff)
                d2 += diff * diff
            if cnt < refine or d2 < best_val[cnt - 1]:
                pos = cnt if cnt < refine else refine - 1
                while pos > 0 and best_val[pos - 1] > d2:
                    best_val[pos] = best_val[pos - 1]
                    best_idx[pos] = best_idx[pos - 1]
                    pos -= 1
                best_val[pos] = d2
                best_idx[pos] = g
                if cnt < refine:
                    cnt += 1
        best = np.inf
        n_starts = _starting_points(qp, E, P, steer_max, m_max, starts, start_d2, start_beta, cw, lam, beta_t,
                                    periodic)
        n_cand = cnt + n + n_starts
        for c in range(n_cand):
            if c < cnt:
                for i in range(3):
                    lam[i] = grid[best_idx[c], i]
            elif c < cnt + n:
                for i in range(3):
                    lam[i] = s_unit[c - cnt, i]
            else:
                for i in range(3):
                    lam[i] = starts[c - cnt - n, i]
            d2 = _steering_dist2(lam, qp, E, P, steer_max, beta_cur, periodic)
            d2, _, _ = _descend(qp, E, P, steer_max, lam, d2, beta_cur, 1e-12, 200, 1.0 / 2**20, grad, lam_t, beta_t,
                                True, periodic)
            if d2 < best:
                best = d2
                lam_out[p, 0] = lam[0]
                lam_out[p, 1] = lam[1]
                lam_out[p, 2] = lam[2]
        d2_out[p] = best


def oracle_tables(geom: RobotGeometry, params: OracleParams = OracleParams()) -> tuple[np.ndarray, np.ndarray]:
    """The grid and its steering configurations S(grid), (M, 3) and (M, n)."""
    grid = oracle_grid(geom, params)
    return grid, np.ascontiguousarray(steering_from_lambda(grid, geom))
