"""Wheel kinematics in the H representation: β = F(λ), its derivatives, wheel speeds and μ.

The constraint of wheel k is eq. (15): ``s⊥1,k(β_k) · λ = 0`` with

* ``s⊥1,k(β) = sin β (a_k − l_k) − cos β a⊥_k``  (normal of the propulsion axis' great circle)
* ``s⊥2,k(β) = cos β (a_k − l_k) + sin β a⊥_k``

so that ``β_k = F_k(λ) = atan2(a⊥_k·λ, (a_k − l_k)·λ)`` taken modulo π into the steering range,
eq. (16)–(17). Write ``N_k = a⊥_k·λ``, ``D_k = (a_k − l_k)·λ`` and ``R_k² = N_k² + D_k²``.

Derivative (derived here; the paper's printed eq. (18) carries sign errors)::

    ∂F_k/∂λ = (D_k a⊥_k − N_k (a_k − l_k)) / R_k²

which equals ``−s⊥1,k / (s⊥2,k · λ)`` with β = F(λ). F is homogeneous of degree 0, so the gradient
is orthogonal to λ. F_k is undefined only where R_k = 0, i.e. λ ∥ s_k: the ICR on steering axis k,
eq. (21).

The numba kernels in this module (``_beta_grad_wheel``, ``_steering_dist2``) are the single
implementation of F that every estimator and the public functions use.

Wheel speeds (sidewise wheel with offset b, radius r; positive φ̇ rolls the wheel toward
(sin γ, −cos γ), γ = α + β)::

    r_k φ̇_k = μ (s⊥2,k − b_k ẑ)·λ − b_k β̇_k

The b_k β̇_k term is the steer-to-drive coupling: turning the module about A_k moves the contact
point, and the drive must compensate.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimation.geometry import RobotGeometry
from estimation.hrep import _canonical_eta_sign, twist_from_eta, unit_and_norm
from estimation.quality import _quality_from_d2

__all__ = [
    "SINGULAR_TOL",
    "steering_from_lambda",
    "steering_gradient",
    "steering_chart_jacobian",
    "singular_wheels",
    "s_perp",
    "propulsion_circle_normals",
    "wheel_speed_coefficients",
    "wheel_speeds",
    "mu_from_wheel_speeds",
    "twist_from_wheels",
    "odometry_twist",
    "integrate_pose",
    "steering_path_derivatives",
    "wheel_speed_path_derivative",
]

#: R_k below which wheel k is treated as singular (ICR on its steering axis, eq. (21)). R_k is at
#: least sin(angle(λ, s_k)), so this is an angle of about 1e-9 rad.
SINGULAR_TOL = 1e-9


# ----------------------------------------------------------------------------------------------
# numba kernels: the one implementation of F and of the joint-space distance
# ----------------------------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _wrap_into_range(beta: float, steer_max: float) -> float:
    """Bring an angle of ]−π, π] into ]steer_max − π, steer_max] by adding multiples of π."""
    while beta > steer_max:
        beta -= math.pi
    while beta <= steer_max - math.pi:
        beta += math.pi
    return beta


@njit(cache=True)
def _beta_wheel(lam0: float, lam1: float, lam2: float, E, P, k: int, steer_max: float):
    """F_k(λ) and R_k². Returns (β_k, R_k²); β_k is meaningless when R_k < SINGULAR_TOL."""
    num = P[k, 0] * lam0 + P[k, 1] * lam1 + P[k, 2] * lam2
    den = E[k, 0] * lam0 + E[k, 1] * lam1 + E[k, 2] * lam2
    r2 = num * num + den * den
    return _wrap_into_range(math.atan2(num, den), steer_max), r2


@njit(cache=True, inline="always")
def _wrap_half_pi(x: float) -> float:
    """x modulo π into [−π/2, π/2[ (the distance between two propulsion axes' angles)."""
    return (x + 0.5 * math.pi) % math.pi - 0.5 * math.pi

@njit(cache=True)
def _steering_dist2_upto(lam, q, E, P, steer_max: float, beta_out, bound: float, periodic: bool = False) -> float:
    """‖q − S(λ)‖², the squared joint-space distance to the surface point of λ, eq. (9); S(λ) is
    written to ``beta_out``. The sum stops as soon as it exceeds ``bound`` (and then returns a
    partial sum above it, with ``beta_out`` incomplete).

    A wheel whose steering axis holds the ICR takes any angle, so it takes the input angle and its
    term is zero (§3.1.3: β_k is copied from the input). ``periodic`` (unlimited steering):
    q_k − β_k modulo π into [−π/2, π/2[, and ``beta_out`` gets the nearer angle of the axis."""
    d = 0.0
    for k in range(q.shape[0]):
        beta, r2 = _beta_wheel(lam[0], lam[1], lam[2], E, P, k, steer_max)
        if r2 >= SINGULAR_TOL * SINGULAR_TOL:
            diff = q[k] - beta
            if periodic:
                diff = _wrap_half_pi(diff)
                beta = q[k] - diff
            d += diff * diff
            beta_out[k] = beta
            if d > bound:
                return d
        else:
            beta_out[k] = q[k]
    return d


@njit(cache=True)
def _steering_dist2(lam, q, E, P, steer_max: float, beta_out, periodic: bool = False) -> float:
    """‖q − S(λ)‖² with S(λ) written to ``beta_out`` (see :func:`_steering_dist2_upto`)."""
    return _steering_dist2_upto(lam, q, E, P, steer_max, beta_out, np.inf, periodic)


@njit(cache=True)
def _grad_wheel(lam, E, P, k: int, grad) -> bool:
    """∂F_k/∂λ = (D a⊥ − N (a − l)) / (N² + D²), written into ``grad``. Returns True (and a zero
    gradient) where wheel k is singular, eq. (21)."""
    num = P[k, 0] * lam[0] + P[k, 1] * lam[1] + P[k, 2] * lam[2]
    den = E[k, 0] * lam[0] + E[k, 1] * lam[1] + E[k, 2] * lam[2]
    r2 = num * num + den * den
    if r2 < SINGULAR_TOL * SINGULAR_TOL:
        grad[0] = 0.0
        grad[1] = 0.0
        grad[2] = 0.0
        return True
    inv = 1.0 / r2
    for i in range(3):
        grad[i] = (den * P[k, i] - num * E[k, i]) * inv
    return False


@njit(cache=True)
def _beta_grad_wheel(lam, E, P, k: int, steer_max: float, grad):
    """F_k(λ) and ∂F_k/∂λ (written into ``grad``). Returns (β_k, singular); β_k = 0 if singular."""
    if _grad_wheel(lam, E, P, k, grad):
        return 0.0, True
    beta, _ = _beta_wheel(lam[0], lam[1], lam[2], E, P, k, steer_max)
    return beta, False


@njit(cache=True)
def _steering_batch(lam, E, P, steer_max: float, fill, use_fill: bool, out):
    n = E.shape[0]
    for i in range(lam.shape[0]):
        for k in range(n):
            beta, r2 = _beta_wheel(lam[i, 0], lam[i, 1], lam[i, 2], E, P, k, steer_max)
            if r2 < SINGULAR_TOL * SINGULAR_TOL:
                beta = fill[i, k] if use_fill else 0.0
            out[i, k] = beta


@njit(cache=True)
def _gradient_batch(lam, E, P, steer_max: float, out):
    g = np.empty(3)
    for i in range(lam.shape[0]):
        for k in range(E.shape[0]):
            _beta_grad_wheel(lam[i], E, P, k, steer_max, g)
            out[i, k, 0] = g[0]
            out[i, k, 1] = g[1]
            out[i, k, 2] = g[2]


@njit(cache=True)
def _speed_coef(lam, E, P, b, k: int, beta: float) -> float:
    """c_k = (s⊥2,k(β) − b_k ẑ)·λ = cos β D_k + sin β N_k − b_k w (see :func:`wheel_speed_coefficients`).
    At a singular wheel (N_k = D_k = 0) it is −b_k w whatever β."""
    num = P[k, 0] * lam[0] + P[k, 1] * lam[1] + P[k, 2] * lam[2]
    den = E[k, 0] * lam[0] + E[k, 1] * lam[1] + E[k, 2] * lam[2]
    return math.cos(beta) * den + math.sin(beta) * num - b[k] * lam[2]


@njit(cache=True)
def _speed_coef_batch(lam, beta, E, P, b, out):
    for i in range(lam.shape[0]):
        for k in range(E.shape[0]):
            out[i, k] = _speed_coef(lam[i], E, P, b, k, beta[i, k])


@njit(cache=True)
def _mu_least_squares(c, y) -> float:
    """μ minimising Σ (y_k − μ c_k)²; 0 if every c_k vanishes."""
    num = 0.0
    den = 0.0
    for k in range(c.shape[0]):
        num += c[k] * y[k]
        den += c[k] * c[k]
    return num / den if den > 0.0 else 0.0


@njit(cache=True)
def _eta_kernel(lam, q, phidot, E, P, b, r, steer_max, mu_tol, f, beta_out, mu_out, qua_out, c, periodic=False):
    """For each row: S(λ) (singular wheels take q_k) and its quality (eq. 29, factor f), μ by least
    squares of r φ̇ = μ c given λ, then the canonical sign of (λ, μ). λ is updated in place.
    ``periodic``: unlimited steering."""
    n = E.shape[0]
    for i in range(lam.shape[0]):
        d2 = _steering_dist2(lam[i], q[i], E, P, steer_max, beta_out[i], periodic)
        qua_out[i] = _quality_from_d2(d2, n, f)
        for k in range(E.shape[0]):
            c[k] = _speed_coef(lam[i], E, P, b, k, beta_out[i, k])
            phidot[i, k] *= r[k]  # phidot holds r φ̇ from here on (a private copy)
        mu = _mu_least_squares(c, phidot[i])
        sign = _canonical_eta_sign(lam[i, 0], lam[i, 1], lam[i, 2], mu, mu_tol)
        mu_out[i] = sign * mu
        for j in range(3):
            lam[i, j] *= sign


# ----------------------------------------------------------------------------------------------
# input checking shared by the public functions
# ----------------------------------------------------------------------------------------------


def _check_lambda(lam, name: str = "lam") -> tuple[np.ndarray, tuple[int, ...]]:
    """Validate λ of shape (3,) or (..., 3); return it flattened to (N, 3) and the batch shape."""
    arr = np.asarray(lam, dtype=np.float64)
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (3,) or (N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    unit, norms = unit_and_norm(arr.reshape(-1, 3))  # at any scale: 1e155·λ overflowed the norm (β = 0)
    if np.any(norms == 0):
        raise ValueError(f"{name} contains a zero vector, which is not a point of Λ")
    return np.ascontiguousarray(unit), arr.shape[:-1]


def _check_angles(q, geom: RobotGeometry, name: str = "q") -> tuple[np.ndarray, tuple[int, ...]]:
    """Validate steering angles of shape (n,) or (..., n); return (N, n) contiguous and batch shape."""
    arr = np.asarray(q, dtype=np.float64)
    if arr.ndim == 0 or arr.shape[-1] != geom.n:
        raise ValueError(f"{name} must have shape ({geom.n},) or (N, {geom.n}) for this robot, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    return np.ascontiguousarray(arr.reshape(-1, geom.n)), arr.shape[:-1]


# ----------------------------------------------------------------------------------------------
# public API
# ----------------------------------------------------------------------------------------------


def steering_from_lambda(lam, geom: RobotGeometry, singular_fill=None) -> np.ndarray:
    """Steering configuration β = F(λ), eq. (16)–(17), wrapped into the steering range.

    Args:
        lam: (3,) or (N, 3) points of Λ (need not be normalised; any sign).
        geom: the robot.
        singular_fill: optional (n,) or (N, n) angles to use for a wheel whose steering axis holds
            the ICR (eq. (21)), where β_k is undefined. Default 0. Estimators' quality is computed
            with the measured angles here, since such a wheel may take any angle.

    Returns:
        (n,) or (N, n) steering angles [rad] in ]β_min, β_max].
    """
    flat, batch = _check_lambda(lam)
    out = np.empty((flat.shape[0], geom.n))
    if singular_fill is None:
        fill = np.zeros((1, geom.n))
        use_fill = False
    else:
        fill = np.ascontiguousarray(np.broadcast_to(np.asarray(singular_fill, dtype=np.float64),
                                                    batch + (geom.n,)).reshape(-1, geom.n))
        use_fill = True
    _steering_batch(flat, geom.a_minus_l, geom.a_perp, geom.steer_max, fill, use_fill, out)
    return out.reshape(batch + (geom.n,))


def steering_gradient(lam, geom: RobotGeometry) -> np.ndarray:
    """∂F_k/∂λ = (D_k a⊥_k − N_k (a_k − l_k)) / (N_k² + D_k²), the corrected eq. (18).

    Returns (n, 3) or (N, n, 3) [rad per unit of λ]; rows of singular wheels are zero (§3.1.3).
    The gradient is taken at λ as given (normalised); it is odd in λ and orthogonal to λ.
    """
    flat, batch = _check_lambda(lam)
    out = np.empty((flat.shape[0], geom.n, 3))
    _gradient_batch(flat, geom.a_minus_l, geom.a_perp, geom.steer_max, out)
    return out.reshape(batch + (geom.n, 3))


def steering_chart_jacobian(lam, geom: RobotGeometry) -> tuple[np.ndarray, np.ndarray]:
    """Chart-wise derivatives (S_u, S_v) of the constraining surface S(λ), eq. (9)–(10), (19).

    Uses the chart selected for λ and its representative with λ_c > 0. Returns ``(chart, J)`` with
    J of shape (n, 2) or (N, n, 2): column j is ∂β/∂p_j for the chart's coordinate p_j.
    """
    from estimation.hrep import chart_tangents, select_chart

    flat, batch = _check_lambda(lam)
    chart = select_chart(flat)
    flat = flat * np.where(np.take_along_axis(flat, chart[:, None], axis=1) < 0, -1.0, 1.0)
    grad = steering_gradient(flat, geom)  # (N, n, 3)
    tang = chart_tangents(flat, chart)  # (N, 2, 3)
    jac = np.einsum("nki,nji->nkj", grad, tang)
    return chart.reshape(batch), jac.reshape(batch + (geom.n, 2))


def singular_wheels(lam, geom: RobotGeometry, tol: float = 1e-6) -> np.ndarray:
    """Structural singularity test, eq. (21): True where λ ∥ s_k (ICR on steering axis k).

    ``tol`` is the sine of the angle between λ and ŝ_k below which the wheel is singular.
    Returns (n,) or (N, n) bool.
    """
    flat, batch = _check_lambda(lam)
    sin_angle = np.linalg.norm(np.cross(flat[:, None, :], geom.s_unit[None, :, :]), axis=-1)
    return (sin_angle <= tol).reshape(batch + (geom.n,))


def s_perp(beta, geom: RobotGeometry) -> tuple[np.ndarray, np.ndarray]:
    """(s⊥1, s⊥2) for steering angles β, each (n, 3) or (N, n, 3); see eq. (15), (27)."""
    beta = np.asarray(beta, dtype=np.float64)
    sb, cb = np.sin(beta)[..., None], np.cos(beta)[..., None]
    s1 = sb * geom.a_minus_l - cb * geom.a_perp
    s2 = cb * geom.a_minus_l + sb * geom.a_perp
    return s1, s2


def propulsion_circle_normals(q, geom: RobotGeometry) -> np.ndarray:
    """Normal c_k = s⊥1,k(q_k) of the great circle of propulsion axis k, eq. (8), (27).

    λ lies on wheel k's propulsion axis iff c_k · λ = 0. Returns (n, 3) or (N, n, 3)."""
    return s_perp(q, geom)[0]


def wheel_speed_coefficients(lam, geom: RobotGeometry, beta=None) -> np.ndarray:
    """c_k = (s⊥2,k(β_k) − b_k ẑ) · λ, so that r_k φ̇_k = μ c_k − b_k β̇_k.

    ``beta`` defaults to F(λ); pass measured angles to use them instead. μ c_k is the velocity of
    contact point k along its rolling direction (sin γ_k, −cos γ_k) [m/s].
    Returns (n,) or (N, n).
    """
    flat, batch = _check_lambda(lam)
    if beta is None:
        beta = steering_from_lambda(flat, geom)
    else:
        beta = np.broadcast_to(np.asarray(beta, dtype=np.float64), batch + (geom.n,)).reshape(-1, geom.n)
        if not np.all(np.isfinite(beta)):
            raise ValueError("beta contains NaN or inf")
    out = np.empty((flat.shape[0], geom.n))
    _speed_coef_batch(flat, np.ascontiguousarray(beta), geom.a_minus_l, geom.a_perp, geom.b, out)
    return out.reshape(batch + (geom.n,))


def wheel_speeds(lam, mu, geom: RobotGeometry, beta_rate=None, beta=None) -> np.ndarray:
    """Wheel spin rates φ̇ [rad/s] that realise (λ, μ): r_k φ̇_k = μ (s⊥2,k − b_k ẑ)·λ − b_k β̇_k.

    Args:
        lam: (3,) or (N, 3); mu: scalar or (N,) [m/s per unit of λ, i.e. μ = ±‖ξ̇‖].
        beta_rate: optional steering rates β̇ [rad/s], (n,) or (N, n): the steer-to-drive coupling.
        beta: optional steering angles to use instead of F(λ).
    """
    c = wheel_speed_coefficients(lam, geom, beta)
    mu = np.asarray(mu, dtype=np.float64)
    if not np.all(np.isfinite(mu)):
        raise ValueError("mu contains NaN or inf")
    rphi = mu[..., None] * c
    if beta_rate is not None:
        rphi = rphi - geom.b * np.asarray(beta_rate, dtype=np.float64)
    return rphi / geom.r


@njit(cache=True)
def _mu_batch(c, y, out):
    for i in range(c.shape[0]):
        out[i] = _mu_least_squares(c[i], y[i])


def mu_from_wheel_speeds(lam, phidot, geom: RobotGeometry, beta=None, beta_rate=None) -> np.ndarray:
    """μ by least squares of r_k φ̇_k + b_k β̇_k = μ c_k over the wheels, given λ.

    Returns a scalar (as a 0-d array) or (N,). Where every c_k vanishes (cannot happen for a valid
    geometry and unit λ), μ = 0.
    """
    c = wheel_speed_coefficients(lam, geom, beta)
    phidot = np.asarray(phidot, dtype=np.float64)
    if phidot.shape[-1:] != (geom.n,):
        raise ValueError(f"phidot must have shape ({geom.n},) or (N, {geom.n}), got {phidot.shape}")
    if not np.all(np.isfinite(phidot)):
        raise ValueError("phidot contains NaN or inf")
    y = geom.r * phidot
    if beta_rate is not None:
        y = y + geom.b * np.asarray(beta_rate, dtype=np.float64)
    batch = np.broadcast_shapes(c.shape, y.shape)[:-1]
    c2 = np.ascontiguousarray(np.broadcast_to(c, batch + (geom.n,)).reshape(-1, geom.n))
    y2 = np.ascontiguousarray(np.broadcast_to(y, batch + (geom.n,)).reshape(-1, geom.n))
    out = np.empty(c2.shape[0])
    _mu_batch(c2, y2, out)
    return out.reshape(batch)


def twist_from_wheels(beta, beta_rate, phidot, geom: RobotGeometry) -> tuple[np.ndarray, float]:
    """Odometry: the chassis twist (ẋ, ẏ, θ̇) in R [m/s, m/s, rad/s] that best explains the wheel
    states, and the residual slip ‖A ξ̇ − y‖ [m/s] (zero when the propulsion axes concur).

    Least squares over every wheel's no-side-slip and rolling constraints, with the contact point
    P_k = A_k + b_k e_k, e_k = (cos γ_k, sin γ_k), rolling direction d_k = (sin γ_k, −cos γ_k)::

        v(P_k) · e_k = 0,    v(P_k) · d_k = r_k φ̇_k + b_k β̇_k

    where v(P) = (ẋ − θ̇ P_y, ẏ + θ̇ P_x): the inverse of :func:`wheel_speeds` for one robot,
    β, β̇, φ̇ of shape (n,).
    """
    beta = np.asarray(beta, dtype=np.float64)
    gamma = geom.alpha + beta
    e = np.stack([np.cos(gamma), np.sin(gamma)], axis=1)
    d = np.stack([np.sin(gamma), -np.cos(gamma)], axis=1)
    p = geom.axis_xy + geom.b[:, None] * e
    rows, rhs = [], []
    for dirs, target in ((e, np.zeros(geom.n)), (d, geom.r * np.asarray(phidot) + geom.b * np.asarray(beta_rate))):
        # v(P)·u = u_x ẋ + u_y ẏ + θ̇ (P_x u_y − P_y u_x)
        rows.append(np.stack([dirs[:, 0], dirs[:, 1], p[:, 0] * dirs[:, 1] - p[:, 1] * dirs[:, 0]], axis=1))
        rhs.append(target)
    a, y = np.concatenate(rows), np.concatenate(rhs)
    twist, *_ = np.linalg.lstsq(a, y, rcond=None)
    return twist, float(np.linalg.norm(a @ twist - y))


def odometry_twist(lam, phidot, beta, beta_rate, geom: RobotGeometry) -> np.ndarray:
    """Odometry in the H representation, batched: the chassis twist (ẋ, ẏ, θ̇) in R [m/s, m/s,
    rad/s] from an ICR estimate λ (N, 3) and the wheel states β, β̇, φ̇ (N, n).

    μ is the least-squares fit of r_k φ̇_k + b_k β̇_k = μ c_k(λ, β_k) (:func:`mu_from_wheel_speeds`;
    the b β̇ term removes the steer-to-drive coupling, so wheels turned in place at rest give
    μ ≈ 0) and ξ̇ = μ (v, −u, w) (``hrep.twist_from_eta``). With λ from an ICR estimator this is
    the dead-reckoning twist of a robot whose propulsion axes need not concur; for one robot whose
    axes concur it equals :func:`twist_from_wheels`.
    """
    mu = mu_from_wheel_speeds(lam, phidot, geom, beta=beta, beta_rate=beta_rate)
    return twist_from_eta(lam, mu)


def integrate_pose(pose, twist, dt: float) -> np.ndarray:
    """Dead reckoning, batched: the world pose (x, y, θ) (..., 3) [m, m, rad] after moving for
    ``dt`` [s] with the constant chassis-frame twist (ẋ, ẏ, θ̇) (..., 3), by the exact SE(2)
    exponential (a circular arc; a straight segment when θ̇ = 0)::

        d = [[sin a, −(1 − cos a)], [1 − cos a, sin a]] / a · (ẋ, ẏ) dt,   a = θ̇ dt
        (x, y) += R(θ) d,   θ += a
    """
    pose = np.asarray(pose, dtype=np.float64)
    twist = np.asarray(twist, dtype=np.float64)
    a = twist[..., 2] * dt
    small = np.abs(a) < 1e-6
    a_safe = np.where(small, 1.0, a)
    s_a = np.where(small, 1.0 - a * a / 6.0, np.sin(a_safe) / a_safe)  # sin a / a
    c_a = np.where(small, 0.5 * a, (1.0 - np.cos(a_safe)) / a_safe)  # (1 − cos a) / a
    dx = (s_a * twist[..., 0] - c_a * twist[..., 1]) * dt
    dy = (c_a * twist[..., 0] + s_a * twist[..., 1]) * dt
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    return np.stack([pose[..., 0] + c * dx - s * dy, pose[..., 1] + s * dx + c * dy, pose[..., 2] + a], axis=-1)


def steering_path_derivatives(lam, dlam, ddlam, geom: RobotGeometry) -> tuple[np.ndarray, np.ndarray]:
    """β′ and β″ along a path λ(s) on the sphere, given λ′ and λ″ (′ = d/ds).

    β′_k = ∇F_k · λ′ = −(s⊥1,k · λ′)/(s⊥2,k · λ)
    β″_k = −(2 β′_k (s⊥2,k · λ′) + s⊥1,k · λ″)/(s⊥2,k · λ)

    (from differentiating s⊥1,k(β_k(s)) · λ(s) = 0 twice, using ds⊥1/dβ = s⊥2, ds⊥2/dβ = −s⊥1).
    Shapes: λ, λ′, λ″ (3,) or (N, 3) -> (n,) or (N, n) each. Singular wheels give ±inf or NaN-free
    large values; callers must avoid steering axes (see control/).
    """
    lam = np.asarray(lam, dtype=np.float64)
    beta = steering_from_lambda(lam, geom)
    s1, s2 = s_perp(beta, geom)
    dlam = np.asarray(dlam, dtype=np.float64)[..., None, :]
    ddlam = np.asarray(ddlam, dtype=np.float64)[..., None, :]
    den = np.sum(s2 * lam[..., None, :], axis=-1)
    d1 = -np.sum(s1 * dlam, axis=-1) / den
    d2 = -(2 * d1 * np.sum(s2 * dlam, axis=-1) + np.sum(s1 * ddlam, axis=-1)) / den
    return d1, d2


def wheel_speed_path_derivative(lam, dlam, mu, dmu, ddbeta, geom: RobotGeometry) -> np.ndarray:
    """φ̇′_k = ((s⊥2,k − b_k ẑ)·(μ λ′ + μ′ λ) + (s⊥2,k)′·μλ − b_k β″_k) / r_k along a path.

    With (s⊥2,k)′ = −β′_k s⊥1,k and s⊥1,k·λ = 0 on the surface, the middle term vanishes, giving
    φ̇′_k = ((s⊥2,k − b_k ẑ)·(μ λ′ + μ′ λ) − b_k β″_k)/r_k (derived in docs/icr-controller.md, §2). Here
    φ̇ is the path form r φ̇ = μ c − b β′ (rates per unit of s).
    """
    lam = np.asarray(lam, dtype=np.float64)
    beta = steering_from_lambda(lam, geom)
    _, s2 = s_perp(beta, geom)
    s2b = s2.copy()
    s2b[..., 2] -= geom.b
    v = np.asarray(mu, dtype=np.float64)[..., None] * np.asarray(dlam, dtype=np.float64) \
        + np.asarray(dmu, dtype=np.float64)[..., None] * lam
    return (np.sum(s2b * v[..., None, :], axis=-1) - geom.b * np.asarray(ddbeta, dtype=np.float64)) / geom.r
