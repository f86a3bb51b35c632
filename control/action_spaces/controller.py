"""The controller behind an RL action space: the action sets its target (or the correction of the
path follower's), and a controller object turns that into wheel commands.

:class:`ActionController` is shared by the single-env wrappers
(:mod:`control.action_spaces.single`), the vector wrapper (:mod:`control.action_spaces.vector`)
and a trained policy's controller (``train.policy.PolicyController``), so a policy drives the
robot in evaluation through the very code it was trained with. The controllers are the ICR
controller's batched step (:class:`~control.icr.batch.BatchICRController`) and the WPILib-style
baseline (:class:`~control.twist.wpilib.SwerveBatch`); the action spaces (``ACTION_KINDS``) and
what their actions mean are described in :mod:`control.action_spaces.vector`.

The env it reads is the batched controller interface
(:class:`~azimut_env.interface.VectorControllerInterface`: (N, …) arrays); the single wrappers
hand it a one-robot view of their env.
"""

from __future__ import annotations

import functools

import numpy as np

from azimut_env.validation import check_bool, check_positive, check_range
from control.action_spaces.shaping import SHAPED_TARGET_CONFIG, initial_frame
from control.action_spaces.targets import RATE_TARGETS, RESIDUAL_TARGETS, SHAPED_TARGETS
from control.commands import WheelCommand
from control.controller import env_threads
from control.follow.batch import BatchFollower
from control.follow.path_follower import PathFollowerConfig
from control.icr.batch import BatchICRController
from control.icr.controller import ICRControllerConfig, reference_stop_mask
from control.limits import limit_exceeded
from control.twist.wpilib import SwerveBatch, SwerveConfig
from estimation.hrep import eta_from_twist

__all__ = ["ActionController", "ACTION_KINDS", "icr_target_from_action"]

#: action kind -> action size
ACTION_KINDS = {"icr_target": 4, "twist": 3, "residual": 3, "icr_rate": 3}


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


class ActionController:
    """The controller of an action space (see the module docstring) for the N robots of ``env``.

    Args:
        env: the batched controller interface it will drive (geometry, limits, control period
            and the number of robots are read from it).
        action: ``"residual"``, ``"icr_rate"``, ``"icr_target"`` or ``"twist"``.
        controller: ``"icr"`` or (twists only) ``"swerve"``.
        The other keyword arguments are those of
        :class:`~control.action_spaces.vector.VectorControllerAction` (validated here).
    """

    def __init__(self, env, action: str = "icr_target", controller: str = "icr", *, mu_max: float = 1.0,
                 min_norm: float = 1e-3, v_max: float = 1.0, w_max: float = 2.0, residual_angle: float = 0.15,
                 residual_mu: float = 0.1, lambda_rate_max: float = 1.5, mu_accel: float = 2.0,
                 shape_targets: bool = True, target_rate: float = 3.0, cross_push: float = 0.6,
                 icr_config: ICRControllerConfig | None = None, swerve_config: SwerveConfig | None = None,
                 follower_config: PathFollowerConfig | None = None, signed_mu: bool = False) -> None:
        if not isinstance(action, str) or action not in ACTION_KINDS:
            raise ValueError(f"action must be one of {', '.join(ACTION_KINDS)}, got {action!r}")
        if (not isinstance(controller, str) or controller not in ("icr", "swerve")
                or (action != "twist" and controller != "icr")):
            raise ValueError(f"controller must be 'icr' (or 'swerve' for twists), got {controller!r}")
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
        self.kind, self.controller = action, controller
        self.action_size = ACTION_KINDS[action]
        self.mu_max, self.min_norm = float(mu_max), float(min_norm)
        self.scale = np.array([v_max, v_max, w_max], dtype=np.float64)
        self.residual_angle, self.residual_mu = float(residual_angle), float(residual_mu)
        self.lambda_rate_max, self.mu_accel = float(lambda_rate_max), float(mu_accel)
        self.shape_targets = bool(shape_targets) and controller == "icr" and action in ("icr_target", "twist")
        self.target_rate, self.cross_push = float(target_rate), float(cross_push)
        self.icr_config = icr_config or (SHAPED_TARGET_CONFIG if self.shape_targets else ICRControllerConfig())
        self.follower_config = follower_config or PathFollowerConfig()
        geom, limits, dt = env.geometry, env.limits, env.control_period
        self.num = N = int(np.shape(env.measured_beta)[0])
        self.geometry, self.limits, self.dt = geom, limits, float(dt)
        #: threads of the compiled target and controller steps (the env's: :func:`~control.controller.env_threads`)
        self.threads = threads = env_threads(env)
        self.icr = BatchICRController(N, geom, limits, dt, self.icr_config, threads) if controller == "icr" else None
        self.swerve = SwerveBatch(N, geom, limits, dt, swerve_config, threads) if controller == "swerve" else None
        # icr_rate's integrated target λ_s, μ_s and tangent frame; push past a stop (icr_rate and
        # shaped absolute targets, which step from the controller's own reference λ)
        self._lam_s = np.tile([0.0, 0.0, 1.0], (N, 1))
        self._mu_s = np.zeros(N)
        self._e1 = initial_frame(self._lam_s)
        self._push = np.zeros(N)
        stop_mask = functools.partial(reference_stop_mask, geom=geom, axis_margin=self.icr_config.axis_margin)
        # residual only: the path followers of all robots, one compiled call per step
        self.follower = BatchFollower(N, self.follower_config, stop_mask, dt, threads) if action == "residual" else None
        self._cos_margin = float(np.cos(self.icr_config.axis_margin))

    @property
    def ready(self) -> np.ndarray:
        """(N,) bool: the robots reset at least once (only those can be commanded)."""
        return self.icr.ready.copy() if self.icr is not None else self.swerve.ready

    def reset(self, env, rows) -> None:
        """Start the robots ``rows`` (integer indices) from the env's state right after their reset."""
        idx = np.asarray(rows, dtype=np.intp)
        if idx.size == 0:
            return
        lam_hat, _ = env.estimated_eta
        beta, phidot = env.measured_beta, env.measured_phidot
        if self.icr is None:
            self.swerve.reset(idx, beta[idx], phidot[idx])
            return
        fresh = self.icr.reset(idx, lam_hat[idx], beta[idx], phidot[idx])
        self._lam_s[idx] = fresh.lam
        self._mu_s[idx] = 0.0
        self._e1[idx] = initial_frame(fresh.lam)
        self._push[idx] = 0.0
        if self.follower is not None:
            tracks, progress = env.tracks, env.progress
            for i in idx:
                self.follower.reset(int(i), tracks[i], float(progress[i]))

    def _targets(self, env, a: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(λ_d, μ_d, held) of the ICR controllers of ``rows`` for the clipped actions ``a``: one
        compiled call (:mod:`control.action_spaces.targets`; the NumPy reference is
        :mod:`control.action_spaces.shaping`, equal to the bit)."""
        geom, dt = self.geometry, self.dt
        M = rows.size
        lam_d, mu_d, held = np.empty((M, 3)), np.empty(M), np.zeros(M, dtype=np.bool_)
        shape = (geom.a_minus_l, geom.a_perp, float(geom.steer_max), geom.s_unit, self._cos_margin,
                 bool(geom.unlimited_steering))
        if self.kind == "residual":  # the pose the observation saw, as every controller (true_pose: evaluation only)
            twists = self.follower.step(env.estimated_pose, rows)
            RESIDUAL_TARGETS.run(self.threads, twists.shape[0], twists, a, self.residual_angle, self.residual_mu,
                                 *shape, lam_d, mu_d, held)
            return lam_d, mu_d, held
        idx = rows.astype(np.int64)
        if self.kind == "icr_rate":
            RATE_TARGETS.run(self.threads, idx.shape[0], idx, a, self._lam_s, self._e1, self._push, self._mu_s,
                             self.lambda_rate_max, self.mu_accel, self.mu_max, dt, self.cross_push, *shape, lam_d,
                             mu_d, held)
            return lam_d, mu_d, held
        if self.kind == "icr_target":
            lam_t, mu_t = icr_target_from_action(a, self.mu_max, self.min_norm, self.signed_mu)
        else:
            lam_t, mu_t = eta_from_twist(a * self.scale)
        if not self.shape_targets:
            return lam_t, mu_t, held
        # one bounded step ahead of the controller's own reference λ; unsigned ICR targets: λ_d is
        # the direction of motion (μ_d ≥ 0), else the nearer representative
        lam_t, mu_t = np.ascontiguousarray(lam_t), np.ascontiguousarray(mu_t, dtype=np.float64)
        SHAPED_TARGETS.run(self.threads, idx.shape[0], idx, self.icr.state.lam, lam_t, mu_t, self._push,
                           self.kind == "twist" or self.signed_mu, self.target_rate * dt, self.cross_push, *shape,
                           lam_d, mu_d, held)
        return lam_d, mu_d, held

    def command(self, env, actions: np.ndarray, rows: np.ndarray) -> WheelCommand:
        """The wheel commands ((M, n) arrays) of the robots ``rows`` for their clipped actions
        (M, A), M = len(rows). ``info`` holds, per robot: ``controller_mode`` (a
        :class:`~control.icr.config.Mode` value, −1 for the baseline), ``limit_exceeded`` (the
        commands exceed a commanded limit), ``target_held`` (the shaped target was held at a
        steering stop or axis cap) and ``mu_lag`` [m/s] (|μ_d − μ| of the ICR controller after the
        step; 0 for the baseline)."""
        rows = np.asarray(rows, dtype=np.intp)
        a = np.asarray(actions, dtype=np.float64)
        beta, phidot = env.measured_beta[rows], env.measured_phidot[rows]
        if self.icr is not None:
            lam_hat, mu_hat = env.estimated_eta
            lam_d, mu_d, held = self._targets(env, a, rows)
            cmd = self.icr.step(rows, lam_hat[rows], mu_hat[rows], beta, phidot, lam_d, mu_d)
            modes = cmd.mode
            lag = np.abs(cmd.info["mu_target"] - self.icr.state.mu[rows])
        else:
            cmd = self.swerve.step(rows, a * self.scale, beta)
            modes = np.full(rows.size, -1, dtype=np.int64)
            held, lag = np.zeros(rows.size, dtype=np.bool_), np.zeros(rows.size)
        exceeded = limit_exceeded(cmd.beta_rate, cmd.beta_accel, cmd.phidot, cmd.phiddot, self.limits)
        info = dict(cmd.info, controller_mode=modes, limit_exceeded=exceeded, target_held=held, mu_lag=lag)
        return WheelCommand(beta=cmd.beta, phidot=cmd.phidot, beta_rate=cmd.beta_rate, beta_accel=cmd.beta_accel,
                            phiddot=cmd.phiddot, info=info, mode=cmd.mode, events=cmd.events)
