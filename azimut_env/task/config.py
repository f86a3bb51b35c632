"""The settings of the task, built once from the envs' keyword arguments.

Both envs (:class:`~azimut_env.env.AzimutEnv`, :class:`~azimut_env.vector_env.AzimutVectorEnv`)
take the same keyword arguments: a few that say *what* is simulated (``track``, ``robot``, ``params``,
``sensors``, ``noise_scale``, ``obstacles``, ``render_mode``) and every field of
:class:`TaskConfig` (step timing, reward weights and scales, termination, observation look-ahead,
latency, pose source). :func:`task_settings` turns them into the validated pair
(:class:`~azimut_env.params.RobotParams`, :class:`TaskConfig`); :func:`front_signature` gives each
env constructor the full keyword list for ``help()`` and ``inspect.signature``, so the defaults
live in one place: the fields of :class:`TaskConfig`.
"""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, field, fields, replace
from typing import Any

from azimut_env.params import RobotParams, SensorParams
from azimut_env.task.localisation import LocalisationParams, check_pose_source
from azimut_env.task.reward import OFF_TRACK, RENAMED_TERMS, check_reward_weights, default_reward_weights
from azimut_env.validation import check_fields, check_int, check_nonnegative, check_positive, check_range
from estimation.threads import check_threads

__all__ = ["TaskConfig", "resolve_params", "robot_label", "robot_of", "task_settings", "front_signature",
           "TASK_CONFIG_FIELDS", "LEGACY_WEIGHT_KEYWORDS", "V1_REWARD_WEIGHTS", "v1_kwargs"]


@dataclass(frozen=True)
class TaskConfig:
    """Settings of the task (see :class:`~azimut_env.env.AzimutEnv`, "Arguments").

    Attributes:
        control_period: seconds per step [s]. substeps: physics substeps per step.
        solver_iterations: pymunk solver iterations per substep (see ``AzimutPhysics``).
        domain_randomization: relative spread d ∈ [0, 0.5] of friction, steering stiffness and
            damping, chassis mass (the loads follow), tire slip stiffness (with its relaxation
            lengths) and contact patch size, drawn per reset.
        reward_weights: the weight of each reward term by name (a read-only
            :class:`~azimut_env.task.reward.RewardWeights`); a partial mapping given to the
            constructor is merged onto the defaults of :data:`~azimut_env.task.reward.REWARD_TERMS`
            (the terms and their units are in :class:`~azimut_env.env.AzimutEnv`, "Rewards").
        lateral_scale [m], heading_scale [rad]: scales of the bounded tracking terms
            w·(1 − exp(−|e|/scale)).
        antagonism_cap: largest per-step cost of each of the slip, antagonism and null-space terms.
        stall_time: end the episode (terminated, with the off-track penalty) after this long [s]
            without ``stall_distance`` [m] of new progress; 0: never.
        time_limit_factor: per-robot step limit = ceil(factor · T / dt), T the nominal lap of the
            reference controller on the episode's track (:func:`~azimut_env.task.lap_time.reference_lap_time`:
            the speed profile plus its stops to turn wheels in place; 1.5 by default); 0: no limit
            of the env's own (``max_episode_steps`` of the vector env, or a ``TimeLimit``, still apply).
        max_lateral_error: lateral error that ends the episode [m].
        lookahead_count: K reference points in the observation. lookahead_spacing: their spacing
            [m of progress]. start_noise: uniform start pose noise [m, rad], 0 to 10.
        action_latency: command latency k [control periods] (default 0): the set-points of the
            action given at step t drive the motors during step t + k (a per-robot FIFO, emptied
            at each reset; for the first k steps of an episode the motors hold the reset
            set-points). Models the transport delay of a real robot's command path for
            sim-to-real work. The observation's ``prev_action`` is the action given, not the
            one being applied.
        pose_source: ``"true"`` (the observation's tracking errors and look-ahead come from the
            true pose) or ``"odometry"`` (from dead reckoning corrected by localisation fixes;
            :mod:`azimut_env.task.localisation`).
        localisation: :class:`~azimut_env.task.localisation.LocalisationParams` (used with
            ``pose_source="odometry"``).
        num_threads: threads of the compiled physics and step pipeline, each taking a block of
            robots (:mod:`estimation.threads`); None (default): the cores this process may use.
            Any count gives the same bits; one robot (the single env) runs on one.
    """

    control_period: float = 0.02
    substeps: int = 8
    solver_iterations: int = 20
    domain_randomization: float = 0.0
    reward_weights: Mapping[str, float] = field(default_factory=default_reward_weights)
    lateral_scale: float = 0.05
    heading_scale: float = 0.1
    antagonism_cap: float = 2.0
    stall_time: float = 0.0
    stall_distance: float = 0.05
    time_limit_factor: float = 1.5
    max_lateral_error: float = 0.5
    lookahead_count: int = 5
    lookahead_spacing: float = 0.3
    start_noise: float = 0.02
    action_latency: int = 0
    pose_source: str = "true"
    localisation: LocalisationParams = field(default_factory=LocalisationParams)
    num_threads: int | None = None

    def __post_init__(self) -> None:
        check_fields(self)
        # every field checked (and stored as its canonical type) here, once, with the field's name
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen)
        # 0.1 ms .. 1 s: below, step counts of the time limit overflow and the render rate is absurd
        fix("control_period", check_range("control_period", self.control_period, 1e-4, 1.0))
        fix("substeps", check_int("substeps", self.substeps, min_value=1, max_value=10_000))
        fix("solver_iterations", check_int("solver_iterations", self.solver_iterations, min_value=1,
                                           max_value=10_000))
        fix("domain_randomization", check_range("domain_randomization", self.domain_randomization, 0.0, 0.5))
        fix("reward_weights", check_reward_weights(self.reward_weights))
        # a start within 10 m and rad of the track's pose (a larger one drew from an overflowing range)
        fix("start_noise", check_range("start_noise", self.start_noise, 0.0, 10.0) + 0.0)  # -0.0 as 0.0
        for name in ("stall_time", "time_limit_factor"):
            fix(name, check_nonnegative(name, getattr(self, name)))
        for name in ("lateral_scale", "heading_scale", "antagonism_cap", "stall_distance"):
            fix(name, check_positive(name, getattr(self, name)))
        fix("max_lateral_error", check_positive("max_lateral_error", self.max_lateral_error))
        fix("lookahead_count", check_int("lookahead_count", self.lookahead_count, min_value=1, max_value=1000))
        fix("lookahead_spacing", check_positive("lookahead_spacing", self.lookahead_spacing))
        fix("action_latency", check_int("action_latency", self.action_latency, min_value=0, max_value=1000))
        check_pose_source(self.pose_source)
        if self.num_threads is not None:
            fix("num_threads", check_threads(self.num_threads))
        if not isinstance(self.localisation, LocalisationParams):
            raise TypeError(f"localisation must be LocalisationParams, got {type(self.localisation).__name__}")

    @property
    def off_track_penalty(self) -> float:
        """The weight of the ``off_track`` term: the penalty of leaving the track, stalling or a blow-up."""
        return self.reward_weights[OFF_TRACK]


def resolve_params(params: RobotParams | None, sensors: SensorParams | str | None, noise_scale: float,
                   robot: str | None = None, imperfections: str | None = None) -> RobotParams:
    """The robot parameters with the imperfections preset, the ``sensors`` override and the
    ``noise_scale`` applied.

    ``robot`` is a preset's name (``RobotParams.preset``) or a description file's path; giving it
    with ``params`` raises ``ValueError`` (a preset with parameters of its own is two robots);
    neither: the default robot, the preset ``azimut3`` (AZIMUT-3 with the ``"paper"``
    imperfections, which its file names). ``imperfections`` (:mod:`azimut_env.imperfections`):
    ``"paper"`` or ``"ideal"`` applied on top of the robot; ``None``: the robot as given (a
    description file and a preset carry the preset their ``[imperfections]`` table names;
    ``params`` are used as they are)."""
    from azimut_env.imperfections import check_imperfections, with_imperfections
    from azimut_env.robot_file import DEFAULT_PRESET, resolve_robot

    if imperfections is not None:
        check_imperfections(imperfections)  # before the robot file is read
    params = resolve_robot(robot, params, RobotParams)
    if params is None:
        params = RobotParams.preset(DEFAULT_PRESET)
    elif not isinstance(params, RobotParams):
        raise TypeError(f"params must be RobotParams or None, got {type(params).__name__}")
    if imperfections is not None:
        params = with_imperfections(params, imperfections)
    if sensors is not None:
        if isinstance(sensors, str):
            if sensors != "ideal":
                raise ValueError(f"sensors must be SensorParams or 'ideal', got {sensors!r}")
            sensors = SensorParams.ideal()
        if not isinstance(sensors, SensorParams):
            raise TypeError(f"sensors must be SensorParams or 'ideal', got {type(sensors).__name__}")
        params = replace(params, sensors=sensors)
    noise_scale = check_nonnegative("noise_scale", noise_scale)
    if noise_scale != 1.0:
        sp = params.sensors
        params = replace(params, sensors=replace(sp, steer_noise=sp.steer_noise * noise_scale,
                                                 motor_noise=sp.motor_noise * noise_scale,
                                                 wheel_speed_noise=sp.wheel_speed_noise * noise_scale))
    return params


#: the keyword arguments of the envs that are :class:`TaskConfig` fields
TASK_CONFIG_FIELDS = tuple(f.name for f in fields(TaskConfig))


def robot_of(env_kwargs) -> RobotParams:
    """The robot an env's keyword arguments ``robot`` and ``imperfections`` make (its other keys
    are not read): :func:`resolve_params` of those two, so that a preset, its file and the default
    compare equal."""
    return resolve_params(None, None, 1.0, env_kwargs.get("robot"), env_kwargs.get("imperfections"))


def robot_label(env_kwargs) -> str:
    """How messages name the robot of an env's keyword arguments: ``"<robot> (imperfections
    <preset>)"``, or ``"(its own imperfections)"`` without that key; the default is ``azimut3``."""
    imp = env_kwargs.get("imperfections")
    return f"{env_kwargs.get('robot') or 'azimut3'} ({f'imperfections {imp}' if imp else 'its own imperfections'})"


def task_settings(params: RobotParams | None = None, sensors: SensorParams | str | None = None,
                  noise_scale: float = 1.0, robot: str | None = None, imperfections: str | None = None,
                  **config: Any) -> tuple[RobotParams, TaskConfig]:
    """The robot parameters and the task settings of an env from its keyword arguments.

    ``robot``, ``params``, ``imperfections``, ``sensors`` and ``noise_scale`` go through
    :func:`resolve_params`; every other
    keyword must be a :class:`TaskConfig` field (``localisation=None`` means the default
    :class:`~azimut_env.task.localisation.LocalisationParams`). Raises ``TypeError`` naming an unknown
    keyword, and the field checks' ``ValueError``/``TypeError`` otherwise."""
    params = resolve_params(params, sensors, noise_scale, robot, imperfections)
    config = _legacy_weights(config)
    unknown = sorted(set(config) - set(TASK_CONFIG_FIELDS))
    if unknown:
        raise TypeError(f"unexpected keyword argument(s) {unknown}: the env takes track, robot, params, "
                        f"imperfections, sensors, "
                        f"noise_scale, obstacles, render_mode and the TaskConfig fields {list(TASK_CONFIG_FIELDS)}")
    if config.get("localisation") is None:  # only None means the default; a falsy 0, "" or [] is refused
        config["localisation"] = LocalisationParams()
    return params, TaskConfig(**config)


#: the reward weights' keywords before ``reward_weights`` (deprecated; recorded in older runs' env_kwargs)
LEGACY_WEIGHT_KEYWORDS = {"progress_weight": "progress", "lateral_weight": "lateral", "heading_weight": "heading",
                          "overspeed_weight": "overspeed", "slip_weight": "slip",
                          "internal_force_weight": "internal_force", "action_rate_weight": "action_rate",
                          "off_track_penalty": "off_track"}

#: ``Azimut-v1``'s reward on top of the current defaults: it priced the minimum-norm null-space force
#: (then called internal_force), not the antagonism, with the same weight (:func:`v1_kwargs`)
V1_REWARD_WEIGHTS = {"antagonism": 0.0, "nullspace_force": 0.01}


def v1_kwargs(kwargs: dict[str, Any]) -> dict[str, Any]:
    """The keyword arguments of an ``Azimut-v1`` env from those given to ``gymnasium.make``: the
    ideal robot (``imperfections="ideal"``) unless another is named, and :data:`V1_REWARD_WEIGHTS`
    under the ``reward_weights`` given (a term named there keeps the value given; what is not a
    mapping is left for :class:`TaskConfig` to refuse). Its rewards are then v1's, bit for bit
    (the antagonism term adds −0.0)."""
    out = dict(kwargs)
    out.setdefault("imperfections", "ideal")
    weights = out.get("reward_weights")
    if weights is None or isinstance(weights, Mapping):
        out["reward_weights"] = {**V1_REWARD_WEIGHTS, **(weights or {})}
    return out


def _legacy_weights(config: dict[str, Any]) -> dict[str, Any]:
    """``config`` with the deprecated per-term weight keywords (:data:`LEGACY_WEIGHT_KEYWORDS`) moved
    into ``reward_weights``, with a ``DeprecationWarning`` naming the new spelling. A term given both
    ways is refused (``TypeError``), whatever the two values."""
    legacy = [k for k in config if k in LEGACY_WEIGHT_KEYWORDS]
    if not legacy:
        return config
    config = dict(config)
    weights = config.get("reward_weights")
    if weights is not None and not isinstance(weights, Mapping):
        raise TypeError(f"reward_weights must be a mapping term name -> weight, got {type(weights).__name__}")
    weights = dict(weights or {})
    for key in legacy:
        term = LEGACY_WEIGHT_KEYWORDS[key]
        if term in RENAMED_TERMS:
            raise ValueError(f"{key}: the term {term!r} is now {RENAMED_TERMS[term]}")
        if term in weights:
            raise TypeError(f"{key} and reward_weights[{term!r}] both set the weight of {term!r}: "
                            f"pass reward_weights only")
        warnings.warn(f"{key}=... is deprecated: pass reward_weights={{{term!r}: ...}}", DeprecationWarning,
                      stacklevel=5)
        weights[term] = config.pop(key)
    config["reward_weights"] = weights
    return config


def front_signature(init: Callable) -> inspect.Signature:
    """The signature of an env constructor ``init(self, ..., **config)`` with ``**config`` spelled
    out as the keyword-only :class:`TaskConfig` fields and their defaults (``localisation``:
    None), for ``help()``, ``inspect.signature`` and IDEs."""
    sig = inspect.signature(init)
    own = [p for p in sig.parameters.values() if p.kind is not inspect.Parameter.VAR_KEYWORD]
    extra = []
    for f in fields(TaskConfig):
        default = None if f.name == "localisation" else (f.default if f.default is not MISSING else f.default_factory())
        extra.append(inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=f.type))
    return sig.replace(parameters=own + extra)
