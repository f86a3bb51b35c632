"""N ICR controllers as one stateful object: :class:`BatchICRController`.

It holds the :class:`~control.icr.state.ICRBatchState` of N robots and steps any subset of them
with one call of the compiled step (:func:`~control.icr.compiled.compiled_control_step_batch`,
the step :func:`~control.icr.controller.icr_control_step_batch` runs too); each robot is reset on
its own (after its episode's reset). Row i of a step is what the one-robot
:class:`~control.icr.controller.ICRController` does for robot i: the step works row by row (no
row reads another), so stepping N robots together gives the same
commands, bit for bit, as stepping them one at a time (``tests/control/test_controller_api.py``
checks it on whole episodes).

Users: the ``icr`` path-following controller of ``azimut eval``
(:class:`control.path_controllers.ICRPathController`) and the RL action spaces
(:class:`control.action_spaces.controller.ActionController`).
"""

from __future__ import annotations

import numpy as np

from control.commands import WheelCommand
from control.icr.compiled import compiled_constants, compiled_control_step_batch
from control.icr.config import ICRControllerConfig, Mode
from control.icr.state import ICRBatchState, initial_state_batch
from control.limits import ActuatorLimits
from estimation.geometry import RobotGeometry
from estimation.threads import check_threads

__all__ = ["BatchICRController"]


def _blank_state(num: int, n: int) -> ICRBatchState:
    """A placeholder state for robots not reset yet (never stepped: :meth:`BatchICRController.step`
    refuses them)."""
    return ICRBatchState(
        mode=np.full(num, int(Mode.RUNNING), dtype=np.int64), lam=np.tile([0.0, 0.0, 1.0], (num, 1)),
        mu=np.zeros(num), lam_rate=np.zeros((num, 3)), beta=np.zeros((num, n)), beta_rate=np.zeros((num, n)),
        phidot=np.zeros((num, n)), mode_time=np.zeros(num), reconfig_lam=np.zeros((num, 3)),
        has_reconfig_lam=np.zeros(num, dtype=np.bool_), events=np.zeros(num, dtype=np.int64),
        beta_meas=np.zeros((num, n)), has_beta_meas=np.zeros(num, dtype=np.bool_), held_miss=np.zeros(num))


class BatchICRController:
    """N ICR controllers (see the module docstring).

    Args:
        num: robots N. geom: the robot; limits: actuator limits; dt: control period [s];
        config: tuning (default :class:`~control.icr.config.ICRControllerConfig`).
        num_threads: threads of the compiled step (None: the cores this process may use; any
            count gives the same bits).
    """

    def __init__(self, num: int, geom: RobotGeometry, limits: ActuatorLimits, dt: float,
                 config: ICRControllerConfig | None = None, num_threads: int | None = None) -> None:
        if isinstance(num, bool) or not isinstance(num, (int, np.integer)) or num < 1:
            raise ValueError(f"num must be an int >= 1, got {num!r}")
        if not isinstance(geom, RobotGeometry):
            raise TypeError(f"geom must be a RobotGeometry, got {type(geom).__name__}")
        if not isinstance(limits, ActuatorLimits):
            raise TypeError(f"limits must be an ActuatorLimits, got {type(limits).__name__}")
        if config is not None and not isinstance(config, ICRControllerConfig):
            raise TypeError(f"config must be an ICRControllerConfig or None, got {type(config).__name__}")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {dt!r}")
        self.num, self.geom, self.limits, self.dt = int(num), geom, limits, float(dt)
        self.config = config or ICRControllerConfig()
        #: threads of the compiled step (blocks of robots)
        self.num_threads = check_threads(num_threads)
        self.state = _blank_state(self.num, geom.n)
        self._constants = compiled_constants(geom, limits, self.config, self.dt)
        #: (N,) bool: the robots reset at least once (only those can be stepped)
        self.ready = np.zeros(self.num, dtype=np.bool_)

    def reset(self, rows: np.ndarray, lam_hat, beta, phidot) -> ICRBatchState:
        """Start the robots ``rows`` (integer indices) at rest from their estimates λ̂ (M, 3) and
        measurements β, φ̇ (M, n) (M = len(rows); :func:`~control.icr.state.initial_state_batch`).
        Returns their fresh state."""
        rows = np.asarray(rows, dtype=np.intp)
        fresh = initial_state_batch(lam_hat, beta, phidot, self.geom, self.config)
        self.state = self.state.put(rows, fresh)
        self.ready[rows] = True
        return fresh

    def step(self, rows: np.ndarray | None, lam_hat, mu_hat, beta, phidot, lam_d, mu_d,
             plan_side=None, plan_excursion=None) -> WheelCommand:
        """One control period of the robots ``rows`` (None: all N); the arrays are theirs, in that
        order (λ̂ (M, 3), μ̂ (M,), β and φ̇ (M, n), target λ_d (M, 3) and μ_d (M,); ``plan_side``
        (M, n) and ``plan_excursion`` (M,): a look-ahead plan's cell and expected excursions, or
        None: :func:`compiled_control_step_batch`). Returns
        their commands ((M, n) arrays, ``info`` as
        :func:`~control.icr.controller.icr_control_step_batch`'s) with
        ``mode`` and ``events`` (the sequences started since each robot's reset) set."""
        idx = np.arange(self.num) if rows is None else np.asarray(rows, dtype=np.intp)
        if not self.ready[idx].all():
            raise RuntimeError(f"robots {idx[~self.ready[idx]].tolist()} were never reset: call reset() first")
        self.state, cmd = compiled_control_step_batch(self.state, lam_hat, mu_hat, beta, phidot, lam_d, mu_d, self.geom,
                                                      self.limits, self.config, self.dt, rows=rows,
                                                      constants=self._constants, plan_side=plan_side,
                                                      plan_excursion=plan_excursion, num_threads=self.num_threads)
        return WheelCommand(beta=cmd.beta, phidot=cmd.phidot, beta_rate=cmd.beta_rate, beta_accel=cmd.beta_accel,
                            phiddot=cmd.phiddot, info=cmd.info, mode=cmd.info["mode"], events=cmd.info["events"])
