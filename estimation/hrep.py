"""The H representation of planar motion (§2): η = (λ, μ) with λ ∈ Λ = S² / (λ ~ −λ).

λ = (u, v, w) is the ICR as a unit vector: the gnomonic image of the ICR point (x, y) of the
chassis plane, eq. (5)–(6), with points at infinity (pure translations) on the equator w = 0.
μ is the motion around the ICR. The pair (λ, μ) and (−λ, −μ) is the same motion.

The chassis twist ξ̇ = (ẋ, ẏ, θ̇), in the chassis frame, is ``ξ̇ = μ (v, −u, w)``, so
``λ ∝ (−ẏ, ẋ, θ̇)`` and ``|μ| = ‖ξ̇‖``. The velocity of a chassis point p is the (x, y) part of
``μ λ × (p_x, p_y, 1)``.

All functions are batched first: a trailing axis of size 3 holds λ, leading axes are batch axes.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from estimation.libm import atan2

__all__ = [
    "normalize",
    "unit_and_norm",
    "canonical_lambda",
    "canonical_eta",
    "lambda_distance",
    "select_chart",
    "chart_params",
    "lambda_from_chart",
    "chart_tangents",
    "lambda_from_plane",
    "plane_from_lambda",
    "eta_from_twist",
    "twist_from_eta",
    "point_velocity",
    "sphere_angle",
    "slerp",
    "exp_map",
    "nearer_representative",
]

#: The charts of the atlas (§2.1, eq. (2)–(4) and circular permutations): chart c is the pair of
#: identified hemispheres λ_c ≠ 0, and its coordinates are the two other components in circular
#: order. Chart 2 (w) uses (u, v), chart 0 (u) uses (v, w), chart 1 (v) uses (w, u).
CHART_COORDS = np.array([[1, 2], [2, 0], [0, 1]])


def _check_last3(lam: np.ndarray, name: str = "lam") -> np.ndarray:
    lam = np.asarray(lam, dtype=np.float64)
    if lam.ndim == 0 or lam.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3), got {lam.shape}")
    if not np.all(np.isfinite(lam)):
        raise ValueError(f"{name} must be finite")
    return lam


def unit_and_norm(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x/‖x‖, ‖x‖) along the last axis of finite x, at any scale: each row is first scaled by the
    power of two 2^−e that brings its largest |component| into [0.5, 1) (exact, so the result is
    bit for bit that of the plain formula wherever the plain one neither overflows nor
    underflows); the plain ‖x‖ overflows to inf beyond ~1e154 (x/‖x‖ = 0) and underflows to 0
    below ~1e−162. Zero rows give unit 0 and norm 0; ‖x‖ itself may still overflow (inf)."""
    peak = np.max(np.abs(x), axis=-1, keepdims=True)
    _, e = np.frexp(peak)
    scaled = np.ldexp(x, -e)
    norm = np.linalg.norm(scaled, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", over="ignore"):
        unit = np.where(norm > 0, scaled / np.where(norm > 0, norm, 1.0), 0.0)
        return unit, np.ldexp(norm, e)[..., 0]


def normalize(lam: np.ndarray) -> np.ndarray:
    """Project non-zero vectors of R³ onto the unit sphere, at any scale (:func:`unit_and_norm`).
    Raises ValueError on a zero vector."""
    lam = _check_last3(lam)
    unit, norm = unit_and_norm(lam)
    if np.any(norm == 0):
        raise ValueError("cannot normalise a zero vector to a point of Λ")
    return unit


@njit(cache=True)
def _hemisphere_sign(lam0: float, lam1: float, lam2: float) -> float:
    """+1 or −1 so that sign·λ has w > 0, or w = 0 and u > 0, or w = u = 0 and v > 0."""
    key = lam2 if lam2 != 0.0 else (lam0 if lam0 != 0.0 else lam1)
    return -1.0 if key < 0 else 1.0


@njit(cache=True)
def _canonicalize_batch(lam) -> None:
    """In place, for (N, 3) rows: the hemisphere rule of :func:`canonical_lambda`."""
    for p in range(lam.shape[0]):
        if _hemisphere_sign(lam[p, 0], lam[p, 1], lam[p, 2]) < 0.0:
            lam[p, 0] = -lam[p, 0]
            lam[p, 1] = -lam[p, 1]
            lam[p, 2] = -lam[p, 2]


def canonical_lambda(lam: np.ndarray) -> np.ndarray:
    """The canonical representative of λ ∈ Λ: the unit vector of the antipodal pair with w > 0
    (ties on the equator broken by u > 0, then v > 0)."""
    lam = normalize(lam)
    flat = np.ascontiguousarray(lam.reshape(-1, 3))  # normalize returned a new array
    _canonicalize_batch(flat)
    return flat.reshape(lam.shape)


@njit(cache=True)
def _canonical_eta_sign(lam0: float, lam1: float, lam2: float, mu: float, mu_tol: float) -> float:
    """+1 or −1 so that (sign·λ, sign·μ) is canonical: μ > 0 where |μ| > mu_tol, else the
    hemisphere rule of :func:`canonical_lambda`."""
    if abs(mu) > mu_tol:
        return -1.0 if mu < 0 else 1.0
    return _hemisphere_sign(lam0, lam1, lam2)


@njit(cache=True)
def _canonical_eta_batch(lam, mu, mu_tol: float) -> None:
    for p in range(lam.shape[0]):
        sign = _canonical_eta_sign(lam[p, 0], lam[p, 1], lam[p, 2], mu[p], mu_tol)
        mu[p] *= sign
        for i in range(3):
            lam[p, i] *= sign


def canonical_eta(lam: np.ndarray, mu: np.ndarray, mu_tol: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Canonical representative of η = (λ, μ) ≡ (−λ, −μ).

    Where |μ| > ``mu_tol`` the sign is chosen so that μ > 0: λ is then the direction of the twist
    (−ẏ, ẋ, θ̇)/‖ξ̇‖, continuous along any motion that does not stop. Elsewhere λ takes the
    hemisphere rule of :func:`canonical_lambda`.
    """
    lam = normalize(lam)
    mu = np.asarray(mu, dtype=np.float64)
    batch = lam.shape[:-1]
    lam2 = np.ascontiguousarray(lam.reshape(-1, 3))
    mu2 = np.ascontiguousarray(np.broadcast_to(mu, batch).reshape(-1)).copy()
    _canonical_eta_batch(lam2, mu2, float(mu_tol))
    return lam2.reshape(batch + (3,)), mu2.reshape(batch)


def lambda_distance(lam1: np.ndarray, lam2: np.ndarray) -> np.ndarray:
    """Angle [rad] between two points of Λ, in [0, π/2] (antipodes identified)."""
    lam1, lam2 = normalize(lam1), normalize(lam2)
    c = np.abs(np.sum(lam1 * lam2, axis=-1))
    s = np.linalg.norm(np.cross(lam1, lam2), axis=-1)
    return atan2(s, c)


def select_chart(lam: np.ndarray) -> np.ndarray:
    """Chart index c ∈ {0: u, 1: v, 2: w} whose domain centre is closest to λ (largest |λ_c|)."""
    lam = _check_last3(lam)
    return np.argmax(np.abs(lam), axis=-1)


def chart_params(lam: np.ndarray, chart: np.ndarray | int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Chart coordinates φ_c(λ), eq. (3): the two non-chart components of the representative
    with λ_c > 0. Returns ``(chart, params)`` with params of shape (..., 2)."""
    lam = normalize(lam)
    chart = select_chart(lam) if chart is None else np.broadcast_to(np.asarray(chart), lam.shape[:-1])
    lam_c = np.take_along_axis(lam, chart[..., None], axis=-1)
    lam = lam * np.where(lam_c < 0, -1.0, 1.0)
    idx = CHART_COORDS[chart]
    return chart, np.take_along_axis(lam, idx, axis=-1)


def lambda_from_chart(chart: np.ndarray | int, params: np.ndarray) -> np.ndarray:
    """Parametrisation φ_c⁻¹, eq. (4): λ with λ_c = sqrt(1 − p₁² − p₂²) ≥ 0."""
    params = np.asarray(params, dtype=np.float64)
    chart = np.broadcast_to(np.asarray(chart), params.shape[:-1])
    rho2 = np.sum(params**2, axis=-1)
    if np.any(rho2 > 1 + 1e-12):
        raise ValueError("chart parameters outside the unit disc are not on the sphere")
    lam = np.zeros(params.shape[:-1] + (3,))
    idx = CHART_COORDS[chart]
    np.put_along_axis(lam, idx, params, axis=-1)
    np.put_along_axis(lam, chart[..., None], np.sqrt(np.clip(1 - rho2, 0, None))[..., None], axis=-1)
    return lam


def chart_tangents(lam: np.ndarray, chart: np.ndarray | int | None = None) -> np.ndarray:
    """∂λ/∂p for the chart's two coordinates, eq. (19): ``e_i − (λ_i / λ_c) e_c``.

    Returns shape (..., 2, 3). λ is taken with λ_c > 0 (the chart's representative).
    """
    lam = normalize(lam)
    chart = select_chart(lam) if chart is None else np.broadcast_to(np.asarray(chart), lam.shape[:-1])
    lam_c = np.take_along_axis(lam, chart[..., None], axis=-1)[..., 0]
    idx = CHART_COORDS[chart]
    out = np.zeros(lam.shape[:-1] + (2, 3))
    for j in range(2):
        i = idx[..., j]
        lam_i = np.take_along_axis(lam, i[..., None], axis=-1)[..., 0]
        np.put_along_axis(out[..., j, :], i[..., None], 1.0, axis=-1)
        np.put_along_axis(out[..., j, :], chart[..., None], (-lam_i / lam_c)[..., None], axis=-1)
    return out


def lambda_from_plane(xy: np.ndarray) -> np.ndarray:
    """ICR point (x, y) of the chassis plane -> λ on the North hemisphere, eq. (5)."""
    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim == 0 or xy.shape[-1] != 2:
        raise ValueError(f"xy must have shape (..., 2), got {xy.shape}")
    if not np.all(np.isfinite(xy)):
        raise ValueError("xy must be finite")
    h = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
    return unit_and_norm(h)[0]


def plane_from_lambda(lam: np.ndarray) -> np.ndarray:
    """λ -> ICR point (x, y) = (u, v)/w on the w = 1 plane, eq. (6). Infinite where w = 0."""
    lam = _check_last3(lam)
    with np.errstate(divide="ignore", invalid="ignore"):
        return lam[..., :2] / lam[..., 2:3]


def eta_from_twist(twist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Chassis twist (ẋ, ẏ, θ̇) [m/s, m/s, rad/s] -> (λ, μ) with μ ≥ 0, from ξ̇ = μ (v, −u, w).

    A zero twist has no ICR; it returns the canonical λ = (0, 0, 1) (rotation about the centre)
    with μ = 0.
    """
    twist = np.asarray(twist, dtype=np.float64)
    if twist.ndim == 0 or twist.shape[-1] != 3:
        raise ValueError(f"twist must have shape (..., 3), got {twist.shape}")
    if not np.all(np.isfinite(twist)):
        raise ValueError("twist must be finite")
    vec = np.stack([-twist[..., 1], twist[..., 0], twist[..., 2]], axis=-1)
    unit, mu = unit_and_norm(vec)
    lam = np.where(mu[..., None] > 0, unit, np.array([0.0, 0.0, 1.0]))
    return lam, mu


def twist_from_eta(lam: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """(λ, μ) -> chassis twist ξ̇ = μ (v, −u, w) [m/s, m/s, rad/s]."""
    lam = _check_last3(lam)
    mu = np.asarray(mu, dtype=np.float64)[..., None]
    return mu * np.stack([lam[..., 1], -lam[..., 0], lam[..., 2]], axis=-1)


def point_velocity(lam: np.ndarray, mu: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Velocity [m/s] in R of chassis point(s) p = (p_x, p_y): the (x, y) of μ λ × (p_x, p_y, 1).

    ``lam`` (..., 3) and ``mu`` (...) broadcast against ``p`` (..., 2).
    """
    lam = _check_last3(lam)
    p = np.asarray(p, dtype=np.float64)
    ph = np.concatenate([p, np.ones(p.shape[:-1] + (1,))], axis=-1)
    return (np.asarray(mu, dtype=np.float64)[..., None] * np.cross(lam, ph))[..., :2]


# ---------------------------------------------------------------- motion of λ on the sphere
#
# A path of motions λ(t) is a path on the unit sphere S² (the double cover of Λ). The ICR controller
# drives its reference λ along great circles; these are the few operations it needs. They act on
# unit vectors of S², not on points of Λ: antipodes are two points here, so that a path is continuous.


def sphere_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle [rad] between unit vectors of S², in [0, π] (antipodes are π apart, unlike
    :func:`lambda_distance`): ``atan2(‖a × b‖, a·b)``, accurate at 0 and π. (..., 3) -> (...).

    ``atan2`` is the C library's (:mod:`estimation.libm`): the same bits on every CPU, and those
    of the compiled ICR controller (:mod:`control.icr.kernels`)."""
    return atan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def _extra_axes(lam: np.ndarray, other: np.ndarray, trailing: int) -> tuple:
    """Index that inserts into ``lam`` (B..., 3) the axes that ``other`` (B..., K..., [3]) has
    beyond the batch axes B... (``trailing`` = 1 if ``other`` ends with a vector axis, else 0)."""
    return (Ellipsis,) + (None,) * (other.ndim - trailing - (lam.ndim - 1)) + (slice(None),)


def slerp(lam, lam_d, angle) -> np.ndarray:
    """The point ``angle`` [rad] from unit λ along the great circle toward unit λ_d.

    λ, λ_d (B..., 3); ``angle`` (B..., K...) -> (B..., K..., 3): e.g. one pair (3,) and K angles,
    or N pairs (N, 3) and angles (N,) or (N, M). Where λ_d = ±λ (no great circle through both),
    returns λ. The point is cos(angle) λ + sin(angle) e, e the unit tangent at λ toward λ_d."""
    lam = np.asarray(lam, dtype=np.float64)
    lam_d = np.asarray(lam_d, dtype=np.float64)
    angle = np.asarray(angle, dtype=np.float64)
    tang = lam_d - np.sum(lam * lam_d, axis=-1)[..., None] * lam
    tn = np.linalg.norm(tang, axis=-1)
    degenerate = tn < 1e-15
    e = tang / np.where(degenerate, 1.0, tn)[..., None]
    idx = _extra_axes(lam, angle, 0)
    lam_b, e_b = lam[idx], e[idx]
    out = np.cos(angle)[..., None] * lam_b + np.sin(angle)[..., None] * e_b
    if np.any(degenerate):
        out = np.where(degenerate[idx[:-1] + (None,)], lam_b, out)
    return out


def exp_map(lam, v) -> np.ndarray:
    """exp_λ(v) on the unit sphere: the point reached from unit λ (B..., 3) along the great circle
    of the tangent vector v (B..., K..., 3) after the arc ‖v‖, cos‖v‖ λ + sin‖v‖ v/‖v‖,
    renormalised. Returns (B..., K..., 3)."""
    lam = np.asarray(lam, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    nv = np.linalg.norm(v, axis=-1, keepdims=True)
    safe = np.where(nv > 0, nv, 1.0)
    out = np.cos(nv) * lam[_extra_axes(lam, v, 1)] + np.sin(nv) * v / safe
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def nearer_representative(lam, lam_d, mu_d) -> tuple[np.ndarray, np.ndarray]:
    """Of the two representatives (λ_d, μ_d) and (−λ_d, −μ_d) of one motion, the one whose λ is
    nearer to λ on S² (λ·λ_d ≥ 0): the motion the reference λ can reach without crossing half the
    sphere. λ, λ_d (..., 3), μ_d (...)."""
    lam = np.asarray(lam, dtype=np.float64)
    lam_d = np.asarray(lam_d, dtype=np.float64)
    sign = np.where(np.sum(lam * lam_d, axis=-1) < 0, -1.0, 1.0)
    return lam_d * sign[..., None], np.asarray(mu_d, dtype=np.float64) * sign
