"""Steering offsets and wheel-speed factors fitted to a log of ordinary driving.

A module whose steering zero is off by δ_k reports β_k − δ_k; a wheel whose rolling radius (or
gearing) is off reports a speed off by a factor s_k. While the robot moves, the wheels' contact
points move as one rigid body: with the right (δ, s), at every sample t a chassis twist ξ_t =
(ẋ, ẏ, θ̇) explains every wheel's rolling and no-side-slip constraint (the model of
:func:`~estimation.kinematics.twist_from_wheels`, contact point P_k = A_k + b_k e_k)::

    v_t(P_k) · e_k = 0,     v_t(P_k) · d_k = s_k r_k φ̇_k + b_k β̇_k,     γ_k = α_k + β_k + δ_k

The fit minimises the sum over moving samples of the squared residuals of these 2n equations, ξ_t
eliminated by least squares at each sample (variable projection), each sample's rows divided by
its speed so that every moving sample weighs the same (the residual is then an angle, and slow
samples do not vanish against fast ones); a Huber weight per sample keeps a skid or a stale
sample from pulling the fit. Gauss–Newton on (δ, log s) from the start below.

**Start, from any offsets** (raw absolute encoders: anywhere in 0–360°). For coaxial modules
(b_k = 0) and written with complex numbers, wheel k's velocity is c_k z_k with z_k = r_k φ̇_k
e^{i(γ_k − π/2)} and the unknown c_k = s_k e^{iδ_k}; rigid motion says c_k z_k = v_t + i ω_t p_k.
With (v_t, ω_t) eliminated this is a quadratic form in c (the real 2n-vector), whose smallest
eigenvector is the global least-squares c: no local minimum, whatever the offsets. The 180°
ambiguity of a coaxial module (δ + π with the wheel speed reversed) is settled by the wheel speeds,
since s_k > 0. Modules with b_k ≠ 0 start from the same solution with their contact points on their
axes, then Gauss–Newton takes b into account.

**What a log can tell.** Only relative wheel factors without a gyro (all s_k times a constant
is the same robot driving faster); the gyro's yaw rate fixes the scale when the robot turns. A
common offset of all modules rotates every wheel velocity by the same angle: a translation stays a
rigid translation, but a rotation about the chassis centre gains a radial component, so the common
offset is observable when the robot turns (or from a gyro) — modulo 180° for coaxial modules
without a gyro (every wheel reversed is the robot driving backwards). Where it is not observable
(its standard error above :data:`COMMON_OBSERVABLE_DEG`), the common part is set so that the
offsets' circular mean is zero, and the result says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from estimation.geometry import RobotGeometry
from estimation.logs.motion import MOVING_SPEED, contact_speeds, rigid_fit

__all__ = ["CalibrationFit", "fit_calibration", "apply_offsets", "linear_start", "beta_rates",
           "COMMON_OBSERVABLE_DEG", "MIN_MOVING_SAMPLES", "MOVING_SPEED"]

#: the common offset is reported as observable when its standard error is below this [deg]
COMMON_OBSERVABLE_DEG = 0.5
#: the log must tell the relative offsets and factors apart: refused when the weakest combination of
#: them has a standard error above this [deg] (all the motions alike: one direction of travel)
MAX_WEAK_STD_DEG = 1.0
#: fewer moving samples than this cannot calibrate (8 parameters need many independent motions)
MIN_MOVING_SAMPLES = 200
#: Huber threshold on a sample's normalised residual norm [rad]: about 3° of disagreement
_HUBER = 0.05
#: added to every sample's speed when its residuals are normalised [m/s]: below it, wheel-speed
#: quantisation and noise dominate
_SPEED_FLOOR = 0.05
#: the wheels' yaw rate after calibration may differ from the gyro's by this [rad/s] plus this share
#: of the gyro's RMS rate (the gyro's rate is a 0.2 s window, the wheels' instantaneous)
_GYRO_TOL = 0.1
_GYRO_REL = 0.3
#: a gap between samples longer than this has no steering rate [s]
_MAX_RATE_GAP_S = 0.1


def beta_rates(t_ns: np.ndarray, beta: np.ndarray, geom: RobotGeometry) -> np.ndarray:
    """β̇ (N, n) [rad/s]: backward differences of consecutive samples (the first sample's and
    those after a gap longer than 0.1 s are 0); with unlimited steering the difference is taken
    modulo π (a coaxial module's angle may jump by π between samples, the same axis)."""
    rate = np.zeros_like(beta)
    if beta.shape[0] < 2:
        return rate
    dt = np.diff(t_ns).astype(np.float64) * 1e-9
    d = np.diff(beta, axis=0)
    if geom.unlimited_steering:
        d = np.mod(d + np.pi / 2, np.pi) - np.pi / 2
    ok = (dt > 0) & (dt <= _MAX_RATE_GAP_S)
    rate[1:][ok] = d[ok] / dt[ok, None]
    return rate


def linear_start(beta, phidot, geom: RobotGeometry, weight=None, beta_rate=None) -> tuple[np.ndarray, np.ndarray]:
    """The global least-squares (δ, s) of the complex linear model (module docstring): the contact
    points where the logged angles put them and the steering's own contact speed b β̇ scaled with
    the wheel's (exact for coaxial modules, a start for the others); s normalised to a geometric
    mean of 1; of c and −c (which fit alike), the one whose offsets' circular mean is within ±90°."""
    n = geom.n
    w = np.ones(beta.shape[0]) if weight is None else weight
    gam = geom.alpha + beta
    h = gam - np.pi / 2
    mag = geom.r * phidot + (0.0 if beta_rate is None else geom.b * beta_rate)
    za, zb = mag * np.cos(h), mag * np.sin(h)
    z = np.empty(beta.shape + (2, 2))  # (N, n, 2, 2): c -> c z as a real 2x2 map of (Re c, Im c)
    z[..., 0, 0], z[..., 0, 1], z[..., 1, 0], z[..., 1, 1] = za, -zb, zb, za
    px = geom.axis_xy[:, 0] + geom.b * np.cos(gam)
    py = geom.axis_xy[:, 1] + geom.b * np.sin(gam)
    basis = np.zeros(beta.shape + (2, 3))  # (N, n, 2, 3): rigid velocities of the contact points
    basis[..., 0, 0] = basis[..., 1, 1] = 1.0
    basis[..., 0, 2], basis[..., 1, 2] = -py, px
    b2 = basis.reshape(beta.shape[0], 2 * n, 3)
    btb = np.einsum("tki,tkj->tij", b2, b2)
    proj = np.einsum("tki,tij,tlj->tkl", b2, np.linalg.inv(btb), b2)
    q = (np.eye(2 * n)[None] - proj).reshape(beta.shape[0], n, 2, n, 2)
    m = np.einsum("t,tkab,tkalc,tlcd->kbld", w, z, q, z, optimize=True).reshape(2 * n, 2 * n)
    _, vec = np.linalg.eigh(m)
    c = vec[0::2, 0] + 1j * vec[1::2, 0]
    mag_c = np.abs(c)
    if np.any(mag_c < 1e-9 * max(mag_c.max(), 1e-300)):
        raise ValueError("a module's wheel never moves in the moving samples: it cannot be calibrated")
    scale = mag_c / np.exp(np.mean(np.log(mag_c)))
    if abs(np.angle(np.sum(c / mag_c))) > np.pi / 2:  # c and −c fit alike: the turn nearer zero
        c = -c
    return np.angle(c), scale


def apply_offsets(beta, phidot, geom: RobotGeometry, offset, scale) -> tuple[np.ndarray, np.ndarray]:
    """β + δ and s φ̇, coaxial modules folded back into the steering range (see
    :func:`estimation.logs.source.fold_coaxial`)."""
    from estimation.logs.source import fold_coaxial

    return fold_coaxial(np.asarray(beta) + offset, np.asarray(phidot) * scale, geom)


@dataclass
class CalibrationFit:
    """What :func:`fit_calibration` found.

    Attributes:
        steer_offset: (n,) δ_k [rad] to add to the logged angle (β or heading alike).
        wheel_scale: (n,) s_k, the factor to apply to the logged wheel speed; relative (geometric
            mean 1) unless ``scale_absolute``.
        offset_std, scale_std: (n,) standard errors of the last Gauss–Newton step (from the
            residuals' spread; they ignore errors that repeat from sample to sample).
        weakest_std_deg: the standard error of the worst-determined combination of relative offsets
            and factors [deg] (at most :data:`MAX_WEAK_STD_DEG`, else the fit is refused).
        common_observable: whether the log fixes the common offset of all modules (else their
            circular mean is set to zero); common_std_deg: its standard error [deg].
        scale_absolute: the factors are absolute (a gyro saw the robot turn).
        samples: moving samples used; iterations: Gauss–Newton iterations; rms_rad: the final RMS
            normalised residual [rad]; notes: what a reader should know (one sentence each).
    """

    steer_offset: np.ndarray
    wheel_scale: np.ndarray
    offset_std: np.ndarray
    scale_std: np.ndarray
    common_observable: bool
    common_std_deg: float
    weakest_std_deg: float
    scale_absolute: bool
    samples: int
    iterations: int
    rms_rad: float
    notes: list[str] = field(default_factory=list)


def _objective(theta, beta, brate, phidot, geom, speed, yaw_rate, yaw_w):
    n = geom.n
    xi, res = rigid_fit(beta, brate, phidot, geom, theta[:n], np.exp(theta[n:]), yaw_rate, yaw_w)
    r = res / speed[:, None]
    if yaw_rate is not None:
        r = np.concatenate([r, (yaw_w * (xi[:, 2] - yaw_rate) / speed)[:, None]], axis=1)
    return r


_STRONG = 1e6


def _gauge(n: int, info: np.ndarray, free_scale: bool, hold_common: bool) -> np.ndarray:
    """Penalty terms that fix what the log leaves free: the mean log-scale (unless ``free_scale``),
    and the common offset, held strongly with ``hold_common``, else weakly (so that a log that
    barely fixes it still gives a well-posed step)."""
    g = np.zeros((2 * n, 2 * n))
    if not free_scale:
        g0 = np.concatenate([np.zeros(n), np.ones(n) / n])
        g += _STRONG * np.outer(g0, g0)
    g1 = np.concatenate([np.ones(n) / n, np.zeros(n)])
    g += (_STRONG if hold_common else 1e-6 * np.trace(info) / (2 * n)) * np.outer(g1, g1)
    return g


def _gauss_newton(theta, beta, brate, phidot, geom, speed, yaw_rate, yaw_w, free_scale, iters=30):
    """Gauss–Newton with Huber sample weights; the mean log-scale held at 0 unless ``free_scale``
    and the common offset softly held where the log leaves it free. Returns θ, the final normalised
    residuals, the information matrix and the iteration count."""
    n = geom.n
    p = 2 * n
    h = 1e-6
    info = np.eye(p)
    it = 0
    for it in range(1, iters + 1):  # noqa: B007 (the count is returned)
        r0 = _objective(theta, beta, brate, phidot, geom, speed, yaw_rate, yaw_w)
        norm = np.sqrt(np.sum(r0**2, axis=1))
        w = np.where(norm <= _HUBER, 1.0, _HUBER / np.maximum(norm, 1e-300))
        sw = np.sqrt(w)[:, None]
        jac = np.empty((r0.size, p))
        for j in range(p):
            tp = theta.copy()
            tp[j] += h
            jac[:, j] = ((_objective(tp, beta, brate, phidot, geom, speed, yaw_rate, yaw_w) - r0) * sw).ravel() / h
        rw = (r0 * sw).ravel()
        info = jac.T @ jac
        a, b = info + _gauge(n, info, free_scale, hold_common=False), -jac.T @ rw
        if not free_scale:  # the mean log-scale pulled back to 0
            g0 = np.concatenate([np.zeros(n), np.ones(n) / n])
            b -= _STRONG * g0 * (g0 @ theta)
        step = np.linalg.lstsq(a, b, rcond=None)[0]
        theta = theta + step
        if np.abs(step).max() < 1e-9:
            break
    return theta, r0, info, it


def _start_theta(beta, brate, phidot, geom: RobotGeometry, pre, yaw_rate, coaxial: bool, start_offset):
    """The start of the fit, (offsets, log scales): the linear start on the moving samples ``pre``
    (or ``start_offset``), turned by 180° where the gyro says coaxial modules drive backwards."""
    n = geom.n
    if start_offset is None:
        spd = np.abs(geom.r * phidot[pre]).max(axis=1)
        offset, scale = linear_start(beta[pre], phidot[pre], geom, weight=1.0 / spd**2, beta_rate=brate[pre])
    else:
        offset, scale = np.asarray(start_offset, dtype=np.float64), np.ones(n)
    if yaw_rate is not None and coaxial and start_offset is None:  # the gyro settles the common 180°
        xi, _ = rigid_fit(beta[pre], brate[pre], phidot[pre], geom, offset, scale)
        ok = np.isfinite(yaw_rate[pre])
        if np.sum(xi[ok, 2] * yaw_rate[pre][ok]) < 0:
            offset = offset + np.pi
    return np.concatenate([offset, np.log(scale)])


def _fit_on_moving(theta, beta, brate, phidot, geom: RobotGeometry, yaw_rate, moving_speed: float):
    """Two passes: the moving mask from the calibrated rigid fit, then the Gauss-Newton fit on it.
    Returns (theta, residuals, information, moving, the samples used, turning, iterations)."""
    n = geom.n
    have_yaw = yaw_rate is not None
    yaw_w = 0.0
    if have_yaw:
        yaw_w = float(np.mean(np.hypot(geom.axis_xy[:, 0], geom.axis_xy[:, 1])))  # a yaw rate as an axis speed
    fit_iters = 0
    for _ in range(2):
        xi, _ = rigid_fit(beta, brate, phidot, geom, theta[:n], np.exp(theta[n:]))
        speed = contact_speeds(xi, beta + theta[:n], geom).max(axis=1)
        moving = speed >= moving_speed
        use = moving & (np.isfinite(yaw_rate) if have_yaw else True)
        if use.sum() < MIN_MOVING_SAMPLES:
            raise ValueError(f"{int(use.sum())} moving samples (the wheels' rigid fit at {moving_speed} m/s or "
                             f"faster); calibration needs at least {MIN_MOVING_SAMPLES}")
        yr = yaw_rate[use] if have_yaw else None
        turning = have_yaw and np.sum(np.abs(yr) * yaw_w >= 0.2 * speed[use]) >= MIN_MOVING_SAMPLES // 4
        # a sample's scale: its speed, plus the contact points' own speed while steering (b β̇: the
        # finite difference of the angles lags and amplifies their noise) and a floor
        norm = speed[use] + np.abs(geom.b * brate[use]).max(axis=1) + _SPEED_FLOOR
        theta, r, info, iters = _gauss_newton(theta, beta[use], brate[use], phidot[use], geom, norm, yr,
                                              yaw_w if have_yaw else 0.0, free_scale=bool(turning))
        fit_iters += iters
    return theta, r, info, moving, use, turning, fit_iters


def _check_gyro(theta, beta, brate, phidot, geom: RobotGeometry, yaw_rate) -> None:
    """The wheels alone (no gyro rows) must turn as the gyro says, else one of them is wrong (``ValueError``)."""
    n = geom.n
    xi, _ = rigid_fit(beta, brate, phidot, geom, theta[:n], np.exp(theta[n:]))
    diff = float(np.sqrt(np.mean((xi[:, 2] - yaw_rate) ** 2)))
    own = float(np.sqrt(np.mean(yaw_rate ** 2)))
    if diff > _GYRO_TOL + _GYRO_REL * own:
        raise ValueError(f"the gyro and the wheels disagree on the turn rate while moving (RMS {diff:.2f} rad/s, "
                         f"the gyro's own {own:.2f} rad/s): a gyro in another unit (--yaw-unit), an entry that is "
                         "not the heading, or a drive motor inverted; calibrate without the gyro, or fix it")


def _uncertainty(r, info, n: int, turning) -> tuple[float, float, bool, float]:
    """The residual variance, the common offset's standard error [rad], whether it is observable,
    and the weakest combination's standard error [deg] (``ValueError`` when the motions are too alike)."""
    dof = max(r.size - 2 * n, 1)
    sigma2 = float(np.sum(r**2) / dof)
    # the common offset's standard error: the mean offset's variance, the other parameters free
    g1 = np.concatenate([np.ones(n) / n, np.zeros(n)])
    cov0 = np.linalg.pinv(info + _gauge(n, info, bool(turning), hold_common=False)) * sigma2
    common_std = math.sqrt(max(float(g1 @ cov0 @ g1), 0.0))
    observable = math.degrees(common_std) < COMMON_OBSERVABLE_DEG
    gauge = np.zeros((2 * n, 2))
    gauge[:n, 0], gauge[n:, 1] = 1.0, 1.0
    proj = np.eye(2 * n) - gauge @ np.linalg.pinv(gauge)
    eig = np.linalg.eigvalsh(proj @ info @ proj)[2:]  # the two gauge directions are the zeros
    weakest = math.degrees(math.sqrt(sigma2 / max(eig.min(), 1e-300)))
    # an exact log of one motion has no noise to scale by: its weakest combination is still unfixed
    if weakest > MAX_WEAK_STD_DEG or eig.min() < 1e-3 * eig.max():
        raise ValueError(f"the log's motions are too alike to tell the modules' offsets apart (the weakest "
                         f"combination is uncertain by ±{weakest:.1f}°, {MAX_WEAK_STD_DEG}° at most): drive in several "
                         "directions and turn (or the angles are not in the unit given: --angle-unit)")
    return sigma2, common_std, observable, weakest


def _offsets_and_notes(theta, n: int, observable: bool, coaxial: bool, have_yaw: bool):
    """The fitted offsets in (-π, π] with the common part the log leaves free settled, the scales,
    and the notes that say how it was settled."""
    offset, scale = theta[:n].copy(), np.exp(theta[n:])
    notes = []
    if not observable:
        offset -= math.atan2(np.mean(np.sin(offset)), np.mean(np.cos(offset)))
        notes.append("The log does not fix the common offset of all modules ("
                     + ("the robot barely turns while moving, and the gyro cannot fix it either" if have_yaw
                        else "the robot barely turns, and no gyro")
                     + "): the offsets are relative, set so that their circular mean is zero (or your current "
                     "offsets' common part); all modules may share one more unknown turn.")
    elif coaxial and not have_yaw:
        mean = math.atan2(np.mean(np.sin(offset)), np.mean(np.cos(offset)))
        if abs(mean) > math.pi / 2:  # the robot driving backwards fits as well: take the turn nearer zero
            offset += math.pi
        notes.append("Without a gyro, every coaxial module turned by 180° fits as well (the robot driving backwards): "
                     "the common offset is taken within ±90°.")
    offset = np.mod(offset + np.pi, 2 * np.pi) - np.pi
    return offset, scale, notes


def fit_calibration(t_ns, beta, phidot, geom: RobotGeometry, *, moving_speed: float = MOVING_SPEED,
                    yaw_rate=None, start_offset=None) -> tuple[CalibrationFit, np.ndarray]:
    """Fit each module's steering offset and wheel factor to a log (module docstring).

    Args:
        t_ns: (N,) int64 timestamps [ns], strictly increasing; beta (N, n) the logged angles in the
            paper's convention (a heading log converted by ``beta_from_heading``); phidot (N, n)
            the logged wheel spin rates [rad/s] (already finite: the caller skips bad samples).
        moving_speed: the moving threshold [m/s] on the rigid fit's fastest axis point.
        yaw_rate: (N,) the gyro's yaw rate at the samples [rad/s] (NaN where it has none), or None.
        start_offset: (n,) offsets to start from [rad] instead of the linear start (tests).

    Returns:
        the fit and the (N,) moving mask it used (after calibration).

    Raises ``ValueError`` with fewer than :data:`MIN_MOVING_SAMPLES` moving samples (the message
    says how many the log has), or motions too alike to tell the offsets apart.
    """
    n = geom.n
    beta = np.asarray(beta, dtype=np.float64)
    phidot = np.asarray(phidot, dtype=np.float64)
    brate = beta_rates(np.asarray(t_ns, dtype=np.int64), beta, geom)
    pre = np.abs(geom.r * phidot).max(axis=1) >= moving_speed
    if pre.sum() < MIN_MOVING_SAMPLES:
        raise ValueError(f"{int(pre.sum())} samples with a wheel moving at {moving_speed} m/s or faster; "
                         f"calibration needs at least {MIN_MOVING_SAMPLES} (drive the robot: translate in several "
                         "directions and turn)")
    have_yaw = yaw_rate is not None
    if have_yaw:
        yaw_rate = np.asarray(yaw_rate, dtype=np.float64)
    coaxial = bool(np.all(geom.b == 0.0))
    theta = _start_theta(beta, brate, phidot, geom, pre, yaw_rate, coaxial, start_offset)
    theta, r, info, moving, use, turning, fit_iters = _fit_on_moving(theta, beta, brate, phidot, geom, yaw_rate,
                                                                     moving_speed)
    if have_yaw:
        _check_gyro(theta, beta[use], brate[use], phidot[use], geom, yaw_rate[use])
    sigma2, common_std, observable, weakest = _uncertainty(r, info, n, turning)
    cov = np.linalg.pinv(info + _gauge(n, info, bool(turning), hold_common=not observable)) * sigma2
    offset, scale, notes = _offsets_and_notes(theta, n, observable, coaxial, have_yaw)
    scale_absolute = bool(have_yaw and turning)
    if not scale_absolute:
        notes.append("Wheel factors are relative (geometric mean 1): "
                     + ("the gyro saw too little turning to fix their scale." if have_yaw
                        else "a log without a gyro cannot tell a uniformly larger wheel from a faster robot."))
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    fit = CalibrationFit(steer_offset=offset, wheel_scale=scale, offset_std=std[:n], scale_std=std[n:] * scale,
                         common_observable=observable, common_std_deg=math.degrees(common_std),
                         weakest_std_deg=weakest,
                         scale_absolute=scale_absolute, samples=int(use.sum()), iterations=fit_iters,
                         rms_rad=float(np.sqrt(np.mean(np.sum(r**2, axis=1)))), notes=notes)
    return fit, moving
