"""Sensor models over arrays of wheels (N, n): steering encoders on the wheel side of the spring,
motor-angle encoders, and wheel encoders whose count difference over a control period gives φ̇.

All noise comes from the generator passed in (the env's ``np_random``): no global state.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .params import SensorParams

__all__ = ["quantize", "measure_angles", "encoder_counts", "measure_wheel_speeds"]


def quantize(x: np.ndarray, resolution: float) -> np.ndarray:
    """Round to the nearest multiple of ``resolution`` (no-op for resolution 0)."""
    if resolution <= 0:
        return np.asarray(x, dtype=np.float64)
    return np.round(np.asarray(x, dtype=np.float64) / resolution) * resolution


def measure_angles(true_angles: np.ndarray, noise_std: float, resolution: float,
                   rng: np.random.Generator) -> np.ndarray:
    """Encoder reading of angles (..., n) [rad]: Gaussian noise then quantisation."""
    x = np.asarray(true_angles, dtype=np.float64)
    if noise_std > 0:
        x = x + noise_std * rng.standard_normal(x.shape)
    return quantize(x, resolution)


def encoder_counts(phi: np.ndarray, cpr: int) -> np.ndarray:
    """Integer wheel-encoder counts of accumulated wheel angles φ (..., n) [rad]."""
    return np.floor(np.asarray(phi, dtype=np.float64) * (cpr / (2 * math.pi)))


def measure_wheel_speeds(phi: np.ndarray, phi_prev: np.ndarray, true_phidot: np.ndarray, dt: float,
                         params: SensorParams, rng: np.random.Generator) -> np.ndarray:
    """Measured φ̇ (..., n) [rad/s]: encoder count difference over the control period ``dt``
    (quantum 2π / (cpr·dt)), plus Gaussian noise. With ``cpr = 0`` the true φ̇ is used."""
    if params.wheel_cpr > 0:
        counts = encoder_counts(phi, params.wheel_cpr) - encoder_counts(phi_prev, params.wheel_cpr)
        x = counts * (2 * math.pi / params.wheel_cpr) / dt
    else:
        x = np.asarray(true_phidot, dtype=np.float64).copy()
    if params.wheel_speed_noise > 0:
        x = x + params.wheel_speed_noise * rng.standard_normal(x.shape)
    return x


@njit(cache=True)
def _measure_kernel(beta, motor, phi, phi_prev, phidot, dt, steer_noise, motor_noise, resolution, cpr,
                    wheel_noise, normals, out):
    """Rows of (N, n) arrays; normals (N, 3, n); out (N, 3, n) = (β, motor angle, φ̇) measured."""
    two_pi = 2 * math.pi
    for i in range(beta.shape[0]):
        for k in range(beta.shape[1]):
            b = beta[i, k] + steer_noise * normals[i, 0, k]
            m = motor[i, k] + motor_noise * normals[i, 1, k]
            if resolution > 0:
                b = np.round(b / resolution) * resolution
                m = np.round(m / resolution) * resolution
            if cpr > 0:
                counts = math.floor(phi[i, k] * (cpr / two_pi)) - math.floor(phi_prev[i, k] * (cpr / two_pi))
                w = counts * (two_pi / cpr) / dt
            else:
                w = phidot[i, k]
            out[i, 0, k] = b
            out[i, 1, k] = m
            out[i, 2, k] = w + wheel_noise * normals[i, 2, k]


def _rows(x, shape) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(x, dtype=np.float64).reshape(shape))


def measure_all(beta, motor, phi, phi_prev, phidot, dt: float, params: SensorParams,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(β, motor angles, φ̇) as measured, each shaped like ``beta``: (n,) for one robot or (N, n).

    The same models as :func:`measure_angles` and :func:`measure_wheel_speeds` in one compiled
    call, with one draw of (N, 3, n) standard normals from ``rng`` (deterministic for a seeded rng).
    """
    beta = np.asarray(beta, dtype=np.float64)
    shape = beta.shape
    n = shape[-1]
    flat = (-1, n)
    b2 = _rows(beta, flat)
    rows = b2.shape[0]
    normals = rng.standard_normal((rows, 3, n)) if rows > 1 else rng.standard_normal((3, n))[None]
    out = np.empty((rows, 3, n))
    _measure_kernel(b2, _rows(motor, flat), _rows(phi, flat), _rows(phi_prev, flat), _rows(phidot, flat),
                    float(dt), params.steer_noise, params.motor_noise, params.steer_resolution, int(params.wheel_cpr),
                    params.wheel_speed_noise, normals, out)
    return out[:, 0].reshape(shape), out[:, 1].reshape(shape), out[:, 2].reshape(shape)
