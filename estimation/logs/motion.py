"""What the wheels say about the chassis motion of a log, sample by sample: the rigid-body twist
that best explains every wheel (the wheels' own odometry, without any ICR estimate), the speed
of the fastest wheel contact point under that twist (which tells moving from standing), and a
gyro's yaw rate on the samples' clock.

**Rigid fit** (:func:`twist_from_wheels_batch`): per sample, the least-squares chassis twist
ξ̇ = (ẋ, ẏ, θ̇) of the no-side-slip and rolling constraints of every wheel,
``v(P_k)·e_k = 0`` and ``v(P_k)·d_k = r_k φ̇_k + b_k β̇_k`` (contact point P_k = A_k + b_k e_k,
e_k = (cos γ_k, sin γ_k), d_k = (sin γ_k, −cos γ_k), γ_k = α_k + β_k, v(P) = (ẋ − θ̇ P_y,
ẏ + θ̇ P_x)): :func:`estimation.kinematics.twist_from_wheels` for N samples at once, through the
normal equations (the 3×3 system AᵀA ξ̇ = Aᵀy, well conditioned: every wheel adds the identity
to its 2×2 translation block). For coaxial swerve modules (b = 0) it is WPILib's own odometry
(``SwerveDriveKinematics.toChassisSpeeds``, the pseudo-inverse of the module velocities).

**Moving** (:data:`MOVING_SPEED`): a sample moves when the fastest contact point of the rigid
fit moves at least 0.05 m/s. The same 5 cm/s as the simulator's ``control.episode.MOVING_MU``
(|μ| > 0.05 m/s of the true motion, 5% of the paper track's 1 m/s); μ = ‖(ẋ, ẏ, θ̇)‖ mixes m/s
and rad/s, where the contact-point speed is a speed in m/s for a rotation in place too (equal to
μ in a translation). 5 cm/s is about 1% of an FRC robot's top speed, below any deliberate
motion, and above the wheel-encoder noise of a robot at rest (FRC drive encoders read exactly 0
or a few mm/s at rest; a steering motor turning a module in place adds b β̇ to the rolling
constraint, which the fit removes). The rigid fit, not an estimator's μ̂, decides: it needs no
ICR and does not depend on which estimator ran.

**Gyro rate** (:func:`window_rate`): a heading (the gyro's yaw, or the odometry's integrated
heading) over a centred window of :data:`RATE_WINDOW_S`: (θ(t + w/2) − θ(t − w/2)) / w with θ
linearly interpolated between its own samples. The wheels' heading goes through the same window,
so both rates are the mean over the same interval and a gyro logged at another rate than the
wheels compares sample for sample.
"""

from __future__ import annotations

import numpy as np

from estimation.geometry import RobotGeometry

__all__ = ["MOVING_SPEED", "RATE_WINDOW_S", "rigid_rows", "rigid_fit", "twist_from_wheels_batch", "contact_speeds",
           "window_rate", "integrated_heading", "interp_on"]

#: [m/s] fastest wheel contact point speed of the rigid fit above which a sample moves
MOVING_SPEED = 0.05
#: [s] the centred window of the yaw rates compared with the gyro (10 loops of a 50 Hz robot)
RATE_WINDOW_S = 0.2

_CHUNK = 65_536  # rows per block of the batched fit (bounded memory for long logs)


def _contact_points(beta: np.ndarray, geom: RobotGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """e, d (N, n, 2) the propulsion and rolling directions and P (N, n, 2) the contact points."""
    gamma = geom.alpha + beta
    c, s = np.cos(gamma), np.sin(gamma)
    e = np.stack([c, s], axis=-1)
    d = np.stack([s, -c], axis=-1)
    p = geom.axis_xy + geom.b[:, None] * e
    return e, d, p


def rigid_rows(beta, beta_rate, phidot, geom: RobotGeometry, offset=0.0, scale=1.0) -> tuple[np.ndarray, np.ndarray]:
    """The 2n constraint rows A (N, 2n, 3) and right-hand sides y (N, 2n) of every sample (module
    docstring), with steering offsets added to β and wheel factors applied to φ̇ (calibration):
    v(P)·u = u_x ẋ + u_y ẏ + θ̇ (P_x u_y − P_y u_x) for u = e_k (target 0) and u = d_k."""
    e, d, p = _contact_points(np.asarray(beta, dtype=np.float64) + offset, geom)
    rows = [np.concatenate([u, (p[..., 0] * u[..., 1] - p[..., 1] * u[..., 0])[..., None]], axis=-1) for u in (e, d)]
    roll = scale * geom.r * phidot + geom.b * beta_rate
    return np.concatenate(rows, axis=1), np.concatenate([np.zeros_like(roll), roll], axis=1)


def rigid_fit(beta, beta_rate, phidot, geom: RobotGeometry, offset=0.0, scale=1.0, yaw_rate=None,
              yaw_weight: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares twist ξ̇ (N, 3) of every sample's rows (:func:`rigid_rows`) and their
    residuals y − A ξ̇ (N, 2n) [m/s]; with ``yaw_rate`` (N,) and ``yaw_weight`` > 0 [m]
    one more row ``yaw_weight (θ̇ − yaw_rate) = 0`` per sample (a gyro, in calibration). Solved
    through the normal equations (AᵀA is well conditioned: every wheel adds the identity to its
    2×2 translation block)."""
    a, y = rigid_rows(beta, beta_rate, phidot, geom, offset, scale)
    ata = np.einsum("kij,kil->kjl", a, a)
    aty = np.einsum("kij,ki->kj", a, y)
    if yaw_rate is not None and yaw_weight > 0:
        ata[:, 2, 2] += yaw_weight**2
        aty[:, 2] += yaw_weight**2 * yaw_rate
    x = np.linalg.solve(ata, aty[..., None])[..., 0]
    return x, y - np.einsum("kij,kj->ki", a, x)


def twist_from_wheels_batch(beta, beta_rate, phidot, geom: RobotGeometry) -> tuple[np.ndarray, np.ndarray]:
    """The rigid-body least-squares twist of every sample: (N, 3) (ẋ, ẏ, θ̇) [m/s, m/s, rad/s] and
    (N,) the residual ‖A ξ̇ − y‖ [m/s] (zero when the wheels agree on one rigid motion).

    ``beta``, ``beta_rate``, ``phidot``: (N, n). Row by row this is
    :func:`estimation.kinematics.twist_from_wheels` (the same least squares, solved through the
    normal equations: equal to rounding); :func:`rigid_fit` in blocks of bounded memory."""
    beta = np.asarray(beta, dtype=np.float64)
    beta_rate = np.asarray(beta_rate, dtype=np.float64)
    phidot = np.asarray(phidot, dtype=np.float64)
    if beta.ndim != 2 or beta.shape[1] != geom.n or beta_rate.shape != beta.shape or phidot.shape != beta.shape:
        raise ValueError(f"beta, beta_rate and phidot must be (N, {geom.n}), got {beta.shape}, {beta_rate.shape}, "
                         f"{phidot.shape}")
    twist = np.empty((beta.shape[0], 3))
    resid = np.empty(beta.shape[0])
    for a in range(0, beta.shape[0], _CHUNK):
        sl = slice(a, a + _CHUNK)
        twist[sl], r = rigid_fit(beta[sl], beta_rate[sl], phidot[sl], geom)
        resid[sl] = np.linalg.norm(r, axis=1)
    return twist, resid


def contact_speeds(twist, beta, geom: RobotGeometry) -> np.ndarray:
    """(N, n) the speed [m/s] of each wheel's contact point P_k (at the measured β) under the
    chassis twist (N, 3): ‖(ẋ − θ̇ P_y, ẏ + θ̇ P_x)‖."""
    twist = np.asarray(twist, dtype=np.float64)
    _, _, p = _contact_points(np.asarray(beta, dtype=np.float64), geom)
    vx = twist[:, None, 0] - twist[:, None, 2] * p[..., 1]
    vy = twist[:, None, 1] + twist[:, None, 2] * p[..., 0]
    return np.hypot(vx, vy)


def interp_on(t_ns: np.ndarray, src_t_ns: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` (M,) given at ``src_t_ns`` linearly interpolated at ``t_ns`` (N,); NaN outside
    the source's time span (no extrapolation)."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    src = np.asarray(src_t_ns, dtype=np.int64)
    out = np.full(t_ns.shape, np.nan)
    if src.size == 0:
        return out
    inside = (t_ns >= src[0]) & (t_ns <= src[-1])
    out[inside] = np.interp((t_ns[inside] - src[0]).astype(np.float64), (src - src[0]).astype(np.float64),
                            np.asarray(values, dtype=np.float64))
    return out


def integrated_heading(t_ns: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """(N,) the heading [rad] from 0 at the first sample of the yaw rates ``omega`` (N,), each acting
    over the period before its sample (as the dead reckoning integrates them)."""
    dt = np.diff(np.asarray(t_ns, dtype=np.int64)) * 1e-9
    return np.concatenate([[0.0], np.cumsum(np.asarray(omega, dtype=np.float64)[1:] * dt)])


def window_rate(t_ns: np.ndarray, src_t_ns: np.ndarray, heading: np.ndarray,
                window_s: float = RATE_WINDOW_S) -> np.ndarray:
    """(N,) the mean rate [rad/s] of ``heading`` (M,) given at ``src_t_ns`` over the window of
    ``window_s`` centred on each of ``t_ns``: (θ(t + w/2) − θ(t − w/2)) / w, θ interpolated
    linearly; NaN where the window leaves the heading's time span."""
    half = int(round(window_s * 0.5e9))
    t_ns = np.asarray(t_ns, dtype=np.int64)
    hi = interp_on(t_ns + half, src_t_ns, heading)
    lo = interp_on(t_ns - half, src_t_ns, heading)
    return (hi - lo) / (2 * half * 1e-9)
