"""Sensor models over arrays of wheels (N, n): steering encoders on the wheel side of the spring,
motor-angle encoders, and wheel encoders whose count difference over a control period gives φ̇.

All noise comes from the generator passed in (the env's ``np_random``): no global state.
"""

from __future__ import annotations

import math

import numpy as np

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


def measure_all(beta, motor, phi, phi_prev, phidot, dt: float, params: SensorParams,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(β, motor angles, φ̇) as measured, each (..., n); draws in a fixed order for determinism."""
    beta_m = measure_angles(beta, params.steer_noise, params.steer_resolution, rng)
    motor_m = measure_angles(motor, params.motor_noise, params.steer_resolution, rng)
    phidot_m = measure_wheel_speeds(phi, phi_prev, phidot, dt, params, rng)
    return beta_m, motor_m, phidot_m
