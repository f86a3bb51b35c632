"""Sensor models over arrays of wheels (N, n): steering encoders on the wheel side of the spring,
motor-angle encoders, and wheel encoders whose count difference over a control period gives φ̇.

:class:`SensorState` holds the sensors of N robots next to their model: the per-episode state
(the steering encoders' constant bias, the wheel angles at the last reading), the noise draws and
the last readings. Per step and at a reset: :meth:`SensorState.draw_noise` (each robot from its own
generator), then :func:`sense`, the sensor stage of the pipeline (:data:`SENSOR_STAGES`), on the
true steering angles, motor angles, wheel angles and spin rates of the physics; the model of one
wheel is :func:`_read_wheel`, which :func:`measure_batch` and :meth:`SensorState.measure` run too.

All noise comes from the generator passed in (the env's ``np_random``): no global state.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit
from numba.typed import List as NumbaList

from azimut_env.params import SensorParams
from azimut_env.physics.layout import MS, WS
from estimation.threads import BlockKernel

# plain-int columns (numba folds them; the IntEnums stay the names)
_WS_BETA, _MS_THETA, _MS_PHI, _MS_PHIDOT = int(WS.BETA), int(MS.THETA), int(MS.PHI), int(MS.PHIDOT)

__all__ = ["quantize", "measure_angles", "encoder_counts", "measure_wheel_speeds", "measure_batch", "SensorState",
           "sense", "SENSOR_STAGES"]


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
def _read_wheel(beta, motor, phi, phi_prev, phidot, n_beta, n_motor, n_phidot, dt, steer_noise, motor_noise,
                resolution, cpr, wheel_noise, wrap):
    """One wheel's readings (β, motor angle, φ̇) from its true steering angle ``beta`` (the
    encoder's bias included), motor angle, wheel angles now and at the last reading, spin rate and
    this step's three standard normals. ``wrap`` (unlimited steering): the angle readings are taken
    modulo 2π into ]−π, π], as an absolute encoder reads them. Scalars in and out: the stages call
    it element by element (an array view per wheel costs more than the model)."""
    two_pi = 2 * math.pi
    b = beta + steer_noise * n_beta
    m = motor + motor_noise * n_motor
    if resolution > 0:
        b = np.round(b / resolution) * resolution
        m = np.round(m / resolution) * resolution
    if wrap:
        b = math.pi - (math.pi - b) % two_pi
        m = math.pi - (math.pi - m) % two_pi
    if cpr > 0:
        counts = math.floor(phi * (cpr / two_pi)) - math.floor(phi_prev * (cpr / two_pi))
        w = counts * (two_pi / cpr) / dt
    else:
        w = phidot
    return b, m, w + wheel_noise * n_phidot


@njit(cache=True)
def _measure_kernel(beta, motor, phi, phi_prev, phidot, dt, steer_noise, motor_noise, resolution, cpr,
                    wheel_noise, normals, out, wrap=False):
    """Rows of (N, n) arrays; normals (N, 3, n); out (N, 3, n) = (β, motor angle, φ̇) measured
    (:func:`_read_wheel` element by element)."""
    for i in range(beta.shape[0]):
        for k in range(beta.shape[1]):
            out[i, 0, k], out[i, 1, k], out[i, 2, k] = _read_wheel(
                beta[i, k], motor[i, k], phi[i, k], phi_prev[i, k], phidot[i, k], normals[i, 0, k], normals[i, 1, k],
                normals[i, 2, k], dt, steer_noise, motor_noise, resolution, cpr, wheel_noise, wrap)


@njit(cache=True)
def sense(ta, rows, action):
    """The sensor stage of the pipeline (:mod:`azimut_env.task.pipeline`): the readings of the
    robots of ``rows`` from the physics' true state and this step's normals (``ta.normals``, drawn
    before the pipeline from each robot's generator); the wheel encoders then count from there."""
    ws, ms, normals, bias, phi_prev = ta.wheel_summary, ta.motor_state, ta.normals, ta.steer_bias, ta.phi_prev
    beta_m, motor_m, phidot_m = ta.beta_m, ta.motor_m, ta.phidot_m
    for i in range(rows.shape[0]):
        if rows[i]:
            for k in range(ws.shape[1]):
                phi = ms[i, k, _MS_PHI]
                beta_m[i, k], motor_m[i, k], phidot_m[i, k] = _read_wheel(
                    ws[i, k, _WS_BETA] + bias[i, k], ms[i, k, _MS_THETA], phi, phi_prev[i, k], ms[i, k, _MS_PHIDOT],
                    normals[i, 0, k], normals[i, 1, k], normals[i, 2, k], ta.control_period, ta.steer_noise,
                    ta.motor_noise, ta.steer_resolution, ta.wheel_cpr, ta.wheel_speed_noise, ta.wrap_angles)
                phi_prev[i, k] = phi


#: the sensor models the step and the reset run, in order (stages ``(ta, rows, action)``; a new
#: sensor adds its own stage here, its readings to :data:`azimut_env.task.arrays.FIELDS`)
SENSOR_STAGES = (sense,)


def _as_rows(x, shape) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(x, dtype=np.float64).reshape(shape))


def measure_batch(beta, motor, phi, phi_prev, phidot, dt: float, params: SensorParams,
                rng: np.random.Generator, wrap: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(β, motor angles, φ̇) as measured, each shaped like ``beta``: (n,) for one robot or (N, n).

    The same models as :func:`measure_angles` and :func:`measure_wheel_speeds` in one compiled
    call, with one draw of (N, 3, n) standard normals from ``rng`` (deterministic for a seeded rng).
    """
    beta = np.asarray(beta, dtype=np.float64)
    shape = beta.shape
    n = shape[-1]
    flat = (-1, n)
    b2 = _as_rows(beta, flat)
    rows = b2.shape[0]
    normals = rng.standard_normal((rows, 3, n)) if rows > 1 else rng.standard_normal((3, n))[None]
    out = np.empty((rows, 3, n))
    _measure_kernel(b2, _as_rows(motor, flat), _as_rows(phi, flat), _as_rows(phi_prev, flat), _as_rows(phidot, flat),
                    float(dt), params.steer_noise, params.motor_noise, params.steer_resolution, int(params.wheel_cpr),
                    params.wheel_speed_noise, normals, out, bool(wrap))
    return out[:, 0].reshape(shape), out[:, 1].reshape(shape), out[:, 2].reshape(shape)


@njit(cache=True)
def _draw_normals_kernel(rngs, rows, out, lo, hi):
    """out[i] (3, n) = rngs[i].standard_normal((3, n)) for the rows ``lo`` to ``hi - 1`` where
    ``rows`` is True: the same numbers, in the same order, as NumPy's (numba's Generator runs
    NumPy's algorithms on the same bit generator state; each robot its own generator, so a block
    of robots per thread draws the same numbers)."""
    for i in range(lo, hi):
        if rows[i]:
            rng = rngs[i]
            for j in range(out.shape[1]):
                for k in range(out.shape[2]):
                    out[i, j, k] = rng.standard_normal()


#: the draws over blocks of robots (a block: at least 32 robots)
_DRAW_NORMALS = BlockKernel(_draw_normals_kernel, min_rows=32)


class SensorState:
    """The sensors of N robots with n wheels each: model, per-episode state and last readings.

    Attributes (leading axis N): ``beta``, ``motor``, ``phidot`` (N, n): the last readings of the
    steering angles [rad], steering motor angles [rad] and wheel spin rates [rad/s];
    ``steer_bias`` (N, n) [rad]: the steering encoders' constant offsets, drawn per episode
    (``SensorParams.steer_bias``); ``phi_prev`` (N, n) [rad]: the wheel angles at the last reading
    (the encoders count from there); ``normals`` (N, 3, n): this step's standard normal draws.
    """

    def __init__(self, params: SensorParams, control_period: float, n_robots: int, n: int,
                 wrap_angles: bool = False) -> None:
        self.params = params
        self._args = (float(control_period), params.steer_noise, params.motor_noise, params.steer_resolution,
                      int(params.wheel_cpr), params.wheel_speed_noise)
        #: readings of β and the motor angles modulo 2π into ]−π, π] (unlimited steering)
        self.wrap_angles = bool(wrap_angles)
        self.beta = np.zeros((n_robots, n))
        self.motor = np.zeros((n_robots, n))
        self.phidot = np.zeros((n_robots, n))
        self.steer_bias = np.zeros((n_robots, n))
        self.phi_prev = np.zeros((n_robots, n))
        self.normals = np.zeros((n_robots, 3, n))
        self._out = np.empty((n_robots, 3, n))
        #: threads of the compiled draw (the task sets its own; any count draws the same numbers)
        self.num_threads = 1

    def draw_bias(self, i: int, rng: np.random.Generator) -> None:
        """Robot i's steering encoder offsets for a new episode (n normal draws when the bias is on)."""
        sb = self.params.steer_bias
        self.steer_bias[i] = rng.normal(0.0, sb, size=self.steer_bias.shape[1]) if sb > 0 else 0.0

    def start(self, i: int, phi: np.ndarray) -> None:
        """Robot i's wheel encoders start counting from the wheel angles ``phi`` (n,) [rad]."""
        self.phi_prev[i] = phi

    def draw_noise(self, rngs: Sequence[np.random.Generator], rows: np.ndarray, all_rows: bool = False) -> None:
        """This step's normals of the robots where ``rows`` is True, robot i from ``rngs[i]``
        (a sequence of N generators, or a ``numba.typed.List`` of them: one compiled call, the
        same streams). ``all_rows``: ``rows`` selects every robot."""
        normals = self.normals
        if isinstance(rngs, NumbaList):
            _DRAW_NORMALS.run(self.num_threads, normals.shape[0], rngs, rows, normals)
        elif all_rows:
            for i, rng in enumerate(rngs):
                rng.standard_normal(out=normals[i])
        else:
            for i in np.flatnonzero(rows):
                rngs[i].standard_normal(out=normals[i])

    def draw_noise_robot(self, i: int, rng: np.random.Generator) -> None:
        """Robot i's normals, from its generator (at its reset)."""
        rng.standard_normal(out=self.normals[i])

    def measure(self, rows: slice, beta: np.ndarray, motor: np.ndarray, phi: np.ndarray, phidot: np.ndarray) -> None:
        """The readings of the robots ``rows`` from their true steering angles, motor angles,
        wheel angles and wheel spin rates (each (rows, n)), with this step's normals; the wheel
        encoders then count from ``phi``."""
        out = self._out[rows]
        _measure_kernel(beta + self.steer_bias[rows], motor, phi, self.phi_prev[rows], phidot, *self._args,
                        self.normals[rows], out, self.wrap_angles)
        self.phi_prev[rows] = phi
        self.beta[rows] = out[:, 0]
        self.motor[rows] = out[:, 1]
        self.phidot[rows] = out[:, 2]
