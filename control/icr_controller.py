"""The ICR-based reference controller: coordinated wheel commands from an H-state target.

It follows the companion control paper (Clavien, Lauria, Michaud, RAS 2018, the estimation paper's
ref. [24]) as summarised in ``shared/notes/icr-controller.md``; bracketed numbers [..] cite that
paper's equations as reported there, (..) cite the estimation paper.

The controller keeps its own *reference* H state η = (λ, μ) and drives it toward the target
(λ_d, μ_d) on the sphere. Every command is the wheel configuration of a single motion, so the
propulsion axes always concur (no actuator antagonism):

* steering set-points β_c = F(λ) (eq. (16)–(17));
* propulsion set-points r φ̇_c = μ (s⊥2 − b ẑ)·λ − b β̇_c, including the b/r steer-to-drive
  coupling of the sidewise wheel (kinematics module).

Per control step (RUNNING):

1. the nearer of ±λ_d is used, μ_d flipping with it [note step 1];
2. μ_d is clamped to what every wheel's φ̇ limit allows at λ_d [25];
3. a target within ``axis_margin`` of a steering axis (eq. (21)) is moved to the rim of that cap,
   along the great circle from the current λ, so β stays defined and slow;
4. the great-circle arc λ -> λ_d is checked: if it passes a steering stop (some β_k wraps) or a
   steering axis, the controller stops, reconfigures the wheels in place and goes on
   (RUNNING -> STOPPING -> RECONFIGURING -> RUNNING); a target only just past a stop is held at
   the stop (λ waits there) for at most ``stop_hold_time``, so jitter does not turn wheels by π
   but a target that stays past the stop is not missed for long;
5. otherwise λ moves along the great circle toward λ_d with a braking profile, and μ toward μ_d.
   The step is *time-scaled* [35–36] in discrete form: a common factor κ ∈ [0, 1] blends the
   previous motion (λ̇, μ̇ carried over) with the desired one, and the largest κ for which every
   wheel's β̇, β̈, φ̇ and φ̈ (finite differences of the commands over one period) stay within
   :class:`azimut_env.params.ActuatorLimits` is taken. Should no κ be feasible (not observed in
   practice), the commands are saturated wheel by wheel and ``info["saturated"]`` is set, so
   commanded limits are never exceeded.

The commands are integrated from the previous *commands*, not from the measurements, so sensor
noise does not reach the set-points; the measurements (β, φ̇, λ̂, μ̂) are used to start, to detect
that the robot has stopped, and to detect a wheel knocked out of place (then the same
stop-and-reconfigure sequence recovers it).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field, replace

import numpy as np

from estimation.geometry import RobotGeometry
from estimation.kinematics import steering_from_lambda, steering_gradient, wheel_speed_coefficients

from .limits import ActuatorLimits

__all__ = [
    "Mode",
    "ICRControllerConfig",
    "ICRControllerState",
    "WheelCommand",
    "ICRController",
    "nearer_target",
    "clamp_mu",
    "mu_bounds",
    "project_off_axes",
    "arc_blocked",
    "arc_check",
    "reference_stop_mask",
    "slerp",
    "initial_state",
    "icr_control_step",
]


class Mode(enum.IntEnum):
    """Controller states [note: reconfiguration state machine]."""

    RUNNING = 0
    STOPPING = 1
    RECONFIGURING = 2


@dataclass(frozen=True)
class ICRControllerConfig:
    """Tuning of the ICR controller.

    Attributes:
        k_lambda: gain of the great-circle approach λ -> λ_d [1/s] (λ̇ = k_λ · angle, capped).
        mu_accel_fraction: fraction of the wheel acceleration limit that the μ ramp uses [-]; the
            rest is kept for the λ motion and the steer-to-drive coupling.
        mu_headroom: fraction of the φ̇ limit that μ_d may use at λ_d [-]; the rest is kept for the
            b/r steer-to-drive coupling and for transitions.
        axis_margin: angular radius of the cap around each steering axis ŝ_k that targets may not
            enter [rad] (eq. (21)).
        n_kappa: number of time-scaling factors κ tried per step (grid on [0, 1]).
        arc_step: spacing of the samples of the λ -> λ_d arc checked for stop crossings [rad].
        stop_mu_tol: |μ| [m/s] below which the robot counts as stopped (commanded and estimated).
        zero_mu_tol: |μ_d| [m/s] below which the target is a stop command: λ is held, the wheels
            do not swing.
        kick_tol: measured-versus-commanded steering error [rad] (modulo π) that counts as a
            wheel knocked out of place; it triggers stop-and-reconfigure.
        reconfig_tol: steering error [rad] below which a reconfiguration is complete.
        reconfig_freeze: while RECONFIGURING, the configuration being reached follows a new target
            only if that target is not reachable from it without another stop, and only while
            some steering command is farther than this [rad] from it (so it converges exactly;
            the RUNNING mode then takes the remaining motion).
        reconfig_timeout: time [s] after which RECONFIGURING resumes even if a measured wheel
            angle has not settled within ``reconfig_tol`` (commands have).
        coupling_from_measurement: in RECONFIGURING, compute the steer-to-drive coupling
            r φ̇ = −b β̇ from the measured steering rate (finite difference of the measured β)
            instead of the commanded one: the compliant steering lags its set-point.
        reconfig_rate_fraction, reconfig_accel_fraction: fractions of the steering rate and
            acceleration limits used when turning the wheels in place [-] (slower turns scrub
            less: the compliant steering lags less behind its set-point).
        stop_hysteresis: a target less than this arc [rad] past a steering stop is held at the
            stop (the robot goes on with λ at the stop) instead of triggering a reconfiguration.
        stop_hold_time: longest time [s] a target may stay held at a steering stop: one that stays
            past the stop longer is not jitter but a motion the wheels cannot make from this side
            (the held λ then misses it, the path follower's feedback pushes it farther past, and
            the tracking error grows until the hysteresis is exceeded, at speed), so the robot
            stops and reconfigures at once.
        stop_timeout: time [s] in STOPPING, with μ_c = 0, after which the robot counts as stopped
            even if μ̂ is noisy.
    """

    k_lambda: float = 15.0
    mu_accel_fraction: float = 0.7
    mu_headroom: float = 0.85
    axis_margin: float = np.deg2rad(3.0)
    n_kappa: int = 33
    arc_step: float = np.deg2rad(0.5)
    stop_mu_tol: float = 0.02
    zero_mu_tol: float = 1e-3
    kick_tol: float = np.deg2rad(25.0)
    reconfig_tol: float = np.deg2rad(2.0)
    reconfig_freeze: float = np.deg2rad(5.0)
    reconfig_timeout: float = 2.0
    stop_timeout: float = 0.5
    stop_hysteresis: float = np.deg2rad(6.0)
    stop_hold_time: float = 0.1
    coupling_from_measurement: bool = False
    reconfig_rate_fraction: float = 0.5
    reconfig_accel_fraction: float = 0.3

    def __post_init__(self) -> None:
        for name in ("k_lambda", "mu_accel_fraction", "mu_headroom", "axis_margin", "arc_step", "stop_mu_tol",
                     "zero_mu_tol", "kick_tol", "reconfig_tol", "reconfig_freeze", "reconfig_timeout", "stop_timeout",
                     "stop_hold_time"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"ICRControllerConfig.{name} must be finite and > 0, got {value!r}")
        if self.mu_headroom > 1:
            raise ValueError(f"ICRControllerConfig.mu_headroom must be in ]0, 1], got {self.mu_headroom}")
        if self.n_kappa < 2:
            raise ValueError(f"ICRControllerConfig.n_kappa must be >= 2, got {self.n_kappa}")


@dataclass(frozen=True)
class ICRControllerState:
    """Internal state between steps (frozen; a step returns a new one).

    Attributes:
        mode: the state machine's mode.
        lam: (3,) reference λ (unit).
        mu: reference μ [m/s].
        lam_rate: (3,) λ̇, tangent to the sphere at ``lam`` [rad/s].
        beta: (n,) last steering commands β_c [rad].
        beta_rate: (n,) last steering rates β̇_c [rad/s].
        phidot: (n,) last propulsion commands φ̇_c [rad/s].
        mode_time: time spent in the current mode [s].
        reconfig_lam: (3,) λ the wheels are being reconfigured for (RECONFIGURING only).
        events: number of stop-and-reconfigure sequences started so far.
        beta_meas: (n,) the previous step's measured steering angles [rad] (for the measured
            steering rate), or None.
        held_time: how long [s] the target has been held at a steering stop without a break.
    """

    mode: Mode
    lam: np.ndarray
    mu: float
    lam_rate: np.ndarray
    beta: np.ndarray
    beta_rate: np.ndarray
    phidot: np.ndarray
    mode_time: float = 0.0
    reconfig_lam: np.ndarray | None = None
    events: int = 0
    beta_meas: np.ndarray | None = None
    held_time: float = 0.0


@dataclass(frozen=True)
class WheelCommand:
    """Set-points for one control period.

    Attributes:
        beta: (n,) steering set-points β_c [rad], inside the steering range.
        phidot: (n,) propulsion set-points φ̇_c [rad/s].
        beta_rate: (n,) β̇_c [rad/s] (finite difference over the period).
        beta_accel: (n,) β̈_c [rad/s²].
        phiddot: (n,) φ̈_c [rad/s²].
        info: diagnostics (mode, κ, the target actually used, saturation flag, ...).
    """

    beta: np.ndarray
    phidot: np.ndarray
    beta_rate: np.ndarray
    beta_accel: np.ndarray
    phiddot: np.ndarray
    info: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------------------------
# pure building blocks
# ----------------------------------------------------------------------------------------------


def _unit3(x, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    norm = np.linalg.norm(arr)
    if norm == 0:
        raise ValueError(f"{name} is the zero vector, not a point of Λ")
    return arr / norm


def _finite(x, name: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    return arr


def nearer_target(lam, lam_d, mu_d) -> tuple[np.ndarray, np.ndarray]:
    """The representative of (λ_d, μ_d) ≡ (−λ_d, −μ_d) nearer to λ: λ·λ_d ≥ 0 [note step 1].

    Batched: λ, λ_d (..., 3), μ_d (...). Returns (λ_d, μ_d) with the sign flipped where needed.
    """
    lam = np.asarray(lam, dtype=np.float64)
    lam_d = np.asarray(lam_d, dtype=np.float64)
    sign = np.where(np.sum(lam * lam_d, axis=-1) < 0, -1.0, 1.0)
    return lam_d * sign[..., None], np.asarray(mu_d, dtype=np.float64) * sign


def mu_bounds(lam, geom: RobotGeometry, limits: ActuatorLimits, headroom: float = 1.0) -> np.ndarray:
    """Largest |μ| [m/s] for which every wheel's |φ̇| ≤ headroom·φ̇_max at λ, at rest in λ [25].

    From r_k φ̇_k = μ c_k with c_k = (s⊥2,k − b_k ẑ)·λ: |μ| ≤ r_k φ̇_max / |c_k|, intersected over
    the wheels (the interval at ±φ̇_max is symmetric, so sorting is not needed). Batched over λ.
    """
    c = np.abs(wheel_speed_coefficients(lam, geom))
    bound = headroom * limits.wheel_speed_max * geom.r / np.where(c > 0, c, np.inf)
    return np.min(bound, axis=-1)


def clamp_mu(lam_d, mu_d, geom: RobotGeometry, limits: ActuatorLimits, headroom: float = 1.0) -> np.ndarray:
    """μ_d clamped to the wheel-speed limits at λ_d (see :func:`mu_bounds`). Batched."""
    bound = mu_bounds(lam_d, geom, limits, headroom)
    return np.clip(np.asarray(mu_d, dtype=np.float64), -bound, bound)


def slerp(lam, lam_d, angle) -> np.ndarray:
    """The point ``angle`` [rad] from unit λ along the great circle toward unit λ_d.

    Batched over ``angle`` (...,) for one pair (λ, λ_d). If λ_d = ±λ, returns λ.
    """
    lam = np.asarray(lam, dtype=np.float64)
    tang = lam_d - np.dot(lam, lam_d) * lam
    tn = np.linalg.norm(tang)
    angle = np.asarray(angle, dtype=np.float64)
    if tn < 1e-15:
        return np.broadcast_to(lam, angle.shape + (3,)).copy()
    e = tang / tn
    return np.cos(angle)[..., None] * lam + np.sin(angle)[..., None] * e


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle [rad] between unit vectors, in [0, π]."""
    return float(np.arctan2(np.linalg.norm(np.cross(a, b)), np.dot(a, b)))


def project_off_axes(lam_d, lam, geom: RobotGeometry, margin: float) -> tuple[np.ndarray, int]:
    """Move a target λ_d out of the cap of angular radius ``margin`` around each steering axis.

    A target inside the cap of ŝ_k (on either hemisphere) is moved to the cap's rim on the great
    circle from ŝ_k through λ_d, or, if λ_d is on the axis itself, through the current λ: along
    that circle β_k = F_k is constant, so approaching the rim does not swing wheel k (all the
    propulsion great circles of wheel k pass through s_k, eq. (15)).

    Returns (λ_d', index of the wheel whose cap held λ_d, or −1).
    """
    lam_d = _unit3(lam_d, "lam_d")
    lam = _unit3(lam, "lam")
    for k in range(geom.n):
        sk = geom.s_unit[k] * (1.0 if np.dot(geom.s_unit[k], lam_d) >= 0 else -1.0)
        if _angle(sk, lam_d) < margin:
            through = lam_d if _angle(sk, lam_d) > 1e-9 else lam * (1.0 if np.dot(lam, sk) >= 0 else -1.0)
            if _angle(sk, through) < 1e-9:
                # λ on the axis too: any direction away from it will do; pick one orthogonal to s_k.
                through = np.cross(sk, [0.0, 0.0, 1.0]) if abs(sk[2]) < 0.9 else np.cross(sk, [1.0, 0.0, 0.0])
                through = sk * np.cos(1.0) + through / np.linalg.norm(through) * np.sin(1.0)
            return slerp(sk, through, margin), k
    return lam_d, -1


def arc_check(lam, lam_d, geom: RobotGeometry, axis_margin: float, step: float) -> tuple[str | None, float, float]:
    """Whether the great-circle arc λ -> λ_d can be driven continuously.

    Returns ``(reason, free, theta)``: ``reason`` is None, ``"stop"`` if some wheel's β = F_k
    would wrap across the steering stops along the arc (a jump of more than π/2 between samples
    ``step`` apart), or ``"axis"`` if the arc passes closer than ``axis_margin``/2 to a steering
    axis (eq. (21)); ``free`` is the arc angle [rad] from λ that can be driven before the first
    such point, ``theta`` the whole arc's angle [rad].
    """
    lam = _unit3(lam, "lam")
    lam_d = _unit3(lam_d, "lam_d")
    theta = _angle(lam, lam_d)
    m = max(2, int(np.ceil(theta / step)) + 1)
    angles = np.linspace(0.0, theta, m)
    pts = slerp(lam, lam_d, angles)
    sin_to_axis = np.linalg.norm(np.cross(pts[:, None, :], geom.s_unit[None, :, :]), axis=-1)
    # the endpoints may sit on a cap rim (projected target, or λ itself): only the interior counts
    near = np.any(sin_to_axis < np.sin(0.5 * axis_margin), axis=1)
    near[0] = near[-1] = False
    beta = steering_from_lambda(pts, geom)
    wraps = np.any(np.abs(np.diff(beta, axis=0)) > np.pi / 2, axis=1)
    first_axis = int(np.argmax(near)) if near.any() else m
    first_wrap = int(np.argmax(wraps)) + 1 if wraps.any() else m
    if first_axis == m and first_wrap == m:
        return None, theta, theta
    if first_axis <= first_wrap - 1:
        return "axis", float(angles[max(first_axis - 1, 0)]), theta
    return "stop", float(angles[first_wrap - 1]), theta


def arc_blocked(lam, lam_d, geom: RobotGeometry, axis_margin: float, step: float) -> str | None:
    """The reason of :func:`arc_check` alone: None, ``"stop"`` or ``"axis"``."""
    return arc_check(lam, lam_d, geom, axis_margin, step)[0]


def reference_stop_mask(lams, geom: RobotGeometry, axis_margin: float = np.deg2rad(3.0)) -> np.ndarray:
    """For a densely sampled reference ICR path λ_0..λ_M (M+1, 3): (M,) bool, True where the
    controller will have to stop and reconfigure between λ_i and λ_{i+1}: some β_k = F_k wraps
    across the steering stops, or λ passes within ``axis_margin``/2 of a steering axis
    (eq. (21)). The same tests as :func:`arc_blocked`, for a path planner (the path follower
    slows down to arrive at these points slowly)."""
    lams = np.asarray(lams, dtype=np.float64)
    if lams.ndim != 2 or lams.shape[1] != 3 or lams.shape[0] < 2:
        raise ValueError(f"lams must have shape (M + 1 >= 2, 3), got {lams.shape}")
    beta = steering_from_lambda(lams, geom)
    wrap = np.any(np.abs(np.diff(beta, axis=0)) > np.pi / 2, axis=1)
    unit = lams / np.linalg.norm(lams, axis=1, keepdims=True)
    near = np.any(np.linalg.norm(np.cross(unit[:, None, :], geom.s_unit[None, :, :]), axis=-1)
                  < np.sin(0.5 * axis_margin), axis=1)
    return wrap | near[1:] | near[:-1]


# ----------------------------------------------------------------------------------------------
# the step
# ----------------------------------------------------------------------------------------------


def initial_state(lam_hat, beta, phidot, geom: RobotGeometry, config: ICRControllerConfig | None = None) -> ICRControllerState:
    """Start from the measurements, at rest (μ = 0).

    The reference λ is the estimate λ̂. If the measured wheels are not at F(λ̂) within
    ``reconfig_tol`` (a random start), the controller starts in RECONFIGURING.
    """
    config = config or ICRControllerConfig()
    lam = _unit3(lam_hat, "lam_hat")
    beta = geom.wrap_steering(_finite(beta, "beta", (geom.n,)))
    phidot = _finite(phidot, "phidot", (geom.n,))
    err = _wrap_half(beta - steering_from_lambda(lam, geom, singular_fill=beta))
    mode = Mode.RUNNING if np.max(np.abs(err)) <= config.reconfig_tol else Mode.RECONFIGURING
    return ICRControllerState(mode=mode, lam=lam, mu=0.0, lam_rate=np.zeros(3), beta=beta.copy(), beta_meas=beta.copy(),
                              beta_rate=np.zeros(geom.n), phidot=phidot.copy(),
                              reconfig_lam=lam if mode == Mode.RECONFIGURING else None)


def _wrap_half(x: np.ndarray) -> np.ndarray:
    """Angle difference modulo π into [−π/2, π/2[ (β and β + π are the same axis)."""
    return np.mod(np.asarray(x) + np.pi / 2, np.pi) - np.pi / 2


def _exp_map(lam: np.ndarray, v: np.ndarray) -> np.ndarray:
    """exp_λ(v) on the unit sphere for tangent vectors v (..., 3) at unit λ (3,)."""
    nv = np.linalg.norm(v, axis=-1, keepdims=True)
    safe = np.where(nv > 0, nv, 1.0)
    out = np.cos(nv) * lam + np.sin(nv) * v / safe
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def _stop_room(beta, beta_rate, geom) -> np.ndarray:
    """Angle [rad] left before the steering stop each wheel is turning toward (inf at rest)."""
    return np.where(beta_rate > 0, geom.steer_max - beta, np.where(beta_rate < 0, beta - geom.steer_min, np.inf))


def _safe_stop_speed(room, accel, dt) -> np.ndarray:
    """Largest steering speed from which braking at ``accel``, one period late, stops within ``room``:
    v dt/2 + v²/(2 a) ≤ room."""
    room = np.maximum(room, 0.0)
    return -0.5 * accel * dt + np.sqrt((0.5 * accel * dt) ** 2 + 2.0 * accel * room)


def _saturate(beta_prev, beta_rate_prev, phidot_prev, beta_want, phidot_want, geom, limits, dt):
    """Per-wheel saturation of a command (fallback): rate, accel, braking before the stops, range,
    then φ̇ and φ̈."""
    a = limits.steer_accel_max
    rate = (beta_want - beta_prev) / dt
    rate = np.clip(rate, beta_rate_prev - a * dt, beta_rate_prev + a * dt)
    rate = np.clip(rate, -limits.steer_rate_max, limits.steer_rate_max)
    # a wheel turning toward its stop brakes (within the accel limit) so it can stop before it
    room = _stop_room(beta_prev + rate * dt, rate, geom)
    v_safe = np.maximum(_safe_stop_speed(room, 0.95 * a, dt), np.abs(beta_rate_prev) - a * dt)
    rate = np.sign(rate) * np.minimum(np.abs(rate), v_safe)
    beta = np.clip(beta_prev + rate * dt, geom.steer_min + 1e-9, geom.steer_max)
    rate = (beta - beta_prev) / dt
    phidot = np.clip(phidot_want, phidot_prev - limits.wheel_accel_max * dt, phidot_prev + limits.wheel_accel_max * dt)
    phidot = np.clip(phidot, -limits.wheel_speed_max, limits.wheel_speed_max)
    return beta, rate, phidot


def _coordinated_step(state: ICRControllerState, lam_d: np.ndarray, mu_d: float, geom: RobotGeometry,
                      limits: ActuatorLimits, config: ICRControllerConfig, dt: float, mu_first: bool = False):
    """One time-scaled step of (λ, μ) toward (λ_d, μ_d) with every wheel on the surface.

    With ``mu_first`` (STOPPING), μ takes its full ramp step whatever κ the λ motion gets, so the
    robot brakes at once even while λ is still slowing down.

    Returns (λ, μ, λ̇, β_c, β̇_c, φ̇_c, info).
    """
    lam = state.lam
    # desired λ̇: along the great circle toward λ_d, braking so that it can stop at λ_d
    theta = _angle(lam, lam_d)
    grad = steering_gradient(lam, geom)  # (n, 3)
    gmax = float(np.max(np.linalg.norm(grad, axis=-1)))
    accel_lam = 0.8 * limits.steer_accel_max / max(gmax, 1e-6)  # λ angular accel every wheel can follow
    speed = min(config.k_lambda * theta, np.sqrt(2.0 * accel_lam * theta), theta / dt)
    tang = lam_d - np.dot(lam, lam_d) * lam
    tn = np.linalg.norm(tang)
    v_des = tang / tn * speed if tn > 1e-15 else np.zeros(3)
    v_prev = state.lam_rate - np.dot(state.lam_rate, lam) * lam  # carried over, in the tangent plane
    # desired μ: a ramp toward μ_d at the acceleration every wheel can follow at λ
    c_now = np.abs(wheel_speed_coefficients(lam, geom))
    accel_mu = config.mu_accel_fraction * limits.wheel_accel_max * float(
        np.min(geom.r / np.where(c_now > 0, c_now, np.inf)))
    mu_des = state.mu + float(np.clip(mu_d - state.mu, -accel_mu * dt, accel_mu * dt))

    kappa = np.linspace(0.0, 1.0, config.n_kappa)
    v = v_prev[None, :] + kappa[:, None] * (v_des - v_prev)[None, :]
    lam_new = _exp_map(lam, v * dt)
    mu_new = np.full(kappa.shape, mu_des) if mu_first else state.mu + kappa * (mu_des - state.mu)
    fill = np.broadcast_to(state.beta, (kappa.size, geom.n))
    beta_new = steering_from_lambda(lam_new, geom, singular_fill=fill)
    dbeta = beta_new - state.beta[None, :]
    flipped = np.any(np.abs(dbeta) > np.pi / 2, axis=1)
    beta_rate = dbeta / dt
    beta_acc = (beta_rate - state.beta_rate[None, :]) / dt
    c = wheel_speed_coefficients(lam_new, geom, beta_new)
    phidot = (mu_new[:, None] * c - geom.b[None, :] * beta_rate) / geom.r[None, :]
    phiddot = (phidot - state.phidot[None, :]) / dt
    # every wheel must keep the room to brake before the stop it turns toward (a wheel that runs
    # into a stop at speed would exceed the acceleration limit there)
    v_stop = _safe_stop_speed(_stop_room(beta_new, beta_rate, geom), 0.8 * limits.steer_accel_max, dt)
    ratio = np.max(np.stack([
        np.abs(beta_rate) / limits.steer_rate_max,
        np.abs(beta_acc) / limits.steer_accel_max,
        np.abs(phidot) / limits.wheel_speed_max,
        np.abs(phiddot) / limits.wheel_accel_max,
        np.abs(beta_rate) / np.maximum(v_stop, 1e-12),
    ]), axis=(0, 2))
    ratio = np.where(flipped, np.inf, ratio)
    feasible = ratio <= 1.0 - 1e-9
    info: dict = {}
    if np.any(feasible):
        i = int(np.flatnonzero(feasible)[-1])
        info["saturated"] = False
        beta_c, rate_c, phidot_c = beta_new[i], beta_rate[i], phidot[i]
    else:
        i = int(np.argmin(ratio))
        info["saturated"] = True
        beta_c, rate_c, phidot_c = _saturate(state.beta, state.beta_rate, state.phidot,
                                             beta_new[i] if not flipped[i] else state.beta,
                                             phidot[i], geom, limits, dt)
    info["kappa"] = float(kappa[i])
    lam_rate = v[i]
    return lam_new[i], float(mu_new[i]), lam_rate, beta_c, rate_c, phidot_c, info


def _must_stop(lam: np.ndarray, lam_d: np.ndarray, geom: RobotGeometry, config: ICRControllerConfig) -> bool:
    """Whether reaching λ_d from λ needs a stop and reconfiguration: the arc passes a steering
    axis, or goes past a steering stop by more than ``stop_hysteresis``."""
    blocked, free, theta = arc_check(lam, lam_d, geom, config.axis_margin, config.arc_step)
    return blocked == "axis" or (blocked == "stop" and theta - free >= config.stop_hysteresis)


def _reconfigure_step(state: ICRControllerState, beta_target: np.ndarray, geom: RobotGeometry,
                      limits: ActuatorLimits, dt: float, exact: bool = False,
                      measured_rate: np.ndarray | None = None, rate_fraction: float = 0.95,
                      accel_fraction: float = 0.95):
    """Turn each wheel in place toward ``beta_target`` (μ = 0), rate- and accel-limited.

    With ``exact``, ``beta_target`` is taken as the next set-point as it is (the caller made it
    feasible). With ``measured_rate``, the coupling uses the wheels' measured steering rate: the
    compliant steering lags its set-point, and it is the actual contact point that must roll.

    Each wheel follows a discrete trapezoidal profile. The propulsion set-point is the pure
    steer-to-drive coupling r φ̇ = −b β̇, so the contact point rolls on its circle about A_k
    instead of scrubbing, and the chassis stays put.
    """
    err = beta_target - state.beta  # both inside the range: the direct way never crosses a stop
    a, vmax = limits.steer_accel_max * accel_fraction, limits.steer_rate_max * rate_fraction
    if exact:  # ``beta_target`` is already a feasible next set-point
        rate = err / dt
    else:
        # discrete braking profile: moving v for one period, then braking at a_plan, covers
        # v²/(2 a_plan) + v dt/2; planning with less deceleration than allowed leaves margin
        a_plan = 0.85 * a
        vstop = -0.5 * a_plan * dt + np.sqrt((0.5 * a_plan * dt) ** 2 + 2.0 * a_plan * np.abs(err))
        want = np.sign(err) * np.minimum(vmax, np.minimum(vstop, np.abs(err) / dt))
        # speeding up follows the gentle profile; braking (less speed, or a reversal) may use the
        # full limit, so a wheel still turning toward a stop when the reconfiguration starts
        # stops short of it instead of being clipped there
        braking = (want * state.beta_rate < 0) | (np.abs(want) < np.abs(state.beta_rate) - 1e-12)
        a_step = np.where(braking, np.maximum(a, 0.95 * limits.steer_accel_max), a) * dt
        rate = np.clip(want, state.beta_rate - a_step, state.beta_rate + a_step)
    beta = np.clip(state.beta + rate * dt, geom.steer_min + 1e-9, geom.steer_max)
    rate = (beta - state.beta) / dt
    phidot_want = -geom.b * (rate if measured_rate is None else measured_rate) / geom.r
    _, _, phidot = _saturate(state.beta, state.beta_rate, state.phidot, beta, phidot_want, geom, limits, dt)
    return beta, rate, phidot


def _stop_step(state: ICRControllerState, geom: RobotGeometry, limits: ActuatorLimits,
               config: ICRControllerConfig, dt: float):
    """Bring μ to 0 with λ held (STOPPING), through the coordinated, time-scaled step."""
    return _coordinated_step(state, state.lam, 0.0, geom, limits, config, dt, mu_first=True)


def icr_control_step(state: ICRControllerState, lam_hat, mu_hat, beta_meas, phidot_meas, lam_d, mu_d,
                     geom: RobotGeometry, limits: ActuatorLimits, config: ICRControllerConfig,
                     dt: float) -> tuple[ICRControllerState, WheelCommand]:
    """One control period of the ICR controller (pure: returns the new state and the command).

    Args:
        state: from :func:`initial_state` or the previous step.
        lam_hat: (3,) estimated λ̂ (any sign); mu_hat: estimated μ̂ [m/s] (sign paired with λ̂).
        beta_meas: (n,) measured steering angles [rad]; phidot_meas: (n,) measured φ̇ [rad/s].
        lam_d: (3,) target ICR (any non-zero vector, any sign); mu_d: target μ [m/s].
        dt: control period [s].

    Raises:
        ValueError: on non-finite input, wrong shapes, a zero λ_d, or dt <= 0.
    """
    n = geom.n
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0, got {dt!r}")
    lam_hat = _unit3(lam_hat, "lam_hat")
    mu_hat = float(_finite(mu_hat, "mu_hat", ()))
    beta_meas = _finite(beta_meas, "beta_meas", (n,))
    _finite(phidot_meas, "phidot_meas", (n,))
    lam_d = _unit3(lam_d, "lam_d")
    mu_d = float(_finite(mu_d, "mu_d", ()))

    info: dict = {"saturated": False, "event": None}
    zero_cmd = abs(mu_d) < config.zero_mu_tol
    if zero_cmd:
        lam_d, mu_d = state.lam, 0.0  # a stop command holds λ: no wheel swings
    lam_d, mu_d = nearer_target(state.lam, lam_d, mu_d)
    lam_d, axis_k = project_off_axes(lam_d, state.lam, geom, config.axis_margin)
    lam_d, mu_d = nearer_target(state.lam, lam_d, mu_d)
    mu_d = float(clamp_mu(lam_d, mu_d, geom, limits, config.mu_headroom))
    info.update(lam_target=lam_d, mu_target=mu_d, axis_cap=axis_k)

    mode, mode_time, events, reconfig_lam = state.mode, state.mode_time + dt, state.events, state.reconfig_lam
    held_time = 0.0

    # a wheel knocked out of place (measured far from commanded) -> stop and reconfigure
    kicked = bool(np.max(np.abs(_wrap_half(beta_meas - state.beta))) > config.kick_tol)
    if mode == Mode.RUNNING:
        blocked = None
        if not zero_cmd:
            blocked, free, theta = arc_check(state.lam, lam_d, geom, config.axis_margin, config.arc_step)
            if blocked == "stop" and theta - free < config.stop_hysteresis:
                held_time = state.held_time + dt
                if held_time <= config.stop_hold_time + 1e-9:
                    # only just past a steering stop: wait at the stop instead of turning wheels
                    # by π; a target that keeps going (or stays past) reconfigures once, a
                    # jittering one never does
                    lam_d = slerp(state.lam, lam_d, free)
                    blocked = None
                    info["held_at_stop"] = True
        if kicked or blocked is not None:
            info["event"] = "kick" if kicked else blocked
            events += 1
            mode, mode_time = Mode.STOPPING, 0.0
    if mode == Mode.STOPPING:
        stopped = state.mu == 0.0 and np.linalg.norm(state.lam_rate) < 1e-9 and (
            abs(mu_hat) < config.stop_mu_tol or mode_time > config.stop_timeout)
        if stopped:
            mode, mode_time = Mode.RECONFIGURING, 0.0
    if mode == Mode.RECONFIGURING and reconfig_lam is None:
        reconfig_lam = lam_d
    if mode == Mode.RECONFIGURING:
        if (not zero_cmd and np.max(np.abs(state.beta - steering_from_lambda(
                reconfig_lam, geom, singular_fill=state.beta))) > config.reconfig_freeze
                and _must_stop(reconfig_lam, lam_d, geom, config)):
            # retarget only if the latest target could not be reached continuously from the
            # configuration being reached (RUNNING does the rest); no chasing a jittery target
            reconfig_lam = lam_d
        beta_target = steering_from_lambda(reconfig_lam, geom, singular_fill=state.beta)
        settled_cmd = np.max(np.abs(state.beta - beta_target)) < 1e-6 and np.max(np.abs(state.beta_rate)) < 1e-9
        settled_meas = np.max(np.abs(_wrap_half(beta_meas - beta_target))) < config.reconfig_tol
        if settled_cmd and (settled_meas or mode_time > config.reconfig_timeout) and not zero_cmd:
            state = replace(state, lam=reconfig_lam, mu=0.0, lam_rate=np.zeros(3))
            mode, mode_time, reconfig_lam = Mode.RUNNING, 0.0, None
            lam_d, mu_d = nearer_target(state.lam, lam_d, mu_d)

    if mode == Mode.RECONFIGURING:
        if zero_cmd:
            # hold: brake the steering to rest where it is (at full deceleration, so it stops
            # short of where the reconfiguration was heading, inside the range); do not swing
            rate = np.sign(state.beta_rate) * np.maximum(np.abs(state.beta_rate) - limits.steer_accel_max * dt, 0.0)
            beta_target = state.beta + rate * dt
        measured_rate = None
        if config.coupling_from_measurement and state.beta_meas is not None:
            measured_rate = _wrap_half(beta_meas - state.beta_meas) / dt
        beta_c, rate_c, phidot_c = _reconfigure_step(state, beta_target, geom, limits, dt,
                                                     exact=zero_cmd, measured_rate=measured_rate,
                                                     rate_fraction=config.reconfig_rate_fraction,
                                                     accel_fraction=config.reconfig_accel_fraction)
        lam_new, mu_new, lam_rate = state.lam, 0.0, np.zeros(3)
        info["kappa"] = 0.0
    elif mode == Mode.STOPPING:
        lam_new, mu_new, lam_rate, beta_c, rate_c, phidot_c, sinfo = _stop_step(state, geom, limits, config, dt)
        info.update(sinfo)
        if abs(mu_new) < 1e-9:
            mu_new = 0.0
    else:
        lam_new, mu_new, lam_rate, beta_c, rate_c, phidot_c, sinfo = _coordinated_step(
            state, lam_d, mu_d, geom, limits, config, dt)
        info.update(sinfo)
    if mode == Mode.STOPPING and abs(mu_new) < 1e-6 * max(1.0, abs(state.mu)) and np.linalg.norm(lam_rate) < 1e-6:
        mu_new, lam_rate = 0.0, np.zeros(3)

    accel = (rate_c - state.beta_rate) / dt
    phiddot = (phidot_c - state.phidot) / dt
    info["mode"] = mode
    info["events"] = events
    new_state = ICRControllerState(mode=mode, lam=lam_new, mu=float(mu_new), lam_rate=np.asarray(lam_rate),
                                   beta=np.asarray(beta_c), beta_rate=np.asarray(rate_c),
                                   phidot=np.asarray(phidot_c), mode_time=mode_time,
                                   reconfig_lam=reconfig_lam, events=events, beta_meas=beta_meas.copy(),
                                   held_time=held_time if info.get("held_at_stop") else 0.0)
    cmd = WheelCommand(beta=new_state.beta.copy(), phidot=new_state.phidot.copy(), beta_rate=rate_c.copy(),
                       beta_accel=accel, phiddot=phiddot, info=info)
    return new_state, cmd


class ICRController:
    """Stateful convenience wrapper around :func:`icr_control_step`.

    Args:
        geom: the robot; limits: actuator limits; dt: control period [s] (the env's, 0.02 s by
            default); config: tuning.
    """

    def __init__(self, geom: RobotGeometry, limits: ActuatorLimits | None = None, dt: float = 0.02,
                 config: ICRControllerConfig | None = None) -> None:
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {dt!r}")
        self.geom = geom
        self.limits = limits or ActuatorLimits()
        self.config = config or ICRControllerConfig()
        self.dt = float(dt)
        self.state: ICRControllerState | None = None

    def reset(self, lam_hat, beta, phidot) -> None:
        """Start (at rest) from the current estimate and measurements."""
        self.state = initial_state(lam_hat, beta, phidot, self.geom, self.config)

    def step(self, lam_hat, mu_hat, beta, phidot, lam_d, mu_d) -> WheelCommand:
        """One control period; resets from the measurements on the first call."""
        if self.state is None:
            self.reset(lam_hat, beta, phidot)
        self.state, cmd = icr_control_step(self.state, lam_hat, mu_hat, beta, phidot, lam_d, mu_d,
                                           self.geom, self.limits, self.config, self.dt)
        return cmd

    @property
    def mode(self) -> Mode:
        """The current mode (RUNNING before the first step)."""
        return Mode.RUNNING if self.state is None else self.state.mode
