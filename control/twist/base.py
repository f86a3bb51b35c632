"""What the two twist controllers share, ``twist`` (:mod:`control.twist.wpilib`) and
``twist-setpoint`` (:mod:`control.twist.setpoint`): their arguments checked, the last commands
kept and reset from the measured state, and a step's inputs checked, in the reference of one robot
(:class:`TwistControllerBase`: :class:`~control.twist.wpilib.SwerveController`,
:class:`~control.twist.setpoint.SetpointController`) and in the compiled batch of N
(:class:`TwistBatchBase`: :class:`~control.twist.wpilib.SwerveBatch`,
:class:`~control.twist.setpoint.SetpointBatch`, whose compiled call runs on ``num_threads``
threads, blocks of robots, :mod:`estimation.threads`: the same bits for any count)."""

from __future__ import annotations

import math

import numpy as np

from control.commands import WheelCommand
from control.limits import ActuatorLimits
from estimation.geometry import RobotGeometry
from estimation.threads import BlockKernel, check_threads

__all__ = ["TwistControllerBase", "TwistBatchBase"]


def _check_dt_config(dt: float, config, config_type: type) -> None:
    if config is not None and not isinstance(config, config_type):
        raise TypeError(f"config must be a {config_type.__name__} or None, got {type(config).__name__}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0, got {dt!r}")


class TwistControllerBase:
    """One robot's twist-to-wheels state, the reference of a batch: ``twist`` (3,) and the last
    commands ``beta``, ``rate``, ``phidot`` (n,). A subclass names its config type in
    ``config_type``; ``config`` None is its defaults.

    Args:
        geom: the robot's geometry; limits: its actuator limits; dt: the control period [s];
        config: an instance of ``config_type`` or None.
    """

    config_type: type

    def __init__(self, geom: RobotGeometry, limits: ActuatorLimits, dt: float = 0.02, config=None) -> None:
        _check_dt_config(dt, config, self.config_type)
        self.geom, self.limits, self.dt = geom, limits, float(dt)
        self.config = config or self.config_type()
        self.reset()

    def reset(self, beta=None, phidot=None) -> None:
        """Forget the history; start from measured angles (default 0) at rest."""
        n = self.geom.n
        self.twist = np.zeros(3)
        beta = None if beta is None else np.asarray(beta, dtype=np.float64)
        self.beta = np.zeros(n) if beta is None else self.geom.measured_steering(beta)
        self.rate = np.zeros(n)
        self.phidot = np.zeros(n) if phidot is None else np.asarray(phidot, dtype=np.float64).copy()
        self._started = beta is not None

    def _step_inputs(self, twist, beta_meas) -> tuple[np.ndarray, np.ndarray]:
        """The twist target (3,) and measured β (n,) as float64 arrays, checked finite; the first
        step after a bare :meth:`reset` starts from β. With unlimited steering the measured angle
        (an absolute encoder's, in ]−π, π]) is put on the last commands' turn."""
        twist = np.asarray(twist, dtype=np.float64)
        beta_meas = np.asarray(beta_meas, dtype=np.float64)
        if twist.shape != (3,) or not np.all(np.isfinite(twist)):
            raise ValueError(f"twist must be a finite (3,) array, got {twist!r}")
        if beta_meas.shape != (self.geom.n,) or not np.all(np.isfinite(beta_meas)):
            raise ValueError(f"beta_meas must be a finite ({self.geom.n},) array")
        if not self._started:
            self.reset(beta_meas)
        if self.geom.unlimited_steering:
            beta_meas = self.beta + (np.mod(beta_meas - self.beta + np.pi, 2 * np.pi) - np.pi)
        return twist, beta_meas

    def _command(self, beta: np.ndarray, rate: np.ndarray, phidot: np.ndarray, info: dict) -> WheelCommand:
        """The step's commands β, β̇, φ̇ (n,) kept as the last ones, with their rates of change."""
        accel = (rate - self.rate) / self.dt
        phiddot = (phidot - self.phidot) / self.dt
        self.beta, self.rate, self.phidot = beta, rate, phidot
        return WheelCommand(beta=beta.copy(), phidot=phidot.copy(), beta_rate=rate, beta_accel=accel,
                            phiddot=phiddot, info=info)


class TwistBatchBase:
    """N robots' twist-to-wheels state, stepped by row: ``twist`` (N, 3) and the last commands
    ``beta``, ``rate``, ``phidot`` (N, n). A subclass names its config type in ``config_type`` and
    sets up its own state and its compiled step's constants in :meth:`_setup`.

    Args:
        num: robots N; geom, limits, dt [s], config: as :class:`TwistControllerBase`; num_threads:
            threads of the compiled step (None: the cores this process may use; any count gives
            the same bits).
    """

    config_type: type

    def __init__(self, num: int, geom: RobotGeometry, limits: ActuatorLimits, dt: float = 0.02,
                 config=None, num_threads: int | None = None) -> None:
        if isinstance(num, bool) or not isinstance(num, (int, np.integer)) or num < 1:
            raise ValueError(f"num must be an int >= 1, got {num!r}")
        _check_dt_config(dt, config, self.config_type)
        self.num, self.geom, self.limits, self.dt, self.config = int(num), geom, limits, float(dt), config
        self.num_threads = check_threads(num_threads)
        n = geom.n
        self.twist, self.beta = np.zeros((self.num, 3)), np.zeros((self.num, n))
        self.rate, self.phidot = np.zeros((self.num, n)), np.zeros((self.num, n))
        self._ready = np.zeros(self.num, dtype=np.bool_)
        self._setup(config or self.config_type())

    def _setup(self, cfg) -> None:
        """Set up the subclass's own state and what its compiled step reads from its config ``cfg``
        (never None)."""

    @property
    def ready(self) -> np.ndarray:
        """(N,) bool: the robots reset at least once (only those can be stepped)."""
        return self._ready.copy()

    def reset(self, rows, beta, phidot) -> None:
        """Restart the robots ``rows`` from their measured β, φ̇ (M, n), at rest."""
        rows = np.asarray(rows, dtype=np.intp)
        beta = np.asarray(beta, dtype=np.float64).reshape(rows.size, self.geom.n)
        self.twist[rows] = 0.0
        self.beta[rows] = self.geom.measured_steering(beta)
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
