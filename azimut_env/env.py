"""The Gymnasium task: drive a simulated AZIMUT-3 along a track (``Azimut-v2``).

The physics lives in :mod:`azimut_env.physics.engine`, the task over N robots at once in
:mod:`azimut_env.task.core` (which runs the stages: :mod:`~azimut_env.task.actions`,
:mod:`~azimut_env.task.sensors`, :mod:`~azimut_env.task.termination`, :mod:`~azimut_env.task.reward`,
:mod:`~azimut_env.task.observation`); this module is the single env, the N = 1 front end of that task
(:class:`~azimut_env.vector_env.AzimutVectorEnv` is the N-robot one; the constructor, the
controller interface and rendering they share are :class:`~azimut_env.frontend.AzimutFrontEnd`).
The controller interface is typed as :class:`~azimut_env.interface.ControllerInterface`.

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
  ``reference_twist_body``, ``query``...) and ``progress`` (s along it [m], from the true pose).
* ``estimated_pose``: the pose (x, y, θ) the observation is computed from: the true pose with
  ``pose_source="true"``, the odometry + localisation estimate with ``"odometry"``
  (:mod:`azimut_env.task.localisation`). Controllers that follow the track should read this one.
* ground truth for evaluation only: ``true_pose``, ``true_twist``, and ``info`` of each step.
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np

from azimut_env.frontend import AzimutFrontEnd
from azimut_env.params import RobotParams, SensorParams
from azimut_env.task.actions import float32_copy
from azimut_env.task.config import front_signature, v1_kwargs
from azimut_env.task.core import observation_layout
from azimut_env.task.info import robot_info
from azimut_env.tracks import Track
from azimut_env.validation import ResetNeeded, check_finite, check_index_list, check_seed
from estimation import estimate_eta

__all__ = ["AzimutEnv", "make_v1", "observation_layout", "h_state_from_measurements", "h_state_batch"]


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


class AzimutEnv(AzimutFrontEnd, gym.Env):
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
    ``Box(-1, 1, (2n,), float32)``, n = 4 wheels in the order of ``geometry.alpha`` (AZIMUT-3:
    front-left, rear-left, rear-right, front-right). ``action[:n]`` are steering set-points
    β_cmd = a · β_max (β_max = π/2, the hard stop); ``action[n:]`` are propulsion set-points
    φ̇_cmd = a · φ̇_max (``limits.wheel_speed_max``). Out-of-range values are clipped; NaN or inf
    raise ``ValueError`` without changing the state. :meth:`setpoints_from_action` and
    :meth:`action_from_setpoints` convert. The steering motors are position-controlled with rate,
    acceleration and torque limits; the propulsion motors are velocity-controlled with acceleration
    and torque limits (:class:`~azimut_env.params.ActuatorLimits`, ``env.unwrapped.limits``).

    ## Observation Space
    ``Box(float32)`` with finite bounds; values are clipped to them. With K = ``lookahead_count``
    the layout is (:meth:`observation_slices` returns these slices by name; the table is
    ``observation.OBSERVATION_FIELDS``, which also sets the bounds and the fill):

    <!-- generated: observation-table -->
    | name          | size | content                                                   | unit   |
    |---------------|------|-----------------------------------------------------------|--------|
    | lambda_hat    | 3    | IT-estimated ICR λ̂ (canonical: μ̂ ≥ 0, else w ≥ 0)         | -      |
    | mu_hat        | 1    | μ̂ from the measured wheel speeds given λ̂ (least squares)  | m/s    |
    | beta          | n    | measured steering angles (wheel side of the spring)       | rad    |
    | phidot        | n    | measured wheel spin rates (encoder counts per period)     | rad/s  |
    | motor_angle   | n    | measured steering motor angles                            | rad    |
    | lateral_error | 1    | signed distance to the path, positive to its left         | m      |
    | heading_error | 1    | θ − θ_ref, wrapped                                        | rad    |
    | speed_along   | 1    | chassis velocity along the path direction                 | m/s    |
    | speed_ref     | 1    | reference progress speed at the current progress          | m/s    |
    | lookahead     | 3K   | K reference points ahead: (x, y) in the chassis frame, Δθ | m, rad |
    | prev_action   | 2n   | the previous action                                       | -      |
    <!-- end generated -->

    **What is privileged.** ``lambda_hat``, ``mu_hat``, ``beta``, ``phidot``, ``motor_angle``
    come from the simulated sensors (noise, quantisation) and the IT estimator; ``speed_ref`` is
    the track's reference; ``prev_action`` is the agent's own. With ``pose_source="true"`` (the
    default) ``lateral_error``, ``heading_error``, ``speed_along`` and ``lookahead`` are computed
    from the **true** chassis pose and velocity (ground truth a real robot does not have; sensor
    noise does not reach them). With ``pose_source="odometry"`` they are computed from a pose
    estimate: dead reckoning from the estimated H state and the wheel encoders, corrected by a
    noisy absolute localisation fix every ``localisation.fix_period_s``
    (:mod:`azimut_env.task.localisation`), and ``speed_along`` from the odometry twist. In both modes
    the reward, the termination, ``progress`` and ``info`` (``pose``, ``twist``, ``eta_true``,
    ``beta_true``, ``lateral_error``...) use the ground truth; ``info["pose_estimate"]`` is the
    pose the observation used.

    ## Rewards
    Per step, the reward is the sum of the terms of the table ``reward.REWARD_TERMS``, in this
    order; each is in ``info["reward_terms"]`` under its name. w is the term's weight
    (``reward_weights={name: w}`` sets it), v_max the track's top reference speed, dt the control
    period; every term but progress is ≤ 0:

    <!-- generated: reward-table -->
    | name            | weight | unit | term (per step)                                             |
    |-----------------|--------|------|-------------------------------------------------------------|
    | progress        | 3      | -    | w·clip(Δs, −v_max·dt, v_ref·dt)/(v_max·dt)                  |
    | lateral         | 0.5    | -    | −w·(1 − exp(−abs(e_lat)/lateral_scale))                     |
    | heading         | 0.3    | -    | −w·(1 − exp(−abs(e_θ)/heading_scale))                       |
    | overspeed       | 2      | -    | −w·max(0, v_along − v_ref)/v_max                            |
    | slip            | 0.02   | 1/W  | −min(w·P_slip, antagonism_cap), P_slip the tire slip power  |
    | antagonism      | 0.01   | 1/N  | −min(w·F_ant, antagonism_cap), F_ant the wheels' antagonism |
    | nullspace_force | 0      | 1/N  | −min(w·F_null, antagonism_cap), F_null the null-space force |
    | action_rate     | 0.05   | -    | −w·‖a − a_prev‖² (normalised actions)                       |
    | off_track       | 10     | -    | −w on the step that leaves the track or stalls              |
    <!-- end generated -->

    * progress: w · v_ref / v_max per step at the reference speed (w at the track's top speed),
      nothing more for going faster, and a backward jump of the track projection costs at most
      one step's worth;
    * lateral and heading: bounded (a lost robot costs at most w) and steepest at zero error, so
      centimetres matter (lateral, default weight: 1 cm −0.09, 5 cm −0.32);
    * overspeed: going faster than the reference is penalised (finishing early would otherwise
      save the per-step costs);
    * slip (P_slip = Σ abs(F·v_slip) [W]) and antagonism (F_ant [N]): the actuator antagonism the
      paper is about (tire slip power, and the forces of wheels that fight each other: the tire
      forces minus the distribution of their net wrench that a common rigid slip would give,
      ``info["antagonism"]``, :mod:`azimut_env.physics.antagonism`; 0 for perfectly coordinated
      wheels, whatever the loads and rolling speeds); nullspace_force (F_null [N], weight 0): the
      minimum-norm null-space force, ``Azimut-v1``'s internal force, which also grows with the
      chassis acceleration;
    * off_track: charged on the step that ends the episode by a failure (the penalised end
      conditions, "Episode End"); a physics blow-up gets −w as its reward.

    Each term's typical size under the reference controller and under random actions, and why
    the progress weight is 3, are measured in the documentation (``docs/results/rl.md``).

    ## Starting State
    At rest at the start of the track (progress ``options["start_progress"]``, default 0), with
    uniform noise of ±``start_noise`` m and rad on the pose, the wheels at the steering angles of
    the reference motion there (plus the same noise), motors on their set-points.

    ## Episode End
    Terminated when an end condition of the table ``termination.TERMINATION_TERMS`` holds (each is
    a bool of ``info`` under its name; a penalised one pays the ``off_track`` term; ``stalled`` is
    off by default, ``stall_time`` 0), or when the physics blows up (non-finite or absurd state,
    ``info["error"]``; the last finite observation is returned):

    <!-- generated: termination-table -->
    | name      | penalised | ends the episode when                                    |
    |-----------|-----------|----------------------------------------------------------|
    | off_track | yes       | left the track: abs(e_lat) > max_lateral_error           |
    | finished  | no        | finished the track (one lap of a closed one)             |
    | stalled   | yes       | stall_time without stall_distance of progress (0: never) |
    <!-- end generated -->

    Truncated at ``time_limit_factor`` (default 1.5) × T, T the
    nominal lap of the ICR reference controller on the episode's track
    (``lap_time.reference_lap_time``: the time of the track's speed profile plus, for each wheel that
    must stop and turn in place across its steering stops along the reference ICR path, the
    time to turn it, 1.79 s for a swing of π with the default limits; ``0`` turns the limit
    off); the registration adds no other limit (``gymnasium.make(..., max_episode_steps=K)``
    does). ``random`` tracks get theirs from the same formula at each reset.

    ## Info
    ``reset`` and ``step`` return the info dict of the table ``info.INFO_FIELDS`` (the vector env's
    is the same, batched); every value is ground truth or the robot's own estimate, as named. The
    step whose physics blew up has only ``reward_terms``, the end conditions' keys and ``error``.

    <!-- generated: info-table -->
    | key             | value      | unit       | content                                                  |
    |-----------------|------------|------------|----------------------------------------------------------|
    | pose            | (3,)       | m, m, rad  | true chassis pose (x, y, θ), world frame                 |
    | pose_estimate   | (3,)       | m, m, rad  | the pose the observation used (pose_source)              |
    | twist           | (3,)       | m/s, rad/s | true chassis twist (ẋ, ẏ, θ̇), chassis frame              |
    | eta_true        | ((3,), ()) | -, m/s     | true H state (λ, μ) of the twist, canonical sign         |
    | eta_hat         | ((3,), ()) | -, m/s     | IT estimate (λ̂, μ̂), the observation's                    |
    | beta_true       | (n,)       | rad        | true steering angles (wheel side of the spring)          |
    | beta_est        | (n,)       | rad        | S(λ̂): steering angles of the estimated ICR               |
    | tire_forces     | (n, 2)     | N          | step-mean tire forces (F_x, F_y), chassis frame          |
    | slip_power      | ()         | W          | step-mean tire slip power Σ abs(F·v_slip)                |
    | antagonism      | ()         | N          | step-mean antagonism: stiffness-weighted internal force  |
    | nullspace_force | ()         | N          | step-mean min-norm null-space force of the tires         |
    | qua             | ()         | -          | qua of the measured steering angles (eq. 28–29)          |
    | progress        | ()         | m          | true progress along the track (unwrapped over laps)      |
    | lateral_error   | ()         | m          | true distance to the path, positive to its left          |
    | heading_error   | ()         | rad        | true θ − θ_ref, wrapped                                  |
    | reward_terms    | {term: ()} | -          | the reward terms of the step by name (0 at a reset)      |
    | off_track       | ()         | bool       | left the track: abs(e_lat) > max_lateral_error           |
    | finished        | ()         | bool       | finished the track (one lap of a closed one)             |
    | stalled         | ()         | bool       | stall_time without stall_distance of progress (0: never) |
    | error           | ()         | str        | the physics failure, only on the step that blew up       |
    <!-- end generated -->

    ## Arguments
    * ``track``: a :class:`~azimut_env.tracks.Track` or a built-in name (``paper``, ``circle``,
      ``figure8``, ``square``, ``crab``, ``random``: a new seeded track per reset). Default ``paper``.
    * ``control_period``: seconds per step (default 0.02). ``substeps``: physics substeps per step
      (default 8: a 2.5 ms substep). ``solver_iterations``: pymunk solver iterations per substep,
      for obstacle contacts (default 20, see ``AzimutPhysics``).
    * ``robot``: a preset by name (``"azimut3"``, the default robot; ``"swerve"``, four coaxial
      modules with unlimited steering; ``"tri"``; ``"hex"``: ``docs/robots.md``) or the path of a
      robot description file (``"my_robot.toml"``), or ``params``:
      :class:`~azimut_env.params.RobotParams` (e.g. ``RobotParams.preset("swerve")`` changed with
      ``dataclasses.replace``); not both. ``imperfections``: ``"paper"`` (the imperfections the
      paper names: steering friction with stiction, the module's centre of mass off its axis, the
      drive's torque–speed line, steering-axis zero offsets and rolling-radius errors, finer wheel
      encoders, and a 20 N·m/rad steering spring identified from the paper's Fig. 11;
      :mod:`azimut_env.imperfections`) or ``"ideal"`` (none: ``Azimut-v1``'s physics), applied on
      top of the robot; default ``None``: the robot as given, with the preset its description
      file names (``[imperfections]`` ``preset``: ``"paper"`` for the default robot ``azimut3``,
      ``"ideal"`` for ``swerve``, ``tri``, ``hex``); ``params`` as they are. ``sensors``: ``SensorParams`` or
      ``"ideal"`` (overrides ``params.sensors``). ``noise_scale``: multiplies the sensor noise
      standard deviations (0: noise-free, quantisation kept).
    * ``domain_randomization``: relative spread d ∈ [0, 0.5]: at each reset the friction, steering
      stiffness and damping, chassis mass (the normal loads follow), tire slip stiffness (with its
      relaxation lengths, so the contact stiffness stays) and contact patch size are scaled by
      factors uniform in [1 − d, 1 + d]; with ``"paper"`` imperfections a new robot's
      steering-axis zero offsets and rolling-radius errors are drawn too (N(0, 0.5°), N(0, 0.3%))
      and the steering friction scaled by one more factor
      (:func:`~azimut_env.physics.wheel_params.randomized_wheel_params`).
    * ``reward_weights``: the weights by term name (see Rewards), e.g. ``{"slip": 0.05}``; the
      terms not named keep their defaults, an unknown name is refused. (The keywords
      ``progress_weight``, ..., ``off_track_penalty`` of earlier versions still work, with a
      ``DeprecationWarning``.) Scales ``lateral_scale`` [m], ``heading_scale`` [rad],
      ``antagonism_cap``; ``max_lateral_error`` [m].
    * ``stall_time`` [s] (0: off) and ``stall_distance`` [m]: stall termination.
      ``time_limit_factor``: the per-track step limit (see Episode End).
    * ``lookahead_count`` K and ``lookahead_spacing`` [m of progress].
    * ``obstacles``: static obstacles, ``(x, y, radius)`` or vertex lists (also
      ``reset(options={"obstacles": ...})``).
    * ``start_noise``: starting pose noise. ``render_mode``: ``None``, ``"human"``, ``"rgb_array"``.
    * ``action_latency``: command latency k in control periods (default 0): the set-points of an
      action drive the motors k steps later (the motors hold the reset set-points for the first k
      steps of an episode); for sim-to-real work. The steering motor model (a kinematic position
      source, or a DC motor under its torque–speed limit) is ``params.steer_motor``.
    * ``pose_source``: ``"true"`` (default) or ``"odometry"`` (see "What is privileged");
      ``localisation``: :class:`~azimut_env.task.localisation.LocalisationParams` (fix period [s], fix
      noise [m], [rad]; default 1 s, 2 cm, 0.01 rad).
    * ``num_threads``: threads of the compiled physics and step pipeline of the vector env, blocks
      of robots (default None: the cores this process may use); one robot runs on one, and any
      count gives the same bits (:mod:`estimation.threads`).

    ``reset(options=...)`` accepts ``"track"`` (a Track or a built-in name, for this episode
    only), ``"start_progress"`` [m] (on an open track within [0, length], else ``ValueError``; on
    a closed track any finite value, wrapped modulo the length), ``"obstacles"`` (for this
    episode; one that overlaps the
    robot at its start raises ``ValueError``) and ``"kick": {"step": int, "wheels": [...],
    "impulse": N·m·s}``, an angular impulse on chosen modules at a given step; :meth:`kick` does it
    immediately. A physics blow-up gives the reward −``reward_weights["off_track"]``.

    ## Version History
    * v2: physics v3, the imperfections the paper names (``imperfections="paper"`` by default):
      steering joint friction (Coulomb, stiction, Stribeck), the module's centre of mass off the
      steering axis, the drive's torque–speed line, per-wheel steering-axis zero offsets and
      rolling-radius errors (drawn anew under domain randomisation), 36,000-count wheel encoders,
      and a 20 N·m/rad steering spring (was 60). The reward prices the antagonism of the wheels
      (term ``antagonism``, weight 0.01 /N, the stiffness-weighted internal force) instead of v1's
      internal force, the minimum-norm null-space force, which also reads the chassis acceleration
      (term ``nullspace_force``, weight 0; ``reward_weights={"internal_force": ...}`` is refused,
      naming the new term); ``info`` has ``antagonism`` and ``nullspace_force`` in place of
      ``internal_force``. Observation, action and termination are unchanged.
      ``gymnasium.make("Azimut-v1")`` still makes v1 (this env with ``imperfections="ideal"`` and
      v1's reward weights, bit for bit the v1 trajectories and rewards), with Gymnasium's warning
      that it is out of date.
    * v1: a reward that prices what the paper measures: bounded exponential tracking terms (were
      quadratic), overspeed penalised, slip power and internal force priced, backward projection
      jumps clipped, optional stall termination, a per-track time limit (1.5 × the reference
      controller's nominal lap, ``time_limit_factor``) instead of 6000 steps; ``info["stalled"]``.
      The same release changes the simulated vehicle dynamics (physics v2: steering modules as
      joint coordinates, a brush tire; ``docs/physics.md``). ``gymnasium.make("Azimut-v0")``
      raises ``gymnasium.error.DeprecatedEnv`` naming the current version.
    * v0: initial version.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 50}
    _robots = 0  # the controller interface reads row 0 of the task's arrays

    def __init__(self, track: str | Track = "paper", *, robot: str | os.PathLike | None = None,
                 params: RobotParams | None = None, imperfections: str | None = None,
                 sensors: SensorParams | str | None = None, noise_scale: float = 1.0, obstacles=(),
                 render_mode: str | None = None, **config: Any) -> None:
        # **config: the TaskConfig fields (see "Arguments"; __signature__ below spells them out)
        self._build(1, track, obstacles, render_mode, dict(
            robot=robot, params=params, imperfections=imperfections, sensors=sensors, noise_scale=noise_scale,
            **config))
        self.action_space = self._single_action_space
        self.observation_space = self._single_observation_space
        self._done_error: str | None = None

    @property
    def track(self) -> Track:
        """The track of the current episode."""
        return self.task.tracks[0]

    def _render_robot(self) -> int:
        return 0

    def kick(self, wheels, impulse: float) -> None:
        """Knock the modules ``wheels`` (distinct indices in 0..n−1) with an angular impulse
        [N·m·s] about their steering axes."""
        wheels = check_index_list("wheels", wheels, self.n)
        impulse = check_finite("impulse", impulse)
        self._check_ready()
        self.physics.kick(0, wheels, impulse)

    def check_can_step(self) -> None:
        """Raise what :meth:`step` would raise for the env's state, whatever the action
        (``ResetNeeded``: no successful reset, or a physics failure ended the episode). A wrapper
        calls it before moving any state of its own."""
        self._check_ready()

    def _check_ready(self) -> None:
        if self._done_error is not None:
            raise ResetNeeded(f"the episode ended with a physics failure ({self._done_error}); call reset()")
        if not self.task.ready[0]:
            raise ResetNeeded("call reset() first: the env has not been reset, or its last reset failed")

    # ------------------------------------------------------------------ gym API

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        seed = check_seed("seed", seed)
        options = self.task.check_reset_options(options, fresh_space=True)  # before any state changes
        previous = (self._np_random, self._np_random_seed)
        super().reset(seed=seed)
        self._done_error = None
        try:
            self.task.reset_robot(0, self.np_random, options, fresh_space=True, checked=True)
        except BaseException:
            self._np_random, self._np_random_seed = previous  # as if this reset had not happened
            raise
        self._start_trail()
        obs = self.task.obs[0].copy()
        info = robot_info(self.task, 0)
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action):
        self._check_ready()
        a = np.asarray(action)
        if a.dtype.kind not in "biuf":
            raise TypeError(f"action must hold real numbers, got dtype {a.dtype}")
        a = float32_copy(a)  # beyond float32: inf, refused below
        if a.shape != self.action_space.shape:
            raise ValueError(f"action must have shape {self.action_space.shape}, got {a.shape}")
        task = self.task
        try:
            a = task.apply_actions(a[None], owned=True)
        except ValueError:
            raise ValueError(f"action contains NaN or inf: {np.asarray(action)}") from None
        errored, messages = task.end_blown_up(task.step_physics())
        if errored[0]:
            self._done_error = messages[0]
            info = robot_info(task, 0, error=self._done_error)
            return task.obs[0].copy(), float(task.reward[0]), True, False, info
        task.observe(a, (self.np_random,))
        self._extend_trail()
        info = robot_info(task, 0)
        if self.render_mode == "human":
            self.render()
        terminated = any(info[name] for name in task.termination_names)  # an end condition holds
        truncated = bool(task.truncated()[0])
        return task.obs[0].copy(), float(task.reward[0]), terminated, truncated, info

    # ------------------------------------------------------------------ rendering

    def close(self) -> None:
        self._close_renderer()


AzimutEnv.__init__.__signature__ = front_signature(AzimutEnv.__init__)


def make_v1(**kwargs: Any) -> AzimutEnv:
    """``gymnasium.make("Azimut-v1", ...)``: this env with v1's robot and reward
    (:func:`~azimut_env.task.config.v1_kwargs`: ``imperfections="ideal"``, the null-space force priced
    in place of the antagonism), the keyword arguments otherwise as given."""
    return AzimutEnv(**v1_kwargs(kwargs))


make_v1.metadata = AzimutEnv.metadata
