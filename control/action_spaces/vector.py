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
  reference would not make. The zero action *is* the reference controller of ``azimut eval`` (the
  same follower, controller and stop mask). A correction bounded in angle rather than in twist
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

``info`` gains ``controller_mode`` (N,) (an ``icr_controller.Mode`` value, −1 for the baseline),
``limit_exceeded`` (N,) (whether the commands exceeded a commanded actuator limit),
``target_held`` (N,) (the shaped target was held at a steering stop or axis cap this step: why the
robot does not follow the action there) and ``mu_lag`` (N,) [m/s] (|μ_d − μ| of the ICR controller
after the step: how far its motion is behind the target's speed, held back by the wheels'
acceleration ramp or by a stop; 0 for the baseline).
"""

from __future__ import annotations

import functools
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from azimut_env.interface import VectorControllerInterface, missing_members
from azimut_env.validation import ResetNeeded, check_bool, check_positive, check_range, check_real_array
from control.action_spaces.shaping import (
    SHAPED_TARGET_CONFIG,
    advance_target,
    exp_step,
    initial_frame,
    shape_target,
    transport_frame,
)
from control.action_spaces.single import icr_target_from_action
from control.follow.batch import BatchFollower
from control.follow.path_follower import PathFollowerConfig
from control.icr.controller import (
    ICRBatchState,
    ICRControllerConfig,
    icr_control_step_batch,
    initial_state_batch,
    reference_stop_mask,
)
from control.limits import limit_violations
from control.twist.wpilib import SwerveConfig, SwerveController
from estimation.hrep import eta_from_twist

__all__ = ["VectorControllerAction", "ACTION_KINDS"]

#: action kind -> action size
ACTION_KINDS = {"icr_target": 4, "twist": 3, "residual": 3, "icr_rate": 3}


class VectorControllerAction(gym.vector.VectorWrapper):
    """Controller action spaces (see the module docstring) for an ``AzimutVectorEnv``.

    Args:
        env: an ``AzimutVectorEnv`` (or a vector wrapper of one).
        action: ``"residual"``, ``"icr_rate"``, ``"icr_target"`` or ``"twist"``.
        controller: ``"icr"`` or (twists only) ``"swerve"``.
        mu_max [m/s], min_norm, signed_mu: ICR targets (as :class:`~control.action_spaces.single.ICRTargetAction`);
            mu_max also bounds μ_d of ``icr_rate``.
        v_max [m/s], w_max [rad/s]: twists at action ±1 (as :class:`~control.action_spaces.single.TwistAction`).
        residual_angle [rad], residual_mu [m/s]: the residual correction at action ±1.
        lambda_rate_max [rad/s], mu_accel [m/s²]: ``icr_rate`` at action ±1.
        shape_targets: shape absolute targets through the ICR controller (default True).
        target_rate [rad/s]: fastest motion of a shaped absolute target on the sphere.
        cross_push [rad]: arc a target must keep pushing past a steering stop before it crosses.
        icr_config, swerve_config, follower_config: tuning of the controllers and the follower.
    """

    def __init__(self, env: gym.vector.VectorEnv, action: str = "icr_target", controller: str = "icr",
                 mu_max: float = 1.0, min_norm: float = 1e-3, v_max: float = 1.0, w_max: float = 2.0,
                 residual_angle: float = 0.15, residual_mu: float = 0.1, lambda_rate_max: float = 1.5,
                 mu_accel: float = 2.0, shape_targets: bool = True, target_rate: float = 3.0,
                 cross_push: float = 0.6, icr_config: ICRControllerConfig | None = None,
                 swerve_config: SwerveConfig | None = None, follower_config: PathFollowerConfig | None = None,
                 signed_mu: bool = False) -> None:
        super().__init__(env)
        if not isinstance(action, str) or action not in ACTION_KINDS:
            raise ValueError(f"action must be one of {', '.join(ACTION_KINDS)}, got {action!r}")
        if (not isinstance(controller, str) or controller not in ("icr", "swerve")
                or (action != "twist" and controller != "icr")):
            raise ValueError(f"controller must be 'icr' (or 'swerve' for twists), got {controller!r}")
        base = env.unwrapped
        missing = missing_members(base, VectorControllerInterface)
        if missing:
            raise ValueError(f"the wrapped env must be AzimutVectorEnv (missing {', '.join(map(repr, missing))})")
        for name, value in dict(mu_max=mu_max, v_max=v_max, w_max=w_max, residual_angle=residual_angle,
                                residual_mu=residual_mu, lambda_rate_max=lambda_rate_max, mu_accel=mu_accel,
                                target_rate=target_rate, cross_push=cross_push).items():
            check_positive(name, value)
        min_norm = check_range("min_norm", min_norm, 0.0, 1.0, lo_open=True, hi_open=True)
        check_bool("shape_targets", shape_targets)
        self.signed_mu = check_bool("signed_mu", signed_mu)
        for name, value, kind in (("icr_config", icr_config, ICRControllerConfig),
                                  ("swerve_config", swerve_config, SwerveConfig),
                                  ("follower_config", follower_config, PathFollowerConfig)):
            if value is not None and not isinstance(value, kind):
                raise TypeError(f"{name} must be {kind.__name__} or None, got {type(value).__name__}")
        self._kind, self._controller = action, controller
        self.mu_max, self.min_norm = float(mu_max), float(min_norm)
        self.scale = np.array([v_max, v_max, w_max], dtype=np.float64)
        self.residual_angle, self.residual_mu = float(residual_angle), float(residual_mu)
        self.lambda_rate_max, self.mu_accel = float(lambda_rate_max), float(mu_accel)
        self.shape_targets = bool(shape_targets) and controller == "icr" and action in ("icr_target", "twist")
        self.target_rate, self.cross_push = float(target_rate), float(cross_push)
        self._icr_config = icr_config or (SHAPED_TARGET_CONFIG if self.shape_targets else ICRControllerConfig())
        self._swerve_config = swerve_config
        self._follower_config = follower_config or PathFollowerConfig()
        self.single_action_space = spaces.Box(-1.0, 1.0, (ACTION_KINDS[action],), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        N = self.num_envs
        self._ctls: list[SwerveController | None] = [None] * N  # swerve baseline only
        self._icr: ICRBatchState | None = None  # the batched ICR controllers' state
        self._icr_ready = np.zeros(N, dtype=np.bool_)
        self._pending = np.zeros(N, dtype=np.bool_)
        # icr_rate's integrated target λ_s, μ_s and tangent frame; push past a stop (icr_rate and
        # shaped absolute targets, which step from the controller's own reference λ)
        self._lam_s = np.tile([0.0, 0.0, 1.0], (N, 1))
        self._mu_s = np.zeros(N)
        self._e1 = initial_frame(self._lam_s)
        self._push = np.zeros(N)
        geom = base.geometry
        self._stop_mask = functools.partial(reference_stop_mask, geom=geom, axis_margin=self._icr_config.axis_margin)
        # residual only: the path followers of all sub-envs, one compiled call per step
        self._follower = BatchFollower(N, self._follower_config, self._stop_mask, base.control_period) \
            if action == "residual" else None
        self.last_command = None  #: the last WheelCommand ((N, n) arrays) of the ICR controllers (diagnostics)

    @property
    def follower(self) -> BatchFollower | None:
        """The residual action space's path followers (a :class:`~control.follow.batch.BatchFollower`
        over the sub-envs; None for the other action spaces)."""
        return self._follower

    def _reset_controllers(self, which: np.ndarray) -> None:
        base = self.env.unwrapped
        idx = np.flatnonzero(which)
        if idx.size == 0:
            return
        lam_hat, _ = base.estimated_eta
        beta, phidot = base.measured_beta, base.measured_phidot
        if self._controller == "icr":
            fresh = initial_state_batch(lam_hat[idx], beta[idx], phidot[idx], base.geometry, self._icr_config)
            if self._icr is None:  # rows not reset yet stay marked so until they are
                self._icr = initial_state_batch(lam_hat, beta, phidot, base.geometry, self._icr_config)
            self._icr = self._icr.put(idx, fresh)
            self._icr_ready[idx] = True
            self._lam_s[idx] = fresh.lam
            self._mu_s[idx] = 0.0
            self._e1[idx] = initial_frame(fresh.lam)
            self._push[idx] = 0.0
            if self._kind == "residual":
                tracks, progress = base.tracks, base.progress
                for i in idx:
                    self._follower.reset(int(i), tracks[i], float(progress[i]))
            return
        for i in idx:
            ctl = SwerveController(base.geometry, base.limits, base.control_period, self._swerve_config)
            ctl.reset(beta[i], phidot[i])
            self._ctls[i] = ctl

    def reset(self, *, seed=None, options=None):
        mask = np.ones(self.num_envs, dtype=np.bool_)
        if isinstance(options, dict) and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"], dtype=np.bool_).copy()
        obs, info = self.env.reset(seed=seed, options=options)
        self._reset_controllers(mask)
        self._pending[mask] = False
        return obs, info

    def _targets(self, a: np.ndarray, rows: np.ndarray, base) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(λ_d, μ_d, held) of the ICR controllers of ``rows`` for the clipped actions ``a``."""
        geom, cfg, dt = base.geometry, self._icr_config, base.control_period
        held = np.zeros(rows.size, dtype=np.bool_)
        if self._kind == "residual":
            lam_f, mu_f = eta_from_twist(self._follower.step(base.true_pose, rows))
            prop = exp_step(lam_f, initial_frame(lam_f), a[:, :2] * self.residual_angle, 1.0)
            lam_d, _, held = advance_target(lam_f, prop, np.zeros(rows.size), geom, cfg.axis_margin, np.inf)
            return lam_d, mu_f + a[:, 2] * self.residual_mu, held
        if self._kind == "icr_rate":
            lam, e1 = self._lam_s[rows], self._e1[rows]
            prop = exp_step(lam, e1, a[:, :2] * self.lambda_rate_max, dt)
            lam_new, push, held = advance_target(lam, prop, self._push[rows], geom, cfg.axis_margin, self.cross_push)
            self._lam_s[rows], self._push[rows] = lam_new, push
            self._e1[rows] = transport_frame(e1, lam_new)
            self._mu_s[rows] = np.clip(self._mu_s[rows] + a[:, 2] * self.mu_accel * dt, -self.mu_max, self.mu_max)
            return lam_new, self._mu_s[rows].copy(), held
        if self._kind == "icr_target":
            lam_t, mu_t = icr_target_from_action(a, self.mu_max, self.min_norm, self.signed_mu)
        else:
            lam_t, mu_t = eta_from_twist(a * self.scale)
        if not self.shape_targets:
            return lam_t, mu_t, held
        # one bounded step ahead of the controller's own reference λ; unsigned ICR targets: λ_d is
        # the direction of motion (μ_d ≥ 0), else the nearer representative
        lam_new, mu_t, push, held = shape_target(self._icr.lam[rows], lam_t, mu_t, self._push[rows], geom,
                                                 cfg.axis_margin, self.target_rate * dt, self.cross_push,
                                                 nearer=self._kind == "twist" or self.signed_mu)
        self._push[rows] = push
        return lam_new, mu_t, held

    def step(self, actions) -> tuple[Any, ...]:
        a = check_real_array("actions", actions)
        if a.shape != self.action_space.shape or not np.all(np.isfinite(a)):
            raise ValueError(f"actions must be a finite {self.action_space.shape} array")
        if not self._icr_ready.all() if self._controller == "icr" else any(c is None for c in self._ctls):
            raise ResetNeeded("call reset() before step()")
        a = np.clip(a, -1.0, 1.0)
        base = self.env.unwrapped
        beta, phidot = base.measured_beta, base.measured_phidot
        N, n = beta.shape
        beta_c, phidot_c = beta.copy(), np.zeros((N, n))  # autoreset this step: the action is ignored
        modes = np.full(N, -1, dtype=np.int64)
        exceeded = np.zeros(N, dtype=np.bool_)
        held = np.zeros(N, dtype=np.bool_)
        lag = np.zeros(N)
        active = np.flatnonzero(~self._pending)
        if self._controller == "icr" and active.size:
            lam_hat, mu_hat = base.estimated_eta
            lam_d, mu_d, held[active] = self._targets(a[active], active, base)
            sub, cmd = icr_control_step_batch(self._icr.take(active), lam_hat[active], mu_hat[active], beta[active],
                                              phidot[active], lam_d, mu_d, base.geometry, base.limits,
                                              self._icr_config, base.control_period)
            self._icr = self._icr.put(active, sub)
            beta_c[active], phidot_c[active] = cmd.beta, cmd.phidot
            modes[active] = cmd.info["mode"]
            lag[active] = np.abs(cmd.info["mu_target"] - sub.mu)
            exceeded[active] = limit_violations(cmd.beta_rate, cmd.beta_accel, cmd.phidot, cmd.phiddot,
                                                base.limits).any(axis=-1)
            self.last_command = cmd
        elif self._controller != "icr":
            for i in active:
                cmd = self._ctls[i].step(a[i] * self.scale, beta[i])
                beta_c[i], phidot_c[i] = cmd.beta, cmd.phidot
                exceeded[i] = bool(limit_violations(cmd.beta_rate, cmd.beta_accel, cmd.phidot, cmd.phiddot,
                                                    base.limits).any())
        obs, reward, terminated, truncated, info = self.env.step(base.action_from_setpoints(beta_c, phidot_c))
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
