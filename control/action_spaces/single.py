"""Higher-level action spaces for ``Azimut-v1`` (for RL): ICR targets and chassis twists.

Both wrappers keep the env's observation and reward; they replace the per-wheel set-point action
with a motion target that a controller turns into coordinated wheel set-points every step:

* :class:`ICRTargetAction`: ``Box(-1, 1, (4,))``: λ_d ∝ action[:3] (a vector of norm below
  ``min_norm`` means "hold": μ_d = 0) and μ_d = (action[3] + 1)/2 · ``mu_max`` ∈ [0, ``mu_max``]
  [m/s]: λ_d on the whole unit sphere is the direction of the motion η = μ_d λ_d and μ_d ≥ 0 its
  speed, the canonical representative (as the observation's λ̂, μ̂ ≥ 0). With ``signed_mu=True``
  μ_d = action[3] · ``mu_max`` and λ_d is a point of Λ (λ ~ −λ), the behaviour before 2026-11;
  under random actions the sign of μ_d then flips at random, μ does a zero-mean walk and the robot
  barely moves (0.5–1.2 m in 500 steps against 2–4.7 m unsigned). The
  :class:`~control.icr.controller.ICRController` does the rest (limits, singularities,
  stop-and-reconfigure).
* :class:`TwistAction`: ``Box(-1, 1, (3,))``: chassis-frame twist (v_x, v_y, ω) = action ·
  (v_max, v_max, ω_max); it goes through the ICR controller (``controller="icr"``, via
  ``eta_from_twist``) or the WPILib-style baseline (``controller="swerve"``).

Through the ICR controller the target is *shaped* (:mod:`control.action_spaces.shaping`, on by default,
``shape_targets=False`` turns it off): λ_d is one step of at most ``target_rate`` [rad/s] from the
controller's reference λ toward the commanded direction (unsigned μ: toward λ_d itself, so the
motion turns continuously instead of decelerating through zero each time a random target lands in
the other hemisphere; signed: toward the nearer of ±λ_d, μ_d's sign following), and crosses a
steering stop only when the command keeps pushing past it for ``cross_push`` [rad] of arc, so a
target that changes every step (an exploring policy) still drives
instead of keeping the controller in RECONFIGURING; without an ``icr_config`` the controller then
runs :data:`~control.action_spaces.shaping.SHAPED_TARGET_CONFIG` (μ follows μ_d at the wheels'
acceleration limit while λ turns).

``info`` gains ``controller_mode`` (an ``icr_controller.Mode`` value, or −1 for the baseline),
``limit_exceeded`` (whether the set-points exceeded a commanded limit), ``reconfigure_events`` and
``target_held`` (the shaped target was held at a steering stop or axis cap this step) and
``mu_lag`` [m/s] (|μ_d − μ| of the ICR controller after the step: how far its motion is behind the
target's speed, held back by the wheels' acceleration ramp or a stop; 0 for the baseline).
For the batched versions and the residual and ICR-rate action spaces see
:mod:`control.action_spaces.vector`.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from azimut_env.interface import ControllerInterface, missing_members
from azimut_env.validation import ResetNeeded, check_bool, check_positive, check_range, check_real_array
from control.action_spaces.shaping import SHAPED_TARGET_CONFIG, shape_target
from control.icr.controller import ICRController, ICRControllerConfig
from control.limits import limit_violations
from control.twist.wpilib import SwerveConfig, SwerveController
from estimation.hrep import eta_from_twist

__all__ = ["ICRTargetAction", "TwistAction", "icr_target_from_action"]


def icr_target_from_action(action, mu_max: float, min_norm: float,
                           signed_mu: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Clipped ICR-target actions (..., 4) -> (λ_d (..., 3), μ_d (...)): λ_d = a[:3]/‖a[:3]‖ and
    μ_d = a[3]·mu_max [m/s] (``signed_mu``) or (a[3] + 1)/2·mu_max ∈ [0, mu_max] (not
    ``signed_mu``: λ_d on the whole sphere is then the direction of motion, the canonical
    representative μ ≥ 0 of η = μλ, as the observation's λ̂); below ``min_norm`` the action means
    "hold": λ_d = (0, 0, 1), μ_d = 0."""
    a = np.asarray(action, dtype=np.float64)
    norm = np.linalg.norm(a[..., :3], axis=-1)
    small = (norm < min_norm) | (norm == 0.0)  # a zero direction is "hold" whatever min_norm
    lam_d = np.where(small[..., None], np.array([0.0, 0.0, 1.0]), a[..., :3] / np.where(small, 1.0, norm)[..., None])
    mu = a[..., 3] * mu_max if signed_mu else 0.5 * (a[..., 3] + 1.0) * mu_max
    mu_d = np.where(small, 0.0, mu)
    return lam_d, mu_d


class _ControllerWrapper(gym.Wrapper):
    """Common part: holds a controller, resets it with the env, steps it with the measurements."""

    def __init__(self, env: gym.Env, controller: str, icr_config: ICRControllerConfig | None,
                 swerve_config: SwerveConfig | None, shape_targets: bool = True, target_rate: float = 3.0,
                 cross_push: float = 0.6) -> None:
        super().__init__(env)
        target_rate, cross_push = check_positive("target_rate", target_rate), check_positive("cross_push", cross_push)
        shape_targets = check_bool("shape_targets", shape_targets)
        if icr_config is not None and not isinstance(icr_config, ICRControllerConfig):
            raise TypeError(f"icr_config must be ICRControllerConfig or None, got {type(icr_config).__name__}")
        if swerve_config is not None and not isinstance(swerve_config, SwerveConfig):
            raise TypeError(f"swerve_config must be SwerveConfig or None, got {type(swerve_config).__name__}")
        self.shape_targets = bool(shape_targets) and controller == "icr"
        self.target_rate, self.cross_push = float(target_rate), float(cross_push)
        self._push = 0.0  # arc [rad] the shaped target has pushed past a steering stop
        if controller not in ("icr", "swerve"):
            raise ValueError(f"controller must be 'icr' or 'swerve', got {controller!r}")
        base = env.unwrapped
        missing = missing_members(base, ControllerInterface)
        if missing:
            raise ValueError(f"the wrapped env must be Azimut-v1 (missing {', '.join(map(repr, missing))})")
        self._kind = controller
        self._icr_config = icr_config or (SHAPED_TARGET_CONFIG if self.shape_targets else None)
        self._swerve_config = swerve_config
        self._ctl: ICRController | SwerveController | None = None

    def _new_controller(self) -> None:
        base = self.env.unwrapped
        if self._kind == "icr":
            self._ctl = ICRController(base.geometry, base.limits, base.control_period, self._icr_config)
            lam_hat, _ = base.estimated_eta
            self._ctl.reset(lam_hat, base.measured_beta, base.measured_phidot)
            self._push = 0.0
        else:
            self._ctl = SwerveController(base.geometry, base.limits, base.control_period, self._swerve_config)
            self._ctl.reset(base.measured_beta, base.measured_phidot)

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._new_controller()
        return obs, info

    def _drive(self, lam_d=None, mu_d=None, twist=None, nearer: bool = True):
        base = self.env.unwrapped
        if self._ctl is None:
            raise ResetNeeded("call reset() before step()")
        held = False
        if isinstance(self._ctl, ICRController):
            lam_hat, mu_hat = base.estimated_eta
            if self.shape_targets:  # one bounded step ahead of the controller's reference λ
                # nearer: the representative of (λ_d, μ_d) nearer λ; else λ_d is the direction of motion
                lam_s, mu_t, push, h = shape_target(
                    self._ctl.state.lam[None, :], np.asarray(lam_d, dtype=np.float64)[None, :],
                    np.array([mu_d], dtype=np.float64), np.array([self._push]), base.geometry,
                    self._ctl.config.axis_margin, self.target_rate * base.control_period, self.cross_push, nearer)
                self._push, held = float(push[0]), bool(h[0])
                lam_d, mu_d = lam_s[0], float(mu_t[0])
            cmd = self._ctl.step(lam_hat, mu_hat, base.measured_beta, base.measured_phidot, lam_d, mu_d)
            mode, events = int(cmd.info["mode"]), self._ctl.state.events
            lag = abs(float(cmd.info["mu_target"]) - float(self._ctl.state.mu))
        else:
            cmd = self._ctl.step(twist, base.measured_beta)
            mode, events, lag = -1, 0, 0.0
        exceeded = bool(limit_violations(cmd.beta_rate, cmd.beta_accel, cmd.phidot, cmd.phiddot, base.limits).any())
        obs, reward, terminated, truncated, info = self.env.step(base.action_from_setpoints(cmd.beta, cmd.phidot))
        info = dict(info, controller_mode=mode, limit_exceeded=exceeded, reconfigure_events=events, target_held=held,
                    mu_lag=lag)
        return obs, reward, terminated, truncated, info


class ICRTargetAction(_ControllerWrapper):
    """Action = ICR target (λ_d direction, μ_d); see the module docstring.

    Args:
        env: an ``Azimut-v1`` env. mu_max: μ_d at action[3] = 1 [m/s]. min_norm: below this norm
        of action[:3] the target is "hold" (μ_d = 0). signed_mu: μ_d ∈ [−mu_max, mu_max] and
        λ_d ∈ Λ (False, default: μ_d ∈ [0, mu_max], λ_d the direction of motion; module
        docstring). icr_config: the controller's tuning.
        shape_targets, target_rate [rad/s], cross_push [rad]: target shaping (module docstring).
    """

    def __init__(self, env: gym.Env, mu_max: float = 1.0, min_norm: float = 1e-3,
                 icr_config: ICRControllerConfig | None = None, shape_targets: bool = True, target_rate: float = 3.0,
                 cross_push: float = 0.6, signed_mu: bool = False) -> None:
        super().__init__(env, "icr", icr_config, None, shape_targets, target_rate, cross_push)
        self.mu_max = check_positive("mu_max", mu_max)
        self.signed_mu = check_bool("signed_mu", signed_mu)
        self.min_norm = check_range("min_norm", min_norm, 0.0, 1.0, lo_open=True, hi_open=True)
        self.action_space = spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)

    def step(self, action):
        a = check_real_array("action", action)
        if a.shape != (4,) or not np.all(np.isfinite(a)):
            raise ValueError(f"action must be a finite (4,) array, got {action!r}")
        lam_d, mu_d = icr_target_from_action(np.clip(a, -1.0, 1.0), self.mu_max, self.min_norm, self.signed_mu)
        return self._drive(lam_d=lam_d, mu_d=float(mu_d), nearer=self.signed_mu)


class TwistAction(_ControllerWrapper):
    """Action = chassis-frame twist; see the module docstring.

    Args:
        env: an ``Azimut-v1`` env. v_max [m/s], w_max [rad/s]: twist at action ±1.
        controller: ``"icr"`` (default) or ``"swerve"``. icr_config, swerve_config: tuning.
        shape_targets, target_rate [rad/s], cross_push [rad]: target shaping (ICR controller only).
    """

    def __init__(self, env: gym.Env, v_max: float = 1.0, w_max: float = 2.0, controller: str = "icr",
                 icr_config: ICRControllerConfig | None = None, swerve_config: SwerveConfig | None = None,
                 shape_targets: bool = True, target_rate: float = 3.0, cross_push: float = 0.6) -> None:
        super().__init__(env, controller, icr_config, swerve_config, shape_targets, target_rate, cross_push)
        v_max, w_max = check_positive("v_max", v_max), check_positive("w_max", w_max)
        self.scale = np.array([v_max, v_max, w_max])
        self.action_space = spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)

    def step(self, action):
        a = check_real_array("action", action)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise ValueError(f"action must be a finite (3,) array, got {action!r}")
        twist = np.clip(a, -1.0, 1.0) * self.scale
        if self._kind == "icr":
            lam_d, mu_d = eta_from_twist(twist)
            return self._drive(lam_d=lam_d, mu_d=float(mu_d))
        return self._drive(twist=twist)
