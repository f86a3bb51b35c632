"""The task of ``Azimut-v1`` over N robots at once: observation, reward, termination, resets.

:class:`AzimutTask` holds N robots in one :class:`~azimut_env.physics.AzimutPhysics` (one pymunk
Space) and every per-robot task quantity as an array with a leading robot axis. Both envs are thin
front ends over it, so there is one copy of the task and of the physics:

* :class:`~azimut_env.env.AzimutEnv` (``Azimut-v1``) is the N = 1 case;
* :class:`~azimut_env.vector_env.AzimutVectorEnv` steps N robots with one call per stage.

One control step is :meth:`AzimutTask.apply_actions` (a compiled check/clip/write of all
actions), :meth:`AzimutTask.step_physics` (per substep one batched read, the compiled force model
over all wheels, one batched write, one ``space.step``) and :meth:`AzimutTask.observe` (a compiled
sensor model over all wheels, one batched IT estimate with ``estimation.estimate_eta``, one
compiled track query for all robots, each on its own track, and one compiled reward and
observation fill for all robots).

Randomness comes from one ``numpy.random.Generator`` per robot, passed in by the caller (the single
env's ``np_random``, or the vector env's sub-env generators). Each robot consumes its generator in
the same order whatever N is, so robot i of a batch replays a single env seeded the same way.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from numba import njit
from numba.typed import List as NumbaList

from estimation import estimate_eta, eta_from_twist, integrate_pose, odometry_twist, steering_from_lambda

from .blowup import BlowUp
from .config import TaskConfig, resolve_params
from .params import RobotParams, _setpoints_row, action_from_setpoints
from .physics import AzimutPhysics, BlowUpLimits, Obstacle, default_wheel_params
from .physics_layout import CMD, MS, RS, RS_POSE, RS_TWIST_BODY, RS_VEL_WORLD, WP, WS, WS_FORCE
from .sensors import _measure_kernel
from .lap_time import nominal_duration, reference_lap_time  # noqa: F401 (nominal_duration: re-exported)
from .tracks import TRACK_NAMES, Track, make_track, query_tracks
from .validation import check_finite, check_index_list, check_int

__all__ = ["TaskConfig", "AzimutTask", "observation_layout", "observation_bounds", "resolve_params",
           "REWARD_TERMS", "RESET_OPTIONS", "coerce_obstacles", "nominal_duration", "reference_lap_time"]

#: the reward terms, in the order of the columns of ``AzimutTask.reward_terms``
REWARD_TERMS = ("progress", "lateral", "heading", "overspeed", "slip", "internal_force", "action_rate", "off_track")
#: the keys ``reset(options=...)`` accepts
RESET_OPTIONS = frozenset({"track", "obstacles", "kick", "start_progress"})


def observation_layout(n: int, lookahead_count: int) -> dict[str, slice]:
    """Names and slices of the observation vector for n wheels and K look-ahead points (see
    :class:`~azimut_env.env.AzimutEnv`, "Observation Space")."""
    sizes = [("lambda_hat", 3), ("mu_hat", 1), ("beta", n), ("phidot", n), ("motor_angle", n),
             ("lateral_error", 1), ("heading_error", 1), ("speed_along", 1), ("speed_ref", 1),
             ("lookahead", 3 * lookahead_count), ("prev_action", 2 * n)]
    out, i = {}, 0
    for name, size in sizes:
        out[name] = slice(i, i + size)
        i += size
    return out


def observation_bounds(n: int, lookahead_count: int, wheel_speed_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Finite (low, high) float32 bounds of the observation vector (the Box limits)."""
    layout = observation_layout(n, lookahead_count)
    size = max(s.stop for s in layout.values())
    lo, hi = np.zeros(size), np.zeros(size)
    bounds = dict(lambda_hat=1.0, mu_hat=10.0, beta=math.pi, phidot=3 * wheel_speed_max, motor_angle=math.pi,
                  lateral_error=10.0, heading_error=math.pi, speed_along=10.0, speed_ref=10.0,
                  lookahead=20.0, prev_action=1.0)
    for name, sl in layout.items():
        lo[sl], hi[sl] = -bounds[name], bounds[name]
    la = layout["lookahead"]
    hi_la = hi[la].reshape(-1, 3)
    hi_la[:, 2] = math.pi
    hi[la] = hi_la.ravel()
    lo[la] = -hi[la]
    lo[layout["speed_ref"]] = 0.0
    return lo.astype(np.float32), hi.astype(np.float32)


def coerce_obstacles(obstacles: Any, what: str = "obstacles") -> tuple[Obstacle, ...]:
    """A sequence of obstacle specs (``Obstacle``, ``(x, y, radius)``, a dict of its fields or a
    vertex list) as a tuple of :class:`~azimut_env.physics.Obstacle`; ``ValueError`` otherwise."""
    if obstacles is None:
        return ()
    if isinstance(obstacles, (str, bytes, dict, Obstacle)) or not hasattr(obstacles, "__iter__"):
        raise TypeError(f"{what} must be a sequence of obstacles, got {type(obstacles).__name__}")
    try:
        return tuple(Obstacle.coerce(o) for o in obstacles)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{what}: {exc}") from None


# ---------------------------------------------------------------------- compiled stages


@njit(cache=True)
def _apply_actions_kernel(a, cmd, rows, steer_min, steer_max, wheel_speed_max):
    """Actions a (N, 2n) float32 for the robots where ``rows`` is True: return the first row with
    NaN/inf (writing nothing), else clip them to [−1, 1] in place and write the set-points of
    ``params.setpoints_from_action`` into cmd (N, n, 2) and return −1."""
    n = cmd.shape[1]
    for i in range(a.shape[0]):
        if rows[i]:
            for j in range(a.shape[1]):
                if not math.isfinite(a[i, j]):
                    return i
    for i in range(a.shape[0]):
        if rows[i]:
            for j in range(a.shape[1]):
                a[i, j] = min(max(a[i, j], -1.0), 1.0)
            _setpoints_row(a, i, n, steer_min, steer_max, wheel_speed_max, cmd)
    return -1


@njit(cache=True)
def _shift_fifo_kernel(fifo, new, cmd, rows):
    """Command latency, for the robots where ``rows`` is True: the oldest set-points fifo[i, 0]
    go to cmd[i], the queue (N, k, n, 2) moves up by one and new[i] enters at its end."""
    k = fifo.shape[1]
    for i in range(fifo.shape[0]):
        if rows[i]:
            cmd[i] = fifo[i, 0]
            for j in range(k - 1):
                fifo[i, j] = fifo[i, j + 1]
            fifo[i, k - 1] = new[i]


@njit(cache=True)
def _draw_normals_kernel(rngs, rows, out):
    """out[i] (3, n) = rngs[i].standard_normal((3, n)) for the rows where ``rows`` is True: the
    same numbers, in the same order, as NumPy's (numba's Generator runs NumPy's algorithms on the
    same bit generator state)."""
    for i in range(len(rngs)):
        if rows[i]:
            rng = rngs[i]
            for j in range(out.shape[1]):
                for k in range(out.shape[2]):
                    out[i, j, k] = rng.standard_normal()


@njit(cache=True)
def _reward_obs_kernel(rows, summ, track_out, look, obs_track, obs_look, obs_vel, s_prev, lengths, max_speeds, lam,
                       mu, beta, phidot, motor, action, prev_action, weights, scales, dt, max_lat, lo, hi, v_along,
                       reward, terms, off_track, finished, obs):
    """For the robots where ``rows`` is True: speed along the path, reward terms and reward,
    off-track and finished flags, and the observation (layout of :func:`observation_layout`;
    non-finite values become 0, all clipped to [lo, hi]); prev_action takes the action.

    The terms (columns of ``terms``, :data:`REWARD_TERMS`; the env docstring has their
    magnitudes): progress w·clip(Δs, −v_max dt, v_ref dt)/(v_max dt) (backward jumps of the
    projection clipped to one step at full speed); lateral and heading −w·(1 − exp(−|e|/scale));
    overspeed −w·max(0, v_along − v_ref)/v_max; slip −min(w·P_slip, cap); internal force
    −min(w·F_int, cap); action rate −w‖a − a_prev‖²; off-track −penalty.

    The reward and flags use the true track state (``track_out``, ``summ``); the observation's
    tracking errors, speeds and look-ahead use ``obs_track`` (N, 5), ``obs_look`` (N, K, 3) and the
    world velocity ``obs_vel`` (N, 2) of the pose source (the same arrays when it is the truth)."""
    n = beta.shape[1]
    for i in range(rows.shape[0]):
        if not rows[i]:
            continue
        s = track_out[i, 0]
        lat = track_out[i, 1]
        head = track_out[i, 2]
        v_ref = track_out[i, 3]
        psi = track_out[i, 4]
        va = summ[i, RS.VX] * math.cos(psi) + summ[i, RS.VY] * math.sin(psi)
        v_along[i] = va
        off = abs(lat) > max_lat
        off_track[i] = off
        finished[i] = s >= lengths[i] - 1e-6
        v_max = max(max_speeds[i], 1e-3)
        da2 = 0.0
        for j in range(action.shape[1]):
            d = action[i, j] - prev_action[i, j]  # float32, as the actions
            da2 += d * d
        ds = min(max(s - s_prev[i], -v_max * dt), v_ref * dt + 1e-3 * dt)
        t0 = weights[0] * ds / (v_max * dt)
        t1 = -weights[1] * (1.0 - math.exp(-abs(lat) / scales[0]))
        t2 = -weights[2] * (1.0 - math.exp(-abs(head) / scales[1]))
        t3 = -weights[3] * max(0.0, va - v_ref) / v_max
        t4 = -min(weights[4] * summ[i, RS.SLIP], scales[2])
        t5 = -min(weights[5] * summ[i, RS.INTERNAL], scales[2])
        t6 = -weights[6] * da2
        t7 = -weights[7] if off else 0.0
        terms[i, 0] = t0
        terms[i, 1] = t1
        terms[i, 2] = t2
        terms[i, 3] = t3
        terms[i, 4] = t4
        terms[i, 5] = t5
        terms[i, 6] = t6
        terms[i, 7] = t7
        reward[i] = 0.0 + t0 + t1 + t2 + t3 + t4 + t5 + t6 + t7
        for j in range(action.shape[1]):
            prev_action[i, j] = action[i, j]
        psi_o = obs_track[i, 4]
        va_o = obs_vel[i, 0] * math.cos(psi_o) + obs_vel[i, 1] * math.sin(psi_o)
        _fill_obs_row(obs[i], lam[i], mu[i], beta[i], phidot[i], motor[i], obs_track[i, 1], obs_track[i, 2], va_o,
                      obs_track[i, 3], obs_look[i], prev_action[i], lo, hi, n)


@njit(cache=True)
def _fill_obs_row(obs, lam, mu, beta, phidot, motor, lat, head, v_along, v_ref, look, prev_action, lo, hi, n):
    """One observation row in the layout of :func:`observation_layout`."""
    i = 0
    for j in range(3):
        obs[i] = lam[j]
        i += 1
    obs[i] = mu
    i += 1
    for j in range(n):
        obs[i] = beta[j]
        obs[i + n] = phidot[j]
        obs[i + 2 * n] = motor[j]
        i += 1
    i += 2 * n
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
    ``reward`` (N,), ``reward_terms`` (N, 8) (columns :data:`REWARD_TERMS`), ``off_track``,
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
        self.params = params
        track = self.check_track(track)
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
        self._weights = np.array([config.weights[k] for k in REWARD_TERMS])
        self._scales = config.reward_scales
        lim = params.limits
        self._lim = (float(lim.steer_min), float(lim.steer_max), float(lim.wheel_speed_max))
        sp = params.sensors
        self._sensor_args = (float(config.control_period), sp.steer_noise, sp.motor_noise, sp.steer_resolution,
                             int(sp.wheel_cpr), sp.wheel_speed_noise)
        self.beta_m = np.zeros((N, n))
        self.phidot_m = np.zeros((N, n))
        self.motor_m = np.zeros((N, n))
        self.lam_hat = np.tile(np.array([0.0, 0.0, 1.0]), (N, 1))
        self.mu_hat = np.zeros(N)
        self.qua = np.ones(N)
        self.beta_est = np.zeros((N, n))
        self.s = np.zeros(N)
        self.lat = np.zeros(N)
        self.head = np.zeros(N)
        self.v_ref = np.zeros(N)
        self.v_along = np.zeros(N)
        self.look = np.zeros((N, K, 3))
        self.track_out = np.zeros((N, 5))
        self.prev_action = np.zeros((N, 2 * n), dtype=np.float32)
        self.obs = np.zeros((N, self.obs_low.shape[0]), dtype=np.float32)
        self.reward = np.zeros(N)
        self.reward_terms = np.zeros((N, len(REWARD_TERMS)))
        self.off_track = np.zeros(N, dtype=np.bool_)
        self.finished = np.zeros(N, dtype=np.bool_)
        self.stalled = np.zeros(N, dtype=np.bool_)
        self.s_best = np.zeros(N)
        self.best_step = np.zeros(N, dtype=np.int64)
        #: per-robot step limit of the current episode (``time_limit_factor``; huge when off)
        self.step_limit = np.full(N, np.iinfo(np.int64).max, dtype=np.int64)
        self.steps = np.zeros(N, dtype=np.int64)
        self.ready = np.zeros(N, dtype=np.bool_)  # robot i's last reset succeeded (step needs it)
        self.steer_bias = np.zeros((N, n))
        self.phi_prev = np.zeros((N, n))
        self.track_length = np.array([t.length for t in self.tracks])
        self.track_max_speed = np.array([t.max_speed for t in self.tracks])
        self.track_closed = np.array([t.closed for t in self.tracks], dtype=np.bool_)
        self.track_rho = np.array([t.progress_radius for t in self.tracks])
        self._packs = NumbaList([t.packed() for t in self.tracks])
        self.kicks: list[dict | None] = [None] * N
        self._kick_step = np.full(N, -1, dtype=np.int64)  # the step of each robot's pending kick, −1: none
        self._all = np.ones(N, dtype=np.bool_)
        self._normals = np.zeros((N, 3, n))
        # command latency: set-points waiting to be applied, oldest first (N, k, n, 2)
        self._cmd_fifo = np.zeros((N, config.action_latency, n, len(CMD)))
        self._cmd_new = np.zeros((N, n, len(CMD)))
        self._cmd_out = np.zeros((N, n, len(CMD)))  # the set-points leaving the FIFOs
        self._meas = np.empty((N, 3, n))
        # the pose source (azimut_env.localisation): with "odometry", the pose estimate and the
        # track state seen from it; with "true" these stay unused and the observation reads the truth
        self.pose_source = config.pose_source
        self._odometry = config.pose_source == "odometry"
        self._fix_every = config.localisation.fix_every(config.control_period)
        loc = config.localisation
        self._fix_sigma = np.array([loc.fix_noise_xy_m, loc.fix_noise_xy_m, loc.fix_noise_theta_rad])
        self.pose_est = np.zeros((N, 3))
        self.beta_m_prev = np.zeros((N, n))
        self.track_out_est = np.zeros((N, 5))
        self.look_est = np.zeros((N, K, 3))
        self.vel_est = np.zeros((N, 2))
        self._loc_rngs: list[np.random.Generator | None] = [None] * N

    # ------------------------------------------------------------------ reset

    def check_reset_options(self, options: dict[str, Any] | None, fresh_space: bool = False) -> dict[str, Any]:
        """Validate ``reset`` options without touching any state; return them normalised.

        Keys (all optional): ``track`` (a :class:`Track` or a built-in name), ``obstacles`` (only
        with ``fresh_space``: a Space of one's own), ``kick`` (a dict with ``step`` (int >= 0),
        ``wheels`` (distinct wheel indices, ints in 0..n−1), ``impulse`` [N·m·s], finite) and
        ``start_progress`` [m], finite. Raises ``ValueError``/``TypeError`` on anything else."""
        if options is None:
            return {}
        if not isinstance(options, dict):
            raise TypeError(f"reset options must be a dict or None, got {type(options).__name__}")
        unknown = set(options) - RESET_OPTIONS
        if unknown:
            raise ValueError(f"unknown reset options {sorted(map(str, unknown))}; valid: {sorted(RESET_OPTIONS)}")
        out: dict[str, Any] = {}
        if "track" in options:
            out["track"] = self.check_track(options["track"], "options['track']")
        if "obstacles" in options:
            if not fresh_space or self.n_robots != 1:
                raise ValueError("per-episode obstacles need a Space of their own: the vector env shares its "
                                 "obstacles between sub-envs (pass obstacles= to the constructor)")
            out["obstacles"] = coerce_obstacles(options["obstacles"], "options['obstacles']")
        if "kick" in options:
            out["kick"] = self.check_kick(options["kick"])
        if "start_progress" in options:
            out["start_progress"] = check_finite("options['start_progress']", options["start_progress"])
        return out

    def check_kick(self, kick: Any) -> dict[str, Any]:
        """A validated ``kick`` option: ``{"step": int >= 0, "wheels": [int], "impulse": float}``."""
        if not isinstance(kick, dict):
            raise TypeError(f"options['kick'] must be a dict, got {type(kick).__name__}")
        extra = set(kick) - {"step", "wheels", "impulse"}
        if extra:
            raise ValueError(f"options['kick'] takes keys 'step', 'wheels', 'impulse', got {sorted(map(str, extra))}")
        return dict(step=check_int("options['kick']['step']", kick.get("step", 0), min_value=0),
                    wheels=check_index_list("options['kick']['wheels']", kick.get("wheels", range(self.n)), self.n),
                    impulse=check_finite("options['kick']['impulse']", kick.get("impulse", 0.5)))

    def check_track(self, track: Any, what: str = "track") -> str | Track:
        """A built-in track name or a :class:`Track` that fits in the simulated world."""
        if isinstance(track, str):
            if track not in TRACK_NAMES:
                raise ValueError(f"{what}: unknown track {track!r}; choose from {list(TRACK_NAMES)} or pass a Track")
            return track
        if not isinstance(track, Track):
            raise TypeError(f"{what} must be a Track or a built-in name, got {type(track).__name__}")
        reach, world = float(np.max(np.abs(track.xy))), 0.9 * BlowUpLimits().position
        if reach > world:
            raise ValueError(f"{what}: the track reaches {reach:.3g} m from the origin; the simulated world ends at "
                             f"|x|, |y| = {BlowUpLimits().position:g} m (BlowUpLimits.position): translate it "
                             f"within {world:g} m")
        return track

    def builtin_track(self, name: str, rng: np.random.Generator) -> Track:
        """The built-in track ``name`` (built once; ``random`` draws a new one from ``rng``)."""
        if name == "random":
            return make_track(name, rng=rng)
        track = self._builtin.get(name)
        if track is None:
            track = self._builtin[name] = make_track(name)
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
        if track is not self.tracks[i]:
            self.tracks[i] = track
            self._packs[i] = track.packed()
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
        self._randomize(i, rng)
        sb = self.params.sensors.steer_bias
        self.steer_bias[i] = rng.normal(0.0, sb, size=n) if sb > 0 else 0.0
        s0 = float(options.get("start_progress", 0.0))
        ref = track.sample(s0)
        noise = cfg.start_noise
        pose = ref[:3] + rng.uniform(-noise, noise, size=3)
        beta = self.reference_beta(track, s0, pose[2]) + rng.uniform(-noise, noise, size=n)
        geom = self.params.geometry
        beta = np.clip(beta, geom.steer_min + 1e-6, geom.steer_max)
        phys.reset_robot(i, pose, beta)
        self._cmd_fifo[i] = phys.commands[i]  # latency: the reset set-points are held for k steps
        clash = phys.overlapping_obstacles(i)
        if clash:
            raise ValueError(f"obstacles {clash} overlap the robot's starting footprint at {np.round(pose, 3)}: "
                             "move them off the start of the track")
        self.phi_prev[i] = phys.motor_state[i, :, MS.PHI]
        self.prev_action[i] = action_from_setpoints(beta, np.zeros(n), self.params.limits)
        self.steps[i] = 0
        self.reward[i] = 0.0
        self.reward_terms[i] = 0.0
        self.off_track[i] = False
        self.finished[i] = False
        self.stalled[i] = False
        self.best_step[i] = 0
        factor = self.config.time_limit_factor
        if factor > 0:
            steps = factor * reference_lap_time(track, self.params.geometry, self.params.limits) / self.config.control_period
        else:
            steps = 0.0
        big = np.iinfo(np.int64).max  # no limit (factor 0), or one beyond any run (a huge factor)
        self.step_limit[i] = int(math.ceil(steps)) if 0 < steps < 9e18 else big
        sl = slice(i, i + 1)
        rng.standard_normal(out=self._normals[i])
        self._measure(sl)
        self._estimate(sl)
        s_, look = track.query_batch(phys.summary[sl, RS_POSE], np.array([s0]), cfg.lookahead_count, cfg.lookahead_spacing)
        self.track_out[i] = s_[0]
        self.look[i] = look[0]
        self._unpack_track(sl)
        self.s_best[i] = self.s[i]
        psi = self.track_out[i, 4]
        summ = phys.summary[i]
        self.v_along[i] = summ[RS.VX] * math.cos(psi) + summ[RS.VY] * math.sin(psi)
        obs_track, obs_look, va = self.track_out[i], self.look[i], self.v_along[i]
        if self._odometry:
            # the localisation system's generator, spawned from the robot's; the first fix now
            self._loc_rngs[i] = np.random.default_rng(int(rng.integers(0, 2**63 - 1)))
            self.beta_m_prev[i] = self.beta_m[i]
            self.pose_est[i] = self._fix(i)
            self.vel_est[i] = 0.0
            s_, look = track.query_batch(self.pose_est[sl], np.array([s0]), cfg.lookahead_count, cfg.lookahead_spacing)
            self.track_out_est[i] = s_[0]
            self.look_est[i] = look[0]
            obs_track, obs_look, va = self.track_out_est[i], self.look_est[i], 0.0
        _fill_obs_row(self.obs[i], self.lam_hat[i], self.mu_hat[i], self.beta_m[i], self.phidot_m[i],
                      self.motor_m[i], obs_track[1], obs_track[2], va, obs_track[3], obs_look,
                      self.prev_action[i], self.obs_low, self.obs_high, n)

    def reference_beta(self, track: Track, s: float, theta: float) -> np.ndarray:
        """Steering angles of the reference motion at progress s (direction only)."""
        tw = track.reference_twist_body(s, theta, speed=1.0)
        if np.linalg.norm(tw) < 1e-9:
            return np.zeros(self.n)
        lam, _ = eta_from_twist(tw)
        return steering_from_lambda(lam, self.params.geometry)

    def _randomize(self, i: int, rng: np.random.Generator) -> None:
        """Robot i's parameters for this episode: the defaults, scaled by factors drawn from
        [1 − d, 1 + d] with d = ``domain_randomization`` (friction, spring, damper, chassis mass,
        tire stiffness, contact patch size). Everything that depends on the mass follows it: the
        body's mass and moment and the wheels' normal loads (``AzimutPhysics.set_chassis_mass``).

        The tire's cornering and longitudinal stiffness coefficients and its relaxation lengths
        take the same factor: σ = C/k with k the carcass (contact) stiffness (Pacejka 2012, Ch. 7),
        so a stiffer or softer tread changes the slip stiffness and the distance to build force,
        and leaves the contact stiffness k, hence the stability budget, as it is. The contact
        half-length scales the aligning trail, the scrub torque limit and the twist stiffness."""
        phys = self.physics
        wp = self._default_wp[i].copy()
        d = self.config.domain_randomization
        mass = self.params.chassis.mass
        if d > 0:
            f = rng.uniform(1 - d, 1 + d, size=6)
            wp[..., WP.MU] *= f[0]
            wp[..., WP.K_S] *= f[1]
            wp[..., WP.C_S] *= f[2]
            mass *= f[3]
            for col in (WP.C_KAPPA, WP.C_ALPHA, WP.SIGMA_LONG, WP.SIGMA_LAT):
                wp[..., col] *= f[4]
            wp[..., WP.HALF_LEN] *= f[5]
        phys.set_wheel_params(wp, robot=i)
        phys.set_chassis_mass(i, mass)

    def park(self, i: int) -> None:
        """Put a blown-up robot back at a finite rest state (its episode is over; it waits for
        its reset), so that no NaN stays in the Space or in its joint, motor and tire states."""
        self.physics.reset_robot(i, (0.0, 0.0, 0.0), np.zeros(self.n))
        self._cmd_fifo[i] = self.physics.commands[i]
        self.phi_prev[i] = 0.0

    def end_blown_up(self, codes: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray, list[str]]:
        """End the episodes of the robots (among ``rows``, default all) whose physics blew up in the
        last :meth:`step_physics` (``codes`` != 0): each is parked (:meth:`park`) and its step gets
        the reward −``off_track_penalty``, no reward terms and false ``off_track``, ``finished``,
        ``stalled`` flags. Call before :meth:`observe`, which leaves these robots out. Returns the
        mask of those robots and the blow-up message of every robot (``""`` where fine)."""
        errored = codes != BlowUp.NONE
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

    def apply_actions(self, actions: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Check, clip and write the set-points of ``actions`` (N, 2n) for ``rows`` (default all).

        With ``config.action_latency`` = k > 0 the set-points enter the rows' FIFOs and the ones
        given k calls earlier go to the motors. Returns the clipped float32 copy. Raises
        ``ValueError`` (changing nothing) on NaN or inf."""
        a = np.asarray(actions)
        if a.dtype.kind not in "biuf":
            raise TypeError(f"actions must hold real numbers, got dtype {a.dtype}")
        with np.errstate(over="ignore"):  # beyond float32: inf, refused below
            a = np.array(a, dtype=np.float32)
        if a.shape != (self.n_robots, 2 * self.n):
            raise ValueError(f"actions must have shape {(self.n_robots, 2 * self.n)}, got {np.shape(actions)}")
        rows = self._all if rows is None else rows
        fifo = self._cmd_fifo
        delayed = fifo.shape[1] > 0
        bad = _apply_actions_kernel(a, self._cmd_new, rows, *self._lim)
        if bad >= 0:
            raise ValueError(f"action contains NaN or inf (robot {bad}): {np.asarray(actions)[bad]}")
        cmd = self._cmd_new
        if delayed:
            cmd = self._cmd_out
            _shift_fifo_kernel(fifo, self._cmd_new, cmd, rows)
        self.physics.set_setpoints(cmd, None if rows is self._all else rows)
        return a

    def step_physics(self) -> np.ndarray:
        """Kicks due now, then one control period of physics for all robots. Returns the blow-up
        codes (N,) (:class:`~azimut_env.blowup.BlowUp`, 0: fine)."""
        phys = self.physics
        if self._kick_step.max() >= 0:
            for i in np.flatnonzero(self._kick_step == self.steps):
                kick = self.kicks[i]
                phys.kick(int(i), kick["wheels"], kick["impulse"])
        phys.step()
        self.steps += 1
        return phys.summary[:, RS.CODE]

    def observe(self, action: np.ndarray, rngs: Sequence[np.random.Generator], rows: np.ndarray | None = None) -> None:
        """After :meth:`step_physics`: measurements, IT estimate, track state, reward and
        observation for ``rows`` (default all), each robot drawing its sensor noise from its
        generator (``rngs``: a sequence of N generators, or a ``numba.typed.List`` of them, which
        draws for all robots in one compiled call with the same streams). Rows left out keep
        their previous values except the raw measurements."""
        rows = self._all if rows is None else rows
        normals = self._normals
        if isinstance(rngs, NumbaList):
            _draw_normals_kernel(rngs, rows, normals)
        elif rows is self._all:
            for i, rng in enumerate(rngs):
                rng.standard_normal(out=normals[i])
        else:
            for i in np.flatnonzero(rows):
                rngs[i].standard_normal(out=normals[i])
        s_prev = self.s.copy()
        keep = None if rows is self._all or rows.all() else ~rows
        if keep is not None:
            saved = [a[keep].copy() for a in (self.lam_hat, self.mu_hat, self.beta_est, self.qua, self.s, self.lat,
                                             self.head, self.v_ref, self.track_out, self.look)]
        all_rows = slice(None)
        self._measure(all_rows)
        self._estimate(all_rows)
        self._query_tracks(s_prev)
        if keep is not None:
            for a, v in zip((self.lam_hat, self.mu_hat, self.beta_est, self.qua, self.s, self.lat, self.head,
                             self.v_ref, self.track_out, self.look), saved):
                a[keep] = v
        obs_track, obs_look, obs_vel = self._pose_source_state(rows)
        _reward_obs_kernel(rows, self.physics.summary, self.track_out, self.look, obs_track, obs_look, obs_vel, s_prev,
                           self.track_length, self.track_max_speed, self.lam_hat, self.mu_hat, self.beta_m, self.phidot_m, self.motor_m,
                           action, self.prev_action, self._weights, self._scales, self.config.control_period,
                           self.config.max_lateral_error, self.obs_low, self.obs_high, self.v_along, self.reward,
                           self.reward_terms, self.off_track, self.finished, self.obs)
        self._check_stall(rows)

    def _check_stall(self, rows: np.ndarray) -> None:
        """Stall termination (``stall_time`` > 0): a robot without ``stall_distance`` of new progress
        for ``stall_time`` is flagged ``stalled`` and pays the off-track penalty (once)."""
        cfg = self.config
        better = rows & (self.s > self.s_best + cfg.stall_distance)
        self.s_best[better] = self.s[better]
        self.best_step[better] = self.steps[better]
        if cfg.stall_time <= 0:
            return
        stalled = rows & ~self.off_track & ((self.steps - self.best_step) * cfg.control_period >= cfg.stall_time)
        self.stalled[:] = stalled
        if stalled.any():
            col = REWARD_TERMS.index("off_track")
            self.reward[stalled] += -cfg.off_track_penalty - self.reward_terms[stalled, col]
            self.reward_terms[stalled, col] = -cfg.off_track_penalty

    # ------------------------------------------------------------------ stages

    def _measure(self, rows: slice) -> None:
        """Sensors (``sensors`` models, compiled) on views of the physics arrays for ``rows``."""
        phys = self.physics
        ms = phys.motor_state
        beta_true = phys.wheel_summary[rows, :, WS.BETA] + self.steer_bias[rows]
        out = self._meas[rows]
        _measure_kernel(beta_true, ms[rows, :, MS.THETA], ms[rows, :, MS.PHI], self.phi_prev[rows], ms[rows, :, MS.PHIDOT],
                        *self._sensor_args, self._normals[rows], out)
        self.phi_prev[rows] = ms[rows, :, MS.PHI]
        self.beta_m[rows] = out[:, 0]
        self.motor_m[rows] = out[:, 1]
        self.phidot_m[rows] = out[:, 2]

    def _estimate(self, rows: slice) -> None:
        """The IT-estimated H state of ``rows``: one batched ``estimation.estimate_eta`` call."""
        lam, mu, beta_est, qua = estimate_eta(self.beta_m[rows], self.phidot_m[rows], self.params.geometry,
                                              mu_tol=1e-3)
        self.lam_hat[rows] = lam
        self.mu_hat[rows] = mu
        self.beta_est[rows] = beta_est
        self.qua[rows] = qua

    def _fix(self, i: int) -> np.ndarray:
        """A localisation fix of robot i: its true pose plus Gaussian noise (draws 3 normals)."""
        return self.physics.summary[i, RS_POSE] + self._fix_sigma * self._loc_rngs[i].standard_normal(3)

    def pose_estimate(self, i: int) -> np.ndarray:
        """Robot i's pose (x, y, θ) as the observation sees it: the estimate with
        ``pose_source="odometry"``, the true pose otherwise."""
        return self.pose_est[i].copy() if self._odometry else self.physics.summary[i, RS_POSE].copy()

    def pose_estimates(self) -> np.ndarray:
        """(N, 3) :meth:`pose_estimate` of every robot."""
        return self.pose_est.copy() if self._odometry else self.physics.chassis_pose()

    def _pose_source_state(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The track state (N, 5), look-ahead (N, K, 3) and world velocity (N, 2) that the
        observation uses: the true ones, or (odometry) those of the pose estimate, which this
        advances for ``rows`` by one control period of dead reckoning (and a fix where one is due)."""
        if not self._odometry:
            return self.track_out, self.look, self.physics.summary[:, RS_VEL_WORLD]
        cfg, geom = self.config, self.params.geometry
        dt = cfg.control_period
        idx = np.flatnonzero(rows)
        beta_rate = (self.beta_m[idx] - self.beta_m_prev[idx]) / dt
        twist = odometry_twist(self.lam_hat[idx], self.phidot_m[idx], self.beta_m[idx], beta_rate, geom)
        pose = integrate_pose(self.pose_est[idx], twist, dt)
        self.beta_m_prev[idx] = self.beta_m[idx]
        th = pose[:, 2] - 0.5 * twist[:, 2] * dt  # the heading at mid-period
        c, sn = np.cos(th), np.sin(th)
        self.vel_est[idx, 0] = c * twist[:, 0] - sn * twist[:, 1]
        self.vel_est[idx, 1] = sn * twist[:, 0] + c * twist[:, 1]
        self.pose_est[idx] = pose
        if self._fix_every > 0:
            for i in idx[self.steps[idx] % self._fix_every == 0]:
                self.pose_est[i] = self._fix(int(i))
        out, look = query_tracks(self._packs, self.track_closed, self.track_length, self.track_rho, self.pose_est,
                                 self.track_out_est[:, 0].copy(), cfg.lookahead_count, cfg.lookahead_spacing)
        self.track_out_est[idx] = out[idx]
        self.look_est[idx] = look[idx]
        return self.track_out_est, self.look_est, self.vel_est

    def _query_tracks(self, s_hint: np.ndarray) -> None:
        """Every robot's track state, each on its own track, in one compiled call."""
        cfg = self.config
        out, look = query_tracks(self._packs, self.track_closed, self.track_length, self.track_rho,
                                 self.physics.summary[:, RS_POSE], s_hint, cfg.lookahead_count, cfg.lookahead_spacing)
        self.track_out[:] = out
        self.look[:] = look
        self._unpack_track(slice(None))

    def _unpack_track(self, rows: slice) -> None:
        out = self.track_out[rows]
        self.s[rows] = out[:, 0]
        self.lat[rows] = out[:, 1]
        self.head[rows] = out[:, 2]
        self.v_ref[rows] = out[:, 3]

    # ------------------------------------------------------------------ pickling

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        d.pop("_packs", None)  # a numba typed list: rebuilt from the tracks
        return d

    def __setstate__(self, d: dict) -> None:
        self.__dict__.update(d)
        self._packs = NumbaList([t.packed() for t in self.tracks])

    # ------------------------------------------------------------------ info

    def info(self, i: int, with_terms: bool = True) -> dict[str, Any]:
        """Robot i's info dict of the single env (ground truth, estimate, reward terms)."""
        phys = self.physics
        summ = phys.summary[i]
        twist = summ[RS_TWIST_BODY]
        # true η from the twist, ξ̇ = μ (v, −u, w): λ ∝ (−ẏ, ẋ, θ̇), μ = ‖ξ̇‖ ≥ 0
        mu = math.sqrt(float(twist @ twist))
        lam = np.array([-twist[1], twist[0], twist[2]]) / mu if mu > 0 else np.array([0.0, 0.0, 1.0])
        if mu <= 1e-3:  # the sign rule of canonical_eta(mu_tol=1e-3), as for the estimate
            key = lam[2] if lam[2] != 0 else (lam[0] if lam[0] != 0 else lam[1])
            if key < 0:
                lam, mu = -lam, -mu
        terms = {name: float(self.reward_terms[i, j]) for j, name in enumerate(REWARD_TERMS)} if with_terms else {}
        return {
            "pose": summ[RS_POSE].copy(),
            "pose_estimate": self.pose_estimate(i),
            "twist": twist,
            "eta_true": (lam, mu),
            "eta_hat": (self.lam_hat[i].copy(), float(self.mu_hat[i])),
            "beta_true": phys.wheel_summary[i, :, WS.BETA].copy(),
            "beta_est": self.beta_est[i].copy(),
            "tire_forces": phys.wheel_summary[i, :, WS_FORCE].copy(),
            "slip_power": float(summ[RS.SLIP]),
            "internal_force": float(summ[RS.INTERNAL]),
            "qua": float(self.qua[i]),
            "progress": float(self.s[i]),
            "lateral_error": float(self.lat[i]),
            "heading_error": float(self.head[i]),
            "reward_terms": terms,
        }
