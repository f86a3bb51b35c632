"""The front end both envs share: construction, the controller interface, rendering.

:class:`~azimut_env.env.AzimutEnv` (one robot) and :class:`~azimut_env.vector_env.AzimutVectorEnv`
(N robots) are front ends over one :class:`~azimut_env.task.core.AzimutTask`. What they have in
common lives here, once:

* construction (:meth:`AzimutFrontEnd._build`): the keyword arguments become
  (:class:`~azimut_env.params.RobotParams`, :class:`~azimut_env.task.config.TaskConfig`) through
  :func:`~azimut_env.task.config.task_settings`, then the task, the action and observation spaces;
* the controller interface (:mod:`azimut_env.interface`): the same properties, reading the
  task's arrays at ``self._robots``, which is ``0`` for the single env (per-robot shapes) and
  ``slice(None)`` for the vector env (a leading robot axis);
* rendering: the drawn robot's :class:`~azimut_env.rendering.Trail` and the explicit inputs of
  :meth:`~azimut_env.rendering.Renderer.draw`.

The gym ``step``/``reset`` stay in each env (their batching, seeding and autoreset differ); the
blow-up handling they share is :meth:`AzimutTask.end_blown_up`.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from azimut_env.params import ActuatorLimits, action_from_setpoints, setpoints_from_action
from azimut_env.physics.engine import AzimutPhysics
from azimut_env.rendering import Trail
from azimut_env.task.config import task_settings
from azimut_env.task.core import AzimutTask
from azimut_env.tracks import Track

__all__ = ["AzimutFrontEnd"]


def _out(x: Any) -> Any:
    """A copy of an array, or a Python float of a NumPy scalar."""
    return x.copy() if isinstance(x, np.ndarray) else float(x)


class AzimutFrontEnd:
    """Mixin of both envs (placed before the Gymnasium base class). Subclasses set ``_robots``
    (``0`` or ``slice(None)``) and implement :meth:`_render_robot`."""

    metadata: dict[str, Any]
    _robots: int | slice

    def _build(self, n_robots: int, track: str | Track, obstacles: Any, render_mode: str | None,
               settings: dict[str, Any]) -> None:
        """Validate the keyword arguments (``settings``: ``params``, ``sensors``, ``noise_scale``
        and the TaskConfig fields) and build the task, the single-robot spaces and the renderer state."""
        params, config = task_settings(**settings)
        modes = type(self).metadata["render_modes"]
        if render_mode is not None and (not isinstance(render_mode, str) or render_mode not in modes):
            raise ValueError(f"render_mode must be one of {modes} or None")
        self.params = params
        self.config = config
        self.task = AzimutTask(params, config, n_robots=n_robots, track=track, obstacles=obstacles)
        self.n = params.n
        self.control_period = float(config.control_period)
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": int(round(1.0 / self.control_period))}
        self._single_action_space = spaces.Box(-1.0, 1.0, (2 * self.n,), dtype=np.float32)
        self._single_observation_space = spaces.Box(self.task.obs_low, self.task.obs_high, dtype=np.float32)
        self._renderer = None
        self._trail = Trail()

    # ------------------------------------------------------------------ controller interface

    @property
    def physics(self) -> AzimutPhysics:
        """The physics (all robots of the task)."""
        return self.task.physics

    @property
    def num_threads(self) -> int:
        """Threads of the compiled physics and step pipeline: ``num_threads`` given (or the cores
        this process may use), at most one per robot (the single env: 1); the controllers' batched
        steps take the same. Any count gives the same bits."""
        return self.task.physics.num_threads

    @property
    def limits(self) -> ActuatorLimits:
        """The actuator limits (steering rate/accel/torque, wheel speed/accel/torque)."""
        return self.params.limits

    @property
    def geometry(self):
        """The robot's :class:`~estimation.geometry.RobotGeometry`."""
        return self.params.geometry

    def setpoints_from_action(self, action) -> tuple[np.ndarray, np.ndarray]:
        """Normalised action(s) (..., 2n) -> (β_cmd [rad], φ̇_cmd [rad/s]), each (..., n)."""
        return setpoints_from_action(action, self.params.limits, self.n)

    def action_from_setpoints(self, beta_cmd, phidot_cmd) -> np.ndarray:
        """(β_cmd [rad], φ̇_cmd [rad/s]), each (..., n) -> normalised float32 action(s) (..., 2n),
        clipped to [−1, 1]."""
        return action_from_setpoints(beta_cmd, phidot_cmd, self.params.limits)

    @property
    def measured_beta(self) -> np.ndarray:
        """Measured steering angles β [rad] of the last step, (n,) / (N, n)."""
        return self.task.beta_m[self._robots].copy()

    @property
    def measured_phidot(self) -> np.ndarray:
        """Measured wheel spin rates φ̇ [rad/s] of the last step, (n,) / (N, n)."""
        return self.task.phidot_m[self._robots].copy()

    @property
    def measured_motor_angles(self) -> np.ndarray:
        """Measured steering motor angles [rad] of the last step, (n,) / (N, n)."""
        return self.task.motor_m[self._robots].copy()

    @property
    def estimated_eta(self) -> tuple[np.ndarray, Any]:
        """IT-estimated H state (λ̂, μ̂ [m/s]) from the last measurements (canonical sign):
        ((3,), float) / ((N, 3), (N,))."""
        return self.task.lam_hat[self._robots].copy(), _out(self.task.mu_hat[self._robots])

    @property
    def progress(self) -> Any:
        """Progress s along the track [m] (unwrapped over laps): float / (N,)."""
        return _out(self.task.s[self._robots])

    @property
    def pose_source(self) -> str:
        """``"true"`` or ``"odometry"``: where the observation's pose comes from (see
        :class:`~azimut_env.env.AzimutEnv`, "What is privileged")."""
        return self.task.pose_source

    @property
    def estimated_pose(self) -> np.ndarray:
        """The pose (x, y, θ) [m, m, rad] the observation was computed from (the true pose with
        ``pose_source="true"``; dead reckoning + localisation fixes with ``"odometry"``): (3,) / (N, 3)."""
        return self.task.pose_estimates()[self._robots]

    @property
    def true_pose(self) -> np.ndarray:
        """Ground-truth chassis pose (x, y, θ) [m, m, rad] (not observed; for evaluation)."""
        return self.physics.chassis_pose()[self._robots]

    @property
    def true_twist(self) -> np.ndarray:
        """Ground-truth chassis twist (ẋ, ẏ, θ̇) in the chassis frame (for evaluation)."""
        return self.physics.chassis_twist()[self._robots].copy()

    def observation_slices(self) -> dict[str, slice]:
        """Names and slices of the observation vector (last axis; see the single env's docstring)."""
        return dict(self.task.layout)

    def decode_observation(self, obs) -> dict[str, np.ndarray]:
        """Split observations (..., D) into named arrays (lookahead reshaped to (..., K, 3))."""
        obs = np.asarray(obs)
        out = {name: obs[..., sl].copy() for name, sl in self.task.layout.items()}
        out["lookahead"] = out["lookahead"].reshape(obs.shape[:-1] + (self.config.lookahead_count, 3))
        return out

    # ------------------------------------------------------------------ rendering

    def _render_robot(self) -> int:
        """The robot that :meth:`render` draws (may be out of range: the vector env's
        ``render_index`` is settable; :meth:`render` refuses it then)."""
        raise NotImplementedError

    def _trail_robot(self) -> int | None:
        """The drawn robot while rendering, None otherwise (the trail is only kept then)."""
        i = self._render_robot()
        return i if self.render_mode is not None and 0 <= i < self.task.n_robots else None

    def _start_trail(self) -> None:
        """A new episode of the drawn robot."""
        i = self._trail_robot()
        if i is not None:
            x, y, _ = self.physics.chassis_pose()[i]
            self._trail.start(x, y)

    def _extend_trail(self) -> None:
        i = self._trail_robot()
        if i is not None:
            x, y, _ = self.physics.chassis_pose()[i]
            self._trail.add(x, y)

    def render(self):
        """Draw the robot (the vector env's ``render_index``): an RGB array in ``"rgb_array"``
        mode, None in ``"human"`` mode (and without a render mode, with a warning)."""
        if self.render_mode is None:
            gym.logger.warn("You are calling render method without specifying any render mode. "
                            "You can specify the render_mode at initialization, "
                            'e.g. gym.make("Azimut-v2", render_mode="rgb_array")')
            return None
        i = self._render_robot()
        if not 0 <= i < self.task.n_robots:
            raise ValueError(f"render_index {i} out of range 0..{self.task.n_robots - 1}")
        if self._renderer is None:
            from azimut_env.rendering import Renderer

            self._renderer = Renderer(self.render_mode, fps=self.metadata["render_fps"])
        phys = self.physics
        return self._renderer.draw(track=self.task.tracks[i], pose=phys.chassis_pose()[i],
                                   twist=phys.chassis_twist()[i], beta=phys.steering_angles()[i],
                                   lam_hat=self.task.lam_hat[i], trail=self._trail.points, obstacles=phys.obstacles,
                                   chassis=self.params.chassis, geometry=self.params.geometry)

    def _close_renderer(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        d["_renderer"] = None
        return d
