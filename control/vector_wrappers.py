"""ICR-target and twist action spaces for the vector env (``AzimutVectorEnv``).

The batched counterpart of :mod:`control.wrappers`: the same actions (see
:class:`~control.wrappers.ICRTargetAction` and :class:`~control.wrappers.TwistAction`), mapped the
same way, with one controller per sub-env fed from the vector env's batched accessors
(``estimated_eta``, ``measured_beta``, ``measured_phidot``) and one batched ``step`` of the vector
env with all set-points. Sub-env i behaves as ``ICRTargetAction(AzimutEnv())`` (or
``TwistAction``) seeded with ``seed + i``.

The ICR controller runs batched: one :func:`~control.icr_controller.icr_control_step_batch` call
per control step for all sub-envs (row i is exactly what a single
:class:`~control.icr_controller.ICRController` would command). The swerve baseline
(:class:`~control.swerve.SwerveController`) is still a per-robot Python object stepped in a loop.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from estimation.hrep import eta_from_twist

from .icr_controller import ICRBatchState, ICRControllerConfig, icr_control_step_batch, initial_state_batch
from .wrappers import icr_target_from_action
from .swerve import SwerveConfig, SwerveController

__all__ = ["VectorControllerAction"]


class VectorControllerAction(gym.vector.VectorWrapper):
    """ICR targets (``action="icr_target"``, (N, 4)) or chassis twists (``action="twist"``, (N, 3))
    for an ``AzimutVectorEnv``, through the ICR controller or (twists only) the swerve baseline.

    Args:
        env: an ``AzimutVectorEnv`` (or a vector wrapper of one).
        action: ``"icr_target"`` or ``"twist"``. controller: ``"icr"`` or ``"swerve"``.
        mu_max [m/s], min_norm: as :class:`~control.wrappers.ICRTargetAction`.
        v_max [m/s], w_max [rad/s]: as :class:`~control.wrappers.TwistAction`.
        icr_config, swerve_config: controller tuning.

    ``info`` gains ``controller_mode`` (N,) (an ``icr_controller.Mode`` value, −1 for the baseline).
    """

    def __init__(self, env: gym.vector.VectorEnv, action: str = "icr_target", controller: str = "icr",
                 mu_max: float = 1.0, min_norm: float = 1e-3, v_max: float = 1.0, w_max: float = 2.0,
                 icr_config: ICRControllerConfig | None = None, swerve_config: SwerveConfig | None = None) -> None:
        super().__init__(env)
        if action not in ("icr_target", "twist"):
            raise ValueError(f"action must be 'icr_target' or 'twist', got {action!r}")
        if controller not in ("icr", "swerve") or (action == "icr_target" and controller != "icr"):
            raise ValueError(f"controller must be 'icr' (or 'swerve' for twists), got {controller!r}")
        base = env.unwrapped
        for attr in ("geometry", "limits", "control_period", "estimated_eta", "measured_beta", "measured_phidot",
                     "action_from_setpoints"):
            if not hasattr(base, attr):
                raise ValueError(f"the wrapped env must be AzimutVectorEnv (missing {attr!r})")
        for name, value in dict(mu_max=mu_max, v_max=v_max, w_max=w_max).items():
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        self._kind, self._controller = action, controller
        self.mu_max, self.min_norm = float(mu_max), float(min_norm)
        self.scale = np.array([v_max, v_max, w_max], dtype=np.float64)
        self._icr_config, self._swerve_config = icr_config, swerve_config
        size = 4 if action == "icr_target" else 3
        self.single_action_space = spaces.Box(-1.0, 1.0, (size,), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._ctls: list[SwerveController | None] = [None] * self.num_envs  # swerve baseline only
        self._icr: ICRBatchState | None = None  # the batched ICR controllers' state
        self._icr_ready = np.zeros(self.num_envs, dtype=np.bool_)
        self._pending = np.zeros(self.num_envs, dtype=np.bool_)

    def _reset_controllers(self, which: np.ndarray) -> None:
        base = self.env.unwrapped
        lam_hat, _ = base.estimated_eta
        beta, phidot = base.measured_beta, base.measured_phidot
        idx = np.flatnonzero(which)
        if idx.size == 0:
            return
        if self._controller == "icr":
            fresh = initial_state_batch(lam_hat[idx], beta[idx], phidot[idx], base.geometry, self._icr_config)
            if self._icr is None:  # rows not reset yet stay marked so until they are
                self._icr = initial_state_batch(lam_hat, beta, phidot, base.geometry, self._icr_config)
            self._icr = self._icr.put(idx, fresh)
            self._icr_ready[idx] = True
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

    def step(self, actions) -> tuple[Any, ...]:
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != self.action_space.shape or not np.all(np.isfinite(a)):
            raise ValueError(f"actions must be a finite {self.action_space.shape} array")
        if not self._icr_ready.all() if self._controller == "icr" else any(c is None for c in self._ctls):
            raise RuntimeError("call reset() before step()")
        a = np.clip(a, -1.0, 1.0)
        base = self.env.unwrapped
        lam_hat, mu_hat = base.estimated_eta
        beta, phidot = base.measured_beta, base.measured_phidot
        n = beta.shape[1]
        beta_c, phidot_c = beta.copy(), np.zeros((self.num_envs, n))  # autoreset this step: the action is ignored
        modes = np.full(self.num_envs, -1, dtype=np.int64)
        active = np.flatnonzero(~self._pending)
        if self._controller == "icr" and active.size:
            if self._kind == "icr_target":
                lam_d, mu_d = icr_target_from_action(a[active], self.mu_max, self.min_norm)
            else:
                lam_d, mu_d = eta_from_twist(a[active] * self.scale)
            sub, cmd = icr_control_step_batch(self._icr.take(active), lam_hat[active], mu_hat[active], beta[active],
                                              phidot[active], lam_d, mu_d, base.geometry, base.limits,
                                              self._icr_config or ICRControllerConfig(), base.control_period)
            self._icr = self._icr.put(active, sub)
            beta_c[active], phidot_c[active] = cmd.beta, cmd.phidot
            modes[active] = cmd.info["mode"]
        elif self._controller != "icr":
            for i in active:
                cmd = self._ctls[i].step(a[i] * self.scale, beta[i])
                beta_c[i], phidot_c[i] = cmd.beta, cmd.phidot
        obs, reward, terminated, truncated, info = self.env.step(base.action_from_setpoints(beta_c, phidot_c))
        done = terminated | truncated
        if base.autoreset_mode == AutoresetMode.SAME_STEP:
            self._reset_controllers(done)
        else:
            self._reset_controllers(self._pending)  # those the step just reset
            next_step = base.autoreset_mode == AutoresetMode.NEXT_STEP
            self._pending = done.copy() if next_step else np.zeros_like(done)
        info = dict(info, controller_mode=modes, _controller_mode=np.ones(self.num_envs, dtype=np.bool_))
        return obs, reward, terminated, truncated, info
