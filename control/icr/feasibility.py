"""What the wheels allow, for planners and tests: steering axes, arcs and stops of the ICR controller.

* steering axes: targets are kept out of a cap around each steering axis ŝ_k, where β_k is
  undefined (:func:`project_off_axes`);
* great-circle arcs: whether λ can move to λ_d without a wheel crossing its steering stop or λ
  passing a steering axis (:func:`arc_check`, and :func:`reference_stop_mask` for a sampled path);
* holds at a steering stop: the point of λ's cell (the region bounded by the wheels' stop
  circles) nearest to a target beyond it (:func:`stop_hold_point_batch`).

Each of them but :func:`reference_stop_mask` runs the compiled function the controller's step
calls (:mod:`control.icr.kernels`), row by row: what they return is what the step sees. The
step itself (the feasible target, the speed bound, the braking room before a stop, the
saturation fallback) is :mod:`control.icr.compiled` only.

Unlimited steering (``RobotGeometry.unlimited_steering``, e.g. the ``swerve`` preset): there is
no stop to cross, so no arc is blocked by one (each wheel takes the angle of its axis nearest
where it is, ``RobotGeometry.nearest_steering``); the steering axes (where β_k is undefined)
still stop the robot.

The derivations are in ``docs/icr-controller.md`` (sections "Feasible targets" and "Arcs"). Every
function is batched over robots (``*_batch`` takes (N, …) rows; the unsuffixed form is its N = 1
case, with the same bits).
"""

from __future__ import annotations

import enum

import numpy as np

from control.checks import check_unit, check_unit_batch
from control.icr.kernels import arc_check_row, project_off_axes_row, stop_hold_row, stop_normals
from estimation.geometry import RobotGeometry
from estimation.kinematics import steering_from_lambda

__all__ = ["project_off_axes_batch", "project_off_axes", "arc_check_batch", "arc_check", "arc_blocked",
           "reference_stop_mask", "stop_hold_point_batch", "wrap_half", "ArcReason"]


class ArcReason(enum.IntEnum):
    """Codes of :func:`arc_check_batch`: why an arc cannot be driven continuously."""

    NONE = 0  #: it can
    STOP = 1  #: some wheel's β_k would wrap across its steering stops
    AXIS = 2  #: λ would pass a steering axis


def wrap_half(x: np.ndarray) -> np.ndarray:
    """Angle difference modulo π into [−π/2, π/2[ (β and β + π are the same axis)."""
    return np.mod(np.asarray(x) + np.pi / 2, np.pi) - np.pi / 2


def _rows(x, name: str) -> np.ndarray:
    """(N, 3) non-zero finite rows as given (the kernels normalise them), refused as
    :func:`~control.checks.check_unit_batch` refuses."""
    check_unit_batch(x, name)
    return np.ascontiguousarray(x, dtype=np.float64)


def project_off_axes_batch(lam_d, lam, geom: RobotGeometry, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`project_off_axes` for (N, 3) targets and current λ: returns ((N, 3), (N,) wheel or −1)."""
    lam_d, lam = _rows(lam_d, "lam_d"), _rows(lam, "lam")
    s_unit = np.ascontiguousarray(geom.s_unit, dtype=np.float64)
    out = np.empty(lam_d.shape)
    idx = np.empty(lam_d.shape[0], dtype=np.int64)
    for i in range(lam_d.shape[0]):
        idx[i] = project_off_axes_row(lam_d[i], lam[i], s_unit, float(margin), out[i])
    return out, idx


def project_off_axes(lam_d, lam, geom: RobotGeometry, margin: float) -> tuple[np.ndarray, int]:
    """Move a target λ_d out of the cap of angular radius ``margin`` around each steering axis.

    A target inside the cap of ŝ_k (on either hemisphere) is moved to the cap's rim on the great
    circle from ŝ_k through λ_d, or, if λ_d is on the axis itself, through the current λ: along
    that circle β_k is constant, so approaching the rim does not swing wheel k (every great
    circle through ŝ_k is one of wheel k's propulsion-axis circles, estimation paper eq. (15)).

    Returns (λ_d', index of the wheel whose cap held λ_d, or −1). The N = 1 case of
    :func:`project_off_axes_batch` (:func:`control.icr.kernels.project_off_axes_row`).
    """
    check_unit(lam_d, "lam_d"), check_unit(lam, "lam")
    out, idx = project_off_axes_batch(np.asarray(lam_d, dtype=np.float64)[None, :],
                                      np.asarray(lam, dtype=np.float64)[None, :], geom, margin)
    return out[0], int(idx[0])


def arc_check_batch(lam, lam_d, geom: RobotGeometry, axis_margin: float, step: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`arc_check` for (N, 3) arcs: (reason (N,) :class:`ArcReason` code, free (N,), theta (N,))."""
    lam, lam_d = _rows(lam, "lam"), _rows(lam_d, "lam_d")
    E, P = np.ascontiguousarray(geom.a_minus_l, dtype=np.float64), np.ascontiguousarray(geom.a_perp, dtype=np.float64)
    s_unit = np.ascontiguousarray(geom.s_unit, dtype=np.float64)
    work = np.empty(geom.n)
    reason = np.empty(lam.shape[0], dtype=np.int64)
    free, theta = np.empty(lam.shape[0]), np.empty(lam.shape[0])
    for i in range(lam.shape[0]):
        reason[i], free[i], theta[i] = arc_check_row(lam[i], lam_d[i], E, P, float(geom.steer_max), s_unit,
                                                     float(np.sin(0.5 * axis_margin)), float(step),
                                                     bool(geom.unlimited_steering), work)
    return reason, free, theta


def arc_check(lam, lam_d, geom: RobotGeometry, axis_margin: float, step: float) -> tuple[str | None, float, float]:
    """Whether the great-circle arc λ -> λ_d can be driven continuously.

    Returns ``(reason, free, theta)``: ``reason`` is None, ``"stop"`` if some wheel's β_k would
    wrap across the steering stops along the arc (a jump of more than π/2 between samples
    ``step`` apart), or ``"axis"`` if the arc passes closer than ``axis_margin``/2 to a steering
    axis (estimation paper eq. (21)); ``free`` is the arc angle [rad] from λ that can be driven
    before the first such point, ``theta`` the whole arc's angle [rad]. The N = 1 case of
    :func:`arc_check_batch` (:func:`control.icr.kernels.arc_check_row`).
    """
    check_unit(lam, "lam"), check_unit(lam_d, "lam_d")
    reason, free, theta = arc_check_batch(np.asarray(lam, dtype=np.float64)[None, :],
                                          np.asarray(lam_d, dtype=np.float64)[None, :], geom, axis_margin, step)
    code = ArcReason(int(reason[0]))
    return (None if code == ArcReason.NONE else code.name.lower()), float(free[0]), float(theta[0])


def arc_blocked(lam, lam_d, geom: RobotGeometry, axis_margin: float, step: float) -> str | None:
    """The reason of :func:`arc_check` alone: None, ``"stop"`` or ``"axis"``."""
    return arc_check(lam, lam_d, geom, axis_margin, step)[0]


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
    point is found). Each row is :func:`control.icr.kernels.stop_hold_row`, the function the
    controller's step calls."""
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

