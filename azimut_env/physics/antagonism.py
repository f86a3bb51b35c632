"""Antagonism of the wheels: the part of the tire forces that a perfectly coordinated robot would
not produce.

Internal forces
---------------
With n wheels in contact, the tire forces F = (F_1, ..., F_n) (2n values, chassis frame) act on
the chassis through the wrench map G = Jᵀ: W = Jᵀ F = Σ_k (F_k, (P_k − O) × F_k), where
J (2n × 3) maps a chassis twist ξ = (v_x, v_y, ω) to the velocities of the contact points,
J_k ξ = (v_x − ω p_y,k, v_y + ω p_x,k). Forces in the null space of G cancel on the chassis:
they are the *internal forces* of a closed kinematic chain (Kumar & Waldron 1988, "Force
distribution in closed kinematic chains", IEEE J. Robotics and Automation 4(6)) or of a grasp
(Yoshikawa & Nagai 1991, "Manipulating and grasping forces in manipulation by multifingered
robot hands", IEEE Trans. Robotics and Automation: the grasping force is an internal force).
Any force set splits as F = F_nat + F_int with Jᵀ F_int = 0 and F_nat one chosen distribution of
the net wrench W. *Which* distribution is taken as natural
decides what the internal part measures.

The minimum-norm choice, F* = J (JᵀJ)⁻¹ W (Kumar & Waldron's "no interaction" solution, the
Moore–Penrose pseudo-inverse), is what :attr:`~azimut_env.physics.layout.RS.NULLSPACE` reports
(``AzimutPhysics.nullspace_force``). It assumes every wheel carries the same share, which no
tire does when loads or rolling speeds differ: a correctly steered robot in a steady turn reads
a null-space force that grows with its acceleration (the inner and outer wheels roll at
different speeds, so they produce their lateral forces from the same slip in different ratios).

The natural distribution of a tire robot
----------------------------------------
A tire makes force from slip. Linearised about zero slip, wheel k's force is
F_k = −D_k s_k with s_k the slip velocity of its contact point and D_k (2 × 2) its slip
stiffness per unit slip velocity (a damping). In steady rolling the brush tire of
:mod:`azimut_env.physics.tire` gives, along its rolling direction d_k and across it (e_k),
F_long = −C_κ s_long/|v_x| and F_lat = −C_α s_lat/|v_x| (C = c N, slip stiffnesses per unit load
times the normal load; v_x the rolling speed over the ground). The term σ/τ below regularises
the tire at rest, where it has no steady state: its contact is a spring k = C/σ (σ the relaxation
length) and a slip held for a time τ deflects it by s τ, a force k τ s; c N/(|v_x| + σ/τ) is the
steady gain of the relaxation equation du/dt = s − (|v_x|/σ) u with an added leak 1/τ, so it
tends to C/|v_x| when rolling and to k τ at rest (τ = :data:`SLIP_MEMORY_TIME`).

Along its rolling direction the tire is in series with the drive: its velocity loop turns a spin
error into the torque K_v (φ̇_ref − φ̇) (``WheelParams.velocity_gain``; the bearing damping with
the motors off), a force K_v/r² per unit speed of the contact point. A mismatch m between the
contact point's motion and r φ̇_ref splits into the tire's slip and the loop's speed error, so
F_long = −m/(|v_x|/C_κ + r²/K_v): the dampings add as compliances, and

    D_k = d_long,k d_k d_kᵀ + d_lat,k e_k e_kᵀ,
    d_long = 1/((|v_x| + σ_κ/τ)/(c_κ N) + r²/K_v),   d_lat = c_α N/(|v_x| + σ_α/τ).

Across the wheel (along e_k, through the steering axis) the tire is alone: the lateral force has
no moment about the steering axis.

A *perfectly coordinated* robot has all wheels on the constraining surface (one ICR) and
commanded at the speeds of one twist ξ_c; when the chassis actually moves with ξ, every contact
point moves off its command by m_k = J_k (ξ − ξ_c): a rigid-body field m = J δξ, and the forces
are F = −D J δξ. The natural distribution of a net wrench W is therefore the one a
common rigid slip produces:

    F_nat = D J (Jᵀ D J)⁻¹ W,        antagonism = ‖F − F_nat‖.

F − F_nat lies in null(Jᵀ) (Jᵀ F_nat = W), so it is an internal force in Kumar & Waldron's
sense; it is zero for any rigid slip field whatever the loads, slip stiffnesses and rolling
speeds; and it is the weighted pseudo-inverse distribution, the one that minimises Fᵀ D⁻¹ F
under Jᵀ F = W. With D the slip damping of a rolling tire, Fᵀ D⁻¹ F = Σ F·s is the slip power,
so F_nat is the distribution of the wrench that dissipates the least; at rest D = K τ, K the
contact stiffness, and Fᵀ K⁻¹ F is twice the tires' elastic energy. Kumar & Waldron (1988) show
that the minimum-norm solution is a force field "geometrically similar to the velocity field in
a rigid body twisting about an instantaneous screw axis": the distribution a common rigid slip
gives when every contact has the same isotropic stiffness. F_nat is the same construction with
the tires' own stiffnesses, which is how statically indeterminate contact forces are resolved
from the compliances of the contacts in walking machines (Gao & Song 1990, "Stiffness matrix
method for foot force distribution of walking vehicles", IEEE ICRA: the forces must satisfy the
equations of the deformations; Kumar & Waldron 1990, "Force distribution in walking vehicles",
ASME J. Mechanical Design 112(1): active compliance with varying leg compliances).

Both F and F_nat are expressed in the chassis frame; the result depends neither on the frame
nor on the reference point of the twist (a change of either maps J to R J T, R a rotation of
the forces and T invertible on ξ, and D J T (Tᵀ Jᵀ D J T)⁻¹ Tᵀ Jᵀ = D J (Jᵀ D J)⁻¹ Jᵀ).

What it does not take out, and reads as antagonism: the tire's non-linearity (the brush force
saturates: near the friction limit the slips of a coordinated robot no longer give forces in the
ratio D); the transient of the relaxation length (a deflection builds over σ of rolling, so a
wheel rolling slower than the others lags them for σ/|v_x|: starting from rest on a curve); the
drive's limits (current, acceleration ramp) and the rolling resistance its loop holds; and the
steering: a wheel whose angle lags its command, or whose series spring yields to the moment
−b F_long of its offset contact (compliance steer), rolls off the constraining surface, which is
the antagonism the ICR controller is about (Clavien, Lauria, Michaud, RAS 2018). The tire's couples (aligning and scrub
torques) are not forces of the wrench map and are left out, as in the null-space force.

In the physics summary the forces are the step means of the substeps' tire forces, the loads
and rolling speeds the step means of theirs (``ACC.LOAD``, ``ACC.ROLL``), the contact points and
directions those at the end of the step.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["SLIP_MEMORY_TIME", "slip_damping_kernel", "antagonism_kernel", "slip_damping", "natural_forces",
           "antagonism_forces", "wrench_map"]

#: τ [s]: the time a slip is held for the slip damping at rest, d = C/(|v_x| + σ/τ) → k τ (module
#: docstring); σ/τ = 0.02 m/s with the default 0.02 m relaxation lengths.
SLIP_MEMORY_TIME = 1.0


@njit(cache=True, inline="always")
def slip_damping_kernel(load: float, roll_speed: float, c_kappa: float, c_alpha: float, sigma_long: float,
                        sigma_lat: float, memory: float, radius: float, drive_gain: float):
    """(d_long, d_lat) [N·s/m]: a wheel's small-slip force per unit slip velocity of its contact point
    along its rolling direction and across it (module docstring): the tire's c N/(|v_x| + σ/τ), in
    series along the rolling direction with the drive's velocity loop K/r². load N [N], roll_speed
    v_x [m/s], c_kappa, c_alpha the slip stiffnesses per unit load, sigma_* the relaxation lengths
    [m], memory τ [s], radius r [m], drive_gain K [N·m·s/rad] (0: a free wheel, no longitudinal
    force)."""
    speed = abs(roll_speed)
    d_long = c_kappa * load / (speed + sigma_long / memory)
    d_lat = c_alpha * load / (speed + sigma_lat / memory)
    if d_long > 0.0:
        d_long = drive_gain / (drive_gain / d_long + radius * radius) if drive_gain > 0.0 else 0.0
    return d_long, d_lat


@njit(cache=True, inline="always")
def _det3(a11, a12, a13, a22, a23, a33):
    """Determinant of the symmetric 3 × 3 matrix [[a11, a12, a13], [a12, a22, a23], [a13, a23, a33]]."""
    return a11 * (a22 * a33 - a23 * a23) + a12 * (a13 * a23 - a12 * a33) + a13 * (a12 * a23 - a13 * a22)


@njit(cache=True, inline="always")
def sym3_cofactors(a11, a12, a13, a22, a23, a33):
    """The cofactors (c11, c12, c13, c22, c23, c33) of the symmetric 3 × 3 matrix of :func:`_det3`:
    its inverse is c / det (the adjugate of a symmetric matrix is symmetric)."""
    return (a22 * a33 - a23 * a23, a13 * a23 - a12 * a33, a12 * a23 - a13 * a22, a11 * a33 - a13 * a13,
            a12 * a13 - a11 * a23, a11 * a22 - a12 * a12)


@njit(cache=True, inline="always")
def _damping_xy(d_long, d_lat, c, s):
    """D = d_long d dᵀ + d_lat e eᵀ (d = (s, −c), e = (c, s)): its (xx, xy, yy)."""
    return d_long * s * s + d_lat * c * c, (d_lat - d_long) * s * c, d_long * c * c + d_lat * s * s


@njit(cache=True)
def antagonism_kernel(P, F, gam, d_long, d_lat, n: int) -> float:
    """‖F − D J (Jᵀ D J)⁻¹ Jᵀ F‖ [N] of one robot (module docstring).

    P (n, 2) contact points, F (n, 2) tire forces, gam (n,) the angles γ of the propulsion axes
    e = (cos γ, sin γ) (the rolling direction is d = (sin γ, −cos γ)), all in one frame;
    d_long, d_lat (n,) the slip dampings. Jᵀ D J (3 × 3, symmetric) is inverted in closed form;
    when it is singular (fewer than two wheels loaded) a 1e-9 relative Tikhonov term stands for the
    pseudo-inverse, and with no wheel loaded the forces are zero and so is the result."""
    a11 = a12 = a13 = a22 = a23 = a33 = 0.0
    w0 = w1 = w2 = 0.0
    for k in range(n):
        px, py = P[k, 0], P[k, 1]
        c, s = math.cos(gam[k]), math.sin(gam[k])
        dxx, dxy, dyy = _damping_xy(d_long[k], d_lat[k], c, s)
        # J_k = [[1, 0, −p_y], [0, 1, p_x]]: Jᵀ D J accumulated
        a11 += dxx
        a12 += dxy
        a22 += dyy
        a13 += -py * dxx + px * dxy
        a23 += -py * dxy + px * dyy
        a33 += py * py * dxx - 2.0 * px * py * dxy + px * px * dyy
        w0 += F[k, 0]
        w1 += F[k, 1]
        w2 += px * F[k, 1] - py * F[k, 0]
    if not (a11 + a22 > 0.0):
        return 0.0
    det = _det3(a11, a12, a13, a22, a23, a33)
    if not det > 1e-12 * a11 * a22 * a33:  # Hadamard: det ≤ a11 a22 a33 for a positive semi-definite matrix
        # fewer than two wheels loaded: the Tikhonov limit of the pseudo-inverse (Jᵀ F is in the range of Jᵀ D J)
        eps = 1e-9 * (a11 + a22 + a33)
        a11 += eps
        a22 += eps
        a33 += eps
        det = _det3(a11, a12, a13, a22, a23, a33)
    if not (det > 0.0 and det < math.inf):
        # the product of three dampings under- or overflowed (slip speeds of 1e200 m/s after an
        # absurd kick gave det = 0 and a ZeroDivisionError): no finite answer; the state is past
        # the blow-up limits and the step ends the episode (AzimutPhysics.check)
        return 0.0
    c11, c12, c13, c22, c23, c33 = sym3_cofactors(a11, a12, a13, a22, a23, a33)
    l0 = (c11 * w0 + c12 * w1 + c13 * w2) / det
    l1 = (c12 * w0 + c22 * w1 + c23 * w2) / det
    l2 = (c13 * w0 + c23 * w1 + c33 * w2) / det
    out = 0.0
    for k in range(n):
        px, py = P[k, 0], P[k, 1]
        c, s = math.cos(gam[k]), math.sin(gam[k])
        dxx, dxy, dyy = _damping_xy(d_long[k], d_lat[k], c, s)
        ux = l0 - py * l2  # J_k λ: the common rigid slip at P_k
        uy = l1 + px * l2
        ex = F[k, 0] - (dxx * ux + dxy * uy)
        ey = F[k, 1] - (dxy * ux + dyy * uy)
        out += ex * ex + ey * ey
    return math.sqrt(out)


def slip_damping(load, roll_speed, c_kappa, c_alpha, sigma_long, sigma_lat, radius, drive_gain,
                 memory: float = SLIP_MEMORY_TIME) -> np.ndarray:
    """(..., 2) the dampings (d_long, d_lat) [N·s/m] of :func:`slip_damping_kernel` over arrays (all
    broadcast together: load [N], roll_speed [m/s], the slip stiffnesses per unit load c_κ, c_α,
    the relaxation lengths σ_κ, σ_α [m] (a :class:`~azimut_env.params.TireParams`'
    ``longitudinal_stiffness``, ``cornering_stiffness``, ``longitudinal_relaxation_length``,
    ``relaxation_length``), the wheel radius [m] and the drive's velocity gain K [N·m·s/rad])."""
    n, v, ck, ca, sl, sa, r, k = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (
        load, roll_speed, c_kappa, c_alpha, sigma_long, sigma_lat, radius, drive_gain)))
    speed = np.abs(v)
    tire = ck * n / (speed + sl / memory)
    with np.errstate(divide="ignore", invalid="ignore"):
        d_long = np.where((tire > 0) & (k > 0), k / (k / np.where(tire > 0, tire, 1.0) + r * r), 0.0)
    return np.stack([d_long, ca * n / (speed + sa / memory)], axis=-1)


def wrench_map(contacts) -> np.ndarray:
    """(2n, 3) J of contact points (n, 2): row pairs [[1, 0, −p_y], [0, 1, p_x]] (the contact-point
    velocities of a twist (v_x, v_y, ω); the wrench map is G = Jᵀ, forces ordered (F_x,1, F_y,1, ...))."""
    p = np.asarray(contacts, dtype=np.float64)
    J = np.zeros((2 * p.shape[0], 3))
    J[0::2, 0] = 1.0
    J[1::2, 1] = 1.0
    J[0::2, 2] = -p[:, 1]
    J[1::2, 2] = p[:, 0]
    return J


def _damping_matrix(gamma, dampings) -> np.ndarray:
    """(2n, 2n) block-diagonal D of the wheels' slip dampings (n, 2) along d and e (angles γ (n,))."""
    g = np.asarray(gamma, dtype=np.float64)
    dm = np.asarray(dampings, dtype=np.float64)
    d = np.stack([np.sin(g), -np.cos(g)], axis=-1)
    e = np.stack([np.cos(g), np.sin(g)], axis=-1)
    blocks = dm[:, 0, None, None] * d[:, :, None] * d[:, None, :] + dm[:, 1, None, None] * e[:, :, None] * e[:, None, :]
    n = g.shape[0]
    D = np.zeros((2 * n, 2 * n))
    for k in range(n):
        D[2 * k:2 * k + 2, 2 * k:2 * k + 2] = blocks[k]
    return D


def natural_forces(forces, contacts, gamma, dampings) -> np.ndarray:
    """(n, 2) F_nat = D J (Jᵀ D J)⁺ Jᵀ F: the forces a common rigid slip would give with the same net
    wrench as ``forces`` (n, 2) (module docstring; NumPy, for analysis and tests). ``contacts``
    (n, 2) and ``gamma`` (n,) in the frame of the forces; ``dampings`` (n, 2) the (d_long, d_lat)
    of :func:`slip_damping`."""
    F = np.asarray(forces, dtype=np.float64).reshape(-1)
    J = wrench_map(contacts)
    D = _damping_matrix(gamma, dampings)
    lam = np.linalg.pinv(J.T @ D @ J) @ (J.T @ F)
    return (D @ J @ lam).reshape(-1, 2)


def antagonism_forces(forces, contacts, gamma, dampings) -> np.ndarray:
    """(n, 2) F − F_nat (:func:`natural_forces`): the antagonistic part of the tire forces, an
    internal force (Jᵀ (F − F_nat) = 0); its norm is the antagonism."""
    return np.asarray(forces, dtype=np.float64) - natural_forces(forces, contacts, gamma, dampings)
