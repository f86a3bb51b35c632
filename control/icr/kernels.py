"""Compiled building blocks of the ICR controller's step, one robot (one row) at a time.

The sphere maths of :mod:`estimation.hrep` and the kinematics of :mod:`estimation.kinematics`
are written here for one row with the same operations in the same order as those NumPy
functions, so that they give the same bits: the vector norm ``√((x₀² + x₁²) + x₂²)`` (NumPy's row
sums run left to right), the cross product ``a₁b₂ − a₂b₁`` ..., every renormalisation (a function
that takes λ normalises it again, and normalising a unit vector may change its last bit).
``atan2`` is the C library's (as :mod:`estimation.libm`'s); ``sin``, ``cos`` and ``sqrt`` agree
without help. The controller's own parts (arcs, axis caps, holds at steering stops, braking
room, saturation) exist only here: :mod:`control.icr.feasibility` runs them for planners and
tests.

The step that strings them together is :mod:`control.icr.compiled`, the only implementation; its
reference in the tests is the same code run as plain Python (``NUMBA_DISABLE_JIT=1``,
``tests/control/test_icr_compiled.py``, bit for bit on recorded episodes).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from estimation.kinematics import SINGULAR_TOL, _beta_wheel, _grad_wheel, _speed_coef

__all__ = ["norm3", "unit_xyz", "unit3", "dot3", "angle_xyz", "nearest1", "steering_difference1", "sphere_angle3",
           "slerp3", "wrap_half1", "steering_row", "speed_coefs_row", "arc_check_row", "project_off_axes_row",
           "safe_stop_speed1", "stop_room1", "saturate_row", "stop_normals", "stop_hold_row", "ARC_NONE", "ARC_STOP",
           "ARC_AXIS"]

# indices into the limit constants ``lim`` (control.icr.compiled.compiled_constants)
L_SAM, L_SRM, L_WSM, L_WAM, L_A_DT, L_WA_DT, L_STEER_LO = 0, 1, 2, 3, 4, 5, 6
L_SAT_C1, L_SAT_C2, L_SAT_C3 = 7, 8, 9  # safe_stop_speed at 0.95·a (saturate)
L_CO_C1, L_CO_C2, L_CO_C3 = 10, 11, 12  # safe_stop_speed at 0.8·a (coordinated_step)
L_ACCEL_LAM = 13  # 0.8·steer_accel_max
L_RC_A, L_RC_VMAX, L_RC_C1, L_RC_C2, L_RC_C3, L_RC_BRAKE = 14, 15, 16, 17, 18, 19  # reconfigure_step
L_MU_ACCEL = 20  # mu_accel_fraction·wheel_accel_max
L_WSM_SLACK, L_WA_DT_SLACK, L_NEG_WSM_SLACK = 21, 22, 23  # mu_own_step
L_HEADROOM_WSM = 24  # mu_headroom·wheel_speed_max
L_BRAKE_DT = 25  # steer_accel_max·dt (a stop command braking the steering in RECONFIGURING)
L_UNLIMITED = 26  # 1.0: unlimited steering (RobotGeometry.unlimited_steering), else 0.0
N_LIM = 27

# the tuning as a float array (indices C_*)
(C_ZERO_MU, C_AXIS_MARGIN, C_ARC_STEP, C_SIN_HALF_MARGIN, C_STOP_HYST, C_HOLD_DIST, C_KICK, C_STOP_MU, C_STOP_TIMEOUT,
 C_FREEZE, C_RECONFIG_TOL, C_HOLD_TOL, C_STILL_TOL, C_RECONFIG_TIMEOUT, C_K_LAMBDA, C_COUPLING_MEAS,
 C_MU_OWN, C_HOLD_SPEED, C_HOLD_ANGLE, C_HOLD_MARGIN, C_PLAN_HOLD_DIST) = range(21)

#: :class:`control.icr.feasibility.ArcReason` codes
ARC_NONE, ARC_STOP, ARC_AXIS = 0, 1, 2

#: a look-ahead plan's flag at the robot's progress (:func:`control.icr.lookahead.plan_sides`):
#: no expected excursion, an expected excursion of the reference, the approach to an open track's end
EXCURSION_NONE, EXCURSION_PLANNED, EXCURSION_END = 0.0, 1.0, 2.0


@njit(cache=True, inline="always")
def dot3(a, b) -> float:
    """``np.sum(a * b, axis=-1)`` of one row: (a₀b₀ + a₁b₁) + a₂b₂."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline="always")
def norm3(a) -> float:
    """``np.linalg.norm(a, axis=-1)`` of one row."""
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@njit(cache=True, inline="always")
def unit_xyz(a0: float, a1: float, a2: float) -> tuple[float, float, float]:
    """(a₀, a₁, a₂)/‖a‖: :func:`estimation.hrep.unit_and_norm` (the row scaled by the power of two
    that brings its largest component into [0.5, 1) first), which is bit for bit ``a /
    np.linalg.norm(a)`` (``control.checks.check_unit_batch``) wherever that neither overflows nor
    underflows."""
    _, e = math.frexp(max(abs(a0), abs(a1), abs(a2)))
    s0, s1, s2 = math.ldexp(a0, -e), math.ldexp(a1, -e), math.ldexp(a2, -e)
    nrm = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    return s0 / nrm, s1 / nrm, s2 / nrm


@njit(cache=True, inline="always")
def unit3(a, out) -> None:
    """a/‖a‖ of one row into ``out`` (may be ``a``): :func:`unit_xyz`."""
    out[0], out[1], out[2] = unit_xyz(a[0], a[1], a[2])


@njit(cache=True, inline="always")
def cross3(a, b, out) -> None:
    """``np.cross(a, b)`` of one row."""
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(cache=True, inline="always")
def angle_xyz(a0, a1, a2, b0, b1, b2) -> float:
    """:func:`estimation.hrep.sphere_angle` of one pair: atan2(‖a × b‖, a·b)."""
    c0 = a1 * b2 - a2 * b1
    c1 = a2 * b0 - a0 * b2
    c2 = a0 * b1 - a1 * b0
    return math.atan2(math.sqrt(c0 * c0 + c1 * c1 + c2 * c2), a0 * b0 + a1 * b1 + a2 * b2)


@njit(cache=True)
def sphere_angle3(a, b) -> float:
    """:func:`angle_xyz` of two rows."""
    return angle_xyz(a[0], a[1], a[2], b[0], b[1], b[2])


@njit(cache=True)
def slerp3(lam, lam_d, angle, out) -> None:
    """:func:`estimation.hrep.slerp` of one pair and one angle [rad], into ``out``."""
    d = dot3(lam, lam_d)
    t0 = lam_d[0] - d * lam[0]
    t1 = lam_d[1] - d * lam[1]
    t2 = lam_d[2] - d * lam[2]
    tn = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if tn < 1e-15:
        out[0], out[1], out[2] = lam[0], lam[1], lam[2]
        return
    c, s = math.cos(angle), math.sin(angle)
    out[0] = c * lam[0] + s * (t0 / tn)
    out[1] = c * lam[1] + s * (t1 / tn)
    out[2] = c * lam[2] + s * (t2 / tn)


@njit(cache=True, inline="always")
def nearest1(beta: float, reference: float, unlimited: bool) -> float:
    """:meth:`estimation.geometry.RobotGeometry.nearest_steering` of one wheel."""
    if not unlimited:
        return beta
    return reference + (np.mod(beta - reference + np.pi / 2, np.pi) - np.pi / 2)


@njit(cache=True, inline="always")
def steering_difference1(q: float, beta: float, unlimited: bool) -> float:
    """:meth:`estimation.geometry.RobotGeometry.steering_difference` of one wheel."""
    d = q - beta
    if not unlimited:
        return d
    return np.mod(d + np.pi / 2, np.pi) - np.pi / 2


@njit(cache=True, inline="always")
def wrap_half1(x: float) -> float:
    """An angle difference modulo π into [−π/2, π/2[: (x + π/2) mod π − π/2 (as
    :func:`control.icr.feasibility.wrap_half`)."""
    return np.mod(x + np.pi / 2, np.pi) - np.pi / 2


@njit(cache=True)
def steering_row(lam, E, P, steer_max, fill, use_fill, out, scratch) -> None:
    """:func:`estimation.kinematics.steering_from_lambda` of one λ (normalised first, as that
    function does) into ``out`` (n,); a singular wheel takes ``fill[k]`` (``use_fill``) or 0.
    ``scratch``: (3,) work space."""
    unit3(lam, scratch)
    for k in range(E.shape[0]):
        beta, r2 = _beta_wheel(scratch[0], scratch[1], scratch[2], E, P, k, steer_max)
        if r2 < SINGULAR_TOL * SINGULAR_TOL:
            beta = fill[k] if use_fill else 0.0
        out[k] = beta


@njit(cache=True)
def speed_coefs_row(lam, beta, have_beta, E, P, b, steer_max, out, scratch, beta_work) -> None:
    """:func:`estimation.kinematics.wheel_speed_coefficients` of one λ into ``out`` (n,): with the
    steering angles ``beta`` (``have_beta``) or F(λ) (computed from the normalised λ, which
    :func:`steering_row` normalises again, as the NumPy functions do). ``scratch`` (3,),
    ``beta_work`` (n,): work space."""
    unit3(lam, scratch)
    if have_beta:
        for k in range(E.shape[0]):
            out[k] = _speed_coef(scratch, E, P, b, k, beta[k])
        return
    u0, u1, u2 = unit_xyz(scratch[0], scratch[1], scratch[2])  # steering_row normalises again
    for k in range(E.shape[0]):
        beta_k, r2 = _beta_wheel(u0, u1, u2, E, P, k, steer_max)
        beta_work[k] = 0.0 if r2 < SINGULAR_TOL * SINGULAR_TOL else beta_k
        out[k] = _speed_coef(scratch, E, P, b, k, beta_work[k])


@njit(cache=True)
def gradient_norm_max(lam, E, P, u, g) -> float:
    """max_k ‖∂F_k/∂λ‖ at λ (normalised first): ``np.max(np.linalg.norm(steering_gradient(λ),
    axis=-1), axis=-1)`` of one row. ``u``, ``g``: (3,) work space."""
    unit3(lam, u)
    best = -np.inf
    for k in range(E.shape[0]):
        _grad_wheel(u, E, P, k, g)
        best = max(best, norm3(g))
    return best


@njit(cache=True)
def arc_check_row(lam_in, lam_d_in, E, P, steer_max, s_unit, sin_half_margin, step, unlimited, beta_prev):
    """Whether the great-circle arc λ -> λ_d can be driven continuously (for one arc,
    :func:`control.icr.feasibility.arc_check`): (reason code, free [rad], theta [rad]). The arc is
    sampled at m = max(2, ⌈θ/step⌉ + 1) points and stops at its first blocked sample.
    ``unlimited``: no stop, only the axes block. ``beta_prev``: (n,) work space.

    Each sample is :func:`slerp3` of (λ, λ_d) (its tangent, which every sample shares, computed
    once), checked against the axes (‖p × ŝ_k‖ < sin(margin/2), interior samples) and steered
    (:func:`steering_row` of p, a singular wheel at 0)."""
    n = E.shape[0]
    l0, l1, l2 = unit_xyz(lam_in[0], lam_in[1], lam_in[2])
    d0, d1, d2 = unit_xyz(lam_d_in[0], lam_d_in[1], lam_d_in[2])
    theta = angle_xyz(l0, l1, l2, d0, d1, d2)
    m = max(2, np.int64(math.ceil(theta / step)) + 1)
    delta = theta / (m - 1)
    dd = l0 * d0 + l1 * d1 + l2 * d2  # slerp3's tangent
    t0 = d0 - dd * l0
    t1 = d1 - dd * l1
    t2 = d2 - dd * l2
    tn = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    first_axis = m
    first_wrap = m
    for j in range(m):
        angle = theta if j >= m - 1 else j * delta
        if tn < 1e-15:
            p0, p1, p2 = l0, l1, l2
        else:
            c, s = math.cos(angle), math.sin(angle)
            p0 = c * l0 + s * (t0 / tn)
            p1 = c * l1 + s * (t1 / tn)
            p2 = c * l2 + s * (t2 / tn)
        if 1 <= j < m - 1:
            for k in range(n):
                s0, s1, s2 = s_unit[k, 0], s_unit[k, 1], s_unit[k, 2]
                c0 = p1 * s2 - p2 * s1
                c1 = p2 * s0 - p0 * s2
                c2 = p0 * s1 - p1 * s0
                if math.sqrt(c0 * c0 + c1 * c1 + c2 * c2) < sin_half_margin:
                    first_axis = j
                    break
        u0, u1, u2 = unit_xyz(p0, p1, p2)
        for k in range(n):
            beta, r2 = _beta_wheel(u0, u1, u2, E, P, k, steer_max)
            if r2 < SINGULAR_TOL * SINGULAR_TOL:
                beta = 0.0
            if j >= 1 and not unlimited and first_wrap == m and abs(beta - beta_prev[k]) > np.pi / 2:
                first_wrap = j
            beta_prev[k] = beta
        # the first blocked sample decides (an axis at j beats a wrap after j; a wrap at j beats an axis at j)
        if first_axis < m or first_wrap < m:
            break
    if first_axis == m and first_wrap == m:
        return ARC_NONE, theta, theta
    if first_axis <= first_wrap - 1:
        j = max(first_axis - 1, 0)
        return ARC_AXIS, (theta if j >= m - 1 else j * delta), theta
    j = min(max(first_wrap - 1, 0), m - 1)
    return ARC_STOP, (theta if j >= m - 1 else j * delta), theta


@njit(cache=True)
def project_off_axes_row(lam_d_in, lam_in, s_unit, margin, out) -> int:
    """A target λ_d moved out of the cap of angular radius ``margin`` around each steering axis
    (for one target, :func:`control.icr.feasibility.project_off_axes`): the projected λ_d into
    ``out``; returns the wheel whose cap held it, or −1."""
    d0, d1, d2 = unit_xyz(lam_d_in[0], lam_d_in[1], lam_d_in[2])
    l0, l1, l2 = unit_xyz(lam_in[0], lam_in[1], lam_in[2])
    out[0], out[1], out[2] = d0, d1, d2
    for k in range(s_unit.shape[0]):
        sign = 1.0 if s_unit[k, 0] * d0 + s_unit[k, 1] * d1 + s_unit[k, 2] * d2 >= 0 else -1.0
        k0, k1, k2 = s_unit[k, 0] * sign, s_unit[k, 1] * sign, s_unit[k, 2] * sign
        ang = angle_xyz(k0, k1, k2, d0, d1, d2)
        if ang < margin:
            if ang > 1e-9:
                h0, h1, h2 = d0, d1, d2
            else:
                sg = 1.0 if l0 * k0 + l1 * k1 + l2 * k2 >= 0 else -1.0
                h0, h1, h2 = l0 * sg, l1 * sg, l2 * sg
            if angle_xyz(k0, k1, k2, h0, h1, h2) < 1e-9:
                # λ on the axis too: any direction away from it will do; one orthogonal to s_k
                if abs(k2) < 0.9:
                    t0, t1, t2 = k1 * 1.0 - k2 * 0.0, k2 * 0.0 - k0 * 1.0, k0 * 0.0 - k1 * 0.0
                else:
                    t0, t1, t2 = k1 * 0.0 - k2 * 0.0, k2 * 1.0 - k0 * 0.0, k0 * 0.0 - k1 * 1.0
                tn = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
                c1, s1 = math.cos(1.0), math.sin(1.0)
                h0 = k0 * c1 + t0 / tn * s1
                h1 = k1 * c1 + t1 / tn * s1
                h2 = k2 * c1 + t2 / tn * s1
            # slerp3(sk, through, margin, out)
            dd = k0 * h0 + k1 * h1 + k2 * h2
            t0, t1, t2 = h0 - dd * k0, h1 - dd * k1, h2 - dd * k2
            tn = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
            if tn < 1e-15:
                out[0], out[1], out[2] = k0, k1, k2
            else:
                c, s = math.cos(margin), math.sin(margin)
                out[0] = c * k0 + s * (t0 / tn)
                out[1] = c * k1 + s * (t1 / tn)
                out[2] = c * k2 + s * (t2 / tn)
            return k
    return -1


@njit(cache=True, inline="always")
def stop_room1(beta, rate, steer_min, steer_max, unlimited) -> float:
    """The angle [rad] one wheel has left before the steering stop it turns toward (inf at rest,
    and always without stops)."""
    if unlimited:
        return np.inf
    if rate > 0:
        return steer_max - beta
    if rate < 0:
        return beta - steer_min
    return np.inf


@njit(cache=True, inline="always")
def safe_stop_speed1(room, c1, c2, c3) -> float:
    """The largest steering speed v of one wheel from which braking at a, one period late, stops
    within ``room``: v dt/2 + v²/(2a) ≤ room (``docs/icr-controller.md``, eq. (B)), with the
    constants c1 = −0.5·a·dt, c2 = (0.5·a·dt)², c3 = 2.0·a computed by the caller."""
    return c1 + math.sqrt(c2 + c3 * max(room, 0.0))


@njit(cache=True)
def saturate_row(beta_prev, rate_prev, phidot_prev, beta_want, phidot_want, steer_min, steer_max, lim, dt,
                 beta_out, rate_out, phidot_out) -> None:
    """Per-wheel saturation of one robot's command (the fallback when no κ is feasible): rate,
    accel, braking before the stops, range, then φ̇ and φ̈. ``lim``: the constants of
    :func:`~control.icr.kernel_constants.compiled_constants`."""
    a_dt, srm, wsm, wa_dt = lim[L_A_DT], lim[L_SRM], lim[L_WSM], lim[L_WA_DT]
    for k in range(beta_prev.shape[0]):
        rate = (beta_want[k] - beta_prev[k]) / dt
        rate = min(max(rate, rate_prev[k] - a_dt), rate_prev[k] + a_dt)
        rate = min(max(rate, -srm), srm)
        unlimited = lim[L_UNLIMITED] != 0.0
        room = stop_room1(beta_prev[k] + rate * dt, rate, steer_min, steer_max, unlimited)
        v_safe = max(safe_stop_speed1(room, lim[L_SAT_C1], lim[L_SAT_C2], lim[L_SAT_C3]), abs(rate_prev[k]) - a_dt)
        rate = np.sign(rate) * min(abs(rate), v_safe)
        beta = beta_prev[k] + rate * dt
        if not unlimited:
            beta = min(max(beta, lim[L_STEER_LO]), steer_max)
        rate_out[k] = (beta - beta_prev[k]) / dt
        beta_out[k] = beta
        ph = min(max(phidot_want[k], phidot_prev[k] - wa_dt), phidot_prev[k] + wa_dt)
        phidot_out[k] = min(max(ph, -wsm), wsm)


@njit(cache=True)
def stop_normals(E, P, steer_max, out) -> None:
    """Unit normals (n, 3) into ``out`` of the wheels' *stop circles*: β_k(λ) = β_max (mod π), the
    steering stop, exactly where n_k·λ = 0 with n_k = sin β_max (a_k − l_k) − cos β_max a⊥_k
    (eq. (15) at β = β_max: every great circle through ŝ_k has one β_k; this one is the stop)."""
    sb, cb = math.sin(steer_max), math.cos(steer_max)
    for k in range(E.shape[0]):
        x0 = sb * E[k, 0] - cb * P[k, 0]
        x1 = sb * E[k, 1] - cb * P[k, 1]
        x2 = sb * E[k, 2] - cb * P[k, 2]
        nrm = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        out[k, 0], out[k, 1], out[k, 2] = x0 / nrm, x1 / nrm, x2 / nrm


@njit(cache=True)
def _inside(q, N, side) -> bool:
    """Whether q is strictly on λ's side (``side``) of every stop circle."""
    for j in range(N.shape[0]):
        if side[j] * dot3(N[j], q) <= 0.0:
            return False
    return True


@njit(cache=True)
def in_cell(lam, side, N, tol=0.0) -> bool:
    """Whether λ or −λ (the same point of Λ) lies in the closed cell ``side`` (n,) (±1 per stop
    circle; 0: either side) of the stop circles ``N`` (n, 3), or within ``tol`` (a sine) of it
    across each circle."""
    plus, minus = True, True
    for k in range(N.shape[0]):
        d = side[k] * dot3(N[k], lam)
        plus = plus and d >= -tol
        minus = minus and d <= tol
    return plus or minus


@njit(cache=True)
def nearest_in_cell(side, lam, N, margin, out, neg, other) -> float:
    """The point of the cell ``side`` nearest to λ as a point of Λ (to λ or to −λ) into ``out``:
    λ itself, angle 0, when it is in the closed cell; else the nearer of the two hold points
    (:func:`cell_hold_row`), returning its angle, or −1.0 (``out`` untouched) when neither has a
    candidate. ``neg``, ``other``: (3,) work space."""
    if in_cell(lam, side, N):
        out[0], out[1], out[2] = lam[0], lam[1], lam[2]
        return 0.0
    a1 = cell_hold_row(side, lam, N, margin, out)
    neg[0], neg[1], neg[2] = -lam[0], -lam[1], -lam[2]
    a2 = cell_hold_row(side, neg, N, margin, other)
    if a2 >= 0.0 and (a1 < 0.0 or a2 < a1):
        out[0], out[1], out[2] = other[0], other[1], other[2]
        return a2
    return a1


@njit(cache=True)
def stop_hold_row(lam_in, lam_d_in, N, margin, out) -> float:
    """The point of λ's *cell* nearest to λ_d, into ``out`` (3,); returns its angle to λ_d [rad],
    or −1.0 (``out`` untouched) when λ_d is in the cell or no candidate is.

    The stop circles (:func:`stop_normals`, ``N`` (n, 3)) cut the sphere into cells: inside one,
    every β_k = F_k(λ) is continuous (no wheel passes its stop), and the cell is convex (an
    intersection of hemispheres). The cell is λ's (:func:`cell_hold_row` does the rest)."""
    n = N.shape[0]
    lam = np.empty(3)
    unit3(lam_in, lam)
    side = np.empty(n)
    for k in range(n):
        side[k] = 1.0 if dot3(N[k], lam) >= 0.0 else -1.0
    return cell_hold_row(side, lam_d_in, N, margin, out)


@njit(cache=True)
def cell_hold_row(side, lam_d_in, N, margin, out) -> float:
    """The point of the cell ``side`` (n,) (±1: the side of each stop circle ``N`` (n, 3)) nearest
    to λ_d, into ``out`` (3,); returns its angle to λ_d [rad], or −1.0 (``out`` untouched) when
    λ_d is in the cell or no candidate is.

    The cell is convex: its point nearest to an outside λ_d lies on an edge (the projection of
    λ_d onto one stop circle) or at a vertex (one of the two intersections of two circles): every
    such candidate, moved ``margin`` [rad] into the cell along the normals of the circles it lies
    on, is kept if it is strictly inside, and the one nearest to λ_d wins (the first on a tie)."""
    n = N.shape[0]
    lam_d = np.empty(3)
    unit3(lam_d_in, lam_d)
    outside = False
    for k in range(n):
        outside = outside or side[k] * dot3(N[k], lam_d) < 0.0
    if not outside:
        return -1.0
    q = np.empty(3)
    best = np.empty(3)
    best_dot = -2.0
    for a in range(n):
        for b in range(a, n):
            for sign in (1.0, -1.0):
                if a == b:  # the projection of λ_d onto circle a (one point)
                    if sign < 0.0:
                        continue
                    d = dot3(N[a], lam_d)
                    q[0], q[1], q[2] = lam_d[0] - d * N[a, 0], lam_d[1] - d * N[a, 1], lam_d[2] - d * N[a, 2]
                else:  # the intersections ±(n_a × n_b) of circles a and b
                    cross3(N[a], N[b], q)
                    q[0], q[1], q[2] = sign * q[0], sign * q[1], sign * q[2]
                if norm3(q) < 1e-12:
                    continue
                unit3(q, q)
                for j in range(3):
                    q[j] = q[j] + margin * side[a] * N[a, j]
                    if a != b:
                        q[j] = q[j] + margin * side[b] * N[b, j]
                unit3(q, q)
                if _inside(q, N, side):
                    dq = dot3(q, lam_d)
                    if dq > best_dot:
                        best_dot = dq
                        best[0], best[1], best[2] = q[0], q[1], q[2]
    if best_dot == -2.0:
        return -1.0
    out[0], out[1], out[2] = best[0], best[1], best[2]
    return sphere_angle3(best, lam_d)
