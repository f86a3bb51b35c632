"""The Gymnasium task: drive a simulated AZIMUT-3 along a track (``Azimut-v0``).

The physics lives in :mod:`azimut_env.physics`; this module holds the task (observation, reward,
termination) and the interface that controllers use (limits, set-point mapping, measurements,
estimated H state, track).

Controller interface (stable names, on ``env.unwrapped``):

* ``limits`` -> :class:`~azimut_env.params.ActuatorLimits` (steer_rate_max [rad/s],
  steer_accel_max [rad/s²], steer_torque_max [N·m], wheel_speed_max [rad/s], wheel_accel_max
  [rad/s²], wheel_torque_max [N·m], steer_min/steer_max [rad]); ``geometry`` -> ``RobotGeometry``;
  ``params`` -> ``RobotParams``; ``control_period`` [s].
* ``action_from_setpoints(beta_cmd, phidot_cmd)`` -> normalised action, and
  ``setpoints_from_action(action)`` -> (β_cmd [rad], φ̇_cmd [rad/s]) (also module-level functions in
  :mod:`azimut_env.params`, batched).
* measurements of the last step: ``measured_beta``, ``measured_phidot``, ``measured_motor_angles``
  ((n,) arrays); ``estimated_eta`` -> (λ̂, μ̂), the IT estimate with the canonical sign.
* ``track`` (:class:`~azimut_env.tracks.Track`: ``sample``, ``reference_twist``,
  ``reference_twist_body``, ``query``...) and ``progress`` (s along it [m]).
* ground truth for evaluation only: ``true_pose``, ``true_twist``, and ``info`` of each step.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from numba import njit

from estimation import estimate_eta, eta_from_twist, steering_from_lambda

from .params import ActuatorLimits, RobotParams, SensorParams, action_from_setpoints, setpoints_from_action
from .physics import WP, AzimutPhysics, BlowUpLimits, Obstacle
from .sensors import _measure_kernel
from .tracks import Track, make_track

__all__ = ["AzimutEnv", "observation_layout", "h_state_from_measurements", "h_state_batch"]


@njit(cache=True)
def _fill_obs(obs, lam, mu, beta, phidot, motor, lat, head, v_along, v_ref, look, prev_action, lo, hi):
    """Write the observation vector in the layout of :func:`observation_layout`; non-finite values
    become 0 and everything is clipped to [lo, hi]."""
    i = 0
    for j in range(3):
        obs[i] = lam[j]
        i += 1
    obs[i] = mu
    i += 1
    for arr in (beta, phidot, motor):
        for j in range(arr.shape[0]):
            obs[i] = arr[j]
            i += 1
    obs[i] = lat
    obs[i + 1] = head
    obs[i + 2] = v_along
    obs[i + 3] = v_ref
    i += 4
    for k in range(look.shape[0]):
        for j in range(3):
            obs[i] = look[k, j]
            i += 1
    for j in range(prev_action.shape[0]):
        obs[i] = prev_action[j]
        i += 1
    for j in range(obs.shape[0]):
        x = obs[j]
        if not math.isfinite(x):
            x = 0.0
        obs[j] = min(max(x, lo[j]), hi[j])


@njit(cache=True)
def _apply_action(a, cmd, steer_min, steer_max, wheel_speed_max) -> bool:
    """Check a (2n,) action for NaN/inf, clip it to [−1, 1] in place and write the set-points of
    ``params.setpoints_from_action`` into cmd (n, 2). Returns False (writing nothing) if not finite."""
    n = cmd.shape[0]
    for j in range(a.shape[0]):
        if not math.isfinite(a[j]):
            return False
    for j in range(a.shape[0]):
        a[j] = min(max(a[j], -1.0), 1.0)
    for k in range(n):
        cmd[k, 0] = max(a[k] * steer_max, steer_min)
        cmd[k, 1] = a[n + k] * wheel_speed_max
    return True


def h_state_batch(q, phidot, geom, mu_tol: float = 1e-3) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`h_state_from_measurements` for N robots at once: q, φ̇ (N, n) ->
    (λ̂ (N, 3), μ̂ (N,), S(λ̂) (N, n), qua (N,)), one batched ``estimation.estimate_eta`` call."""
    return estimate_eta(np.reshape(q, (-1, geom.n)), np.reshape(phidot, (-1, geom.n)), geom, mu_tol=mu_tol)


def h_state_from_measurements(q, phidot, geom, mu_tol: float = 1e-3) -> tuple[np.ndarray, float, np.ndarray, float]:
    """The observed H state from measured steering angles q (n,) and wheel speeds φ̇ (n,):
    ``(λ̂, μ̂, S(λ̂), qua)``, from ``estimation.estimate_eta`` with the paper's IT: λ̂ the IT
    estimate, μ̂ the least-squares wheel-speed fit given λ̂, (λ̂, μ̂) with the sign of
    ``canonical_eta`` (μ̂ ≥ 0 when moving), and qua = ``quality(S(λ̂), q)`` (eq. 28–29)."""
    lam, mu, beta_est, qua = estimate_eta(q, phidot, geom, mu_tol=mu_tol)
    return lam, float(mu), beta_est, float(qua)


def observation_layout(n: int, lookahead_count: int) -> dict[str, slice]:
    """Names and slices of the observation vector for n wheels and K look-ahead points (see
    :class:`AzimutEnv`, "Observation Space")."""
    sizes = [("lambda_hat", 3), ("mu_hat", 1), ("beta", n), ("phidot", n), ("motor_angle", n),
             ("lateral_error", 1), ("heading_error", 1), ("speed_along", 1), ("speed_ref", 1),
             ("lookahead", 3 * lookahead_count), ("prev_action", 2 * n)]
    out, i = {}, 0
    for name, size in sizes:
        out[name] = slice(i, i + size)
        i += size
    return out


class AzimutEnv(gym.Env):
    """
    ## Description
    A four-wheel AZIMUT-3-like nonholonomic omnidirectional robot (sidewise-offset steerable
    wheels with series-elastic, compliant steering) simulated in pymunk, top-down, must follow a
    reference track: a path with its own heading profile and speed profile. While it moves, tire
    forces deflect the compliant steering, so the wheels' propulsion axes stop concurring: the
    robot's instantaneous centre of rotation (ICR) is not defined by the wheels and must be
    estimated. The observation carries the IT estimate (λ̂, μ̂) of the H state computed from the
    measured steering angles and wheel speeds with ``estimation``.

    ## Action Space
    ``Box(-1, 1, (2n,), float32)``, n = 4 wheels. ``action[:n]`` are steering set-points
    β_cmd = a · β_max (β_max = π/2, the hard stop); ``action[n:]`` are propulsion set-points
    φ̇_cmd = a · φ̇_max (``limits.wheel_speed_max``). Out-of-range values are clipped; NaN or inf
    raise ``ValueError`` without changing the state. :meth:`setpoints_from_action` and
    :meth:`action_from_setpoints` convert. The steering motors are position-controlled with rate,
    acceleration and torque limits; the propulsion motors are velocity-controlled with acceleration
    and torque limits (:class:`~azimut_env.params.ActuatorLimits`, ``env.unwrapped.limits``).

    ## Observation Space
    ``Box(float32)`` with finite bounds; values are clipped to them. With K = ``lookahead_count``
    the layout is (:meth:`observation_slices` returns these slices by name):

    | name            | size | content                                                        | unit  |
    |-----------------|------|----------------------------------------------------------------|-------|
    | lambda_hat      | 3    | IT-estimated ICR λ̂ (canonical: μ̂ ≥ 0, else w ≥ 0)              | -     |
    | mu_hat          | 1    | μ̂ from the measured wheel speeds given λ̂ (least squares)      | m/s   |
    | beta            | n    | measured steering angles (wheel side of the spring)            | rad   |
    | phidot          | n    | measured wheel spin rates (encoder counts per period)          | rad/s |
    | motor_angle     | n    | measured steering motor angles                                 | rad   |
    | lateral_error   | 1    | signed distance to the path, positive to its left             | m     |
    | heading_error   | 1    | θ − θ_ref, wrapped                                             | rad   |
    | speed_along     | 1    | chassis velocity along the path direction                      | m/s   |
    | speed_ref       | 1    | reference progress speed at the current progress              | m/s   |
    | lookahead       | 3K   | K reference points ahead: (x, y) in the chassis frame, Δθ      | m, rad|
    | prev_action     | 2n   | the previous action                                            | -     |

    ## Rewards
    Per step, ``reward = progress − lateral − heading − slip − action_rate − off_track`` with
    * progress = ``progress_weight`` · min(Δs, v_ref·dt) / (v_max·dt): advancing along the track at
      the reference speed gives about ``progress_weight`` per step (no bonus for going faster);
    * lateral = ``lateral_weight`` · e_lat² [m²]; heading = ``heading_weight`` · e_θ² [rad²];
    * slip = ``slip_weight`` · Σ|F·v_slip| [W] (tire slip power);
    * action_rate = ``action_rate_weight`` · ‖a − a_prev‖²;
    * off_track = ``off_track_penalty`` on the step that leaves the track.
    Each term is in ``info["reward_terms"]``.

    ## Starting State
    At rest at the start of the track (progress ``options["start_progress"]``, default 0), with
    uniform noise of ±``start_noise`` m and rad on the pose, the wheels at the steering angles of
    the reference motion there (plus the same noise), motors on their set-points.

    ## Episode End
    Terminated when the lateral error exceeds ``max_lateral_error`` (``info["off_track"]``), when
    the track is finished (``info["finished"]``; one lap of a closed track), or when the physics
    blows up (non-finite or absurd state, ``info["error"]``; the last finite observation is
    returned). Truncation comes from ``max_episode_steps`` (registration: 6000 steps, 120 s; the
    paper track takes about 82 s at its reference speed).

    ## Arguments
    * ``track``: a :class:`~azimut_env.tracks.Track` or a built-in name (``paper``, ``circle``,
      ``figure8``, ``square``, ``crab``, ``random``: a new seeded track per reset). Default ``paper``.
    * ``control_period``: seconds per step (default 0.02). ``substeps``: physics substeps per step
      (default 8: a 2.5 ms substep).
    * ``params``: :class:`~azimut_env.params.RobotParams`. ``sensors``: ``SensorParams`` or
      ``"ideal"`` (overrides ``params.sensors``). ``noise_scale``: multiplies the sensor noise
      standard deviations (0: noise-free, quantisation kept).
    * ``domain_randomization``: relative spread d ∈ [0, 0.5]: at each reset the friction, steering
      stiffness and damping and chassis mass are scaled by factors uniform in [1 − d, 1 + d].
    * reward weights: ``progress_weight``, ``lateral_weight``, ``heading_weight``, ``slip_weight``,
      ``action_rate_weight``, ``off_track_penalty``; ``max_lateral_error`` [m].
    * ``lookahead_count`` K and ``lookahead_spacing`` [m of progress].
    * ``obstacles``: static obstacles, ``(x, y, radius)`` or vertex lists (also
      ``reset(options={"obstacles": ...})``).
    * ``start_noise``: starting pose noise. ``render_mode``: ``None``, ``"human"``, ``"rgb_array"``.

    ``reset(options=...)`` accepts ``"track"`` (a Track or a built-in name, for this episode
    only), ``"start_progress"`` [m], ``"obstacles"`` (for this episode; one that overlaps the
    robot at its start raises ``ValueError``) and ``"kick": {"step": int, "wheels": [...],
    "impulse": N·m·s}``, an angular impulse on chosen modules at a given step; :meth:`kick` does it
    immediately. A physics blow-up gives the reward ``−off_track_penalty``.

    ## Version History
    * v0: initial version.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 50}

    def __init__(self, track: str | Track = "paper", control_period: float = 0.02, substeps: int = 8,
                 params: RobotParams | None = None, sensors: SensorParams | str | None = None,
                 noise_scale: float = 1.0, domain_randomization: float = 0.0, progress_weight: float = 1.0, lateral_weight: float = 5.0,
                 heading_weight: float = 0.5, slip_weight: float = 0.002, action_rate_weight: float = 0.05,
                 off_track_penalty: float = 10.0, max_lateral_error: float = 0.5, lookahead_count: int = 5,
                 lookahead_spacing: float = 0.3, obstacles=(), start_noise: float = 0.02,
                 render_mode: str | None = None) -> None:
        params = params if params is not None else RobotParams()
        if sensors is not None:
            from dataclasses import replace

            sensors = SensorParams.ideal() if sensors == "ideal" else sensors
            if not isinstance(sensors, SensorParams):
                raise ValueError(f"sensors must be SensorParams or 'ideal', got {sensors!r}")
            params = replace(params, sensors=sensors)
        if not (math.isfinite(noise_scale) and noise_scale >= 0):
            raise ValueError(f"noise_scale must be finite and >= 0, got {noise_scale!r}")
        if noise_scale != 1.0:
            from dataclasses import replace

            sp = params.sensors
            params = replace(params, sensors=replace(sp, steer_noise=sp.steer_noise * noise_scale,
                                                     motor_noise=sp.motor_noise * noise_scale,
                                                     wheel_speed_noise=sp.wheel_speed_noise * noise_scale))
        if not 0.0 <= domain_randomization <= 0.5:
            raise ValueError(f"domain_randomization must be in [0, 0.5], got {domain_randomization!r}")
        for name, value in dict(progress_weight=progress_weight, lateral_weight=lateral_weight,
                                heading_weight=heading_weight, slip_weight=slip_weight,
                                action_rate_weight=action_rate_weight, off_track_penalty=off_track_penalty,
                                start_noise=start_noise).items():
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
        if not max_lateral_error > 0:
            raise ValueError("max_lateral_error must be > 0 [m]")
        if int(lookahead_count) != lookahead_count or lookahead_count < 1 or not lookahead_spacing > 0:
            raise ValueError("lookahead_count must be a positive integer and lookahead_spacing > 0")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None")
        if isinstance(track, str):
            make_track(track, rng=np.random.default_rng(0))  # validate the name now
        elif not isinstance(track, Track):
            raise ValueError(f"track must be a Track or a built-in name, got {track!r}")
        self.params = params
        self.physics = AzimutPhysics(params, n_robots=1, control_period=control_period, substeps=substeps,
                                     blowup=BlowUpLimits())
        self.physics.set_obstacles(obstacles)
        self._default_obstacles = self.physics.obstacles
        self._track_spec = track
        self.track: Track = track if isinstance(track, Track) else make_track(track, rng=np.random.default_rng(0))
        self.control_period = float(control_period)
        self.domain_randomization = float(domain_randomization)
        self.weights = dict(progress=progress_weight, lateral=lateral_weight, heading=heading_weight,
                            slip=slip_weight, action_rate=action_rate_weight, off_track=off_track_penalty)
        self.max_lateral_error = float(max_lateral_error)
        self.lookahead_count = int(lookahead_count)
        self.lookahead_spacing = float(lookahead_spacing)
        self.start_noise = float(start_noise)
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": int(round(1.0 / self.control_period))}
        n = self.n = params.n
        self.action_space = spaces.Box(-1.0, 1.0, (2 * n,), dtype=np.float32)
        self._layout = observation_layout(n, self.lookahead_count)
        size = max(s.stop for s in self._layout.values())
        lo, hi = np.zeros(size), np.zeros(size)
        wmax = params.limits.wheel_speed_max
        bounds = dict(lambda_hat=1.0, mu_hat=10.0, beta=math.pi, phidot=3 * wmax, motor_angle=math.pi,
                      lateral_error=10.0, heading_error=math.pi, speed_along=10.0, speed_ref=10.0,
                      lookahead=20.0, prev_action=1.0)
        for name, sl in self._layout.items():
            lo[sl], hi[sl] = -bounds[name], bounds[name]
        la = self._layout["lookahead"]
        hi_la = hi[la].reshape(-1, 3)
        hi_la[:, 2] = math.pi
        hi[la] = hi_la.ravel()
        lo[la] = -hi[la]
        lo[self._layout["speed_ref"]] = 0.0
        self.observation_space = spaces.Box(lo.astype(np.float32), hi.astype(np.float32), dtype=np.float32)
        self._obs_lo, self._obs_hi = self.observation_space.low, self.observation_space.high
        self._renderer = None
        self._trail: list[tuple[float, float]] = []
        self._reset_state()

    # ------------------------------------------------------------------ controller interface

    @property
    def limits(self) -> ActuatorLimits:
        """The actuator limits (steering rate/accel/torque, wheel speed/accel/torque)."""
        return self.params.limits

    @property
    def geometry(self):
        """The robot's :class:`~estimation.geometry.RobotGeometry`."""
        return self.params.geometry

    def setpoints_from_action(self, action) -> tuple[np.ndarray, np.ndarray]:
        """Normalised action (2n,) -> (β_cmd [rad], φ̇_cmd [rad/s]), each (n,)."""
        return setpoints_from_action(action, self.params.limits, self.n)

    def action_from_setpoints(self, beta_cmd, phidot_cmd) -> np.ndarray:
        """(β_cmd [rad], φ̇_cmd [rad/s]) -> normalised float32 action (2n,), clipped to [−1, 1]."""
        return action_from_setpoints(beta_cmd, phidot_cmd, self.params.limits)

    @property
    def measured_beta(self) -> np.ndarray:
        """Measured steering angles β (n,) [rad] of the last step."""
        return self._beta_m.copy()

    @property
    def measured_phidot(self) -> np.ndarray:
        """Measured wheel spin rates φ̇ (n,) [rad/s] of the last step."""
        return self._phidot_m.copy()

    @property
    def measured_motor_angles(self) -> np.ndarray:
        """Measured steering motor angles (n,) [rad] of the last step."""
        return self._motor_m.copy()

    @property
    def estimated_eta(self) -> tuple[np.ndarray, float]:
        """IT-estimated H state (λ̂ (3,), μ̂ [m/s]) from the last measurements (canonical sign)."""
        return self._lam_hat.copy(), float(self._mu_hat)

    @property
    def progress(self) -> float:
        """Progress s along the track [m] (unwrapped over laps)."""
        return self._s

    @property
    def true_pose(self) -> np.ndarray:
        """Ground-truth chassis pose (x, y, θ) [m, m, rad] (not observed; for evaluation)."""
        return self.physics.chassis_pose()[0]

    @property
    def true_twist(self) -> np.ndarray:
        """Ground-truth chassis twist (ẋ, ẏ, θ̇) in the chassis frame (for evaluation)."""
        return self.physics.chassis_twist()[0]

    def observation_slices(self) -> dict[str, slice]:
        """Names and slices of the observation vector (see the class docstring)."""
        return dict(self._layout)

    def decode_observation(self, obs) -> dict[str, np.ndarray]:
        """Split an observation into named arrays (lookahead reshaped to (K, 3))."""
        obs = np.asarray(obs)
        out = {name: obs[sl].copy() for name, sl in self._layout.items()}
        out["lookahead"] = out["lookahead"].reshape(self.lookahead_count, 3)
        return out

    def kick(self, wheels, impulse: float) -> None:
        """Knock the modules ``wheels`` with an angular impulse [N·m·s] about their steering axes."""
        self.physics.kick(0, list(wheels), float(impulse))

    # ------------------------------------------------------------------ gym API

    def _reset_state(self) -> None:
        n = self.n
        self._beta_m = np.zeros(n)
        self._phidot_m = np.zeros(n)
        self._motor_m = np.zeros(n)
        self._lam_hat = np.array([0.0, 0.0, 1.0])
        self._mu_hat = 0.0
        self._qua = 1.0
        self._beta_est = np.zeros(n)
        self._s = 0.0
        self._track_max_speed = self.track.max_speed
        self._lat = self._head = self._v_ref = self._v_along = 0.0
        self._look = np.zeros((self.lookahead_count, 3))
        self._prev_action = np.zeros(2 * n, dtype=np.float32)
        self._obs = np.zeros(self.observation_space.shape, dtype=np.float32)
        self._steps = 0
        self._done_error: str | None = None
        self._kick: dict | None = None
        self._steer_bias: np.ndarray | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"track", "obstacles", "kick", "start_progress"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}")
        rng = self.np_random
        self._reset_state()
        spec = options.get("track", self._track_spec)
        if isinstance(spec, Track):
            self.track = spec
        elif spec == "random" or spec != getattr(self.track, "name", None):
            self.track = make_track(spec, rng=rng)
        self._track_max_speed = self.track.max_speed
        obstacles = self._default_obstacles
        if "obstacles" in options:
            obstacles = tuple(Obstacle.coerce(o) for o in options["obstacles"])
        self.physics.obstacles = obstacles
        self.physics.rebuild()  # a fresh Space: bit-for-bit replay of a seeded episode
        if "kick" in options:
            kick = dict(options["kick"])
            if set(kick) - {"step", "wheels", "impulse"}:
                raise ValueError("kick option takes keys 'step', 'wheels', 'impulse'")
            self._kick = dict(step=int(kick.get("step", 0)), wheels=list(kick.get("wheels", range(self.n))),
                              impulse=float(kick.get("impulse", 0.5)))
        self._randomize(rng)
        sb = self.params.sensors.steer_bias
        self._steer_bias = rng.normal(0.0, sb, size=self.n) if sb > 0 else None
        s0 = float(options.get("start_progress", 0.0))
        if not math.isfinite(s0):
            raise ValueError("start_progress must be finite")
        ref = self.track.sample(s0)
        noise = self.start_noise
        pose = ref[:3] + rng.uniform(-noise, noise, size=3)
        beta = self._reference_beta(s0, pose[2]) + rng.uniform(-noise, noise, size=self.n)
        beta = np.clip(beta, self.geometry.steer_min + 1e-6, self.geometry.steer_max)
        self.physics.reset_robot(0, pose, beta)
        clash = self.physics.overlapping_obstacles(0)
        if clash:
            raise ValueError(f"obstacles {clash} overlap the robot's starting footprint at {np.round(pose, 3)}: "
                             "move them off the start of the track")
        self._phi_prev = self.physics.motor_state[:1, :, 4].copy()
        self._prev_action = self.action_from_setpoints(beta, np.zeros(self.n))
        self._measure()
        self._track_state(s0)
        self._trail = [(float(pose[0]), float(pose[1]))]
        obs = self._get_obs()
        self._obs = obs
        info = self._get_info(reward_terms={})
        if self.render_mode == "human":
            self.render()
        return obs, info

    def _reference_beta(self, s: float, theta: float) -> np.ndarray:
        """Steering angles of the reference motion at progress s (direction only)."""
        tw = self.track.reference_twist_body(s, theta, speed=1.0)
        if np.linalg.norm(tw) < 1e-9:
            return np.zeros(self.n)
        lam, _ = eta_from_twist(tw)
        return steering_from_lambda(lam, self.geometry)

    def _randomize(self, rng: np.random.Generator) -> None:
        phys = self.physics
        wp = phys._default_wheel_params()
        d = self.domain_randomization
        if d > 0:
            f = rng.uniform(1 - d, 1 + d, size=4)
            wp[..., WP.MU] *= f[0]
            wp[..., WP.K_S] *= f[1]
            wp[..., WP.C_S] *= f[2]
            phys.set_chassis_mass(0, self.params.chassis.mass * f[3])
        phys.set_wheel_params(wp)

    def step(self, action):
        a = np.asarray(action, dtype=np.float32)
        if a.shape != self.action_space.shape:
            raise ValueError(f"action must have shape {self.action_space.shape}, got {a.shape}")
        if self._done_error is not None:
            raise RuntimeError(f"step() after the physics failed ({self._done_error}); call reset()")
        lim, phys = self.params.limits, self.physics
        a = a.copy()
        # checks, clips (in the copy) and writes the set-points of params.setpoints_from_action
        if not _apply_action(a, phys.commands[0], lim.steer_min, lim.steer_max, lim.wheel_speed_max):
            raise ValueError(f"action contains NaN or inf: {np.asarray(action)}")
        if self._kick is not None and self._steps == self._kick["step"]:
            phys.kick(0, self._kick["wheels"], self._kick["impulse"])
        phys.step()
        self._steps += 1
        code = phys.summary[0, 10]
        if code != 0:
            self._done_error = phys.check()[1][0]
            info = {"error": self._done_error, "reward_terms": {}, "off_track": False, "finished": False}
            return self._obs.copy(), -self.weights["off_track"], True, False, info
        self._measure()
        s_prev = self._s
        self._track_state(s_prev)
        lat, head = self._lat, self._head
        off_track = abs(lat) > self.max_lateral_error
        finished = self.track.finished(self._s)
        reward, terms = self._get_rew(self._s - s_prev, lat, head, a, off_track)
        self._prev_action = a
        obs = self._get_obs()
        self._obs = obs
        summ = phys.summary[0]
        self._trail.append((float(summ[0]), float(summ[1])))
        if len(self._trail) > 2000:
            del self._trail[:1000]
        info = self._get_info(terms)
        info["off_track"] = bool(off_track)
        info["finished"] = bool(finished)
        if self.render_mode == "human":
            self.render()
        return obs, reward, bool(off_track or finished), False, info

    # ------------------------------------------------------------------ steps of step()

    def _measure(self) -> None:
        phys, sp = self.physics, self.params.sensors
        ms = phys.motor_state
        out = np.empty((1, 3, self.n))
        # sensors.measure_all on strided views of the physics arrays (no copies)
        beta_true = phys.wheel_summary[:1, :, 0]
        if self._steer_bias is not None:
            beta_true = beta_true + self._steer_bias
        _measure_kernel(beta_true, ms[:1, :, 0], ms[:1, :, 4], self._phi_prev, ms[:1, :, 3],
                        self.control_period, sp.steer_noise, sp.motor_noise, sp.steer_resolution, sp.wheel_cpr,
                        sp.wheel_speed_noise, self.np_random.standard_normal((1, 3, self.n)), out)
        self._phi_prev = ms[:1, :, 4].copy()
        beta_m, motor_m, phidot_m = out[0]
        self._beta_m, self._motor_m, self._phidot_m = beta_m, motor_m, phidot_m
        self._lam_hat, self._mu_hat, self._beta_est, self._qua = h_state_from_measurements(
            beta_m, phidot_m, self.geometry)

    def _track_state(self, s_hint: float) -> None:
        """Project the true pose on the track (windowed at ``s_hint``) and cache the errors."""
        summ = self.physics.summary[0]
        s, lat, head, v_ref, psi, look = self.track.query(summ[:3], s_hint, self.lookahead_count,
                                                          self.lookahead_spacing)
        self._s, self._lat, self._head, self._v_ref, self._look = s, lat, head, v_ref, look
        self._v_along = summ[3] * math.cos(psi) + summ[4] * math.sin(psi)

    def _get_obs(self) -> np.ndarray:
        obs = np.empty(self.observation_space.shape, dtype=np.float32)
        _fill_obs(obs, self._lam_hat, self._mu_hat, self._beta_m, self._phidot_m, self._motor_m, self._lat,
                  self._head, self._v_along, self._v_ref, self._look, self._prev_action, self._obs_lo, self._obs_hi)
        return obs

    def _get_rew(self, ds: float, lat: float, head: float, action: np.ndarray, off_track: bool):
        w = self.weights
        dt = self.control_period
        v_max = max(self._track_max_speed, 1e-3)
        da = action - self._prev_action
        terms = {
            "progress": w["progress"] * min(ds, self._v_ref * dt + 1e-3 * dt) / (v_max * dt),
            "lateral": -w["lateral"] * lat * lat,
            "heading": -w["heading"] * head * head,
            "slip": -w["slip"] * self.physics.summary[0, 8].item(),
            "action_rate": -w["action_rate"] * float(da @ da),
            "off_track": -w["off_track"] if off_track else 0.0,
        }
        return sum(terms.values()), terms

    def _get_info(self, reward_terms: dict) -> dict:
        phys = self.physics
        summ = phys.summary[0]
        twist = summ[[6, 7, 5]]
        # true η from the twist, ξ̇ = μ (v, −u, w): λ ∝ (−ẏ, ẋ, θ̇), μ = ‖ξ̇‖ ≥ 0
        mu = math.sqrt(float(twist @ twist))
        lam = np.array([-twist[1], twist[0], twist[2]]) / mu if mu > 0 else np.array([0.0, 0.0, 1.0])
        if mu <= 1e-3:  # the sign rule of canonical_eta(mu_tol=1e-3), as for the estimate
            key = lam[2] if lam[2] != 0 else (lam[0] if lam[0] != 0 else lam[1])
            if key < 0:
                lam, mu = -lam, -mu
        return {
            "pose": summ[0:3].copy(),
            "twist": twist,
            "eta_true": (lam, mu),
            "eta_hat": (self._lam_hat.copy(), self._mu_hat),
            "beta_true": phys.wheel_summary[0, :, 0].copy(),
            "beta_est": self._beta_est.copy(),
            "tire_forces": phys.wheel_summary[0, :, 2:4].copy(),
            "slip_power": float(summ[8]),
            "internal_force": float(summ[9]),
            "qua": self._qua,
            "progress": self._s,
            "lateral_error": float(self._lat),
            "heading_error": float(self._head),
            "reward_terms": reward_terms,
        }

    # ------------------------------------------------------------------ rendering

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("You are calling render method without specifying any render mode. "
                            "You can specify the render_mode at initialization, "
                            f'e.g. gym.make("Azimut-v0", render_mode="rgb_array")')
            return None
        if self._renderer is None:
            from .rendering import Renderer

            self._renderer = Renderer(self.render_mode, fps=self.metadata["render_fps"])
        return self._renderer.draw(self)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        d["_renderer"] = None
        return d
