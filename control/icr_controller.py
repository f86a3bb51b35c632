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

Batching: :func:`icr_control_step_batch` steps N controllers at once (state :class:`ICRBatchState`,
(N, …) arrays; the modes are per-row masks; the κ grid and the arc checks are evaluated for all
rows together). It is the only implementation: :func:`icr_control_step`, :func:`initial_state`,
:func:`arc_check` and :func:`project_off_axes` are its N = 1 case, and give the same bits as
before the batching.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

from azimut_env.validation import check_bool, check_int, check_positive, check_range
from estimation.geometry import RobotGeometry
from estimation.kinematics import steering_from_lambda, steering_gradient, wheel_speed_coefficients

from .limits import ActuatorLimits

__all__ = [
    "Mode",
    "ICRControllerConfig",
    "ICRControllerState",
    "ICRBatchState",
    "BatchWheelCommand",
    "initial_state_batch",
    "icr_control_step_batch",
    "project_off_axes_batch",
    "arc_check_batch",
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
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen)
        for name in ("k_lambda", "mu_accel_fraction", "axis_margin", "arc_step", "stop_mu_tol",
                     "zero_mu_tol", "kick_tol", "reconfig_tol", "reconfig_freeze", "reconfig_timeout", "stop_timeout",
                     "stop_hysteresis", "stop_hold_time"):
            fix(name, check_positive(f"ICRControllerConfig.{name}", getattr(self, name)))
        for name in ("mu_headroom", "reconfig_rate_fraction", "reconfig_accel_fraction"):  # fractions of a limit
            fix(name, check_range(f"ICRControllerConfig.{name}", getattr(self, name), 0.0, 1.0, lo_open=True))
        fix("n_kappa", check_int("ICRControllerConfig.n_kappa", self.n_kappa, min_value=2, max_value=100_000))
        fix("coupling_from_measurement", check_bool("ICRControllerConfig.coupling_from_measurement",
                                                    self.coupling_from_measurement))


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


def _unit_rows(x, name: str) -> np.ndarray:
    """(N, 3) rows normalised; raises on non-finite or zero rows."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    norm = np.linalg.norm(arr, axis=-1)
    if np.any(norm == 0):
        raise ValueError(f"{name} is the zero vector, not a point of Λ")
    return arr / norm[:, None]


def _dot_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sum(a * b, axis=-1)


def _angle_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles [rad] between unit vectors, row by row (..., 3) -> (...), in [0, π]."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), _dot_rows(a, b))


def _slerp_rows(lam: np.ndarray, lam_d: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """:func:`slerp` row by row: λ, λ_d (N, 3), angle (N,) or (N, M) -> (N, 3) or (N, M, 3)."""
    tang = lam_d - _dot_rows(lam, lam_d)[:, None] * lam
    tn = np.linalg.norm(tang, axis=-1)
    degenerate = tn < 1e-15
    e = tang / np.where(degenerate, 1.0, tn)[:, None]
    extra = (None,) * (angle.ndim - 1)
    lam_b, e_b = lam[(slice(None),) + extra], e[(slice(None),) + extra]
    out = np.cos(angle)[..., None] * lam_b + np.sin(angle)[..., None] * e_b
    if np.any(degenerate):
        out[degenerate] = np.broadcast_to(lam_b[degenerate], out[degenerate].shape)
    return out


def project_off_axes_batch(lam_d, lam, geom: RobotGeometry, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`project_off_axes` for (N, 3) targets and current λ: returns ((N, 3), (N,) wheel or −1)."""
    lam_d = _unit_rows(lam_d, "lam_d")
    lam = _unit_rows(lam, "lam")
    out = lam_d.copy()
    idx = np.full(lam_d.shape[0], -1, dtype=np.int64)
    for k in range(geom.n):
        s = geom.s_unit[k]
        sk = s[None, :] * np.where(np.sum(s[None, :] * lam_d, axis=-1) >= 0, 1.0, -1.0)[:, None]
        ang = _angle_rows(sk, lam_d)
        hit = (idx < 0) & (ang < margin)
        for i in np.flatnonzero(hit):  # rare: a target within the margin of a steering axis
            ski = sk[i]
            through = lam_d[i] if ang[i] > 1e-9 else lam[i] * (1.0 if np.sum(lam[i] * ski) >= 0 else -1.0)
            if _angle_rows(ski, through) < 1e-9:
                # λ on the axis too: any direction away from it will do; pick one orthogonal to s_k.
                through = np.cross(ski, [0.0, 0.0, 1.0]) if abs(ski[2]) < 0.9 else np.cross(ski, [1.0, 0.0, 0.0])
                through = ski * np.cos(1.0) + through / np.linalg.norm(through) * np.sin(1.0)
            out[i] = _slerp_rows(ski[None, :], np.asarray(through)[None, :], np.array([margin]))[0]
            idx[i] = k
    return out, idx


def project_off_axes(lam_d, lam, geom: RobotGeometry, margin: float) -> tuple[np.ndarray, int]:
    """Move a target λ_d out of the cap of angular radius ``margin`` around each steering axis.

    A target inside the cap of ŝ_k (on either hemisphere) is moved to the cap's rim on the great
    circle from ŝ_k through λ_d, or, if λ_d is on the axis itself, through the current λ: along
    that circle β_k = F_k is constant, so approaching the rim does not swing wheel k (all the
    propulsion great circles of wheel k pass through s_k, eq. (15)).

    Returns (λ_d', index of the wheel whose cap held λ_d, or −1). The N = 1 case of
    :func:`project_off_axes_batch`.
    """
    _unit3(lam_d, "lam_d"), _unit3(lam, "lam")
    out, idx = project_off_axes_batch(np.asarray(lam_d, dtype=np.float64)[None, :],
                                      np.asarray(lam, dtype=np.float64)[None, :], geom, margin)
    return out[0], int(idx[0])


_REASONS = (None, "stop", "axis")


def arc_check_batch(lam, lam_d, geom: RobotGeometry, axis_margin: float, step: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`arc_check` for (N, 3) arcs: (reason (N,) 0 none / 1 stop / 2 axis, free (N,), theta (N,))."""
    lam = _unit_rows(lam, "lam")
    lam_d = _unit_rows(lam_d, "lam_d")
    nrows = lam.shape[0]
    theta = _angle_rows(lam, lam_d)
    m = np.maximum(2, np.ceil(theta / step).astype(np.int64) + 1)
    big = int(m.max()) if nrows else 2
    j = np.arange(big)
    # np.linspace(0, θ, m) row by row (the same arithmetic), padded with θ beyond m
    angles = j[None, :] * (theta / (m - 1))[:, None]
    angles = np.where(j[None, :] >= (m - 1)[:, None], theta[:, None], angles)
    pts = _slerp_rows(lam, lam_d, angles)  # (N, M, 3)
    sin_to_axis = np.linalg.norm(np.cross(pts[:, :, None, :], geom.s_unit[None, None, :, :]), axis=-1)
    # the endpoints may sit on a cap rim (projected target, or λ itself): only the interior counts
    near = np.any(sin_to_axis < np.sin(0.5 * axis_margin), axis=-1) & (j[None, :] >= 1) & (j[None, :] < (m - 1)[:, None])
    beta = steering_from_lambda(pts.reshape(-1, 3), geom).reshape(nrows, big, geom.n)
    wraps = np.any(np.abs(np.diff(beta, axis=1)) > np.pi / 2, axis=-1) & (j[None, :-1] < (m - 1)[:, None])
    first_axis = np.where(near.any(axis=1), np.argmax(near, axis=1), m)
    first_wrap = np.where(wraps.any(axis=1), np.argmax(wraps, axis=1) + 1, m)
    rows = np.arange(nrows)
    none = (first_axis == m) & (first_wrap == m)
    axis = ~none & (first_axis <= first_wrap - 1)
    reason = np.where(none, 0, np.where(axis, 2, 1))
    free = np.where(none, theta, np.where(axis, angles[rows, np.maximum(first_axis - 1, 0)],
                                          angles[rows, np.clip(first_wrap - 1, 0, big - 1)]))
    return reason, free, theta


def arc_check(lam, lam_d, geom: RobotGeometry, axis_margin: float, step: float) -> tuple[str | None, float, float]:
    """Whether the great-circle arc λ -> λ_d can be driven continuously.

    Returns ``(reason, free, theta)``: ``reason`` is None, ``"stop"`` if some wheel's β = F_k
    would wrap across the steering stops along the arc (a jump of more than π/2 between samples
    ``step`` apart), or ``"axis"`` if the arc passes closer than ``axis_margin``/2 to a steering
    axis (eq. (21)); ``free`` is the arc angle [rad] from λ that can be driven before the first
    such point, ``theta`` the whole arc's angle [rad]. The N = 1 case of :func:`arc_check_batch`.
    """
    _unit3(lam, "lam"), _unit3(lam_d, "lam_d")
    reason, free, theta = arc_check_batch(np.asarray(lam, dtype=np.float64)[None, :],
                                          np.asarray(lam_d, dtype=np.float64)[None, :], geom, axis_margin, step)
    return _REASONS[int(reason[0])], float(free[0]), float(theta[0])


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


@dataclass(frozen=True)
class ICRBatchState:
    """The state of N controllers, as (N, …) arrays (see :class:`ICRControllerState`, field by field).

    ``reconfig_lam`` and ``beta_meas`` are valid only where ``has_reconfig_lam`` / ``has_beta_meas``.
    """

    mode: np.ndarray  # (N,) int64, Mode values
    lam: np.ndarray  # (N, 3)
    mu: np.ndarray  # (N,)
    lam_rate: np.ndarray  # (N, 3)
    beta: np.ndarray  # (N, n)
    beta_rate: np.ndarray  # (N, n)
    phidot: np.ndarray  # (N, n)
    mode_time: np.ndarray  # (N,)
    reconfig_lam: np.ndarray  # (N, 3)
    has_reconfig_lam: np.ndarray  # (N,) bool
    events: np.ndarray  # (N,) int64
    beta_meas: np.ndarray  # (N, n)
    has_beta_meas: np.ndarray  # (N,) bool
    held_time: np.ndarray  # (N,)

    @property
    def num(self) -> int:
        return int(self.mode.shape[0])

    @staticmethod
    def stack(states: "list[ICRControllerState]") -> "ICRBatchState":
        """N single-robot states as one batch."""
        n = states[0].beta.shape[0]
        return ICRBatchState(
            mode=np.array([int(s.mode) for s in states], dtype=np.int64),
            lam=np.array([s.lam for s in states], dtype=np.float64),
            mu=np.array([s.mu for s in states], dtype=np.float64),
            lam_rate=np.array([s.lam_rate for s in states], dtype=np.float64),
            beta=np.array([s.beta for s in states], dtype=np.float64),
            beta_rate=np.array([s.beta_rate for s in states], dtype=np.float64),
            phidot=np.array([s.phidot for s in states], dtype=np.float64),
            mode_time=np.array([s.mode_time for s in states], dtype=np.float64),
            reconfig_lam=np.array([np.zeros(3) if s.reconfig_lam is None else s.reconfig_lam for s in states],
                                  dtype=np.float64),
            has_reconfig_lam=np.array([s.reconfig_lam is not None for s in states], dtype=np.bool_),
            events=np.array([s.events for s in states], dtype=np.int64),
            beta_meas=np.array([np.zeros(n) if s.beta_meas is None else s.beta_meas for s in states],
                               dtype=np.float64),
            has_beta_meas=np.array([s.beta_meas is not None for s in states], dtype=np.bool_),
            held_time=np.array([s.held_time for s in states], dtype=np.float64))

    def robot(self, i: int) -> ICRControllerState:
        """Robot i's state as a single-robot :class:`ICRControllerState`."""
        return ICRControllerState(
            mode=Mode(int(self.mode[i])), lam=self.lam[i].copy(), mu=float(self.mu[i]),
            lam_rate=self.lam_rate[i].copy(), beta=self.beta[i].copy(), beta_rate=self.beta_rate[i].copy(),
            phidot=self.phidot[i].copy(), mode_time=float(self.mode_time[i]),
            reconfig_lam=self.reconfig_lam[i].copy() if self.has_reconfig_lam[i] else None,
            events=int(self.events[i]), beta_meas=self.beta_meas[i].copy() if self.has_beta_meas[i] else None,
            held_time=float(self.held_time[i]))

    def take(self, idx: np.ndarray) -> "ICRBatchState":
        """The rows ``idx`` (integer indices) as a smaller batch."""
        return ICRBatchState(**{name: getattr(self, name)[idx].copy() for name in self.__dataclass_fields__})

    def put(self, idx: np.ndarray, other: "ICRBatchState") -> "ICRBatchState":
        """A copy with the rows ``idx`` (integer indices) replaced by the rows of ``other``."""
        out = {}
        for name in self.__dataclass_fields__:
            arr = getattr(self, name).copy()
            arr[idx] = getattr(other, name)
            out[name] = arr
        return ICRBatchState(**out)


@dataclass(frozen=True)
class BatchWheelCommand:
    """Set-points of N robots for one control period: (N, n) arrays as in :class:`WheelCommand`;
    ``info`` holds (N, …) arrays (mode, events, kappa, saturated, event code 0 none / 1 kick /
    2 stop / 3 axis, held_at_stop, lam_target, mu_target, axis_cap)."""

    beta: np.ndarray
    phidot: np.ndarray
    beta_rate: np.ndarray
    beta_accel: np.ndarray
    phiddot: np.ndarray
    info: dict = field(default_factory=dict)


_EVENTS = (None, "kick", "stop", "axis")


def initial_state_batch(lam_hat, beta, phidot, geom: RobotGeometry,
                        config: ICRControllerConfig | None = None) -> ICRBatchState:
    """:func:`initial_state` for N robots: λ̂ (N, 3), β (N, n), φ̇ (N, n)."""
    config = config or ICRControllerConfig()
    lam = _unit_rows(lam_hat, "lam_hat")
    nrows = lam.shape[0]
    beta = geom.wrap_steering(_finite(beta, "beta", (nrows, geom.n)))
    phidot = _finite(phidot, "phidot", (nrows, geom.n))
    err = _wrap_half(beta - steering_from_lambda(lam, geom, singular_fill=beta))
    reconf = np.max(np.abs(err), axis=-1) > config.reconfig_tol
    return ICRBatchState(
        mode=np.where(reconf, int(Mode.RECONFIGURING), int(Mode.RUNNING)).astype(np.int64), lam=lam,
        mu=np.zeros(nrows), lam_rate=np.zeros((nrows, 3)), beta=beta.copy(), beta_rate=np.zeros((nrows, geom.n)),
        phidot=phidot.copy(), mode_time=np.zeros(nrows), reconfig_lam=np.where(reconf[:, None], lam, 0.0),
        has_reconfig_lam=reconf.copy(), events=np.zeros(nrows, dtype=np.int64), beta_meas=beta.copy(),
        has_beta_meas=np.ones(nrows, dtype=np.bool_), held_time=np.zeros(nrows))


def initial_state(lam_hat, beta, phidot, geom: RobotGeometry, config: ICRControllerConfig | None = None) -> ICRControllerState:
    """Start from the measurements, at rest (μ = 0).

    The reference λ is the estimate λ̂. If the measured wheels are not at F(λ̂) within
    ``reconfig_tol`` (a random start), the controller starts in RECONFIGURING. The N = 1 case of
    :func:`initial_state_batch`.
    """
    _unit3(lam_hat, "lam_hat")
    beta = _finite(beta, "beta", (geom.n,))
    phidot = _finite(phidot, "phidot", (geom.n,))
    return initial_state_batch(np.asarray(lam_hat, dtype=np.float64)[None, :], beta[None, :], phidot[None, :], geom,
                               config).robot(0)


def _wrap_half(x: np.ndarray) -> np.ndarray:
    """Angle difference modulo π into [−π/2, π/2[ (β and β + π are the same axis)."""
    return np.mod(np.asarray(x) + np.pi / 2, np.pi) - np.pi / 2


def _exp_map(lam: np.ndarray, v: np.ndarray) -> np.ndarray:
    """exp_λ(v) on the unit sphere for tangent vectors v (N, K, 3) at unit λ (N, 3)."""
    nv = np.linalg.norm(v, axis=-1, keepdims=True)
    safe = np.where(nv > 0, nv, 1.0)
    out = np.cos(nv) * lam[:, None, :] + np.sin(nv) * v / safe
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


def _coordinated_step(lam, mu, lam_rate, beta, beta_rate, phidot, lam_d, mu_d, mu_first, geom: RobotGeometry,
                      limits: ActuatorLimits, config: ICRControllerConfig, dt: float):
    """One time-scaled step of (λ, μ) toward (λ_d, μ_d) with every wheel on the surface, for N rows
    (λ (N, 3), μ (N,), λ̇ (N, 3), β, β̇, φ̇ (N, n), λ_d (N, 3), μ_d (N,), ``mu_first`` (N,) bool).

    With ``mu_first`` (STOPPING), μ takes its full ramp step whatever κ the λ motion gets, so the
    robot brakes at once even while λ is still slowing down.

    Returns (λ, μ, λ̇, β_c, β̇_c, φ̇_c, κ, saturated), row by row.
    """
    nrows, n = beta.shape
    rows = np.arange(nrows)
    # desired λ̇: along the great circle toward λ_d, braking so that it can stop at λ_d
    theta = _angle_rows(lam, lam_d)
    grad = steering_gradient(lam, geom)  # (N, n, 3)
    gmax = np.max(np.linalg.norm(grad, axis=-1), axis=-1)
    accel_lam = 0.8 * limits.steer_accel_max / np.maximum(gmax, 1e-6)  # λ angular accel every wheel can follow
    speed = np.minimum(np.minimum(config.k_lambda * theta, np.sqrt(2.0 * accel_lam * theta)), theta / dt)
    tang = lam_d - _dot_rows(lam, lam_d)[:, None] * lam
    tn = np.linalg.norm(tang, axis=-1)
    ok = tn > 1e-15
    v_des = np.where(ok[:, None], tang / np.where(ok, tn, 1.0)[:, None] * speed[:, None], 0.0)
    v_prev = lam_rate - _dot_rows(lam_rate, lam)[:, None] * lam  # carried over, in the tangent plane
    # desired μ: a ramp toward μ_d at the acceleration every wheel can follow at λ
    c_now = np.abs(wheel_speed_coefficients(lam, geom))
    accel_mu = config.mu_accel_fraction * limits.wheel_accel_max * np.min(
        geom.r / np.where(c_now > 0, c_now, np.inf), axis=-1)
    mu_des = mu + np.clip(mu_d - mu, -accel_mu * dt, accel_mu * dt)

    kappa = np.linspace(0.0, 1.0, config.n_kappa)
    nk = kappa.size
    v = v_prev[:, None, :] + kappa[None, :, None] * (v_des - v_prev)[:, None, :]  # (N, K, 3)
    lam_new = _exp_map(lam, v * dt)
    mu_new = np.where(mu_first[:, None], mu_des[:, None], mu[:, None] + kappa[None, :] * (mu_des - mu)[:, None])
    fill = np.broadcast_to(beta[:, None, :], (nrows, nk, n)).reshape(-1, n)
    beta_new = steering_from_lambda(lam_new.reshape(-1, 3), geom, singular_fill=fill).reshape(nrows, nk, n)
    dbeta = beta_new - beta[:, None, :]
    flipped = np.any(np.abs(dbeta) > np.pi / 2, axis=-1)
    b_rate = dbeta / dt
    b_acc = (b_rate - beta_rate[:, None, :]) / dt
    c = wheel_speed_coefficients(lam_new.reshape(-1, 3), geom, beta_new.reshape(-1, n)).reshape(nrows, nk, n)
    phid = (mu_new[:, :, None] * c - geom.b * b_rate) / geom.r
    phidd = (phid - phidot[:, None, :]) / dt
    # every wheel must keep the room to brake before the stop it turns toward (a wheel that runs
    # into a stop at speed would exceed the acceleration limit there)
    v_stop = _safe_stop_speed(_stop_room(beta_new, b_rate, geom), 0.8 * limits.steer_accel_max, dt)
    ratio = np.max(np.stack([
        np.abs(b_rate) / limits.steer_rate_max,
        np.abs(b_acc) / limits.steer_accel_max,
        np.abs(phid) / limits.wheel_speed_max,
        np.abs(phidd) / limits.wheel_accel_max,
        np.abs(b_rate) / np.maximum(v_stop, 1e-12),
    ]), axis=(0, 3))
    ratio = np.where(flipped, np.inf, ratio)
    feasible = ratio <= 1.0 - 1e-9
    any_ok = feasible.any(axis=1)
    last_ok = nk - 1 - np.argmax(feasible[:, ::-1], axis=1)
    i = np.where(any_ok, last_ok, np.argmin(ratio, axis=1))
    beta_c, rate_c, phidot_c = beta_new[rows, i], b_rate[rows, i], phid[rows, i]
    sat = ~any_ok
    if np.any(sat):
        want = np.where(flipped[rows, i][:, None], beta, beta_c)
        sb, sr, sp = _saturate(beta[sat], beta_rate[sat], phidot[sat], want[sat], phidot_c[sat], geom, limits, dt)
        beta_c, rate_c, phidot_c = beta_c.copy(), rate_c.copy(), phidot_c.copy()
        beta_c[sat], rate_c[sat], phidot_c[sat] = sb, sr, sp
    return lam_new[rows, i], mu_new[rows, i], v[rows, i], beta_c, rate_c, phidot_c, kappa[i], sat


def _must_stop(lam: np.ndarray, lam_d: np.ndarray, geom: RobotGeometry, config: ICRControllerConfig) -> np.ndarray:
    """Whether reaching λ_d from λ (N, 3) needs a stop and reconfiguration, row by row: the arc
    passes a steering axis, or goes past a steering stop by more than ``stop_hysteresis``."""
    reason, free, theta = arc_check_batch(lam, lam_d, geom, config.axis_margin, config.arc_step)
    return (reason == 2) | ((reason == 1) & (theta - free >= config.stop_hysteresis))


def _reconfigure_step(beta0: np.ndarray, beta_rate0: np.ndarray, phidot0: np.ndarray, beta_target: np.ndarray,
                      geom: RobotGeometry, limits: ActuatorLimits, dt: float, exact: np.ndarray,
                      measured_rate: np.ndarray, use_measured: np.ndarray, rate_fraction: float = 0.95,
                      accel_fraction: float = 0.95):
    """Turn each wheel in place toward ``beta_target`` (μ = 0), rate- and accel-limited; (N, n) rows.

    Where ``exact`` (N,), ``beta_target`` is taken as the next set-point as it is (the caller made it
    feasible). Where ``use_measured`` (N,), the coupling uses the wheels' measured steering rate
    ``measured_rate``: the compliant steering lags its set-point, and it is the actual contact
    point that must roll.

    Each wheel follows a discrete trapezoidal profile. The propulsion set-point is the pure
    steer-to-drive coupling r φ̇ = −b β̇, so the contact point rolls on its circle about A_k
    instead of scrubbing, and the chassis stays put.
    """
    err = beta_target - beta0  # both inside the range: the direct way never crosses a stop
    a, vmax = limits.steer_accel_max * accel_fraction, limits.steer_rate_max * rate_fraction
    # discrete braking profile: moving v for one period, then braking at a_plan, covers
    # v²/(2 a_plan) + v dt/2; planning with less deceleration than allowed leaves margin
    a_plan = 0.85 * a
    vstop = -0.5 * a_plan * dt + np.sqrt((0.5 * a_plan * dt) ** 2 + 2.0 * a_plan * np.abs(err))
    want = np.sign(err) * np.minimum(vmax, np.minimum(vstop, np.abs(err) / dt))
    # speeding up follows the gentle profile; braking (less speed, or a reversal) may use the
    # full limit, so a wheel still turning toward a stop when the reconfiguration starts
    # stops short of it instead of being clipped there
    braking = (want * beta_rate0 < 0) | (np.abs(want) < np.abs(beta_rate0) - 1e-12)
    a_step = np.where(braking, np.maximum(a, 0.95 * limits.steer_accel_max), a) * dt
    rate = np.clip(want, beta_rate0 - a_step, beta_rate0 + a_step)
    rate = np.where(exact[:, None], err / dt, rate)  # ``beta_target`` is already a feasible next set-point
    beta = np.clip(beta0 + rate * dt, geom.steer_min + 1e-9, geom.steer_max)
    rate = (beta - beta0) / dt
    phidot_want = -geom.b * np.where(use_measured[:, None], measured_rate, rate) / geom.r
    _, _, phidot = _saturate(beta0, beta_rate0, phidot0, beta, phidot_want, geom, limits, dt)
    return beta, rate, phidot


def icr_control_step_batch(state: ICRBatchState, lam_hat, mu_hat, beta_meas, phidot_meas, lam_d, mu_d,
                           geom: RobotGeometry, limits: ActuatorLimits, config: ICRControllerConfig,
                           dt: float) -> tuple[ICRBatchState, BatchWheelCommand]:
    """One control period of N ICR controllers at once (pure: returns the new state and the commands).

    Row i is exactly what :func:`icr_control_step` does for robot i (that function is the N = 1
    case of this one); the modes of the state machine are handled with per-row masks.

    Args:
        state: from :func:`initial_state_batch` or the previous step.
        lam_hat: (N, 3) estimated λ̂ (any sign); mu_hat: (N,) estimated μ̂ [m/s].
        beta_meas: (N, n) measured steering angles [rad]; phidot_meas: (N, n) measured φ̇ [rad/s].
        lam_d: (N, 3) target ICRs (non-zero, any sign); mu_d: (N,) target μ [m/s].
        dt: control period [s].

    Raises:
        ValueError: on non-finite input, wrong shapes, a zero λ_d, or dt <= 0.
    """
    n = geom.n
    nrows = state.num
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0, got {dt!r}")
    _unit_rows(lam_hat, "lam_hat")
    if np.asarray(lam_hat).shape[0] != nrows:
        raise ValueError(f"lam_hat must have shape ({nrows}, 3)")
    mu_hat = _finite(mu_hat, "mu_hat", (nrows,))
    beta_meas = _finite(beta_meas, "beta_meas", (nrows, n))
    _finite(phidot_meas, "phidot_meas", (nrows, n))
    lam_d = _unit_rows(lam_d, "lam_d")
    if lam_d.shape[0] != nrows:
        raise ValueError(f"lam_d must have shape ({nrows}, 3)")
    mu_d = _finite(mu_d, "mu_d", (nrows,))

    zero_cmd = np.abs(mu_d) < config.zero_mu_tol
    lam_d = np.where(zero_cmd[:, None], state.lam, lam_d)  # a stop command holds λ: no wheel swings
    mu_d = np.where(zero_cmd, 0.0, mu_d)
    lam_d, mu_d = nearer_target(state.lam, lam_d, mu_d)
    lam_d, axis_k = project_off_axes_batch(lam_d, state.lam, geom, config.axis_margin)
    lam_d, mu_d = nearer_target(state.lam, lam_d, mu_d)
    mu_d = clamp_mu(lam_d, mu_d, geom, limits, config.mu_headroom)
    info: dict = {"lam_target": lam_d.copy(), "mu_target": mu_d.copy(), "axis_cap": axis_k}

    mode, mode_time, events = state.mode.copy(), state.mode_time + dt, state.events.copy()
    reconfig_lam, has_rl = state.reconfig_lam.copy(), state.has_reconfig_lam.copy()
    s_lam, s_mu, s_lam_rate = state.lam.copy(), state.mu.copy(), state.lam_rate.copy()
    held = np.zeros(nrows, dtype=np.bool_)
    held_time = np.zeros(nrows)
    event = np.zeros(nrows, dtype=np.int64)

    # a wheel knocked out of place (measured far from commanded) -> stop and reconfigure
    kicked = np.max(np.abs(_wrap_half(beta_meas - state.beta)), axis=-1) > config.kick_tol
    running = mode == Mode.RUNNING
    blocked = np.zeros(nrows, dtype=np.int64)
    check = running & ~zero_cmd
    if np.any(check):
        r = np.flatnonzero(check)
        reason, free, theta = arc_check_batch(state.lam[r], lam_d[r], geom, config.axis_margin, config.arc_step)
        near_stop = (reason == 1) & (theta - free < config.stop_hysteresis)
        ht = state.held_time[r] + dt
        # only just past a steering stop: wait at the stop instead of turning wheels by π; a
        # target that keeps going (or stays past) reconfigures once, a jittering one never does
        hold = near_stop & (ht <= config.stop_hold_time + 1e-9)
        if np.any(hold):
            rh = r[hold]
            lam_d[rh] = _slerp_rows(state.lam[rh], lam_d[rh], free[hold])
        reason = np.where(hold, 0, reason)
        blocked[r] = reason
        held[r] = hold
        held_time[r] = np.where(hold, ht, 0.0)
    trig = running & (kicked | (blocked != 0))
    event = np.where(trig, np.where(kicked, 1, blocked + 1), 0)
    events = events + trig
    mode = np.where(trig, int(Mode.STOPPING), mode)
    mode_time = np.where(trig, 0.0, mode_time)

    stopping = mode == Mode.STOPPING
    stopped = stopping & (state.mu == 0.0) & (np.linalg.norm(state.lam_rate, axis=-1) < 1e-9) & (
        (np.abs(mu_hat) < config.stop_mu_tol) | (mode_time > config.stop_timeout))
    mode = np.where(stopped, int(Mode.RECONFIGURING), mode)
    mode_time = np.where(stopped, 0.0, mode_time)

    recon = mode == Mode.RECONFIGURING
    fresh = recon & ~has_rl
    reconfig_lam[fresh] = lam_d[fresh]
    has_rl |= fresh
    beta_target = np.zeros((nrows, n))
    if np.any(recon):
        r = np.flatnonzero(recon)
        cand = ~zero_cmd[r] & (np.max(np.abs(state.beta[r] - steering_from_lambda(
            reconfig_lam[r], geom, singular_fill=state.beta[r])), axis=-1) > config.reconfig_freeze)
        if np.any(cand):
            rc = r[cand]
            # retarget only if the latest target could not be reached continuously from the
            # configuration being reached (RUNNING does the rest); no chasing a jittery target
            rt = rc[_must_stop(reconfig_lam[rc], lam_d[rc], geom, config)]
            reconfig_lam[rt] = lam_d[rt]
        bt = steering_from_lambda(reconfig_lam[r], geom, singular_fill=state.beta[r])
        beta_target[r] = bt
        settled_cmd = (np.max(np.abs(state.beta[r] - bt), axis=-1) < 1e-6) & (
            np.max(np.abs(state.beta_rate[r]), axis=-1) < 1e-9)
        settled_meas = np.max(np.abs(_wrap_half(beta_meas[r] - bt)), axis=-1) < config.reconfig_tol
        resume = settled_cmd & (settled_meas | (mode_time[r] > config.reconfig_timeout)) & ~zero_cmd[r]
        if np.any(resume):
            rr = r[resume]
            s_lam[rr], s_mu[rr], s_lam_rate[rr] = reconfig_lam[rr], 0.0, 0.0
            mode[rr], mode_time[rr], has_rl[rr] = int(Mode.RUNNING), 0.0, False
            lam_d[rr], mu_d[rr] = nearer_target(s_lam[rr], lam_d[rr], mu_d[rr])

    lam_new, mu_new, lam_rate = s_lam.copy(), np.zeros(nrows), np.zeros((nrows, 3))
    beta_c, rate_c, phidot_c = state.beta.copy(), state.beta_rate.copy(), state.phidot.copy()
    kappa, saturated = np.zeros(nrows), np.zeros(nrows, dtype=np.bool_)
    recon = mode == Mode.RECONFIGURING
    if np.any(recon):
        r = np.flatnonzero(recon)
        bt = beta_target[r]
        zr = zero_cmd[r]
        if np.any(zr):
            # hold: brake the steering to rest where it is (at full deceleration, so it stops
            # short of where the reconfiguration was heading, inside the range); do not swing
            br = state.beta_rate[r]
            rate = np.sign(br) * np.maximum(np.abs(br) - limits.steer_accel_max * dt, 0.0)
            bt = np.where(zr[:, None], state.beta[r] + rate * dt, bt)
        use_meas = np.zeros(r.size, dtype=np.bool_)
        measured_rate = np.zeros((r.size, n))
        if config.coupling_from_measurement:
            use_meas = state.has_beta_meas[r].copy()
            measured_rate = _wrap_half(beta_meas[r] - state.beta_meas[r]) / dt
        beta_c[r], rate_c[r], phidot_c[r] = _reconfigure_step(
            state.beta[r], state.beta_rate[r], state.phidot[r], bt, geom, limits, dt, exact=zr,
            measured_rate=measured_rate, use_measured=use_meas, rate_fraction=config.reconfig_rate_fraction,
            accel_fraction=config.reconfig_accel_fraction)
    moving = ~recon
    if np.any(moving):
        r = np.flatnonzero(moving)
        stop_r = mode[r] == Mode.STOPPING
        tgt_lam = np.where(stop_r[:, None], s_lam[r], lam_d[r])
        tgt_mu = np.where(stop_r, 0.0, mu_d[r])
        ln, mn, lr, bc, rcm, pc, kp, sat = _coordinated_step(
            s_lam[r], s_mu[r], s_lam_rate[r], state.beta[r], state.beta_rate[r], state.phidot[r], tgt_lam, tgt_mu,
            stop_r, geom, limits, config, dt)
        mn = np.where(stop_r & (np.abs(mn) < 1e-9), 0.0, mn)
        rest = stop_r & (np.abs(mn) < 1e-6 * np.maximum(1.0, np.abs(s_mu[r]))) & (np.linalg.norm(lr, axis=-1) < 1e-6)
        mn = np.where(rest, 0.0, mn)
        lr = np.where(rest[:, None], 0.0, lr)
        lam_new[r], mu_new[r], lam_rate[r] = ln, mn, lr
        beta_c[r], rate_c[r], phidot_c[r] = bc, rcm, pc
        kappa[r], saturated[r] = kp, sat

    accel = (rate_c - state.beta_rate) / dt
    phiddot = (phidot_c - state.phidot) / dt
    info.update(mode=mode.copy(), events=events.copy(), kappa=kappa, saturated=saturated, event=event,
                held_at_stop=held)
    new_state = ICRBatchState(mode=mode, lam=lam_new, mu=mu_new, lam_rate=lam_rate, beta=beta_c, beta_rate=rate_c,
                              phidot=phidot_c, mode_time=mode_time,
                              reconfig_lam=np.where(has_rl[:, None], reconfig_lam, 0.0), has_reconfig_lam=has_rl,
                              events=events, beta_meas=beta_meas.copy(), has_beta_meas=np.ones(nrows, dtype=np.bool_),
                              held_time=held_time)
    cmd = BatchWheelCommand(beta=beta_c.copy(), phidot=phidot_c.copy(), beta_rate=rate_c.copy(), beta_accel=accel,
                            phiddot=phiddot, info=info)
    return new_state, cmd


def icr_control_step(state: ICRControllerState, lam_hat, mu_hat, beta_meas, phidot_meas, lam_d, mu_d,
                     geom: RobotGeometry, limits: ActuatorLimits, config: ICRControllerConfig,
                     dt: float) -> tuple[ICRControllerState, WheelCommand]:
    """One control period of the ICR controller (pure: returns the new state and the command).

    The N = 1 case of :func:`icr_control_step_batch`.

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
    _unit3(lam_hat, "lam_hat")
    lam_hat = np.asarray(lam_hat, dtype=np.float64)
    mu_hat = float(_finite(mu_hat, "mu_hat", ()))
    beta_meas = _finite(beta_meas, "beta_meas", (n,))
    phidot_meas = _finite(phidot_meas, "phidot_meas", (n,))
    _unit3(lam_d, "lam_d")
    lam_d = np.asarray(lam_d, dtype=np.float64)
    mu_d = float(_finite(mu_d, "mu_d", ()))
    bstate, bcmd = icr_control_step_batch(ICRBatchState.stack([state]), lam_hat[None, :], np.array([mu_hat]),
                                          beta_meas[None, :], phidot_meas[None, :], lam_d[None, :],
                                          np.array([mu_d]), geom, limits, config, dt)
    bi = bcmd.info
    info: dict = {"saturated": bool(bi["saturated"][0]), "event": _EVENTS[int(bi["event"][0])],
                  "lam_target": bi["lam_target"][0], "mu_target": float(bi["mu_target"][0]),
                  "axis_cap": int(bi["axis_cap"][0]), "kappa": float(bi["kappa"][0]),
                  "mode": Mode(int(bi["mode"][0])), "events": int(bi["events"][0])}
    if bi["held_at_stop"][0]:
        info["held_at_stop"] = True
    cmd = WheelCommand(beta=bcmd.beta[0], phidot=bcmd.phidot[0], beta_rate=bcmd.beta_rate[0],
                       beta_accel=bcmd.beta_accel[0], phiddot=bcmd.phiddot[0], info=info)
    return bstate.robot(0), cmd


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
