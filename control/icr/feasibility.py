"""What the wheels allow: the ICR controller's feasibility checks.

* speed: the largest |μ| every wheel's φ̇ limit allows at λ (:func:`mu_bounds`, :func:`clamp_mu`);
* steering axes: targets are kept out of a cap around each steering axis ŝ_k, where β_k is
  undefined (:func:`project_off_axes`);
* great-circle arcs: whether λ can move to λ_d without a wheel crossing its steering stop or λ
  passing a steering axis (:func:`arc_check`, :func:`reference_stop_mask`);
* holds at a steering stop: the point of λ's cell (the region bounded by the wheels' stop
  circles) nearest to a target beyond it (:func:`stop_hold_point_batch`);
* steering stops: the room each wheel has to brake before its stop (:func:`stop_room`,
  :func:`safe_stop_speed`) and the per-wheel saturation fallback (:func:`saturate`).

Unlimited steering (``RobotGeometry.unlimited_steering``, e.g. the ``swerve`` preset): there is
no stop to cross, so no arc is blocked by one (each wheel takes the angle of its axis nearest
where it is, ``RobotGeometry.nearest_steering``) and no wheel brakes for one; the steering axes
(where β_k is undefined) still stop the robot.

The derivations are in ``docs/icr-controller.md`` (sections "Feasible targets" and "Arcs"). Every
function is batched over robots (``*_batch`` takes (N, …) rows; the unsuffixed form is its N = 1
case, with the same bits).
"""

from __future__ import annotations

import enum

import numpy as np

from control.checks import check_unit, check_unit_batch
from control.icr.config import ICRControllerConfig
from control.icr.kernels import stop_hold_row, stop_normals
from control.limits import ActuatorLimits
from estimation.geometry import RobotGeometry
from estimation.hrep import nearer_representative, slerp, sphere_angle
from estimation.kinematics import steering_from_lambda, wheel_speed_coefficients

__all__ = ["mu_bounds", "clamp_mu", "feasible_target", "project_off_axes_batch", "project_off_axes",
           "arc_check_batch", "arc_check", "arc_blocked", "must_stop", "reference_stop_mask", "stop_hold_point_batch",
           "stop_room",
           "safe_stop_speed", "saturate", "wrap_half", "ArcReason"]


class ArcReason(enum.IntEnum):
    """Codes of :func:`arc_check_batch`: why an arc cannot be driven continuously."""

    NONE = 0  #: it can
    STOP = 1  #: some wheel's β_k would wrap across its steering stops
    AXIS = 2  #: λ would pass a steering axis


def wrap_half(x: np.ndarray) -> np.ndarray:
    """Angle difference modulo π into [−π/2, π/2[ (β and β + π are the same axis)."""
    return np.mod(np.asarray(x) + np.pi / 2, np.pi) - np.pi / 2


def mu_bounds(lam, geom: RobotGeometry, limits: ActuatorLimits, headroom: float = 1.0) -> np.ndarray:
    """Largest |μ| [m/s] for which every wheel's |φ̇| ≤ headroom·φ̇_max at λ, at rest in λ.

    From r_k φ̇_k = μ c_k with c_k = (s⊥2,k − b_k ẑ)·λ (``docs/icr-controller.md``, eq. (W)):
    |μ| ≤ r_k φ̇_max / |c_k|, intersected over the wheels (the interval at ±φ̇_max is symmetric,
    so sorting is not needed). Batched over λ.
    """
    c = np.abs(wheel_speed_coefficients(lam, geom))
    bound = headroom * limits.wheel_speed_max * geom.r / np.where(c > 0, c, np.inf)
    return np.min(bound, axis=-1)


def clamp_mu(lam_d, mu_d, geom: RobotGeometry, limits: ActuatorLimits, headroom: float = 1.0) -> np.ndarray:
    """μ_d clamped to the wheel-speed limits at λ_d (see :func:`mu_bounds`). Batched."""
    bound = mu_bounds(lam_d, geom, limits, headroom)
    return np.clip(np.asarray(mu_d, dtype=np.float64), -bound, bound)


def project_off_axes_batch(lam_d, lam, geom: RobotGeometry, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`project_off_axes` for (N, 3) targets and current λ: returns ((N, 3), (N,) wheel or −1)."""
    lam_d = check_unit_batch(lam_d, "lam_d")
    lam = check_unit_batch(lam, "lam")
    out = lam_d.copy()
    idx = np.full(lam_d.shape[0], -1, dtype=np.int64)
    for k in range(geom.n):
        s = geom.s_unit[k]
        sk = s[None, :] * np.where(np.sum(s[None, :] * lam_d, axis=-1) >= 0, 1.0, -1.0)[:, None]
        ang = sphere_angle(sk, lam_d)
        hit = (idx < 0) & (ang < margin)
        for i in np.flatnonzero(hit):  # rare: a target within the margin of a steering axis
            ski = sk[i]
            through = lam_d[i] if ang[i] > 1e-9 else lam[i] * (1.0 if np.sum(lam[i] * ski) >= 0 else -1.0)
            if sphere_angle(ski, through) < 1e-9:
                # λ on the axis too: any direction away from it will do; pick one orthogonal to s_k.
                through = np.cross(ski, [0.0, 0.0, 1.0]) if abs(ski[2]) < 0.9 else np.cross(ski, [1.0, 0.0, 0.0])
                through = ski * np.cos(1.0) + through / np.linalg.norm(through) * np.sin(1.0)
            out[i] = slerp(ski[None, :], np.asarray(through)[None, :], np.array([margin]))[0]
            idx[i] = k
    return out, idx


def project_off_axes(lam_d, lam, geom: RobotGeometry, margin: float) -> tuple[np.ndarray, int]:
    """Move a target λ_d out of the cap of angular radius ``margin`` around each steering axis.

    A target inside the cap of ŝ_k (on either hemisphere) is moved to the cap's rim on the great
    circle from ŝ_k through λ_d, or, if λ_d is on the axis itself, through the current λ: along
    that circle β_k is constant, so approaching the rim does not swing wheel k (every great
    circle through ŝ_k is one of wheel k's propulsion-axis circles, estimation paper eq. (15)).

    Returns (λ_d', index of the wheel whose cap held λ_d, or −1). The N = 1 case of
    :func:`project_off_axes_batch`.
    """
    check_unit(lam_d, "lam_d"), check_unit(lam, "lam")
    out, idx = project_off_axes_batch(np.asarray(lam_d, dtype=np.float64)[None, :],
                                      np.asarray(lam, dtype=np.float64)[None, :], geom, margin)
    return out[0], int(idx[0])


def feasible_target(lam, lam_d, mu_d, geom: RobotGeometry, limits: ActuatorLimits, config: ICRControllerConfig
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The target the controller drives toward, row by row (λ, λ_d (N, 3) unit, μ_d (N,)):

    1. a stop command (|μ_d| < ``zero_mu_tol``) holds λ: no wheel swings;
    2. the representative of (λ_d, μ_d) nearer to λ;
    3. λ_d moved out of the steering-axis caps (:func:`project_off_axes_batch`), then 2. again;
    4. μ_d clamped to the wheel-speed limits at λ_d, with ``mu_headroom`` (:func:`clamp_mu`).

    Returns (λ_d, μ_d, stop command (N,) bool, axis cap (N,): the wheel whose cap held λ_d, or −1).
    """
    zero_cmd = np.abs(mu_d) < config.zero_mu_tol
    lam_d = np.where(zero_cmd[:, None], lam, lam_d)
    mu_d = np.where(zero_cmd, 0.0, mu_d)
    lam_d, mu_d = nearer_representative(lam, lam_d, mu_d)
    lam_d, axis_k = project_off_axes_batch(lam_d, lam, geom, config.axis_margin)
    lam_d, mu_d = nearer_representative(lam, lam_d, mu_d)
    mu_d = clamp_mu(lam_d, mu_d, geom, limits, config.mu_headroom)
    return lam_d, mu_d, zero_cmd, axis_k


def arc_check_batch(lam, lam_d, geom: RobotGeometry, axis_margin: float, step: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`arc_check` for (N, 3) arcs: (reason (N,) :class:`ArcReason` code, free (N,), theta (N,))."""
    lam = check_unit_batch(lam, "lam")
    lam_d = check_unit_batch(lam_d, "lam_d")
    nrows = lam.shape[0]
    theta = sphere_angle(lam, lam_d)
    m = np.maximum(2, np.ceil(theta / step).astype(np.int64) + 1)
    big = int(m.max()) if nrows else 2
    j = np.arange(big)
    # np.linspace(0, θ, m) row by row (the same arithmetic), padded with θ beyond m
    angles = j[None, :] * (theta / (m - 1))[:, None]
    angles = np.where(j[None, :] >= (m - 1)[:, None], theta[:, None], angles)
    pts = slerp(lam, lam_d, angles)  # (N, M, 3)
    sin_to_axis = np.linalg.norm(np.cross(pts[:, :, None, :], geom.s_unit[None, None, :, :]), axis=-1)
    # the endpoints may sit on a cap rim (projected target, or λ itself): only the interior counts
    near = (np.any(sin_to_axis < np.sin(0.5 * axis_margin), axis=-1)
            & (j[None, :] >= 1) & (j[None, :] < (m - 1)[:, None]))
    beta = steering_from_lambda(pts.reshape(-1, 3), geom).reshape(nrows, big, geom.n)
    wraps = np.any(np.abs(np.diff(beta, axis=1)) > np.pi / 2, axis=-1) & (j[None, :-1] < (m - 1)[:, None])
    if geom.unlimited_steering:  # no stop: a wrap of F is the same axis, the wheel goes on turning
        wraps[:] = False
    first_axis = np.where(near.any(axis=1), np.argmax(near, axis=1), m)
    first_wrap = np.where(wraps.any(axis=1), np.argmax(wraps, axis=1) + 1, m)
    rows = np.arange(nrows)
    none = (first_axis == m) & (first_wrap == m)
    axis = ~none & (first_axis <= first_wrap - 1)
    reason = np.where(none, ArcReason.NONE, np.where(axis, ArcReason.AXIS, ArcReason.STOP))
    free = np.where(none, theta, np.where(axis, angles[rows, np.maximum(first_axis - 1, 0)],
                                          angles[rows, np.clip(first_wrap - 1, 0, big - 1)]))
    return reason, free, theta


def arc_check(lam, lam_d, geom: RobotGeometry, axis_margin: float, step: float) -> tuple[str | None, float, float]:
    """Whether the great-circle arc λ -> λ_d can be driven continuously.

    Returns ``(reason, free, theta)``: ``reason`` is None, ``"stop"`` if some wheel's β_k would
    wrap across the steering stops along the arc (a jump of more than π/2 between samples
    ``step`` apart), or ``"axis"`` if the arc passes closer than ``axis_margin``/2 to a steering
    axis (estimation paper eq. (21)); ``free`` is the arc angle [rad] from λ that can be driven
    before the first such point, ``theta`` the whole arc's angle [rad]. The N = 1 case of
    :func:`arc_check_batch`.
    """
    check_unit(lam, "lam"), check_unit(lam_d, "lam_d")
    reason, free, theta = arc_check_batch(np.asarray(lam, dtype=np.float64)[None, :],
                                          np.asarray(lam_d, dtype=np.float64)[None, :], geom, axis_margin, step)
    code = ArcReason(int(reason[0]))
    return (None if code == ArcReason.NONE else code.name.lower()), float(free[0]), float(theta[0])


def arc_blocked(lam, lam_d, geom: RobotGeometry, axis_margin: float, step: float) -> str | None:
    """The reason of :func:`arc_check` alone: None, ``"stop"`` or ``"axis"``."""
    return arc_check(lam, lam_d, geom, axis_margin, step)[0]


def must_stop(lam: np.ndarray, lam_d: np.ndarray, geom: RobotGeometry, config: ICRControllerConfig) -> np.ndarray:
    """Whether reaching λ_d from λ (N, 3) needs a stop and reconfiguration, row by row: the arc
    passes a steering axis, or goes past a steering stop by more than ``stop_hysteresis``."""
    reason, free, theta = arc_check_batch(lam, lam_d, geom, config.axis_margin, config.arc_step)
    return (reason == ArcReason.AXIS) | ((reason == ArcReason.STOP) & (theta - free >= config.stop_hysteresis))


def stop_hold_point_batch(lam, lam_d, geom: RobotGeometry, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Where to hold a target λ_d that lies beyond a steering stop, row by row (λ, λ_d (N, 3)).

    Wheel k's steering stop β_k = β_max (mod π) is a great circle through ŝ_k, its *stop circle*
    n_k·λ = 0 with n_k = sin β_max (a_k − l_k) − cos β_max a⊥_k (eq. (15) at β_max; for AZIMUT's
    ±π/2 stops n_k = a_k − l_k, the denominator of eq. (16)). The stop circles cut the sphere into
    convex *cells* in which no β_k passes its stop. The hold point is the point of λ's cell nearest
    to λ_d (on an edge or at a vertex), moved ``margin`` [rad] into the cell
    (``ICRControllerConfig.stop_hold_margin``): the motion the wheels can make without a
    reconfiguration that misses the target's least, with every wheel at least ``margin`` (in β:
    |∂β_k/∂λ| ≥ ‖a_k − l_k‖ ≥ 1 on its stop circle) short of its stop. A path that runs *along* a stop
    circle (a wheel at ±π/2 for a while) is then followed exactly, sliding along the circle,
    instead of being held at one point of it.

    Returns (points (N, 3), angle from each point to λ_d [rad], −1 where λ_d is in λ's cell or no
    point is found). One compiled function computes each row (:func:`control.icr.kernels.stop_hold_row`),
    for this reference and for the compiled step alike."""
    lam = np.ascontiguousarray(lam, dtype=np.float64)
    lam_d = np.ascontiguousarray(lam_d, dtype=np.float64)
    normals = np.empty((geom.n, 3))
    stop_normals(geom.a_minus_l, geom.a_perp, float(geom.steer_max), normals)
    points = np.zeros(lam.shape)
    angle = np.empty(lam.shape[0])
    for i in range(lam.shape[0]):
        angle[i] = stop_hold_row(lam[i], lam_d[i], normals, float(margin), points[i])
    return points, angle


def reference_stop_mask(lams, geom: RobotGeometry, axis_margin: float = np.deg2rad(3.0)) -> np.ndarray:
    """For a densely sampled reference ICR path λ_0..λ_M (M+1, 3): (M,) bool, True where the
    controller will have to stop and reconfigure between λ_i and λ_{i+1}: some β_k wraps across
    the steering stops, or λ passes within ``axis_margin``/2 of a steering axis (estimation paper
    eq. (21)). The same tests as :func:`arc_blocked`, for a path planner (the path follower slows
    down to arrive at these points slowly)."""
    lams = np.asarray(lams, dtype=np.float64)
    if lams.ndim != 2 or lams.shape[1] != 3 or lams.shape[0] < 2:
        raise ValueError(f"lams must have shape (M + 1 >= 2, 3), got {lams.shape}")
    beta = steering_from_lambda(lams, geom)
    wrap = np.any(np.abs(np.diff(beta, axis=0)) > np.pi / 2, axis=1) & (not geom.unlimited_steering)
    unit = lams / np.linalg.norm(lams, axis=1, keepdims=True)
    near = np.any(np.linalg.norm(np.cross(unit[:, None, :], geom.s_unit[None, :, :]), axis=-1)
                  < np.sin(0.5 * axis_margin), axis=1)
    return wrap | near[1:] | near[:-1]


def stop_room(beta, beta_rate, geom: RobotGeometry) -> np.ndarray:
    """Angle [rad] left before the steering stop each wheel is turning toward (inf at rest, and
    always without stops)."""
    if geom.unlimited_steering:
        return np.full(np.broadcast(beta, beta_rate).shape, np.inf)
    return np.where(beta_rate > 0, geom.steer_max - beta, np.where(beta_rate < 0, beta - geom.steer_min, np.inf))


def safe_stop_speed(room, accel, dt) -> np.ndarray:
    """Largest steering speed v from which braking at ``accel``, one period late, stops within
    ``room``: v dt/2 + v²/(2 a) ≤ room (``docs/icr-controller.md``, eq. (B))."""
    room = np.maximum(room, 0.0)
    return -0.5 * accel * dt + np.sqrt((0.5 * accel * dt) ** 2 + 2.0 * accel * room)


def saturate(beta_prev, beta_rate_prev, phidot_prev, beta_want, phidot_want, geom: RobotGeometry,
             limits: ActuatorLimits, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-wheel saturation of a command (fallback): rate, accel, braking before the stops, range,
    then φ̇ and φ̈."""
    a = limits.steer_accel_max
    rate = (beta_want - beta_prev) / dt
    rate = np.clip(rate, beta_rate_prev - a * dt, beta_rate_prev + a * dt)
    rate = np.clip(rate, -limits.steer_rate_max, limits.steer_rate_max)
    # a wheel turning toward its stop brakes (within the accel limit) so it can stop before it
    room = stop_room(beta_prev + rate * dt, rate, geom)
    v_safe = np.maximum(safe_stop_speed(room, 0.95 * a, dt), np.abs(beta_rate_prev) - a * dt)
    rate = np.sign(rate) * np.minimum(np.abs(rate), v_safe)
    beta = beta_prev + rate * dt
    if not geom.unlimited_steering:
        beta = np.clip(beta, geom.steer_min + 1e-9, geom.steer_max)
    rate = (beta - beta_prev) / dt
    phidot = np.clip(phidot_want, phidot_prev - limits.wheel_accel_max * dt, phidot_prev + limits.wheel_accel_max * dt)
    phidot = np.clip(phidot, -limits.wheel_speed_max, limits.wheel_speed_max)
    return beta, rate, phidot

