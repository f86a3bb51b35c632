"""Target shaping for RL action spaces: an ICR target that moves continuously on the sphere.

An RL policy that commands an absolute ICR target (λ_d, μ_d) changes it at random while it
explores. The ICR controller (:mod:`control.icr.controller`) must stop and turn the wheels in place
whenever the great-circle arc λ -> λ_d crosses a steering stop or axis, so a target that jumps
across the sphere every step keeps it in RECONFIGURING for good and the robot never moves (under
random targets, nearly every step; ``docs/results/rl.md``).

The shaped target is a state (λ_s, μ_s) per robot that the action *moves*:

* :func:`advance_target` takes a proposed next λ (a rate step for the ICR-rate action space, or a
  bounded step toward the policy's absolute target) and accepts it unless it crosses a steering
  stop (some β_k = F_k(λ) wraps across ±π/2, the stop of eq. (16)–(17)'s range) or enters the
  cap of half-angle ``axis_margin`` around a steering axis ŝ_k (eq. (21)), where β_k is undefined.
  A blocked step leaves λ_s where it is; the arc length the policy keeps pushing past a stop is
  accumulated, and once it exceeds ``cross_push`` the crossing is accepted: the controller then
  stops and reconfigures, as on the real robot when the commanded motion needs a wheel turned past
  its stop. A policy that only jitters near the stop never pays for a reconfiguration.
* Between two cells bounded by those stop great circles (β_k = ±π/2 is a great circle through
  ŝ_k: all the curves of constant β_k are, eq. (15)), a spherical polygon is convex, so the
  controller's own arc λ -> λ_s stays inside the cell and needs no stop either.

All functions are batched over N robots ((N, 3) arrays) and pure. They are the reference of the
compiled targets the action spaces use (:mod:`control.action_spaces.targets`, equal to the bit).
"""

from __future__ import annotations

import numpy as np

from control.icr.config import ICRControllerConfig
from estimation.geometry import RobotGeometry
from estimation.hrep import exp_map, nearer_representative, sphere_angle
from estimation.kinematics import steering_from_lambda
from estimation.libm import atan2

__all__ = ["shape_target", "advance_target", "step_toward", "exp_step", "transport_frame", "initial_frame",
           "SHAPED_TARGET_CONFIG"]

#: The ICR controller's tuning behind shaped absolute targets when none is given: μ gets its own
#: time scaling (``mu_own_scale``) and ramps at 0.95 of the wheel acceleration limit (instead of
#: 0.7, the rest kept for λ; the φ̇ and φ̈ limits are enforced at the chosen λ either way). A
#: target that changes every step has a zero-mean μ_d, so μ is a mean-reverting walk whose size
#: grows with its acceleration: random policies travel farther with this tuning
#: (``docs/results/rl.md``, "Action spaces under random actions").
SHAPED_TARGET_CONFIG = ICRControllerConfig(mu_own_scale=True, mu_accel_fraction=0.95)


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def initial_frame(lam: np.ndarray) -> np.ndarray:
    """A unit tangent vector e₁ (N, 3) at each unit λ (N, 3): the projection of the axis least
    aligned with λ."""
    lam = np.asarray(lam, dtype=np.float64)
    axes = np.eye(3)[np.argmin(np.abs(lam), axis=-1)]
    e1 = axes - np.sum(axes * lam, axis=-1, keepdims=True) * lam
    return _unit(e1)


def transport_frame(e1: np.ndarray, lam_new: np.ndarray) -> np.ndarray:
    """Carry the tangent vector e₁ to the tangent plane at ``lam_new`` (projection and
    renormalisation: parallel transport to first order for small steps)."""
    e = e1 - np.sum(e1 * lam_new, axis=-1, keepdims=True) * lam_new
    n = np.linalg.norm(e, axis=-1, keepdims=True)
    bad = n[:, 0] < 1e-9
    if np.any(bad):
        e[bad] = initial_frame(lam_new[bad])
        n[bad] = 1.0
    return e / n


def exp_step(lam: np.ndarray, e1: np.ndarray, rate: np.ndarray, dt: float) -> np.ndarray:
    """exp_λ(dt (r₁ e₁ + r₂ e₂)) with e₂ = λ × e₁: λ moved by the tangent rate ``rate`` (N, 2)
    [rad/s] for ``dt`` [s], on the unit sphere."""
    e2 = np.cross(lam, e1)
    return exp_map(lam, dt * (rate[:, :1] * e1 + rate[:, 1:2] * e2))


def step_toward(lam: np.ndarray, target: np.ndarray, max_angle: float) -> np.ndarray:
    """λ moved along the great circle toward ``target`` (both unit (N, 3)) by at most
    ``max_angle`` [rad]."""
    dot = np.clip(np.sum(lam * target, axis=-1), -1.0, 1.0)
    tang = target - dot[:, None] * lam
    tn = np.linalg.norm(tang, axis=-1)
    theta = atan2(tn, dot)  # the C library's (estimation.libm), as the compiled twin
    ang = np.minimum(theta, max_angle)
    e = tang / np.where(tn > 1e-15, tn, 1.0)[:, None]
    out = np.cos(ang)[:, None] * lam + np.sin(ang)[:, None] * e
    return np.where((tn > 1e-15)[:, None], _unit(out), lam)


def advance_target(lam: np.ndarray, proposal: np.ndarray, push: np.ndarray, geom: RobotGeometry,
                   axis_margin: float, cross_push: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Accept the proposed next shaped targets unless they cross a steering stop or enter a
    steering-axis cap (see the module docstring).

    Args:
        lam: (N, 3) current shaped λ_s (unit). proposal: (N, 3) proposed next λ (unit, a small
            step: less than π/2 from ``lam``).
        push: (N,) arc [rad] pushed past a stop so far. axis_margin: cap half-angle [rad].
        cross_push: arc [rad] of consecutive pushing past a stop after which it is crossed.

    Returns:
        (λ_s (N, 3), push (N,), held (N,) bool: the step was refused this time).
    """
    beta0 = steering_from_lambda(lam, geom)
    beta1 = steering_from_lambda(proposal, geom)
    crosses = np.any(np.abs(beta1 - beta0) > 0.5 * np.pi, axis=-1) & (not geom.unlimited_steering)
    # (N, n): |cos| of the angle to ±ŝ_k (a row sum, not a BLAS product: the compiled twin's bits)
    cos_axis = np.abs(np.sum(proposal[:, None, :] * geom.s_unit[None, :, :], axis=-1))
    in_cap = np.any(cos_axis > np.cos(axis_margin), axis=-1)
    step = sphere_angle(lam, proposal)
    blocked = crosses | in_cap
    push = np.where(crosses & ~in_cap, push + step, 0.0)
    accept = ~blocked | (crosses & ~in_cap & (push > cross_push))
    push = np.where(accept, 0.0, push)
    return np.where(accept[:, None], proposal, lam), push, ~accept


def shape_target(lam: np.ndarray, lam_t: np.ndarray, mu_t: np.ndarray, push: np.ndarray, geom: RobotGeometry,
                 axis_margin: float, max_angle: float, cross_push: float, nearer: bool = True
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One shaping step (see the module docstring), shared by the single and the vector action
    wrappers: (with ``nearer``) the representative of (λ_t, μ_t) nearer λ, one step of at most
    ``max_angle`` [rad] from λ toward λ_t, then :func:`advance_target`. Without ``nearer`` λ_t is
    the direction of motion (μ_t ≥ 0) and is approached as given.

    Args:
        lam: (N, 3) the controller's reference λ (unit). lam_t, mu_t: (N, 3) unit, (N,) target.
        push: (N,) arc [rad] pushed past a stop so far.

    Returns:
        (λ_s (N, 3), μ_t (N,), push (N,), held (N,) bool).
    """
    if nearer:
        lam_t, mu_t = nearer_representative(lam, lam_t, mu_t)
    prop = step_toward(lam, lam_t, max_angle)
    lam_s, push, held = advance_target(lam, prop, push, geom, axis_margin, cross_push)
    return lam_s, mu_t, push, held
