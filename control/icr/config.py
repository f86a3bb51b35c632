"""The ICR controller's modes and tuning.

The controller is a three-mode state machine (see ``docs/icr-controller.md``, "Modes"):
RUNNING (coordinated motion on the constraining surface), STOPPING (μ brought to 0 with λ held)
and RECONFIGURING (the wheels turned in place, the chassis at rest, to the steering angles of
the new λ).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from azimut_env.validation import check_bool, check_fields, check_int, check_positive, check_range

__all__ = ["Mode", "Event", "ICRControllerConfig"]


class Mode(enum.IntEnum):
    """The controller's modes (the state machine of ``docs/icr-controller.md``)."""

    RUNNING = 0
    STOPPING = 1
    RECONFIGURING = 2


class Event(enum.IntEnum):
    """Why a stop-and-reconfigure sequence started (``info["event"]`` of a step)."""

    NONE = 0
    KICK = 1  #: a wheel knocked out of place (measured far from commanded)
    STOP = 2  #: the arc to the target crosses a steering stop
    AXIS = 3  #: the arc to the target passes a steering axis


@dataclass(frozen=True)
class ICRControllerConfig:
    """Tuning of the ICR controller.

    Attributes:
        k_lambda: gain of the great-circle approach λ -> λ_d [1/s] (λ̇ = k_λ · angle, capped).
        mu_accel_fraction: fraction of the wheel acceleration limit that the μ ramp uses [-]; the
            rest is kept for the λ motion and the steer-to-drive coupling.
        mu_headroom: fraction of the φ̇ limit that μ_d may use at λ_d [-]; the rest is kept for the
            b/r steer-to-drive coupling and for transitions.
        axis_margin: angular radius of the cap around each steering axis ŝ_k that targets may not
            enter [rad] (eq. (21)).
        n_kappa: number of time-scaling factors κ tried per step (grid on [0, 1]).
        arc_step: spacing of the samples of the λ -> λ_d arc checked for stop crossings [rad].
        stop_mu_tol: |μ| [m/s] below which the robot counts as stopped (commanded and estimated).
        zero_mu_tol: |μ_d| [m/s] below which the target is a stop command: λ is held, the wheels
            do not swing.
        kick_tol: measured-versus-commanded steering error [rad] (modulo π) that counts as a
            wheel knocked out of place; it triggers stop-and-reconfigure.
        reconfig_tol: steering error [rad] below which a reconfiguration is complete.
        reconfig_freeze: while RECONFIGURING, the configuration being reached follows a new target
            only if that target is not reachable from it without another stop, differs from it by
            a motion of at least ``stop_hold_speed`` (|μ_d| times the chord between the two λ, the
            nearer representative), and only while some steering command is farther than this
            [rad] from it (so it converges exactly; the RUNNING mode then takes the remaining
            motion).
        reconfig_timeout: time [s] after which RECONFIGURING resumes even if a measured wheel
            angle has not settled within ``reconfig_tol`` (commands have).
        reconfig_hold_tol, reconfig_still_tol: a wheel also counts as settled (once the commands
            have) when it is within ``reconfig_hold_tol`` [rad] of its target and its measured
            angle moved less than ``reconfig_still_tol`` [rad] in the last period: it has stopped
            where the steering's stiction and the tread's grip hold it at rest (the dead band
            τ_s/k_s of a compliant steering with friction, 1.9° for the ``"paper"`` robot, plus
            the scrub torque's deflection), and rolling will bring it the rest of the way; the
            robot need not wait for ``reconfig_timeout``. A ``reconfig_still_tol`` above π/2
            tests no stillness (a wheel moves less than that in a period): any wheel within
            ``reconfig_hold_tol`` counts as settled.
        coupling_from_measurement: in RECONFIGURING, compute the steer-to-drive coupling
            r φ̇ = −b β̇ from the measured steering rate (finite difference of the measured β)
            instead of the commanded one: the compliant steering lags its set-point.
        reconfig_rate_fraction, reconfig_accel_fraction: fractions of the steering rate and
            acceleration limits used when turning the wheels in place [-] (slower turns scrub
            less: the compliant steering lags less behind its set-point).
        mu_own_scale: give μ its own time scaling (default False): after the common factor κ of
            the λ and μ motion is chosen, μ goes on toward its ramp target as far as the wheels'
            φ̇ and φ̈ limits allow at the chosen λ (μ changes only those; the steering rate and
            acceleration limits, which bind while λ turns quickly, do not involve μ). μ then
            follows μ_d at its ramp while λ is being turned instead of waiting for λ: for targets
            that change often (an exploring RL policy, :mod:`control.action_spaces.shaping`).
        stop_hysteresis: a target beyond a steering stop by less than this angle [rad] (from the
            hold point, below) whose missed speed is below ``stop_hold_speed`` is held at the stop
            for as long as it stays so: it does not draw on ``stop_hold_distance``.
        stop_hold_speed: [m/s] the missed speed below which a hold at a steering stop is free
            (with ``stop_hysteresis``), and the speed difference below which a reconfiguration
            does not follow a new target (see ``reconfig_freeze``).
        stop_hold_angle: a target beyond a steering stop by less than this angle [rad] is held at
            the stop, within ``stop_hold_distance``; one farther beyond stops the robot at once.
        stop_hold_distance: [m] how much motion a hold at a steering stop may miss before the robot
            stops and reconfigures. A target beyond a stop is held at the point of the current
            configuration's cell nearest to it (:func:`control.icr.feasibility.stop_hold_point_batch`);
            each period the hold misses ``max(|μ_d|, |μ|)·‖λ_hold − λ_d‖·dt`` of motion (the speed
            of the twist difference, the robot's own μ counted while it is still faster than the
            target), summed while the target stays beyond the stop. A target that keeps asking for
            the other side (a corner, a motion the wheels cannot make from here) is reconfigured for
            within that much missed motion, at any speed; one that only grazes the stop (jitter, a
            path running along a wheel's stop, a slow target pointing anywhere) is held: the wheels
            are not turned by π for motion the robot hardly needs.
        stop_hold_margin: [rad] how far inside the current cell the hold point lies, off the stop
            circles it is on: the held wheel is commanded at least this far (in β, ≥ 0.17° for the
            default) short of its hard stop, where a compliant steering with stiction would press
            it against the stop at speed (on the default robot's ``figure8``, holds at 1e-7 rad raised
            the slip energy from 14.8 J to 23.5 J); the held motion then misses a path that runs
            exactly along the stop by this angle, too little to need a reconfiguration.
        planned_hold_distance: [m] the motion a hold may miss, summed as for
            ``stop_hold_distance``, where a look-ahead plan (:mod:`control.icr.lookahead`) wants
            the robot in its current cell: the plan holds through the reference's short excursions
            (up to a few centimetres each on ``paper``), and beyond this budget (a disturbance, a
            path along a stop circle that drifts) the controller decides as without a plan.
        stop_timeout: time [s] in STOPPING, with μ_c = 0, after which the robot counts as stopped
            even if μ̂ is noisy.
    """

    k_lambda: float = 15.0
    mu_accel_fraction: float = 0.7
    mu_headroom: float = 0.85
    axis_margin: float = np.deg2rad(3.0)
    n_kappa: int = 33
    arc_step: float = np.deg2rad(0.5)
    stop_mu_tol: float = 0.02
    zero_mu_tol: float = 1e-3
    kick_tol: float = np.deg2rad(25.0)
    reconfig_tol: float = np.deg2rad(2.0)
    reconfig_freeze: float = np.deg2rad(5.0)
    reconfig_timeout: float = 2.0
    reconfig_hold_tol: float = np.deg2rad(6.0)
    reconfig_still_tol: float = np.deg2rad(0.5)
    stop_timeout: float = 0.5
    stop_hysteresis: float = np.deg2rad(6.0)
    stop_hold_speed: float = 0.04
    stop_hold_angle: float = np.deg2rad(30.0)
    stop_hold_distance: float = 0.01
    stop_hold_margin: float = 0.003
    planned_hold_distance: float = 0.5
    coupling_from_measurement: bool = False
    reconfig_rate_fraction: float = 0.5
    reconfig_accel_fraction: float = 0.3
    mu_own_scale: bool = False

    def __post_init__(self) -> None:
        check_fields(self)
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen)
        for name in ("k_lambda", "mu_accel_fraction", "axis_margin", "arc_step", "stop_mu_tol",
                     "zero_mu_tol", "kick_tol", "reconfig_tol", "reconfig_freeze", "reconfig_timeout", "stop_timeout",
                     "stop_hysteresis", "stop_hold_speed", "stop_hold_angle", "stop_hold_distance", "stop_hold_margin",
                     "planned_hold_distance",
                     "reconfig_hold_tol", "reconfig_still_tol"):
            fix(name, check_positive(f"ICRControllerConfig.{name}", getattr(self, name)))
        for name in ("mu_headroom", "reconfig_rate_fraction", "reconfig_accel_fraction"):  # fractions of a limit
            fix(name, check_range(f"ICRControllerConfig.{name}", getattr(self, name), 0.0, 1.0, lo_open=True))
        fix("n_kappa", check_int("ICRControllerConfig.n_kappa", self.n_kappa, min_value=2, max_value=100_000))
        fix("coupling_from_measurement", check_bool("ICRControllerConfig.coupling_from_measurement",
                                                    self.coupling_from_measurement))
        fix("mu_own_scale", check_bool("ICRControllerConfig.mu_own_scale", self.mu_own_scale))
