"""The track-following controllers of ``azimut eval``: a path follower per robot feeding the ICR
controller (``icr``), the WPILib-style twist baseline (``twist``) or the setpoint generator
(``twist-setpoint``).

All implement :class:`control.controller.Controller` for the N robots of an env. Each robot has
its own path follower (on its own track, from the pose the env's observation uses,
``estimated_pose``), all N stepped in one compiled call (:class:`~control.follow.batch.BatchFollower`,
equal to the bit to one :class:`~control.follow.path_follower.PathFollower` per robot), so the
controllers get the same targets and a comparison isolates how the wheels are coordinated:

* :class:`ICRPathController`: (λ_d, μ_d) of the follower's twist into the ICR controller
  (:class:`~control.icr.batch.BatchICRController`, all robots in one batched step); the
  follower slows down before the points where the reference motion needs a stop and
  reconfiguration (its ``stop_mask``, :func:`~control.icr.controller.reference_stop_mask`);
* :class:`TwistPathController`: the follower's twist into the twist baseline
  (:class:`~control.twist.wpilib.SwerveBatch`, all robots in one compiled step);
* :class:`SetpointPathController` (``twist-setpoint``): the follower's twist into the setpoint
  generator (:class:`~control.twist.setpoint.SetpointBatch`, all robots in one compiled step),
  which never commands beyond the actuator limits.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np

from azimut_env.tracks import SCENARIO_NAMES
from control.commands import WheelCommand
from control.controller import env_threads
from control.follow.batch import BatchFollower
from control.follow.path_follower import PathFollower, PathFollowerConfig
from control.icr.batch import BatchICRController
from control.icr.config import ICRControllerConfig
from control.icr.feasibility import reference_stop_mask
from control.icr.kernel_constants import stop_circle_normals
from control.icr.lookahead import (
    CellPlan,
    LookaheadConfig,
    capped_track,
    plan_cells,
    plan_sides,
    plan_table,
)
from control.twist.setpoint import SetpointBatch, SetpointConfig
from control.twist.wpilib import SwerveBatch, SwerveConfig

__all__ = ["ICRPathController", "TwistPathController", "SetpointPathController", "PATH_ICR_CONFIG"]

#: the look-ahead's default tuning
DEFAULT_LOOKAHEAD = LookaheadConfig()

#: the ICR controller's tuning behind a path follower with look-ahead: stopped wheels turn at the
#: full steering rate and acceleration limits (the default's 50% and 30% were for a controller
#: that stopped often and without knowing why), μ is time-scaled apart from λ's turn
#: (``mu_own_scale``), and once the commands have arrived a wheel within 0.2 rad (11.5°) of its
#: target counts as settled (``reconfig_hold_tol``, 6° by default), still turning or not
#: (``reconfig_still_tol`` = π: no stillness test): a compliant steering with stiction stops the
#: last degrees short under the tyre's scrub torque at rest and creeps there, and a stiffer one
#: still lags its set-point by about 10° when the commands arrive; rolling off from rest closes
#: either gap within a few periods (figures: ``docs/icr-controller.md`` §9)
PATH_ICR_CONFIG = ICRControllerConfig(reconfig_rate_fraction=1.0, reconfig_accel_fraction=1.0, mu_own_scale=True,
                                      reconfig_hold_tol=0.2, reconfig_still_tol=np.pi)


def _follower_config(speed_scale: float, follower_config: PathFollowerConfig | None) -> PathFollowerConfig:
    if follower_config is not None:
        if not isinstance(follower_config, PathFollowerConfig):
            raise TypeError(f"follower_config must be a PathFollowerConfig or None, got "
                            f"{type(follower_config).__name__}")
        return follower_config
    if isinstance(speed_scale, bool) or not isinstance(speed_scale, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(speed_scale) and speed_scale > 0):
        raise ValueError(f"speed_scale must be a finite number > 0, got {speed_scale!r}")
    return PathFollowerConfig(speed_scale=float(speed_scale))


class _PathFollowing:
    """The path followers of all robots (the part the controllers share), one
    :class:`~control.follow.batch.BatchFollower`. A scenario's track
    (``azimut_env.tracks.SCENARIO_NAMES``, whose speeds are the robot's own) is followed with
    :meth:`PathFollowerConfig.for_robot` unless a ``follower_config`` is given. Each command's
    ``info["hold"]`` (N,) says which robots' followers were holding (``Track.holds``)."""

    def __init__(self, speed_scale: float, follower_config: PathFollowerConfig | None) -> None:
        self._config_given = follower_config is not None
        self.follower_config = _follower_config(speed_scale, follower_config)
        #: the speed scale of the track's profile (a given ``follower_config``'s own)
        self.speed_scale = self.follower_config.speed_scale
        self.followers: BatchFollower | None = None

    def _stop_mask(self, env):
        return None

    def _follower_track(self, env, i: int, track, config: PathFollowerConfig, progress: float):
        """The reference robot i's follower follows (``track`` itself, or a copy with a slower
        speed profile) and the progress values where it should also arrive slowly (None: none)."""
        return track, None

    def _reset_followers(self, env, rows: np.ndarray) -> None:
        num = int(np.shape(env.measured_beta)[0])
        if self.followers is None or self.followers.num != num:
            self.followers = BatchFollower(num, self.follower_config, stop_mask=self._stop_mask(env),
                                           dt=env.control_period, num_threads=env_threads(env))
        tracks, progress = env.tracks, np.atleast_1d(env.progress)
        for i in rows:
            cfg = self.follower_config
            if not self._config_given:
                if tracks[i].name in SCENARIO_NAMES:
                    cfg = PathFollowerConfig.for_robot(env.params, speed_scale=self.speed_scale)
                cfg = self._own_follower_config(cfg)
            track, extra = self._follower_track(env, int(i), tracks[i], cfg, float(progress[i]))
            self.followers.reset(int(i), track, float(progress[i]), cfg, extra_stops=extra)

    def _own_follower_config(self, cfg: PathFollowerConfig) -> PathFollowerConfig:
        """The followers' gains this controller asks for on top of the default ones (a config the
        user gives is used as it is)."""
        return cfg

    def _targets(self, env):
        """Every robot's follower output (:class:`~control.follow.batch.FollowerBatchOutput`)."""
        # the true pose unless the env's pose_source is "odometry"
        targets = self.followers.step_all(env.estimated_pose)
        self._holding = targets.holding
        return targets

    def _with_holds(self, cmd: WheelCommand) -> WheelCommand:
        return replace(cmd, info={**cmd.info, "hold": self._holding})


class ICRPathController(_PathFollowing):
    """``icr``: path followers + the ICR controller (see the module docstring).

    Args:
        speed_scale: multiplies the track's speed profile (ignored when ``follower_config`` is given).
        follower_config: the followers' gains (default: ``PathFollowerConfig(speed_scale=speed_scale)``).
        icr_config: the ICR controller's tuning (default :data:`PATH_ICR_CONFIG` with look-ahead,
            ``ICRControllerConfig()`` without).
        follower_stops: the followers slow down before the reference's stops and reconfigurations
            (default True; ``azimut record-d2`` records D2 without).
        lookahead: the look-ahead plan's tuning (:mod:`control.icr.lookahead`: which configuration
            cell to be in along the track and where to change it, planned at each reset); None:
            no plan, the controller decides from the current target alone.
    """

    name = "icr"

    def __init__(self, speed_scale: float = 1.0, *, follower_config: PathFollowerConfig | None = None,
                 icr_config: ICRControllerConfig | None = None, follower_stops: bool = True,
                 lookahead: LookaheadConfig | None = DEFAULT_LOOKAHEAD) -> None:
        super().__init__(speed_scale, follower_config)
        if icr_config is not None and not isinstance(icr_config, ICRControllerConfig):
            raise TypeError(f"icr_config must be an ICRControllerConfig or None, got {type(icr_config).__name__}")
        if lookahead is not None and not isinstance(lookahead, LookaheadConfig):
            raise TypeError(f"lookahead must be a LookaheadConfig or None, got {type(lookahead).__name__}")
        self.icr_config = icr_config or (PATH_ICR_CONFIG if lookahead is not None else ICRControllerConfig())
        self.follower_stops = bool(follower_stops)
        self.lookahead = lookahead
        self.controller: BatchICRController | None = None
        self._plans: list[CellPlan | None] = []
        self._table = None  # the plans packed for the lookup, rebuilt after a reset
        self._plan_cache: dict[tuple, tuple] = {}
        self._segment = np.zeros(0, dtype=np.int64)
        self._best = np.zeros(0)  # each robot's farthest progress [m] and the time since it grew [s]
        self._stalled = np.zeros(0)
        self._off = np.zeros(0, dtype=np.bool_)  # steered without its plan (after a stall)
        self._normals = np.zeros((0, 3))

    def _stop_mask(self, env):
        if not self.follower_stops or self.lookahead is not None:
            return None
        return functools.partial(reference_stop_mask, geom=env.geometry, axis_margin=self.icr_config.axis_margin)

    def _own_follower_config(self, cfg: PathFollowerConfig) -> PathFollowerConfig:
        """With a plan, the follower crawls at ``lookahead.corner_speed`` at its stop points, not
        at 2 cm/s, where the target's direction is the position feedback's (LookaheadConfig), and
        takes the junctions where the path turns back in (x, y, ρθ) as cusps
        (``PathFollowerConfig.rotation_cusps``)."""
        if self.lookahead is None:
            return cfg
        return replace(cfg, corner_speed=max(cfg.corner_speed, self.lookahead.corner_speed), rotation_cusps=True)

    def _follower_track(self, env, i: int, track, config: PathFollowerConfig, progress: float):
        if self.lookahead is None:
            return track, None
        key = (id(track), config, progress, id(env.geometry), id(env.limits))
        if key not in self._plan_cache:
            if len(self._plan_cache) > 64:
                self._plan_cache.clear()
            cfg = self.icr_config
            plan = plan_cells(track, env.geometry, env.limits, speed_scale=config.speed_scale, start=progress,
                              decel=config.corner_decel, rate_fraction=cfg.reconfig_rate_fraction,
                              accel_fraction=cfg.reconfig_accel_fraction, hold_margin=cfg.stop_hold_margin,
                              hold_angle=cfg.stop_hold_angle,
                              corners=PathFollower(track, config).stops, corner_speed=config.corner_speed,
                              config=self.lookahead)
            slowed = track if plan is None else capped_track(track, plan, config.speed_scale)
            self._plan_cache[key] = (track, plan, slowed)
        _, plan, slowed = self._plan_cache[key]
        while len(self._plans) <= i:
            self._plans.append(None)
        self._plans[i] = plan
        self._table = None
        if self._segment.size <= i:
            grow = i + 1 - self._segment.size
            self._segment = np.concatenate([self._segment, np.zeros(grow, dtype=np.int64)])
            self._best = np.concatenate([self._best, np.zeros(grow)])
            self._stalled = np.concatenate([self._stalled, np.zeros(grow)])
            self._off = np.concatenate([self._off, np.zeros(grow, dtype=np.bool_)])
        self._segment[i], self._best[i], self._stalled[i], self._off[i] = 0, -np.inf, 0.0, False
        self._normals = stop_circle_normals(env.geometry)
        if plan is None or not self.follower_stops:
            return track, None
        return slowed, plan.switches

    def reset(self, env, rows) -> None:
        rows = np.asarray(rows, dtype=np.intp)
        self._reset_followers(env, rows)
        if self.controller is None or self.controller.num != self.followers.num:
            self.controller = BatchICRController(self.followers.num, env.geometry, env.limits, env.control_period,
                                                 self.icr_config, self.followers.num_threads)
        lam_hat, _ = env.estimated_eta
        self.controller.reset(rows, lam_hat[rows], env.measured_beta[rows], env.measured_phidot[rows])

    def act(self, env, obs) -> WheelCommand:
        targets = self._targets(env)
        lam_hat, mu_hat = env.estimated_eta
        plan = excursion = None
        if self.lookahead is not None and self._table is None:
            self._table = plan_table(self._plans, env.tracks, env.geometry.n)
        if self.lookahead is not None and self._table.counts.any():
            plan, excursion = plan_sides(self._table, targets.progress, targets.lam, self._normals, self._segment)
            # a robot whose progress stalls (a reference the plan's cells cannot follow near a change
            # of cell) is steered without its plan for the rest of its episode
            ahead = targets.progress > self._best + self.lookahead.stall_distance
            self._best = np.where(ahead, targets.progress, self._best)
            self._stalled = np.where(ahead | targets.holding | targets.finished, 0.0,
                                     self._stalled + env.control_period)
            self._off |= self._stalled > self.lookahead.stall_time
            plan[self._off] = 0.0
            excursion[self._off] = 0.0
        return self._with_holds(self.controller.step(None, lam_hat, mu_hat, env.measured_beta, env.measured_phidot,
                                                     targets.lam, targets.mu, plan_side=plan,
                                                     plan_excursion=excursion))


class _TwistFollowing(_PathFollowing):
    """Path followers feeding their twists to a batch of twist controllers (``batch_type``:
    :class:`~control.twist.wpilib.SwerveBatch` or :class:`~control.twist.setpoint.SetpointBatch`,
    built with ``batch_config``, None for its defaults): what ``twist`` and ``twist-setpoint``
    share. ``config_name``: the keyword that gave ``batch_config``, for its error message."""

    batch_type: type

    def __init__(self, speed_scale: float, follower_config: PathFollowerConfig | None, config_name: str,
                 batch_config) -> None:
        super().__init__(speed_scale, follower_config)
        config_type = self.batch_type.config_type
        if batch_config is not None and not isinstance(batch_config, config_type):
            raise TypeError(f"{config_name} must be a {config_type.__name__} or None, got "
                            f"{type(batch_config).__name__}")
        self.batch_config = batch_config
        self.controller = None

    def reset(self, env, rows) -> None:
        rows = np.asarray(rows, dtype=np.intp)
        self._reset_followers(env, rows)
        if self.controller is None or self.controller.num != self.followers.num:
            self.controller = self.batch_type(self.followers.num, env.geometry, env.limits, env.control_period,
                                              self.batch_config, self.followers.num_threads)
        self.controller.reset(rows, env.measured_beta[rows], env.measured_phidot[rows])

    def act(self, env, obs) -> WheelCommand:
        return self._with_holds(self.controller.step(None, self._targets(env).twist, env.measured_beta))


class TwistPathController(_TwistFollowing):
    """``twist``: path followers + the WPILib-style baseline (see the module docstring).

    Args:
        speed_scale, follower_config: as :class:`ICRPathController`.
        swerve_config: the baseline's options.
    """

    name = "twist"
    batch_type = SwerveBatch

    def __init__(self, speed_scale: float = 1.0, *, follower_config: PathFollowerConfig | None = None,
                 swerve_config: SwerveConfig | None = None) -> None:
        super().__init__(speed_scale, follower_config, "swerve_config", swerve_config)


class SetpointPathController(_TwistFollowing):
    """``twist-setpoint``: path followers + the setpoint generator (see the module docstring and
    :mod:`control.twist.setpoint`).

    Args:
        speed_scale, follower_config: as :class:`ICRPathController`.
        setpoint_config: the generator's options.
    """

    name = "twist-setpoint"
    batch_type = SetpointBatch

    def __init__(self, speed_scale: float = 1.0, *, follower_config: PathFollowerConfig | None = None,
                 setpoint_config: SetpointConfig | None = None) -> None:
        super().__init__(speed_scale, follower_config, "setpoint_config", setpoint_config)
