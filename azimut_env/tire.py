"""Tire-ground contact model: regularised Coulomb friction inside a friction circle.

At the contact point P_k the slip velocity has a longitudinal part (along the rolling direction
d_k = (sin γ_k, −cos γ_k)), ``s_long = v(P_k)·d_k − r_k φ̇_k``, and a lateral part (along the
propulsion axis e_k = (cos γ_k, sin γ_k), the no-slip direction), ``s_lat = v(P_k)·e_k``. The force
on the robot is

    F = −μ N (s_long d + s_lat e) / v_knee,   scaled back onto ‖F‖ = μ N when it is larger,

and its longitudinal part acts back on the wheel spin with torque ``−r F_long``.

The scalar kernels here are numba functions inlined into the physics substep (one loop over
robots × wheels); :func:`tire_forces` is the same model as a numpy function over (N, n) arrays, for
analysis and tests.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["tire_force_kernel", "tire_forces"]


@njit(cache=True, inline="always")
def tire_force_kernel(s_long: float, s_lat: float, mu_n: float, knee: float):
    """(F_long, F_lat, saturated) on the robot for slip (s_long, s_lat) [m/s], friction limit μN [N]."""
    c = mu_n / knee
    f_long = -c * s_long
    f_lat = -c * s_lat
    mag = math.sqrt(f_long * f_long + f_lat * f_lat)
    if mag > mu_n:
        scale = mu_n / mag
        return f_long * scale, f_lat * scale, True
    return f_long, f_lat, False


def tire_forces(s_long, s_lat, normal_load, friction: float, knee: float) -> tuple[np.ndarray, np.ndarray]:
    """Numpy version of the tire model over arrays: slip (..., n) [m/s], loads (..., n) [N] ->
    (F_long, F_lat) [N] on the robot."""
    s_long = np.asarray(s_long, dtype=np.float64)
    s_lat = np.asarray(s_lat, dtype=np.float64)
    mu_n = friction * np.asarray(normal_load, dtype=np.float64)
    f_long = -mu_n * s_long / knee
    f_lat = -mu_n * s_lat / knee
    mag = np.hypot(f_long, f_lat)
    scale = np.where(mag > mu_n, mu_n / np.where(mag > 0, mag, 1.0), 1.0)
    return f_long * scale, f_lat * scale
