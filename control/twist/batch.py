"""What the two compiled twist batches share (:class:`~control.twist.wpilib.SwerveBatch`,
:class:`~control.twist.setpoint.SetpointBatch`): their arguments checked, each robot's last
commands in (N, ...) arrays, the reset of rows from the measured state, a step's rows and
inputs checked before the compiled call, and the threads that call runs on (blocks of robots,
:mod:`estimation.threads`: the same bits for any count)."""

from __future__ import annotations

import math

import numpy as np

from control.commands import WheelCommand
from control.limits import ActuatorLimits
from estimation.geometry import RobotGeometry
from estimation.threads import BlockKernel, check_threads

__all__ = ["TwistBatchBase"]


class TwistBatchBase:
    """N robots' twist-to-wheels state, stepped by row: ``twist`` (N, 3) and the last commands
    ``beta``, ``rate``, ``phidot`` (N, n). A subclass names its config type in ``config_type``."""

    config_type: type

    def __init__(self, num: int, geom: RobotGeometry, limits: ActuatorLimits, dt: float, config,
                 num_threads: int | None = None) -> None:
        if isinstance(num, bool) or not isinstance(num, (int, np.integer)) or num < 1:
            raise ValueError(f"num must be an int >= 1, got {num!r}")
        if config is not None and not isinstance(config, self.config_type):
            raise TypeError(f"config must be a {self.config_type.__name__} or None, got {type(config).__name__}")
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {dt!r}")
        self.num, self.geom, self.limits, self.dt, self.config = int(num), geom, limits, float(dt), config
        #: threads of the compiled step (blocks of robots; None given: the cores this process may use)
        self.num_threads = check_threads(num_threads)
        n = geom.n
        self.twist, self.beta = np.zeros((self.num, 3)), np.zeros((self.num, n))
        self.rate, self.phidot = np.zeros((self.num, n)), np.zeros((self.num, n))
        self._ready = np.zeros(self.num, dtype=np.bool_)

    @property
    def ready(self) -> np.ndarray:
        """(N,) bool: the robots reset at least once (only those can be stepped)."""
        return self._ready.copy()

    def reset(self, rows, beta, phidot) -> None:
        """Restart the robots ``rows`` from their measured β, φ̇ (M, n), at rest."""
        rows = np.asarray(rows, dtype=np.intp)
        beta = np.asarray(beta, dtype=np.float64).reshape(rows.size, self.geom.n)
        self.twist[rows] = 0.0
        self.beta[rows] = beta if self.geom.unlimited_steering else self.geom.wrap_steering(beta)
        self.rate[rows] = 0.0
        self.phidot[rows] = np.asarray(phidot, dtype=np.float64).reshape(rows.size, self.geom.n)
        self._ready[rows] = True

    def _step_inputs(self, rows, twists, beta_meas) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows to step (None: all; each reset before; distinct) and the twists (M, 3) and
        measured β (M, n) as contiguous float64 arrays, their shapes checked and finite."""
        idx = np.arange(self.num, dtype=np.int64) if rows is None else np.asarray(rows, dtype=np.int64)
        if not self._ready[idx].all():
            raise RuntimeError("a robot of this batch was never reset: call reset() first")
        M, n = idx.size, self.geom.n
        twists = np.ascontiguousarray(twists, dtype=np.float64)
        beta_meas = np.ascontiguousarray(beta_meas, dtype=np.float64)
        if twists.shape != (M, 3):
            raise ValueError(f"twists must have shape ({M}, 3), got {twists.shape}")
        if beta_meas.shape != (M, n):
            raise ValueError(f"beta_meas must have shape ({M}, {n}), got {beta_meas.shape}")
        if not np.isfinite(twists).all():
            raise ValueError("twist must be finite")
        if not np.isfinite(beta_meas).all():
            raise ValueError("beta_meas must be finite")
        if rows is not None and self.num_threads > 1 and np.unique(idx).size != M:
            raise ValueError("rows must be distinct robots")
        return idx, twists, beta_meas

    def _run(self, kernel: BlockKernel, idx: np.ndarray, *args) -> None:
        """The compiled step ``kernel`` of the robots ``idx`` on :attr:`num_threads` threads."""
        kernel.run(self.num_threads, idx.shape[0], idx, *args)

    @staticmethod
    def _command(out: np.ndarray, **fields) -> WheelCommand:
        """The commands from the compiled step's outputs ``out`` (5, M, n: β, φ̇, β̇, β̈, φ̈) and
        ``fields``."""
        return WheelCommand(beta=out[0], phidot=out[1], beta_rate=out[2], beta_accel=out[3], phiddot=out[4],
                            **fields)
