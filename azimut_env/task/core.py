"""The task of ``Azimut-v2`` over N robots at once: the stages of a step, and resets.

:class:`AzimutTask` holds N robots in one :class:`~azimut_env.physics.engine.AzimutPhysics` (one pymunk
Space) and every per-robot task quantity as an array with a leading robot axis. Both envs are thin
front ends over it (:mod:`azimut_env.frontend`), so there is one copy of the task and of the
physics: :class:`~azimut_env.env.AzimutEnv` (``Azimut-v2``) is the N = 1 case,
:class:`~azimut_env.vector_env.AzimutVectorEnv` steps N robots with one call per stage.

Data flow of one control step (each stage batched over the robots, compiled where it pays):

1. :meth:`AzimutTask.apply_actions`: action → set-points (check, clip, ``params`` map; with
   ``action_latency`` through a per-robot FIFO) written to the physics' commands.
2. :meth:`AzimutTask.step_physics`: kicks due now, then ``substeps`` physics substeps (motors,
   series-elastic steering, tires, ``space.step``), which end with the robot and wheel summaries
   (:mod:`azimut_env.physics.layout`: ``RS``, ``WS``) and the blow-up codes; the front end ends
   blown-up robots' episodes (:meth:`AzimutTask.end_blown_up`).
3. :meth:`AzimutTask.observe`:
   sensors (:class:`~azimut_env.task.sensors.SensorState`: noise draws, encoders) →
   estimation (one batched IT estimate ``estimation.estimate_eta``: λ̂, μ̂) →
   track state (one compiled query, each robot on its own track: s, errors, v_ref, look-ahead;
   columns :class:`~azimut_env.tracks.TQ`) →
   termination (:mod:`azimut_env.task.termination`: off track, finished) →
   reward (:mod:`azimut_env.task.reward`: the terms from the true state) →
   pose source (the truth, or odometry + localisation fixes, :mod:`azimut_env.task.localisation`) →
   observation (:mod:`azimut_env.task.observation`: the layout table's fields, clipped) →
   stall check (termination, with its penalty).

Resets (:meth:`AzimutTask.reset_robot`) draw the episode's parameters and starting configuration
(:mod:`azimut_env.task.start_state`); both envs build their ``info`` from the table of
:mod:`azimut_env.task.info`.

Where to add things: a sensor in :mod:`azimut_env.task.sensors` (its state in ``SensorState``), a
reward term in :mod:`azimut_env.task.reward` (a row and a function), an observation field in
:mod:`azimut_env.task.observation`, an info key in :mod:`azimut_env.task.info`, an end condition in
:mod:`azimut_env.task.termination`, a setting in :class:`~azimut_env.task.config.TaskConfig`.

Randomness comes from one ``numpy.random.Generator`` per robot, passed in by the caller (the single
env's ``np_random``, or the vector env's sub-env generators). Each robot consumes its generator in
the same order whatever N is, so robot i of a batch replays a single env seeded the same way.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from azimut_env.params import RobotParams, action_from_setpoints
from azimut_env.physics.blowup import BlowUp
from azimut_env.physics.engine import AzimutPhysics, BlowUpLimits
from azimut_env.physics.layout import MS, RS, RS_POSE, RS_VEL_WORLD, WS
from azimut_env.physics.wheel_params import default_wheel_params, randomized_wheel_params
from azimut_env.task.actions import CommandPath
from azimut_env.task.compiled_step import observe_kernel, task_arrays
from azimut_env.task.config import TaskConfig, resolve_params
from azimut_env.task.lap_time import nominal_duration, reference_lap_time  # noqa: F401 (re-exported)
from azimut_env.task.localisation import OdometryPoses
from azimut_env.task.observation import (
    field_offsets,
    fill_observation,
    fill_row,
    observation_bounds,
    observation_layout,
    speed_along,
)
from azimut_env.task.reset_options import (  # noqa: F401
    RESET_OPTIONS,
    check_reset_options,
    check_track,
    coerce_obstacles,
    start_progress_on,
)
from azimut_env.task.reward import (
    OFF_TRACK,
    RewardInput,
    charge_penalty,
    current_reward_terms,
    reward_constants,
    reward_kernel,
    reward_weight_array,
)
from azimut_env.task.sensors import SensorState
from azimut_env.task.start_state import start_configuration
from azimut_env.task.termination import check_stalls, check_track_limits, episode_step_limit
from azimut_env.tracks import TQ, Track, make_track, named_track, query_tracks
from azimut_env.typed_lists import array_list, set_item
from azimut_env.validation import check_int
from estimation import estimate_eta
from estimation.estimate import estimate_eta_rows

# plain-int columns for the per-step paths (numpy indexes with an IntEnum member µs slower)
_RS_CODE, _RS_SLIP, _RS_ANTAGONISM, _RS_NULLSPACE = int(RS.CODE), int(RS.SLIP), int(RS.ANTAGONISM), int(RS.NULLSPACE)
_MS_THETA, _MS_PHI, _MS_PHIDOT = int(MS.THETA), int(MS.PHI), int(MS.PHIDOT)
_WS_BETA = int(WS.BETA)
_TQ_S, _TQ_LATERAL, _TQ_HEADING, _TQ_V_REF = int(TQ.S), int(TQ.LATERAL), int(TQ.HEADING), int(TQ.V_REF)

__all__ = ["TaskConfig", "AzimutTask", "observation_layout", "observation_bounds", "resolve_params",
           "RESET_OPTIONS", "coerce_obstacles", "nominal_duration", "reference_lap_time"]

_FINE = int(BlowUp.NONE)  # a plain int: comparing an array with the IntEnum member is ~7x slower

# ---------------------------------------------------------------------- the task over N robots


class AzimutTask:
    """N robots on their tracks in one physics Space: the state and the stages of the task.

    Args:
        params: robot parameters (shared; domain randomisation varies them per robot and reset).
        config: :class:`TaskConfig`.
        n_robots: N.
        track: a :class:`~azimut_env.tracks.Track` or a built-in name, the default of every robot.
        obstacles: static obstacles shared by all robots (robots never collide with each other).

    Per-robot arrays (leading axis N), valid after the robot's reset: ``beta_m``, ``phidot_m``,
    ``motor_m`` (measurements, (N, n)); ``lam_hat`` (N, 3), ``mu_hat``, ``qua`` (N,), ``beta_est``
    (N, n) (the IT estimate); ``s``, ``lat``, ``head``, ``v_ref``, ``v_along`` (N,), ``look``
    (N, K, 3) (track state); ``prev_action`` (N, 2n) float32; ``obs`` (N, D) float32;
    ``reward`` (N,), ``reward_terms`` (N, T) (columns: the terms of ``reward_table``), ``off_track``,
    ``finished``, ``stalled`` (N,) bool of the last step; ``steps`` (N,) steps since the robot's
    reset; ``step_limit`` (N,) the episode's step limit (``time_limit_factor``).
    """

    def __init__(self, params: RobotParams, config: TaskConfig, n_robots: int = 1, track: str | Track = "paper",
                 obstacles: Sequence = ()) -> None:
        if not isinstance(params, RobotParams):
            raise TypeError(f"params must be RobotParams, got {type(params).__name__}")
        if not isinstance(config, TaskConfig):
            raise TypeError(f"config must be TaskConfig, got {type(config).__name__}")
        self.n_robots = check_int("n_robots", n_robots, min_value=1)
        self.n = params.n
        track = check_track(track)
        obstacles = coerce_obstacles(obstacles)
        self._builtin: dict[str, Track] = {}
        self.params = params
        self.config = config
        n, N = self.n, self.n_robots
        self.physics = AzimutPhysics(params, n_robots=N, control_period=config.control_period,
                                     substeps=config.substeps, blowup=BlowUpLimits(),
                                     solver_iterations=config.solver_iterations)
        self.physics.set_obstacles(obstacles)
        self.default_obstacles = self.physics.obstacles
        self.track_spec = track
        default = track if isinstance(track, Track) else self.builtin_track(track, np.random.default_rng(0))
        self.tracks: list[Track] = [default] * N
        self._default_wp = default_wheel_params(params, N)
        K = config.lookahead_count
        self.layout = observation_layout(n, K)
        self.obs_low, self.obs_high = observation_bounds(n, K, params.limits.wheel_speed_max)
        self._obs_offsets = field_offsets(n, K)
        # the reward (azimut_env.task.reward): the table as it is now, its weights, constants and compiled kernel
        self.reward_table = current_reward_terms()
        self.reward_names = tuple(t.name for t in self.reward_table)
        self._reward_kernel = reward_kernel(self.reward_table)
        self._weights = reward_weight_array(config.reward_weights, self.reward_table)
        self._reward_constants = reward_constants(config.control_period, config.lateral_scale, config.heading_scale,
                                                  config.antagonism_cap)
        self._off_track_column = self.reward_names.index(OFF_TRACK)
        self.sensors = SensorState(params.sensors, config.control_period, N, n,
                                   wrap_angles=params.geometry.unlimited_steering)
        # the last readings, by the names the task uses (the sensors' arrays, written in place)
        self.beta_m, self.phidot_m, self.motor_m = self.sensors.beta, self.sensors.phidot, self.sensors.motor
        self.lam_hat = np.tile(np.array([0.0, 0.0, 1.0]), (N, 1))
        self.mu_hat = np.zeros(N)
        self.qua = np.ones(N)
        self.beta_est = np.zeros((N, n))
        self.s, self.lat, self.head, self.v_ref, self.v_along = (np.zeros(N) for _ in range(5))
        self.look = np.zeros((N, K, 3))
        self.track_out = np.zeros((N, len(TQ)))
        self.prev_action = np.zeros((N, 2 * n), dtype=np.float32)
        self.obs = np.zeros((N, self.obs_low.shape[0]), dtype=np.float32)
        self.reward = np.zeros(N)
        self.reward_terms = np.zeros((N, len(self.reward_table)))
        self.reward_inputs = np.zeros((N, len(RewardInput)))
        self.off_track, self.finished, self.stalled = (np.zeros(N, dtype=np.bool_) for _ in range(3))
        self.s_best = np.zeros(N)
        self.best_step = np.zeros(N, dtype=np.int64)
        #: per-robot step limit of the current episode (``time_limit_factor``; huge when off)
        self.step_limit = np.full(N, np.iinfo(np.int64).max, dtype=np.int64)
        self._limit_track: list[Track | None] = [None] * N  # the (immutable) track step_limit[i] is of
        self.steps = np.zeros(N, dtype=np.int64)
        self.ready = np.zeros(N, dtype=np.bool_)  # robot i's last reset succeeded (step needs it)
        self.track_length = np.array([t.length for t in self.tracks])
        self.track_max_speed = np.array([t.max_speed for t in self.tracks])
        self.track_closed = np.array([t.closed for t in self.tracks], dtype=np.bool_)
        self.track_rho = np.array([t.progress_radius for t in self.tracks])
        self._packs = array_list([t.packed() for t in self.tracks])
        self.kicks: list[dict | None] = [None] * N
        self._kick_step = np.full(N, -1, dtype=np.int64)  # the step of each robot's pending kick, −1: none
        self._all = np.ones(N, dtype=np.bool_)
        self.commands = CommandPath(params.limits, N, n, config.action_latency)
        # the pose source (azimut_env.task.localisation): with "odometry", the pose estimates and the
        # track state seen from them; with "true" (None) the observation reads the truth
        self.pose_source = config.pose_source
        self.odometry = (OdometryPoses(config.localisation, config.control_period, params.geometry, N, n, K)
                         if config.pose_source == "odometry" else None)
        self.compiled_step = True  #: the stages after the physics in one compiled call (observe); False: one by one
        self._compiled = None  # (TaskArrays, kernel) of azimut_env.task.compiled_step, built at the first step

    # ------------------------------------------------------------------ reset

    def check_reset_options(self, options: dict[str, Any] | None, fresh_space: bool = False) -> dict[str, Any]:
        """:func:`~azimut_env.task.reset_options.check_reset_options` for this task's robots
        (``obstacles`` only with ``fresh_space`` and a single robot)."""
        out = check_reset_options(options, self.n, own_space=fresh_space and self.n_robots == 1)
        if "start_progress" in out:  # its range is the episode's track's (a random one: at reset, closed)
            spec = out.get("track", self.track_spec)
            if isinstance(spec, Track) or spec != "random":
                track = spec if isinstance(spec, Track) else self.builtin_track(spec, None)
                out["start_progress"] = start_progress_on(track, out["start_progress"])
        return out

    def builtin_track(self, name: str, rng: np.random.Generator) -> Track:
        """The built-in track or scenario ``name`` (built once, a scenario for this robot;
        ``random`` draws a new one from ``rng``)."""
        if name == "random":
            return make_track(name, rng=rng)
        track = self._builtin.get(name)
        if track is None:
            track = self._builtin[name] = named_track(name, self.params)
        return track

    def reset_robot(self, i: int, rng: np.random.Generator, options: dict[str, Any] | None = None,
                    fresh_space: bool = False, checked: bool = False) -> None:
        """Start robot i's episode, drawing from ``rng`` (its generator) in the single env's order.

        ``fresh_space`` rebuilds the whole Space (the single env's bit-exact replay, N = 1 only);
        otherwise the robot is reset inside the running Space (its whole state is its body and
        its joint, motor and tire arrays), which replays the same episode bit for bit as long as
        no obstacle contact is involved (contacts keep pymunk solver caches).

        The options are validated first (``checked``: they come from :meth:`check_reset_options`
        already), so a refused option changes nothing. A reset that fails later (an obstacle over
        the starting footprint) restores ``rng`` and leaves robot i not ready
        (``ready[i]`` False) until a reset succeeds."""
        if not checked:
            options = self.check_reset_options(options, fresh_space)
        options = options or {}
        if fresh_space and self.n_robots != 1:
            raise ValueError("fresh_space rebuilds every robot: only for a single robot")
        state = rng.bit_generator.state
        self.ready[i] = False
        try:
            self._reset_robot(i, rng, options, fresh_space)
        except BaseException:
            rng.bit_generator.state = state
            raise
        self.ready[i] = True

    def _reset_robot(self, i: int, rng: np.random.Generator, options: dict[str, Any], fresh_space: bool) -> None:
        phys, cfg, n = self.physics, self.config, self.n
        spec = options.get("track", self.track_spec)
        track = spec if isinstance(spec, Track) else self.builtin_track(spec, rng)
        s0 = start_progress_on(track, float(options.get("start_progress", 0.0)))  # before any state changes
        if track is not self.tracks[i]:
            self.tracks[i] = track
            set_item(self._packs, i, track.packed())
        self.track_length[i] = track.length
        self.track_max_speed[i] = track.max_speed
        self.track_closed[i] = track.closed
        self.track_rho[i] = track.progress_radius
        if fresh_space:  # per-episode obstacles come with a Space of their own (check_reset_options)
            phys.rebuild(options.get("obstacles", self.default_obstacles))
        self.kicks[i] = None
        self._kick_step[i] = -1
        if "kick" in options:
            self.kicks[i] = dict(options["kick"])
            self._kick_step[i] = self.kicks[i]["step"]
        wp, mass = randomized_wheel_params(self._default_wp[i], self.params, cfg.domain_randomization, rng)
        phys.set_wheel_params(wp, robot=i)
        phys.set_chassis_mass(i, mass)
        self.sensors.draw_bias(i, rng)
        pose, beta = start_configuration(track, s0, cfg.start_noise, self.params.geometry, rng)
        phys.reset_robot(i, pose, beta)
        self.commands.reset_robot(i, phys.commands[i])  # latency: the reset set-points are held for k steps
        clash = phys.overlapping_obstacles(i)
        if clash:
            raise ValueError(f"obstacles {clash} overlap the robot's starting footprint at {np.round(pose, 3)}: "
                             "move them off the start of the track")
        self.sensors.start(i, phys.motor_state[i, :, MS.PHI])
        self.prev_action[i] = action_from_setpoints(beta, np.zeros(n), self.params.limits)
        self.steps[i] = 0
        self.reward[i] = 0.0
        self.reward_terms[i] = 0.0
        self.off_track[i] = False
        self.finished[i] = False
        self.stalled[i] = False
        self.best_step[i] = 0
        if track is not self._limit_track[i]:  # the reference lap (~0.7 ms) once per track, not per reset
            self.step_limit[i] = episode_step_limit(track, cfg.time_limit_factor, cfg.control_period,
                                                    self.params.geometry, self.params.limits)
            self._limit_track[i] = track
        sl = slice(i, i + 1)
        self.sensors.draw_noise_robot(i, rng)
        self._measure(sl)
        self._estimate(sl)
        s_, look = track.query_batch(phys.summary[sl, RS_POSE], np.array([s0]), cfg.lookahead_count,
                                     cfg.lookahead_spacing)
        self.track_out[i] = s_[0]
        self.look[i] = look[0]
        self._unpack_track(sl)
        self.s_best[i] = self.s[i]
        self.v_along[i] = speed_along(phys.summary[i, RS_VEL_WORLD], self.track_out[i, TQ.PSI])
        obs_track, obs_look, va = self.track_out[i], self.look[i], self.v_along[i]
        odo = self.odometry
        if odo is not None:  # the localisation system's generator, spawned from the robot's; the first fix now
            odo.reset_robot(i, rng, phys.summary[i, RS_POSE], self.beta_m[i])
            s_, look = track.query_batch(odo.pose[sl], np.array([s0]), cfg.lookahead_count, cfg.lookahead_spacing)
            odo.track_state[i] = s_[0]
            odo.look[i] = look[0]
            obs_track, obs_look, va = odo.track_state[i], odo.look[i], 0.0
        fill_row(self.obs[i], self._obs_offsets, self.lam_hat[i], self.mu_hat[i], self.beta_m[i], self.phidot_m[i],
                 self.motor_m[i], obs_track[TQ.LATERAL], obs_track[TQ.HEADING], va, obs_track[TQ.V_REF], obs_look,
                 self.prev_action[i], self.obs_low, self.obs_high)

    def park(self, i: int) -> None:
        """Put a blown-up robot back at a finite rest state (its episode is over; it waits for
        its reset), so that no NaN stays in the Space or in its joint, motor and tire states."""
        self.physics.reset_robot(i, (0.0, 0.0, 0.0), np.zeros(self.n))
        self.commands.reset_robot(i, self.physics.commands[i])
        self.sensors.start(i, 0.0)

    def end_blown_up(self, codes: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray, list[str]]:
        """End the episodes of the robots (among ``rows``, default all) whose physics blew up in the
        last :meth:`step_physics` (``codes`` != 0): each is parked (:meth:`park`) and its step gets
        the reward −``off_track_penalty``, no reward terms and false ``off_track``, ``finished``,
        ``stalled`` flags. Call before :meth:`observe`, which leaves these robots out. Returns the
        mask of those robots and the blow-up message of every robot (``""`` where fine)."""
        if self.n_robots == 1 and codes[0] == _FINE:  # the single env's step: no array operations
            return np.zeros(1, dtype=np.bool_), [""]
        errored = codes != _FINE
        if rows is not None:
            errored &= rows
        if not errored.any():
            return errored, [""] * self.n_robots
        messages = self.physics.check()[1]
        for i in np.flatnonzero(errored):
            self.park(int(i))
        self.reward[errored] = -self.config.off_track_penalty
        self.reward_terms[errored] = 0.0
        self.off_track[errored] = False
        self.finished[errored] = False
        self.stalled[errored] = False
        return errored, messages

    def terminated(self) -> np.ndarray:
        """(N,) bool: the last step ended the episode (off the track, finished or stalled)."""
        return self.off_track | self.finished | self.stalled

    def truncated(self) -> np.ndarray:
        """(N,) bool: the episode reached its step limit (``time_limit_factor``)."""
        return self.steps >= self.step_limit

    # ------------------------------------------------------------------ step

    def apply_actions(self, actions: np.ndarray, rows: np.ndarray | None = None, owned: bool = False) -> np.ndarray:
        """Check, clip and write the set-points of ``actions`` (N, 2n) for ``rows`` (default all),
        through the latency FIFO (:class:`~azimut_env.task.actions.CommandPath`; ``owned``: see
        there). Returns the clipped float32 copy; ``ValueError`` (changing nothing) on NaN or inf."""
        return self.commands.apply(actions, self.physics, None if rows is None or rows is self._all else rows, owned)

    def step_physics(self) -> np.ndarray:
        """Kicks due now, then one control period of physics for all robots. Returns the blow-up
        codes (N,) (:class:`~azimut_env.physics.blowup.BlowUp`, 0: fine)."""
        phys = self.physics
        if self._kick_step.max() >= 0:
            for i in np.flatnonzero(self._kick_step == self.steps):
                kick = self.kicks[i]
                phys.kick(int(i), kick["wheels"], kick["impulse"])
        phys.step()
        self.steps += 1
        return phys.summary[:, _RS_CODE]

    def observe(self, action: np.ndarray, rngs: Sequence[np.random.Generator], rows: np.ndarray | None = None) -> None:
        """After :meth:`step_physics`, for ``rows`` (default all): sensors, IT estimate, track state,
        termination, reward and observation, each robot drawing its sensor noise from its
        generator (``rngs``: a sequence of N generators, or a ``numba.typed.List`` of them, which
        draws for all robots in one compiled call with the same streams). Rows left out keep
        their previous values except the raw measurements; ``action`` (N, 2n) is what
        :meth:`apply_actions` returned. A step of every robot with the true pose as the pose
        source runs the stages in one compiled call (:mod:`.compiled_step`, the same bits) unless
        ``compiled_step`` is False."""
        all_rows = rows is None
        rows = self._all if all_rows else rows
        self.sensors.draw_noise(rngs, rows, all_rows)
        keep = None if all_rows or rows is self._all or rows.all() else ~rows
        if keep is None and self.compiled_step and self.odometry is None:  # every stage in one compiled call
            if self._compiled is None:
                self._compiled = (task_arrays(self), observe_kernel(self._reward_kernel))
            return self._compiled[1](self._compiled[0], action)
        s_prev = self.s.copy()
        if keep is not None:
            saved = [a[keep].copy() for a in (self.lam_hat, self.mu_hat, self.beta_est, self.qua, self.s, self.lat,
                                             self.head, self.v_ref, self.track_out, self.look)]
        everyone = slice(None)
        self._measure(everyone)
        self._estimate(everyone)
        self._query_tracks(s_prev)
        if keep is not None:
            for a, v in zip((self.lam_hat, self.mu_hat, self.beta_est, self.qua, self.s, self.lat, self.head,
                             self.v_ref, self.track_out, self.look), saved):
                a[keep] = v
        self._outputs(rows, action, s_prev)

    def _outputs(self, rows: np.ndarray, action: np.ndarray, s_prev: np.ndarray) -> None:
        """Termination, reward and observation of ``rows`` (the stages of :mod:`.termination`,
        :mod:`.reward` and :mod:`.observation`); ``prev_action`` takes the action."""
        cfg, summary = self.config, self.physics.summary
        check_track_limits(rows, self.track_out, self.track_length, cfg.max_lateral_error, self.off_track,
                           self.finished)
        self._reward_kernel(rows, self.track_out, s_prev, summary[:, RS_VEL_WORLD], self.track_max_speed,
                            summary[:, _RS_SLIP], summary[:, _RS_ANTAGONISM], summary[:, _RS_NULLSPACE], action,
                            self.prev_action, self.off_track, self.v_along, self.reward_inputs, self._reward_constants,
                            self._weights, self.reward_terms, self.reward)
        if rows is self._all:
            np.copyto(self.prev_action, action)
        else:
            np.copyto(self.prev_action, action, where=rows[:, None])
        obs_track, obs_look, obs_vel = self._pose_source_state(rows)
        fill_observation(rows, self._obs_offsets, self.lam_hat, self.mu_hat, self.beta_m, self.phidot_m, self.motor_m,
                         obs_track, obs_look, obs_vel, self.prev_action, self.obs_low, self.obs_high, self.obs)
        stalled = check_stalls(rows, self.s, self.s_best, self.best_step, self.steps, self.off_track, cfg.stall_time,
                               cfg.stall_distance, cfg.control_period)
        if stalled is not None:
            self.stalled[:] = stalled
            if stalled.any():
                charge_penalty(stalled, cfg.off_track_penalty, self.reward, self.reward_terms, self._off_track_column)

    # ------------------------------------------------------------------ stages

    def _measure(self, rows: slice) -> None:
        """The sensors (:class:`~azimut_env.task.sensors.SensorState`) on the physics' true states of ``rows``."""
        phys = self.physics
        ms = phys.motor_state
        self.sensors.measure(rows, phys.wheel_summary[rows, :, _WS_BETA], ms[rows, :, _MS_THETA], ms[rows, :, _MS_PHI],
                             ms[rows, :, _MS_PHIDOT])

    def _estimate(self, rows: slice) -> None:
        """The IT-estimated H state of ``rows``: ``estimation.estimate_eta`` (every robot: its
        compiled twin ``estimate_eta_rows``, writing in place, the same bits)."""
        if rows == slice(None):  # every robot: written in place, one compiled call
            estimate_eta_rows(self.beta_m, self.phidot_m, self.params.geometry, 1e-3, self.lam_hat, self.mu_hat,
                              self.beta_est, self.qua)
            return
        lam, mu, beta_est, qua = estimate_eta(self.beta_m[rows], self.phidot_m[rows], self.params.geometry,
                                              mu_tol=1e-3)
        self.lam_hat[rows] = lam
        self.mu_hat[rows] = mu
        self.beta_est[rows] = beta_est
        self.qua[rows] = qua

    def pose_estimates(self) -> np.ndarray:
        """(N, 3) each robot's pose (x, y, θ) as the observation sees it: the estimate with
        ``pose_source="odometry"``, the true pose otherwise."""
        return self.odometry.pose.copy() if self.odometry else self.physics.chassis_pose()

    def _pose_source_state(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The track state (N, 5), look-ahead (N, K, 3) and world velocity (N, 2) that the
        observation uses: the true ones, or (odometry) those of the pose estimates, which this
        advances for ``rows`` by one control period (:class:`~azimut_env.task.localisation.OdometryPoses`)."""
        odo = self.odometry
        if odo is None:
            return self.track_out, self.look, self.physics.summary[:, RS_VEL_WORLD]
        cfg = self.config
        idx = np.flatnonzero(rows)
        odo.advance(idx, self.lam_hat, self.phidot_m, self.beta_m, self.steps, self.physics.summary[:, RS_POSE])
        out, look = query_tracks(self._packs, self.track_closed, self.track_length, self.track_rho, odo.pose,
                                 odo.track_state[:, _TQ_S].copy(), cfg.lookahead_count, cfg.lookahead_spacing,
                                 n_packs=self.n_robots)
        odo.track_state[idx] = out[idx]
        odo.look[idx] = look[idx]
        return odo.track_state, odo.look, odo.vel

    def _query_tracks(self, s_hint: np.ndarray) -> None:
        """Every robot's track state, each on its own track, in one compiled call."""
        cfg = self.config
        out, look = query_tracks(self._packs, self.track_closed, self.track_length, self.track_rho,
                                 self.physics.summary[:, RS_POSE], s_hint, cfg.lookahead_count, cfg.lookahead_spacing,
                                 n_packs=self.n_robots)
        self.track_out[:] = out
        self.look[:] = look
        self._unpack_track(slice(None))

    def _unpack_track(self, rows: slice) -> None:
        out = self.track_out[rows]
        self.s[rows] = out[:, _TQ_S]
        self.lat[rows] = out[:, _TQ_LATERAL]
        self.head[rows] = out[:, _TQ_HEADING]
        self.v_ref[rows] = out[:, _TQ_V_REF]

    # ------------------------------------------------------------------ pickling

    def __getstate__(self) -> dict:  # a numba typed list and a struct of references: rebuilt
        return {**self.__dict__, "_packs": None, "_compiled": None}

    def __setstate__(self, d: dict) -> None:
        self.__dict__.update(d)
        self._packs = array_list([t.packed() for t in self.tracks])
