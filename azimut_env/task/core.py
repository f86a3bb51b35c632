"""The task of ``Azimut-v2`` over N robots at once: the stages of a step, and resets.

:class:`AzimutTask` holds N robots in one :class:`~azimut_env.physics.engine.AzimutPhysics` (one pymunk
Space) and every per-robot task quantity as an array with a leading robot axis. Both envs are thin
front ends over it (:mod:`azimut_env.frontend`), so there is one copy of the task and of the
physics: :class:`~azimut_env.env.AzimutEnv` (``Azimut-v2``) is the N = 1 case,
:class:`~azimut_env.vector_env.AzimutVectorEnv` steps N robots with one call per stage.

Data flow of one control step (each stage batched over the robots, compiled where it pays):

1. :meth:`AzimutTask.apply_actions`: action → set-points (check, clip, ``params`` map; with
   ``action_latency`` through a per-robot FIFO) written to the physics' commands.
2. :meth:`AzimutTask.step_physics`: the interval events (the kicks due now), then ``substeps`` physics substeps (motors,
   series-elastic steering, tires, ``space.step``), which end with the robot and wheel summaries
   (:mod:`azimut_env.physics.layout`: ``RS``, ``WS``) and the blow-up codes; the front end ends
   blown-up robots' episodes (:meth:`AzimutTask.end_blown_up`).
3. :meth:`AzimutTask.observe`: each robot's sensor noise drawn from its generator, then the step
   pipeline (:mod:`azimut_env.task.pipeline`: sense → estimate → odometry → track → terminate →
   reward → remember_action → observe, one function per stage in the module of its concern, over
   the task's arrays held in one struct, :mod:`azimut_env.task.arrays`), for every robot or a
   mask of them, compiled (``jit``) or as plain Python (the reference).

Resets (:meth:`AzimutTask.reset_robot`) draw the episode through the reset events
(:mod:`azimut_env.task.events`: track, kick, domain randomisation, sensor bias, starting
configuration, noise), then run the reset pipeline (the same stages: sense → estimate →
odometry → track → start_episode → observe) for the robot; both envs build their ``info`` from
the table of :mod:`azimut_env.task.info`.

Where to add things: a sensor in :mod:`azimut_env.task.sensors` (a stage in ``SENSOR_STAGES``, its
readings a row of :data:`azimut_env.task.arrays.FIELDS`), a reward term in
:mod:`azimut_env.task.reward`, an observation field in :mod:`azimut_env.task.observation`, an end
condition in :mod:`azimut_env.task.termination` (each a function and a row of its table), an
info key in :mod:`azimut_env.task.info`, a setting in :class:`~azimut_env.task.config.TaskConfig`.

Randomness comes from one ``numpy.random.Generator`` per robot, passed in by the caller (the single
env's ``np_random``, or the vector env's sub-env generators). Each robot consumes its generator in
the same order whatever N is, so robot i of a batch replays a single env seeded the same way.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from azimut_env.params import RobotParams
from azimut_env.physics.blowup import BlowUp
from azimut_env.physics.engine import AzimutPhysics, BlowUpLimits
from azimut_env.physics.layout import RS
from azimut_env.physics.wheel_params import default_wheel_params
from azimut_env.task import events, observation, termination
from azimut_env.task.actions import CommandPath
from azimut_env.task.arrays import allocate, task_arrays
from azimut_env.task.config import TaskConfig, resolve_params
from azimut_env.task.events import Episode
from azimut_env.task.lap_time import nominal_duration, reference_lap_time  # noqa: F401 (re-exported)
from azimut_env.task.localisation import OdometryPoses
from azimut_env.task.observation import field_offsets, observation_bounds, observation_layout
from azimut_env.task.pipeline import Pipeline, reset_stages, step_stages
from azimut_env.task.reset_options import (  # noqa: F401
    RESET_OPTIONS,
    check_reset_options,
    check_track,
    coerce_obstacles,
    start_progress_on,
)
from azimut_env.task.reward import RewardInput, current_reward_terms, reward_constants, reward_weight_array
from azimut_env.task.sensors import SensorState
from azimut_env.task.termination import episode_step_limit
from azimut_env.tracks import Track, make_track, named_track
from azimut_env.typed_lists import array_list, set_item
from azimut_env.validation import check_int

# plain-int columns for the per-step paths (numpy indexes with an IntEnum member µs slower)
_RS_CODE = int(RS.CODE)

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
    ``reward`` (N,), ``reward_terms`` (N, T) (columns: the terms of ``reward_table``), ``ended``
    (N, E) bool (columns: the end conditions of ``termination_table``) of the last step; ``steps``
    (N,) steps since the robot's reset; ``step_limit`` (N,) the episode's step limit
    (``time_limit_factor``): the rows of :data:`azimut_env.task.arrays.FIELDS` the task owns.
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
                                     solver_iterations=config.solver_iterations, num_threads=config.num_threads)
        self.physics.set_obstacles(obstacles)
        self.default_obstacles = self.physics.obstacles
        self.track_spec = track
        default = track if isinstance(track, Track) else self.builtin_track(track, np.random.default_rng(0))
        self.tracks: list[Track] = [default] * N
        self.default_wheel_params = default_wheel_params(params, N)
        self._packs = array_list([t.packed() for t in self.tracks])
        # the tables as they are now (a test may extend one): the observation, termination and reward
        K = config.lookahead_count
        self.observation_fields = observation.OBSERVATION_FIELDS
        self.layout = observation_layout(n, K)
        self.obs_low, self.obs_high = observation_bounds(n, K, params.limits.wheel_speed_max)
        self.obs_offsets = field_offsets(n, K)
        self.termination_table = termination.TERMINATION_TERMS
        self.termination_names = tuple(t.name for t in self.termination_table)
        self.reward_table = current_reward_terms()
        self.reward_names = tuple(t.name for t in self.reward_table)
        self.reward_input_count = len(RewardInput)
        self.weight_values = reward_weight_array(config.reward_weights, self.reward_table)
        self.reward_constant_values = reward_constants(config.control_period, config.lateral_scale,
                                                       config.heading_scale, config.antagonism_cap)
        self.sensors = SensorState(params.sensors, config.control_period, N, n,
                                   wrap_angles=params.geometry.unlimited_steering)
        self.sensors.num_threads = self.physics.num_threads
        # the last readings, by the names the task uses (the sensors' arrays, written in place)
        self.beta_m, self.phidot_m, self.motor_m = self.sensors.beta, self.sensors.phidot, self.sensors.motor
        # the pose source (azimut_env.task.localisation): with "odometry", the pose estimates and the
        # track state seen from them; with "true" (None) the observation reads the truth
        self.pose_source = config.pose_source
        self.odometry = (OdometryPoses(config.localisation, config.control_period, params.geometry, N, n, K)
                         if config.pose_source == "odometry" else None)
        allocate(self)  # the per-robot arrays of azimut_env.task.arrays.FIELDS, as attributes
        #: per-robot step limit of the current episode (``time_limit_factor``; huge when off)
        self.step_limit = np.full(N, np.iinfo(np.int64).max, dtype=np.int64)
        self._limit_track: list[Track | None] = [None] * N  # the (immutable) track step_limit[i] is of
        self.ready = np.zeros(N, dtype=np.bool_)  # robot i's last reset succeeded (step needs it)
        self.kicks: list[dict | None] = [None] * N
        self.kick_step = np.full(N, -1, dtype=np.int64)  # the step of each robot's pending kick, −1: none
        self._all = np.ones(N, dtype=np.bool_)
        self._one = np.zeros(N, dtype=np.bool_)  # the row mask of a reset
        self.commands = CommandPath(params.limits, N, n, config.action_latency)
        #: the pipeline's stages compiled (False: as plain Python, the reference path)
        self.jit = True
        self._pipelines: tuple[Pipeline, Pipeline] | None = None  # (step, reset), built at first use

    def pipelines(self) -> tuple[Pipeline, Pipeline]:
        """The (step, reset) :class:`~azimut_env.task.pipeline.Pipeline` of this task (built at
        the first call after construction, unpickling or a change of ``jit``)."""
        p = self._pipelines
        if p is None or p[0].jit != self.jit:
            ta, ns = task_arrays(self, self.jit)
            threads = self.physics.num_threads
            N = self.n_robots
            p = self._pipelines = (Pipeline(step_stages(self, self.jit), ta, ns, self.jit, threads, N),
                                   Pipeline(reset_stages(self, self.jit), ta, ns, self.jit, threads, N))
        return p

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
        """The reset events (:data:`~azimut_env.task.events.RESET_EVENTS`, in the order of their
        draws from ``rng``), then the reset pipeline for robot i
        (:func:`~azimut_env.task.pipeline.reset_stages`)."""
        episode = Episode(options, fresh_space)
        for event in events.RESET_EVENTS:
            event.function(self, i, rng, episode)
        rows = self._one
        rows[i] = True
        try:
            self.pipelines()[1](rows, self.prev_action)
        finally:
            rows[i] = False

    def set_track(self, i: int, track: Track) -> None:
        """Robot i on ``track``: its packed rows, its constants and its step limit."""
        if track is not self.tracks[i]:
            self.tracks[i] = track
            set_item(self._packs, i, track.packed())
        self.track_length[i] = track.length
        self.track_max_speed[i] = track.max_speed
        self.track_closed[i] = track.closed
        self.track_rho[i] = track.progress_radius
        if track is not self._limit_track[i]:  # the reference lap (~0.7 ms) once per track, not per reset
            cfg = self.config
            self.step_limit[i] = episode_step_limit(track, cfg.time_limit_factor, cfg.control_period,
                                                    self.params.geometry, self.params.limits)
            self._limit_track[i] = track

    def park(self, i: int) -> None:
        """Put a blown-up robot back at a finite rest state (its episode is over; it waits for
        its reset), so that no NaN stays in the Space or in its joint, motor and tire states."""
        self.physics.reset_robot(i, (0.0, 0.0, 0.0), np.zeros(self.n))
        self.commands.reset_robot(i, self.physics.commands[i])
        self.sensors.start(i, 0.0)

    def end_blown_up(self, codes: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray, list[str]]:
        """End the episodes of the robots (among ``rows``, default all) whose physics blew up in the
        last :meth:`step_physics` (``codes`` != 0): each is parked (:meth:`park`) and its step gets
        the reward −``off_track_penalty``, no reward terms and no end condition's flag. Call
        before :meth:`observe`, which leaves these robots out. Returns the
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
        self.ended[errored] = False
        self.failed[errored] = False
        return errored, messages

    def terminated(self) -> np.ndarray:
        """(N,) bool: the last step ended the episode (an end condition of ``termination_table`` holds)."""
        return self.ended.any(axis=1)

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
        for event in events.INTERVAL_EVENTS:
            event.function(self)
        phys.step()
        self.steps += 1
        return phys.summary[:, _RS_CODE]

    def observe(self, action: np.ndarray, rngs: Sequence[np.random.Generator], rows: np.ndarray | None = None) -> None:
        """After :meth:`step_physics`, for ``rows`` (default all): the step pipeline
        (:func:`~azimut_env.task.pipeline.step_stages`: sensors, IT estimate, odometry, track
        state, termination, reward, observation), each robot drawing its sensor noise from its
        generator first (``rngs``: a sequence of N generators, or a ``numba.typed.List`` of them,
        which draws for all robots in one compiled call with the same streams). Rows left out keep
        their previous values; ``action`` (N, 2n) is what :meth:`apply_actions` returned."""
        all_rows = rows is None
        rows = self._all if all_rows else rows
        self.sensors.draw_noise(rngs, rows, all_rows)
        self.pipelines()[0](rows, action)

    def pose_estimates(self) -> np.ndarray:
        """(N, 3) each robot's pose (x, y, θ) as the observation sees it: the estimate with
        ``pose_source="odometry"``, the true pose otherwise."""
        return self.odometry.pose.copy() if self.odometry else self.physics.chassis_pose()

    # ------------------------------------------------------------------ pickling

    def __getstate__(self) -> dict:  # a numba typed list and a struct of references: rebuilt
        return {**self.__dict__, "_packs": None, "_pipelines": None}

    def __setstate__(self, d: dict) -> None:
        self.__dict__.update(d)
        self._packs = array_list([t.packed() for t in self.tracks])
