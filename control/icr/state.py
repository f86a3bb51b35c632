"""The ICR controller's state: :class:`ICRBatchState` for N robots; one robot's state
(:class:`ICRControllerState`) is a batch of one, read through row 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from control.checks import check_finite_array, check_unit, check_unit_batch
from control.icr.config import ICRControllerConfig, Mode
from estimation.geometry import RobotGeometry
from estimation.kinematics import steering_from_lambda

__all__ = ["ICRBatchState", "ICRControllerState", "initial_state_batch", "initial_state"]


@dataclass(frozen=True)
class ICRBatchState:
    """The state of N controllers between steps, as (N, …) arrays (frozen; a step returns a new one).

    Attributes:
        mode: (N,) int64 :class:`~control.icr.config.Mode` values.
        lam: (N, 3) reference λ (unit).
        mu: (N,) reference μ [m/s].
        lam_rate: (N, 3) λ̇, tangent to the sphere at ``lam`` [rad/s].
        beta: (N, n) last steering commands β_c [rad].
        beta_rate: (N, n) last steering rates β̇_c [rad/s].
        phidot: (N, n) last propulsion commands φ̇_c [rad/s].
        mode_time: (N,) time spent in the current mode [s].
        reconfig_lam: (N, 3) λ the wheels are being reconfigured for (where ``has_reconfig_lam``).
        events: (N,) number of stop-and-reconfigure sequences started so far.
        beta_meas: (N, n) the previous step's measured steering angles [rad] (for the measured
            steering rate; where ``has_beta_meas``).
        held_miss: (N,) the motion [m] a hold at a steering stop has missed so far, without a break
            (``ICRControllerConfig.stop_hold_distance``).
    """

    mode: np.ndarray  # (N,) int64, Mode values
    lam: np.ndarray  # (N, 3)
    mu: np.ndarray  # (N,)
    lam_rate: np.ndarray  # (N, 3)
    beta: np.ndarray  # (N, n)
    beta_rate: np.ndarray  # (N, n)
    phidot: np.ndarray  # (N, n)
    mode_time: np.ndarray  # (N,)
    reconfig_lam: np.ndarray  # (N, 3)
    has_reconfig_lam: np.ndarray  # (N,) bool
    events: np.ndarray  # (N,) int64
    beta_meas: np.ndarray  # (N, n)
    has_beta_meas: np.ndarray  # (N,) bool
    held_miss: np.ndarray  # (N,)


    @property
    def num(self) -> int:
        return int(self.mode.shape[0])

    def robot(self, i: int) -> ICRControllerState:
        """Robot i's state, as a batch of one."""
        return ICRControllerState(self.take(np.array([i])))

    def take(self, idx: np.ndarray) -> ICRBatchState:
        """The rows ``idx`` (integer indices) as a smaller batch."""
        return ICRBatchState(**{name: getattr(self, name)[idx].copy() for name in self.__dataclass_fields__})

    def put(self, idx: np.ndarray, other: ICRBatchState) -> ICRBatchState:
        """A copy with the rows ``idx`` (integer indices) replaced by the rows of ``other``."""
        out = {}
        for name in self.__dataclass_fields__:
            arr = getattr(self, name).copy()
            arr[idx] = getattr(other, name)
            out[name] = arr
        return ICRBatchState(**out)


#: fields of :class:`ICRBatchState` that one robot reads as Python scalars (the others as arrays)
_SCALAR = {"mode": Mode, "mu": float, "mode_time": float, "events": int, "held_miss": float}
#: fields valid only where their ``has_*`` flag is set (None for one robot otherwise)
_OPTIONAL = ("reconfig_lam", "beta_meas")


@dataclass(frozen=True)
class ICRControllerState:
    """One robot's controller state: an :class:`ICRBatchState` of one row (``batch``).

    Its fields read row 0 of the batch: ``mode`` (a :class:`~control.icr.config.Mode`), ``mu``,
    ``mode_time`` [s], ``held_miss`` [m] and ``events`` as Python scalars; ``lam``, ``lam_rate``,
    ``beta``, ``beta_rate``, ``phidot`` as arrays; ``reconfig_lam`` and ``beta_meas`` as arrays or
    None (see :class:`ICRBatchState` for their meaning and units).
    """

    batch: ICRBatchState

    def __post_init__(self) -> None:
        if self.batch.num != 1:
            raise ValueError(f"a single robot's state is a batch of one, got {self.batch.num} rows")

    def __getattr__(self, name: str):
        if name.startswith("has_") or name not in ICRBatchState.__dataclass_fields__:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        if name in _OPTIONAL and not getattr(self.batch, "has_" + name)[0]:
            return None
        value = getattr(self.batch, name)[0]
        return _SCALAR[name](value) if name in _SCALAR else value


def initial_state_batch(lam_hat, beta, phidot, geom: RobotGeometry,
                        config: ICRControllerConfig | None = None) -> ICRBatchState:
    """:func:`initial_state` for N robots: λ̂ (N, 3), β (N, n), φ̇ (N, n)."""
    config = config or ICRControllerConfig()
    lam = check_unit_batch(lam_hat, "lam_hat")
    nrows = lam.shape[0]
    beta = check_finite_array(beta, "beta", (nrows, geom.n))
    beta = geom.measured_steering(beta)
    phidot = check_finite_array(phidot, "phidot", (nrows, geom.n))
    # with stops the plain difference: a wheel at one stop is not at the other (the same axis mod π,
    # but a turn by π away); unlimited steering: modulo π (RobotGeometry.steering_difference)
    err = geom.steering_difference(beta, steering_from_lambda(lam, geom, singular_fill=beta))
    reconf = np.max(np.abs(err), axis=-1) > config.reconfig_tol
    return ICRBatchState(
        mode=np.where(reconf, int(Mode.RECONFIGURING), int(Mode.RUNNING)).astype(np.int64), lam=lam,
        mu=np.zeros(nrows), lam_rate=np.zeros((nrows, 3)), beta=beta.copy(), beta_rate=np.zeros((nrows, geom.n)),
        phidot=phidot.copy(), mode_time=np.zeros(nrows), reconfig_lam=np.where(reconf[:, None], lam, 0.0),
        has_reconfig_lam=reconf.copy(), events=np.zeros(nrows, dtype=np.int64), beta_meas=beta.copy(),
        has_beta_meas=np.ones(nrows, dtype=np.bool_), held_miss=np.zeros(nrows))


def initial_state(lam_hat, beta, phidot, geom: RobotGeometry,
                  config: ICRControllerConfig | None = None) -> ICRControllerState:
    """Start from the measurements, at rest (μ = 0).

    The reference λ is the estimate λ̂. If the measured wheels are not at F(λ̂) within
    ``reconfig_tol`` (a random start), the controller starts in RECONFIGURING. The N = 1 case of
    :func:`initial_state_batch`.
    """
    check_unit(lam_hat, "lam_hat")
    beta = check_finite_array(beta, "beta", (geom.n,))
    phidot = check_finite_array(phidot, "phidot", (geom.n,))
    return initial_state_batch(np.asarray(lam_hat, dtype=np.float64)[None, :], beta[None, :], phidot[None, :], geom,
                               config).robot(0)
