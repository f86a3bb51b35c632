"""The options of ``reset`` and the constructor arguments that name a track or obstacles, checked
where they enter: each function validates and normalises without touching any state, so a refused
option changes nothing (``AzimutTask.reset_robot`` applies them).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from azimut_env.physics.blowup import BlowUpLimits
from azimut_env.physics.obstacles import Obstacle
from azimut_env.tracks import Track, library, scenarios
from azimut_env.validation import check_finite, check_index_list, check_int, check_range

__all__ = ["RESET_OPTIONS", "KICK_IMPULSE_MAX", "check_reset_options", "check_kick", "check_track",
           "coerce_obstacles", "start_progress_on"]

#: the keys ``reset(options=...)`` accepts
RESET_OPTIONS = frozenset({"track", "obstacles", "kick", "start_progress"})
_INT64_MAX = int(np.iinfo(np.int64).max)
#: the largest |impulse| of a ``kick`` [N·m·s]: 2000 × the default 0.5, already 5·10⁴ rad/s on a
#: 0.02 kg·m² module, far past every blow-up limit; 1e200 overflowed the physics' summary
KICK_IMPULSE_MAX = 1000.0


def coerce_obstacles(obstacles: Any, what: str = "obstacles") -> tuple[Obstacle, ...]:
    """A sequence of obstacle specs (``Obstacle``, ``(x, y, radius)``, a dict of its fields or a
    vertex list) as a tuple of :class:`~azimut_env.physics.engine.Obstacle`; ``ValueError`` otherwise."""
    if obstacles is None:
        return ()
    if isinstance(obstacles, (str, bytes, dict, Obstacle)) or not hasattr(obstacles, "__iter__"):
        raise TypeError(f"{what} must be a sequence of obstacles, got {type(obstacles).__name__}")
    try:
        return tuple(Obstacle.coerce(o) for o in obstacles)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{what}: {exc}") from None


def check_reset_options(options: dict[str, Any] | None, n: int, own_space: bool = False) -> dict[str, Any]:
    """Validate ``reset`` options without touching any state; return them normalised.

    For robots with n wheels; ``own_space``: the robot has a physics Space of its own (the single
    env), which per-episode obstacles need. Keys (all optional): ``track`` (a :class:`Track` or a
    built-in name), ``obstacles`` (only with ``own_space``), ``kick`` (a dict with ``step`` (int
    >= 0), ``wheels`` (distinct wheel indices, ints in 0..n−1), ``impulse`` [N·m·s], finite) and
    ``start_progress`` [m], finite (its range depends on the track: :func:`start_progress_on`).
    Raises ``ValueError``/``TypeError`` on anything else."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise TypeError(f"reset options must be a dict or None, got {type(options).__name__}")
    unknown = set(options) - RESET_OPTIONS
    if unknown:
        raise ValueError(f"unknown reset options {sorted(map(str, unknown))}; valid: {sorted(RESET_OPTIONS)}")
    out: dict[str, Any] = {}
    if "track" in options:
        out["track"] = check_track(options["track"], "options['track']")
    if "obstacles" in options:
        if not own_space:
            raise ValueError("per-episode obstacles need a Space of their own: the vector env shares its "
                             "obstacles between sub-envs (pass obstacles= to the constructor)")
        out["obstacles"] = coerce_obstacles(options["obstacles"], "options['obstacles']")
    if "kick" in options:
        out["kick"] = check_kick(options["kick"], n)
    if "start_progress" in options:
        out["start_progress"] = check_finite("options['start_progress']", options["start_progress"])
    return out


def start_progress_on(track: Track, s0: float, what: str = "options['start_progress']") -> float:
    """The starting progress ``s0`` [m] on ``track``: on a closed track any finite value, wrapped
    into [0, length) (one lap is the same place); on an open track it must lie in [0, length]
    (``ValueError``: before, −5 and 1e9 on ``paper`` were silently clamped to its ends, and 1e9
    on ``circle`` ended the episode after one step)."""
    length = float(track.length)
    if track.closed:
        s = float(s0) % length
        return 0.0 if s >= length else s
    if not 0.0 <= s0 <= length:
        raise ValueError(f"{what} = {s0!r} m is off the open track: it must lie in [0, {length:.6g}] m")
    return float(s0)


def check_kick(kick: Any, n: int) -> dict[str, Any]:
    """A validated ``kick`` option: ``{"step": int in [0, 2**63 − 1], "wheels": [int], "impulse":
    float}`` (every value storable in the task's arrays, so applying it cannot fail)."""
    if not isinstance(kick, dict):
        raise TypeError(f"options['kick'] must be a dict, got {type(kick).__name__}")
    extra = set(kick) - {"step", "wheels", "impulse"}
    if extra:
        raise ValueError(f"options['kick'] takes keys 'step', 'wheels', 'impulse', got {sorted(map(str, extra))}")
    # the step is stored in an int64 array: a larger one (2**63) raised OverflowError mid-reset
    return dict(step=check_int("options['kick']['step']", kick.get("step", 0), min_value=0, max_value=_INT64_MAX),
                wheels=check_index_list("options['kick']['wheels']", kick.get("wheels", range(n)), n),
                impulse=check_range("options['kick']['impulse']", kick.get("impulse", 0.5), -KICK_IMPULSE_MAX,
                                     KICK_IMPULSE_MAX))


def check_track(track: Any, what: str = "track") -> str | Track:
    """A built-in track or scenario name or a :class:`Track` that fits in the simulated world."""
    if isinstance(track, str):
        names = library.TRACK_NAMES + scenarios.SCENARIO_NAMES  # read now: a test may extend them
        if track not in names:
            raise ValueError(f"{what}: unknown track {track!r}; choose from {list(names)} or pass a Track")
        return track
    if not isinstance(track, Track):
        raise TypeError(f"{what} must be a Track or a built-in name, got {type(track).__name__}")
    reach, world = float(np.max(np.abs(track.xy))), 0.9 * BlowUpLimits().position
    if reach > world:
        raise ValueError(f"{what}: the track reaches {reach:.3g} m from the origin; the simulated world ends at "
                         f"|x|, |y| = {BlowUpLimits().position:g} m (BlowUpLimits.position): translate it "
                         f"within {world:g} m")
    return track
