"""Controller action spaces for the vector env (``AzimutVectorEnv``), for RL.

Every action space here goes through a controller, batched over the N sub-envs (one
:func:`~control.icr.controller.icr_control_step_batch` call per control step for all robots, and
one batched ``step`` of the vector env with all set-points):

* ``"residual"`` ((N, 3)): the path follower (:class:`~control.follow.path_follower.PathFollower`'s
  arithmetic, compiled for all sub-envs in :class:`~control.follow.batch.BatchFollower`, each on
  its own track) + the ICR controller, with the policy adding a bounded
  correction to the follower's target (λ_f, μ_f): action[:2] · ``residual_angle`` [rad] turns λ_f
  on the sphere (in a tangent frame carried with it) and action[2] · ``residual_mu`` [m/s] is added
  to μ_f. A correction that would carry λ_f across a steering stop or into an axis cap is dropped
  (the reference target is used), so the policy cannot cause a stop-and-reconfigure that the
  reference would not make. The zero action *is* the reference controller of ``azimut eval``
  without its look-ahead (``ICRPathController(lookahead=None)``: the same follower, controller and
  stop mask; the shipped agents were trained on it, and the residual corrects a target of the
  moment). A correction bounded in angle rather than in twist
  stays small at low speed too (a twist residual of 0.2 m/s swamps the target at rest, and the
  controller then stopped and reconfigured half of the time under random actions).
* ``"icr_rate"`` ((N, 3)): the action moves the ICR target: action[:2] · ``lambda_rate_max`` is the
  rate [rad/s] of λ_d along the sphere (in a tangent frame carried with λ_d) and action[2] ·
  ``mu_accel`` the rate of μ_d [m/s²] (μ_d ∈ [−``mu_max``, ``mu_max``]). λ_d moves continuously
  and is held at a steering stop unless the policy keeps pushing across it
  (:mod:`control.action_spaces.shaping`), so a stop-and-reconfigure happens only when λ really crosses
  a steering limit.
* ``"icr_target"`` ((N, 4)) and ``"twist"`` ((N, 3)): absolute targets, as
  :class:`~control.action_spaces.single.ICRTargetAction` and
  :class:`~control.action_spaces.single.TwistAction` (sub-env i behaves as that single-env wrapper
  seeded with ``seed + i``). Through the ICR controller, the
  target is shaped (:mod:`control.action_spaces.shaping`): λ_d is one step of at most ``target_rate``
  [rad/s] from the controller's reference λ toward the commanded direction (so the controller's
  own arc is short and checked by the shaping) and crosses a steering stop or axis only when the
  command stays across it,
  so a policy whose target changes every step still drives (the unshaped controller sat in
  RECONFIGURING for good under random targets); without an ``icr_config`` the controller then
  runs :data:`~control.action_spaces.shaping.SHAPED_TARGET_CONFIG` (μ with its own time scaling, ramped
  at 0.95 of the wheel acceleration limit). ``shape_targets=False`` restores the raw targets.
  Twists may also go to the WPILib-style baseline (``controller="swerve"``, a per-robot Python
  object).

Residual agents can be kept near the reference controller with ``correction_cost`` (w ≥ 0, default 0):
the wrapper subtracts w · mean_k(a_k²) from each robot's reward (a ∈ [−1, 1]³ the clipped action; so
at most w per step), an L2 cost on the correction's size. Without it nothing in ``Azimut-v2``'s reward
ties the correction to zero where the reference is already near the reward's optimum (on a lap at the
track's speed the reward is nearly flat in small corrections), and the policy's mean drifts with the
noise of the advantage estimates. Residual RL: Johannink et al., *Residual Reinforcement Learning for
Robot Control*, ICRA 2019; Silver et al., *Residual Policy Learning*, arXiv:1812.06298 (2018).

``info`` gains ``controller_mode`` (N,) (an ``icr_controller.Mode`` value, −1 for the baseline),
``limit_exceeded`` (N,) (whether the commands exceeded a commanded actuator limit),
``target_held`` (N,) (the shaped target was held at a steering stop or axis cap this step: why the
robot does not follow the action there) and ``mu_lag`` (N,) [m/s] (|μ_d − μ| of the ICR controller
after the step: how far its motion is behind the target's speed, held back by the wheels'
acceleration ramp or by a stop; 0 for the baseline).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from azimut_env.interface import VectorControllerInterface, missing_members
from azimut_env.validation import ResetNeeded, check_real_array
from control.action_spaces.controller import ACTION_KINDS, ActionController
from control.follow.batch import BatchFollower
from control.follow.path_follower import PathFollowerConfig
from control.icr.controller import ICRControllerConfig
from control.twist.wpilib import SwerveConfig

__all__ = ["VectorControllerAction", "ACTION_KINDS"]


class VectorControllerAction(gym.vector.VectorWrapper):
    """Controller action spaces (see the module docstring) for an ``AzimutVectorEnv``.

    The controller is an :class:`~control.action_spaces.controller.ActionController` (the one a
    trained policy's controller uses in ``azimut eval``); this wrapper adds the Gymnasium vector
    API: action checks, autoresets (a sub-env's controller restarts with its episode) and the
    ``info`` keys.

    Args:
        env: an ``AzimutVectorEnv`` (or a vector wrapper of one).
        action: ``"residual"``, ``"icr_rate"``, ``"icr_target"`` or ``"twist"``.
        controller: ``"icr"`` or (twists only) ``"swerve"``.
        mu_max [m/s], min_norm, signed_mu: ICR targets (as
            :class:`~control.action_spaces.single.ICRTargetAction`); mu_max also bounds μ_d of ``icr_rate``.
        v_max [m/s], w_max [rad/s]: twists at action ±1 (as :class:`~control.action_spaces.single.TwistAction`).
        residual_angle [rad], residual_mu [m/s]: the residual correction at action ±1.
        lambda_rate_max [rad/s], mu_accel [m/s²]: ``icr_rate`` at action ±1.
        shape_targets: shape absolute targets through the ICR controller (default True).
        target_rate [rad/s]: fastest motion of a shaped absolute target on the sphere.
        cross_push [rad]: arc a target must keep pushing past a steering stop before it crosses.
        icr_config, swerve_config, follower_config: tuning of the controllers and the follower.
        correction_cost: weight w of the residual's correction cost (see the module docstring;
            ``residual`` only, default 0: none).
    """

    def __init__(self, env: gym.vector.VectorEnv, action: str = "icr_target", controller: str = "icr",
                 mu_max: float = 1.0, min_norm: float = 1e-3, v_max: float = 1.0, w_max: float = 2.0,
                 residual_angle: float = 0.15, residual_mu: float = 0.1, lambda_rate_max: float = 1.5,
                 mu_accel: float = 2.0, shape_targets: bool = True, target_rate: float = 3.0,
                 cross_push: float = 0.6, icr_config: ICRControllerConfig | None = None,
                 swerve_config: SwerveConfig | None = None, follower_config: PathFollowerConfig | None = None,
                 signed_mu: bool = False, correction_cost: float = 0.0) -> None:
        super().__init__(env)
        if not isinstance(action, str) or action not in ACTION_KINDS:
            raise ValueError(f"action must be one of {', '.join(ACTION_KINDS)}, got {action!r}")
        if (not isinstance(controller, str) or controller not in ("icr", "swerve")
                or (action != "twist" and controller != "icr")):
            raise ValueError(f"controller must be 'icr' (or 'swerve' for twists), got {controller!r}")
        if isinstance(correction_cost, bool) or not isinstance(correction_cost, (int, float)) \
                or not (np.isfinite(correction_cost) and correction_cost >= 0.0):
            raise ValueError(f"correction_cost must be a finite number >= 0, got {correction_cost!r}")
        if correction_cost and action != "residual":
            raise ValueError(f"correction_cost applies to the residual action space only, not {action!r}")
        self.correction_cost = float(correction_cost)
        base = env.unwrapped
        missing = missing_members(base, VectorControllerInterface)
        if missing:
            raise ValueError(f"the wrapped env must be AzimutVectorEnv (missing {', '.join(map(repr, missing))})")
        self.controller = ActionController(
            base, action, controller, mu_max=mu_max, min_norm=min_norm, v_max=v_max, w_max=w_max,
            residual_angle=residual_angle, residual_mu=residual_mu, lambda_rate_max=lambda_rate_max,
            mu_accel=mu_accel, shape_targets=shape_targets, target_rate=target_rate, cross_push=cross_push,
            icr_config=icr_config, swerve_config=swerve_config, follower_config=follower_config,
            signed_mu=signed_mu)
        ctl = self.controller
        self.signed_mu, self.mu_max, self.min_norm, self.scale = ctl.signed_mu, ctl.mu_max, ctl.min_norm, ctl.scale
        self.residual_angle, self.residual_mu = ctl.residual_angle, ctl.residual_mu
        self.lambda_rate_max, self.mu_accel = ctl.lambda_rate_max, ctl.mu_accel
        self.shape_targets, self.target_rate, self.cross_push = ctl.shape_targets, ctl.target_rate, ctl.cross_push
        self.single_action_space = spaces.Box(-1.0, 1.0, (ACTION_KINDS[action],), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._pending = np.zeros(self.num_envs, dtype=np.bool_)
        self.last_command = None  #: the last WheelCommand ((N, n) arrays) of the ICR controllers (diagnostics)

    @property
    def follower(self) -> BatchFollower | None:
        """The residual action space's path followers (a :class:`~control.follow.batch.BatchFollower`
        over the sub-envs; None for the other action spaces)."""
        return self.controller.follower

    def _reset_controllers(self, which: np.ndarray) -> None:
        self.controller.reset(self.env.unwrapped, np.flatnonzero(which))

    def reset(self, *, seed=None, options=None):
        mask = np.ones(self.num_envs, dtype=np.bool_)
        if isinstance(options, dict) and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"], dtype=np.bool_).copy()
        obs, info = self.env.reset(seed=seed, options=options)
        self._reset_controllers(mask)
        self._pending[mask] = False
        return obs, info

    def step(self, actions) -> tuple[Any, ...]:
        a = check_real_array("actions", actions)
        if a.shape != self.action_space.shape or not np.all(np.isfinite(a)):
            raise ValueError(f"actions must be a finite {self.action_space.shape} array")
        if not self.controller.ready.all():
            raise ResetNeeded("call reset() before step()")
        a = np.clip(a, -1.0, 1.0)
        base = self.env.unwrapped
        base.check_can_step()  # what the env would refuse, before any controller or target state moves
        N = self.num_envs
        active = np.flatnonzero(~self._pending)
        if active.size == N:  # every robot commanded (no autoreset pending): the command's arrays as they are
            cmd = self.controller.command(base, a, active)
            beta_c, phidot_c = cmd.beta, cmd.phidot
            modes, exceeded = cmd.info["controller_mode"], cmd.info["limit_exceeded"]
            held, lag = cmd.info["target_held"], cmd.info["mu_lag"]
            if self.controller.icr is not None:
                self.last_command = cmd
        else:
            beta = base.measured_beta
            beta_c, phidot_c = beta.copy(), np.zeros(beta.shape)  # autoreset this step: the action is ignored
            modes = np.full(N, -1, dtype=np.int64)
            exceeded = np.zeros(N, dtype=np.bool_)
            held = np.zeros(N, dtype=np.bool_)
            lag = np.zeros(N)
            if active.size:
                cmd = self.controller.command(base, a[active], active)
                beta_c[active], phidot_c[active] = cmd.beta, cmd.phidot
                modes[active] = cmd.info["controller_mode"]
                exceeded[active] = cmd.info["limit_exceeded"]
                held[active] = cmd.info["target_held"]
                lag[active] = cmd.info["mu_lag"]
                if self.controller.icr is not None:
                    self.last_command = cmd
        obs, reward, terminated, truncated, info = self.env.step(base.action_from_setpoints(beta_c, phidot_c))
        if self.correction_cost:
            cost = np.zeros(N)
            cost[active] = self.correction_cost * np.mean(a[active] ** 2, axis=1)
            reward = reward - cost
            info = dict(info, correction_cost=cost, _correction_cost=np.ones(N, dtype=np.bool_))
        done = terminated | truncated
        if base.autoreset_mode == AutoresetMode.SAME_STEP:
            self._reset_controllers(done)
        else:
            self._reset_controllers(self._pending)  # those the step just reset
            next_step = base.autoreset_mode == AutoresetMode.NEXT_STEP
            self._pending = done.copy() if next_step else np.zeros_like(done)
        every = np.ones(N, dtype=np.bool_)
        info = dict(info, controller_mode=modes, _controller_mode=every, limit_exceeded=exceeded,
                    _limit_exceeded=every.copy(), target_held=held, _target_held=every.copy(), mu_lag=lag,
                    _mu_lag=every.copy())
        return obs, reward, terminated, truncated, info
