"""Higher-level action spaces for ``Azimut-v2`` (for RL): ICR targets and chassis twists.

Both wrappers keep the env's observation and reward; they replace the per-wheel set-point action
with a motion target that a controller turns into coordinated wheel set-points every step:

* :class:`ICRTargetAction`: ``Box(-1, 1, (4,))``: λ_d ∝ action[:3] (a vector of norm below
  ``min_norm`` means "hold": μ_d = 0) and μ_d = (action[3] + 1)/2 · ``mu_max`` ∈ [0, ``mu_max``]
  [m/s]: λ_d on the whole unit sphere is the direction of the motion η = μ_d λ_d and μ_d ≥ 0 its
  speed, the canonical representative (as the observation's λ̂, μ̂ ≥ 0). With ``signed_mu=True``
  μ_d = action[3] · ``mu_max`` and λ_d is a point of Λ (λ ~ −λ), the behaviour before 2026-11;
  under random actions the sign of μ_d then flips at random, μ does a zero-mean walk and the robot
  moves a fraction of the unsigned default's distance (``docs/results/rl.md``). The
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
from azimut_env.validation import ResetNeeded, check_bool, check_positive, check_real_array
from control.action_spaces.controller import ActionController, icr_target_from_action
from control.icr.controller import ICRControllerConfig
from control.twist.wpilib import SwerveConfig

__all__ = ["ICRTargetAction", "TwistAction", "icr_target_from_action"]

_ROW = np.zeros(1, dtype=np.intp)


class _OneRobot:
    """A single env's controller interface seen as a batch of one robot ((1, …) arrays), the
    form :class:`~control.action_spaces.controller.ActionController` reads."""

    def __init__(self, env) -> None:
        self._env = env

    geometry = property(lambda self: self._env.geometry)
    limits = property(lambda self: self._env.limits)
    control_period = property(lambda self: self._env.control_period)
    measured_beta = property(lambda self: self._env.measured_beta[None, :])
    measured_phidot = property(lambda self: self._env.measured_phidot[None, :])
    true_pose = property(lambda self: self._env.true_pose[None, :])
    estimated_pose = property(lambda self: self._env.estimated_pose[None, :])
    progress = property(lambda self: np.array([self._env.progress]))
    tracks = property(lambda self: [self._env.track])

    @property
    def estimated_eta(self) -> tuple[np.ndarray, np.ndarray]:
        lam, mu = self._env.estimated_eta
        return lam[None, :], np.array([mu])


class _ControllerWrapper(gym.Wrapper):
    """Common part: an :class:`~control.action_spaces.controller.ActionController` of one robot,
    reset with the env and fed the clipped action every step."""

    def __init__(self, env: gym.Env, action: str, controller: str, icr_config: ICRControllerConfig | None,
                 swerve_config: SwerveConfig | None, shape_targets: bool = True, target_rate: float = 3.0,
                 cross_push: float = 0.6, **params) -> None:
        super().__init__(env)
        target_rate, cross_push = check_positive("target_rate", target_rate), check_positive("cross_push", cross_push)
        shape_targets = check_bool("shape_targets", shape_targets)
        if icr_config is not None and not isinstance(icr_config, ICRControllerConfig):
            raise TypeError(f"icr_config must be ICRControllerConfig or None, got {type(icr_config).__name__}")
        if swerve_config is not None and not isinstance(swerve_config, SwerveConfig):
            raise TypeError(f"swerve_config must be SwerveConfig or None, got {type(swerve_config).__name__}")
        if controller not in ("icr", "swerve"):
            raise ValueError(f"controller must be 'icr' or 'swerve', got {controller!r}")
        self.shape_targets = bool(shape_targets) and controller == "icr"
        self.target_rate, self.cross_push = float(target_rate), float(cross_push)
        base = env.unwrapped
        missing = missing_members(base, ControllerInterface)
        if missing:
            raise ValueError("the wrapped env must be Azimut-v2 or Azimut-v1 "
                             f"(missing {', '.join(map(repr, missing))})")
        self._kind = controller
        self._view = _OneRobot(base)
        self._ctl = ActionController(self._view, action, controller, icr_config=icr_config,
                                     swerve_config=swerve_config, shape_targets=shape_targets,
                                     target_rate=target_rate, cross_push=cross_push, **params)

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._ctl.reset(self._view, _ROW)
        return obs, info

    def step(self, action):
        """One step: the action checked (finite, of the action space's shape) and clipped to [-1, 1]."""
        a = check_real_array("action", action)
        size = self.action_space.shape[0]
        if a.shape != (size,) or not np.all(np.isfinite(a)):
            raise ValueError(f"action must be a finite ({size},) array, got {action!r}")
        return self._drive(np.clip(a, -1.0, 1.0))

    def _drive(self, a: np.ndarray):
        """One step with the clipped action ``a``."""
        if not self._ctl.ready[0]:
            raise ResetNeeded("call reset() before step()")
        self.env.unwrapped.check_can_step()  # what the env would refuse, before the controller moves
        cmd = self._ctl.command(self._view, a[None, :], _ROW)
        ci = cmd.info
        events = int(cmd.events[0]) if cmd.events is not None else 0
        base = self.env.unwrapped
        obs, reward, terminated, truncated, info = self.env.step(base.action_from_setpoints(cmd.beta[0], cmd.phidot[0]))
        info = dict(info, controller_mode=int(ci["controller_mode"][0]), limit_exceeded=bool(ci["limit_exceeded"][0]),
                    reconfigure_events=events, target_held=bool(ci["target_held"][0]), mu_lag=float(ci["mu_lag"][0]))
        return obs, reward, terminated, truncated, info


class ICRTargetAction(_ControllerWrapper):
    """Action = ICR target (λ_d direction, μ_d); see the module docstring.

    Args:
        env: an ``Azimut-v2`` env. mu_max: μ_d at action[3] = 1 [m/s]. min_norm: below this norm
        of action[:3] the target is "hold" (μ_d = 0). signed_mu: μ_d ∈ [−mu_max, mu_max] and
        λ_d ∈ Λ (False, default: μ_d ∈ [0, mu_max], λ_d the direction of motion; module
        docstring). icr_config: the controller's tuning.
        shape_targets, target_rate [rad/s], cross_push [rad]: target shaping (module docstring).
    """

    def __init__(self, env: gym.Env, mu_max: float = 1.0, min_norm: float = 1e-3,
                 icr_config: ICRControllerConfig | None = None, shape_targets: bool = True, target_rate: float = 3.0,
                 cross_push: float = 0.6, signed_mu: bool = False) -> None:
        super().__init__(env, "icr_target", "icr", icr_config, None, shape_targets, target_rate, cross_push,
                         mu_max=mu_max, min_norm=min_norm, signed_mu=signed_mu)
        self.mu_max, self.signed_mu, self.min_norm = self._ctl.mu_max, self._ctl.signed_mu, self._ctl.min_norm
        self.action_space = spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)


class TwistAction(_ControllerWrapper):
    """Action = chassis-frame twist; see the module docstring.

    Args:
        env: an ``Azimut-v2`` env. v_max [m/s], w_max [rad/s]: twist at action ±1.
        controller: ``"icr"`` (default) or ``"swerve"``. icr_config, swerve_config: tuning.
        shape_targets, target_rate [rad/s], cross_push [rad]: target shaping (ICR controller only).
    """

    def __init__(self, env: gym.Env, v_max: float = 1.0, w_max: float = 2.0, controller: str = "icr",
                 icr_config: ICRControllerConfig | None = None, swerve_config: SwerveConfig | None = None,
                 shape_targets: bool = True, target_rate: float = 3.0, cross_push: float = 0.6) -> None:
        super().__init__(env, "twist", controller, icr_config, swerve_config, shape_targets, target_rate, cross_push,
                         v_max=v_max, w_max=w_max)
        self.scale = self._ctl.scale
        self.action_space = spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)
