"""The ICR-based reference controller: coordinated wheel commands from an H-state target.

It follows the ICR-based motion control of L. Clavien, M. Lauria, F. Michaud, "Instantaneous
centre of rotation-based motion control for omnidirectional mobile robots with sidewise-offset
steerable wheels", Robotics and Autonomous Systems (2018), in the H representation of their
"Estimation of the Instantaneous Centre of Rotation with Nonholonomic Omnidirectional Mobile
Robots", whose equation numbers (..) the docstrings cite. Every formula the code uses is derived
in ``docs/icr-controller.md``.

The controller keeps its own *reference* H state η = (λ, μ) and drives it toward the target
(λ_d, μ_d) on the sphere. Every command is the wheel configuration of a single motion, so the
propulsion axes always concur (no actuator antagonism):

* steering set-points β_c = F(λ) (eq. (16)–(17));
* propulsion set-points r φ̇_c = μ (s⊥2 − b ẑ)·λ − b β̇_c, including the b/r steer-to-drive
  coupling of the sidewise wheel.

One control period (:func:`icr_control_step_batch`, N robots at once) is one call of the compiled
step, :func:`control.icr.compiled.compiled_control_step_batch` (numba, row by row; its building
blocks are in :mod:`control.icr.kernels` and :mod:`control.icr.kernels_motion`):

1. the feasible target: the representative of (λ_d, μ_d) nearer to λ, moved out of the
   steering-axis caps (:func:`control.icr.feasibility.project_off_axes`), μ_d clamped to the
   wheel-speed limits at λ_d;
2. the mode transitions: RUNNING -> STOPPING -> RECONFIGURING -> RUNNING when the great-circle arc
   λ -> λ_d crosses a steering axis, or a steering stop farther than a hold takes, or a wheel is
   knocked out of place; a target beyond a stop is held at the nearest point of the current
   configuration's cell (:func:`control.icr.feasibility.stop_hold_point_batch`) until the hold has
   missed ``stop_hold_distance`` of motion;
3. the commands of each mode: a time-scaled step of (λ, μ) (the largest κ ∈ [0, 1] blending the
   previous motion with the desired one for which every wheel's β̇, β̈, φ̇, φ̈ stays within
   :class:`azimut_env.params.ActuatorLimits`; per-wheel saturation if none is, flagged in
   ``info["saturated"]``), or wheels turned in place.

The commands are integrated from the previous *commands*, not from the measurements, so sensor
noise does not reach the set-points; the measurements (β, φ̇, λ̂, μ̂) are used to start, to detect
that the robot has stopped, and to detect a wheel knocked out of place.

The compiled step is the only implementation: the tests' reference is the same code run as plain
Python (``NUMBA_DISABLE_JIT=1``, ``tests/control/test_icr_compiled.py``). One robot is a batch of
one: :func:`icr_control_step` runs :func:`icr_control_step_batch` on the one-row
:class:`~control.icr.state.ICRBatchState` inside its :class:`ICRControllerState`.

Their neighbours' names are importable from here too: :mod:`control.icr.config` (modes,
tuning), :mod:`control.icr.state` (state), :mod:`control.icr.feasibility` (axes, arcs, stops, for
planners and tests), :mod:`control.commands` (the command type shared with the twist baseline);
the great-circle maths is in :mod:`estimation.hrep`.
"""

from __future__ import annotations

import numpy as np

from control.checks import check_finite_array, check_unit, check_unit_batch
from control.commands import WheelCommand
from control.icr.compiled import compiled_control_step_batch
from control.icr.config import Event, ICRControllerConfig, Mode
from control.icr.feasibility import (
    arc_blocked,
    arc_check,
    arc_check_batch,
    project_off_axes,
    project_off_axes_batch,
    reference_stop_mask,
)
from control.icr.state import ICRBatchState, ICRControllerState, initial_state, initial_state_batch
from control.limits import ActuatorLimits
from estimation.geometry import RobotGeometry
from estimation.hrep import nearer_representative as nearer_target
from estimation.hrep import slerp

__all__ = [
    "Mode",
    "Event",
    "ICRControllerConfig",
    "ICRControllerState",
    "ICRBatchState",
    "initial_state_batch",
    "icr_control_step_batch",
    "project_off_axes_batch",
    "arc_check_batch",
    "WheelCommand",
    "ICRController",
    "nearer_target",
    "project_off_axes",
    "arc_blocked",
    "arc_check",
    "reference_stop_mask",
    "slerp",
    "initial_state",
    "icr_control_step",
]


def _event_name(code: int) -> str | None:
    return None if code == Event.NONE else Event(code).name.lower()


def icr_control_step_batch(state: ICRBatchState, lam_hat, mu_hat, beta_meas, phidot_meas, lam_d, mu_d,
                           geom: RobotGeometry, limits: ActuatorLimits, config: ICRControllerConfig,
                           dt: float) -> tuple[ICRBatchState, WheelCommand]:
    """One control period of N ICR controllers at once (pure: returns the new state and the commands).

    Row i is exactly what :func:`icr_control_step` does for robot i (that function is the N = 1
    case of this one): the compiled step works row by row, no row reads another.

    Args:
        state: from :func:`initial_state_batch` or the previous step.
        lam_hat: (N, 3) estimated λ̂ (any sign); mu_hat: (N,) estimated μ̂ [m/s].
        beta_meas: (N, n) measured steering angles [rad]; phidot_meas: (N, n) measured φ̇ [rad/s].
        lam_d: (N, 3) target ICRs (non-zero, any sign); mu_d: (N,) target μ [m/s].
        dt: control period [s].

    Raises:
        ValueError: on non-finite input, wrong shapes, a zero λ_d, or dt <= 0.
    """
    n, nrows = geom.n, state.num
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0, got {dt!r}")
    check_unit_batch(lam_hat, "lam_hat")
    if np.asarray(lam_hat).shape[0] != nrows:
        raise ValueError(f"lam_hat must have shape ({nrows}, 3)")
    mu_hat = check_finite_array(mu_hat, "mu_hat", (nrows,))
    beta_meas = check_finite_array(beta_meas, "beta_meas", (nrows, n))
    check_finite_array(phidot_meas, "phidot_meas", (nrows, n))
    if check_unit_batch(lam_d, "lam_d").shape[0] != nrows:
        raise ValueError(f"lam_d must have shape ({nrows}, 3)")
    mu_d = check_finite_array(mu_d, "mu_d", (nrows,))
    # the compiled step normalises λ̂ and λ_d itself (once: normalising twice may change a bit)
    return compiled_control_step_batch(state, lam_hat, mu_hat, beta_meas, phidot_meas, lam_d, mu_d, geom, limits,
                                       config, dt)


def icr_control_step(state: ICRControllerState, lam_hat, mu_hat, beta_meas, phidot_meas, lam_d, mu_d,
                     geom: RobotGeometry, limits: ActuatorLimits, config: ICRControllerConfig,
                     dt: float) -> tuple[ICRControllerState, WheelCommand]:
    """One control period of the ICR controller (pure: returns the new state and the command).

    The N = 1 case of :func:`icr_control_step_batch`.

    Args:
        state: from :func:`initial_state` or the previous step.
        lam_hat: (3,) estimated λ̂ (any sign); mu_hat: estimated μ̂ [m/s] (sign paired with λ̂).
        beta_meas: (n,) measured steering angles [rad]; phidot_meas: (n,) measured φ̇ [rad/s].
        lam_d: (3,) target ICR (any non-zero vector, any sign); mu_d: target μ [m/s].
        dt: control period [s].

    Raises:
        ValueError: on non-finite input, wrong shapes, a zero λ_d, or dt <= 0.
    """
    n = geom.n
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be finite and > 0, got {dt!r}")
    check_unit(lam_hat, "lam_hat")
    lam_hat = np.asarray(lam_hat, dtype=np.float64)
    mu_hat = float(check_finite_array(mu_hat, "mu_hat", ()))
    beta_meas = check_finite_array(beta_meas, "beta_meas", (n,))
    phidot_meas = check_finite_array(phidot_meas, "phidot_meas", (n,))
    check_unit(lam_d, "lam_d")
    lam_d = np.asarray(lam_d, dtype=np.float64)
    mu_d = float(check_finite_array(mu_d, "mu_d", ()))
    bstate, bcmd = icr_control_step_batch(state.batch, lam_hat[None, :], np.array([mu_hat]),
                                          beta_meas[None, :], phidot_meas[None, :], lam_d[None, :],
                                          np.array([mu_d]), geom, limits, config, dt)
    bi = bcmd.info
    info: dict = {"saturated": bool(bi["saturated"][0]), "event": _event_name(int(bi["event"][0])),
                  "lam_target": bi["lam_target"][0], "mu_target": float(bi["mu_target"][0]),
                  "axis_cap": int(bi["axis_cap"][0]), "kappa": float(bi["kappa"][0]),
                  "mode": Mode(int(bi["mode"][0])), "events": int(bi["events"][0])}
    if bi["held_at_stop"][0]:
        info["held_at_stop"] = True
    cmd = WheelCommand(beta=bcmd.beta[0], phidot=bcmd.phidot[0], beta_rate=bcmd.beta_rate[0],
                       beta_accel=bcmd.beta_accel[0], phiddot=bcmd.phiddot[0], info=info)
    return ICRControllerState(bstate), cmd



class ICRController:
    """Stateful convenience wrapper around :func:`icr_control_step`.

    Args:
        geom: the robot; limits: actuator limits; dt: control period [s] (the env's, 0.02 s by
            default); config: tuning.
    """

    def __init__(self, geom: RobotGeometry, limits: ActuatorLimits | None = None, dt: float = 0.02,
                 config: ICRControllerConfig | None = None) -> None:
        if not isinstance(geom, RobotGeometry):
            raise TypeError(f"geom must be a RobotGeometry, got {type(geom).__name__}")
        if limits is not None and not isinstance(limits, ActuatorLimits):
            raise TypeError(f"limits must be an ActuatorLimits or None, got {type(limits).__name__}")
        if config is not None and not isinstance(config, ICRControllerConfig):
            raise TypeError(f"config must be an ICRControllerConfig or None, got {type(config).__name__}")
        if isinstance(dt, bool) or not isinstance(dt, (int, float, np.integer, np.floating)):
            raise TypeError(f"dt must be a number of seconds, got {type(dt).__name__}")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be finite and > 0, got {dt!r}")
        self.geom = geom
        self.limits = limits or ActuatorLimits()
        self.config = config or ICRControllerConfig()
        self.dt = float(dt)
        self.state: ICRControllerState | None = None

    def reset(self, lam_hat, beta, phidot) -> None:
        """Start (at rest) from the current estimate and measurements."""
        self.state = initial_state(lam_hat, beta, phidot, self.geom, self.config)

    def step(self, lam_hat, mu_hat, beta, phidot, lam_d, mu_d) -> WheelCommand:
        """One control period; resets from the measurements on the first call."""
        if self.state is None:
            self.reset(lam_hat, beta, phidot)
        self.state, cmd = icr_control_step(self.state, lam_hat, mu_hat, beta, phidot, lam_d, mu_d,
                                           self.geom, self.limits, self.config, self.dt)
        return cmd

    @property
    def mode(self) -> Mode:
        """The current mode (RUNNING before the first step)."""
        return Mode.RUNNING if self.state is None else self.state.mode
