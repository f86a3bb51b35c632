"""The three estimators of §3.2 that work in the operational space: NE, LS and NS.

Each is one function over a batch q (N, n), serving single points and batches alike: numba
kernels for NE and LS, numpy's batched LAPACK SVD for NS.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimation.kinematics import propulsion_circle_normals

__all__ = ["ne_kernel_batch", "ls_kernel_batch", "ns_batch"]


@njit(cache=True, inline="always")
def _circle_normal(q_k: float, E, P, k: int, c):
    """c = s⊥1,k(q_k) = sin q (a − l) − cos q a⊥, normal of propulsion axis k's great circle."""
    sb = math.sin(q_k)
    cb = math.cos(q_k)
    for i in range(3):
        c[i] = sb * E[k, i] - cb * P[k, i]


@njit(cache=True)
def ne_kernel_batch(q, E, P, lam_out):
    """NE, §3.2.1: the intersection of wheel 1's and wheel 2's propulsion axes, eq. (8).

    If they are collinear (null cross product), wheel 2 is replaced by wheel 3, and so on; the
    other wheels are ignored."""
    n = q.shape[1]
    c1 = np.empty(3)
    ck = np.empty(3)
    for p in range(q.shape[0]):
        _circle_normal(q[p, 0], E, P, 0, c1)
        found = False
        first = 0
        for k in range(1, n):
            _circle_normal(q[p, k], E, P, k, ck)
            x = c1[1] * ck[2] - c1[2] * ck[1]
            y = c1[2] * ck[0] - c1[0] * ck[2]
            z = c1[0] * ck[1] - c1[1] * ck[0]
            nrm = math.sqrt(x * x + y * y + z * z)
            if nrm > 1e-12:
                lam_out[p, 0] = x / nrm
                lam_out[p, 1] = y / nrm
                lam_out[p, 2] = z / nrm
                found = True
                break
        if not found:
            # Every other axis coincides with wheel 1's (impossible for a valid geometry with
            # finite angles); any point of that line will do: its point at infinity.
            lam_out[p, 0] = -P[first, 0] * math.sin(q[p, 0]) + E[first, 0] * math.cos(q[p, 0])
            lam_out[p, 1] = -P[first, 1] * math.sin(q[p, 0]) + E[first, 1] * math.cos(q[p, 0])
            lam_out[p, 2] = 0.0
            nrm = math.sqrt(lam_out[p, 0] ** 2 + lam_out[p, 1] ** 2)
            lam_out[p, 0] /= nrm
            lam_out[p, 1] /= nrm


@njit(cache=True)
def ls_kernel_batch(q, alpha, axis_xy, lam_out):
    """LS, §3.2.2: least-squares intersection of the propulsion axes in R², eq. (22)–(26).

    Minimising ‖A X − B‖² of eq. (23) over the free parameters p_k first leaves the sum of squared
    distances from (x, y) to each line, whose normal equations are the 2×2 system
    ``M (x, y) = r`` with ``M = Σ n_k n_kᵀ``, ``r = Σ n_k n_kᵀ A_k`` and n_k = (sin γ_k, −cos γ_k).
    This is the same least-squares solution as solving (23) with LAPACK, without the
    (2n × (2+n)) matrix. The ICR is then mapped to Λ with eq. (5), in homogeneous form
    (adj(M) r, det M) so that nearly parallel axes give a point near the equator.

    Degenerate case (A singular): every line parallel to direction γ, so the ICR is the point at
    infinity (cos γ, sin γ, 0): γ = 0 gives λ = (1, 0, 0) and γ = π/2 gives λ = (0, 1, 0). (The
    paper's text states these two the other way round; F confirms this order.)
    """
    n = q.shape[1]
    for p in range(q.shape[0]):
        m11 = 0.0
        m12 = 0.0
        m22 = 0.0
        r1 = 0.0
        r2 = 0.0
        for k in range(n):
            g = alpha[k] + q[p, k]
            nx = math.sin(g)
            ny = -math.cos(g)
            proj = nx * axis_xy[k, 0] + ny * axis_xy[k, 1]
            m11 += nx * nx
            m12 += nx * ny
            m22 += ny * ny
            r1 += nx * proj
            r2 += ny * proj
        det = m11 * m22 - m12 * m12
        hx = m22 * r1 - m12 * r2
        hy = m11 * r2 - m12 * r1
        # det = Σ_{i<j} sin²(γ_i − γ_j) (Cauchy–Binet): zero iff every line is parallel.
        if det > 1e-14 * (m11 + m22) ** 2:
            nrm = math.sqrt(hx * hx + hy * hy + det * det)
            lam_out[p, 0] = hx / nrm
            lam_out[p, 1] = hy / nrm
            lam_out[p, 2] = det / nrm
        else:
            g = alpha[0] + q[p, 0]
            lam_out[p, 0] = math.cos(g)
            lam_out[p, 1] = math.sin(g)
            lam_out[p, 2] = 0.0


def ns_batch(q: np.ndarray, geom) -> np.ndarray:
    """NS, §3.2.3: λ in the null space of S, whose rows are s⊥1,k(q_k)ᵀ, eq. (27), via the SVD
    (LAPACK, through numpy's batched ``linalg.svd``): the right singular vector of the smallest
    singular value. q is (N, n); returns (N, 3) unit vectors (sign not normalised)."""
    S = propulsion_circle_normals(q, geom)  # (N, n, 3)
    _, _, vt = np.linalg.svd(S, full_matrices=False)
    return np.ascontiguousarray(vt[:, 2, :])
