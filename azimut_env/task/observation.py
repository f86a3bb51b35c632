"""The observation of ``Azimut-v2``: one table of fields, one compiled function per field.

:data:`OBSERVATION_FIELDS` is the single description of the observation vector: each field's
name, size, bound, unit, meaning and the function that writes it, in the order of the vector. It
drives

* :func:`observation_layout` (the slices by name, ``env.observation_slices()``),
* :func:`observation_bounds` (the ``Box`` limits, where every value is clipped),
* :func:`observe_kernel` (the observation stage of the pipeline, generated from the table: each
  field's function per robot, then non-finite values as 0 and everything clipped), and
* :func:`observation_table` (the Markdown table of the docs, :mod:`azimut_env.doc_tables`).

**To add a field**: its function ``_obs_<name>(ta, i, obs, j)`` (``numba.njit``: robot i's values
into ``obs[i, j]``, ``obs[i, j + 1]``... (its place in the row), read from the task's struct
``ta``, :data:`azimut_env.task.arrays.FIELDS`; element by element: an array view per robot costs
more than the field) and its row in :data:`OBSERVATION_FIELDS`. The spaces,
the layout, the bounds and the docs follow.

The track state the fields read (``ta.obs_track``, ``ta.obs_look``, ``ta.obs_vel``) is the pose
source's: the true one, or that of the odometry estimate (:mod:`azimut_env.task.localisation`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numba import njit

from azimut_env.task.codegen import check_table, markdown_table, row_stage
from azimut_env.tracks import TQ

__all__ = ["ObservationField", "OBSERVATION_FIELDS", "observation_layout", "observation_bounds", "field_offsets",
           "observation_table", "observe_kernel", "speed_along", "speed_along_xy"]

# plain-int columns (numba folds them; the IntEnums stay the names)
_LAT, _HEAD, _V_REF, _PSI = int(TQ.LATERAL), int(TQ.HEADING), int(TQ.V_REF), int(TQ.PSI)


@njit(cache=True)
def speed_along_xy(vx, vy, psi):
    """The velocity (v_x, v_y) [m/s] along the path direction ψ [rad]."""
    return vx * math.cos(psi) + vy * math.sin(psi)


@njit(cache=True)
def speed_along(vel_world, psi):
    """:func:`speed_along_xy` of ``vel_world`` (2,)."""
    return speed_along_xy(vel_world[0], vel_world[1], psi)


@njit(cache=True, inline="always")
def _row(values, i, obs, j):
    """Row i of ``values`` (N, m) into obs[i, j:j + m], element by element."""
    for k in range(values.shape[1]):
        obs[i, j + k] = values[i, k]


@njit(cache=True)
def _obs_lambda_hat(ta, i, obs, j):
    _row(ta.lam_hat, i, obs, j)


@njit(cache=True)
def _obs_mu_hat(ta, i, obs, j):
    obs[i, j] = ta.mu_hat[i]


@njit(cache=True)
def _obs_beta(ta, i, obs, j):
    _row(ta.beta_m, i, obs, j)


@njit(cache=True)
def _obs_phidot(ta, i, obs, j):
    _row(ta.phidot_m, i, obs, j)


@njit(cache=True)
def _obs_motor_angle(ta, i, obs, j):
    _row(ta.motor_m, i, obs, j)


@njit(cache=True)
def _obs_lateral_error(ta, i, obs, j):
    obs[i, j] = ta.obs_track[i, _LAT]


@njit(cache=True)
def _obs_heading_error(ta, i, obs, j):
    obs[i, j] = ta.obs_track[i, _HEAD]


@njit(cache=True)
def _obs_speed_along(ta, i, obs, j):
    obs[i, j] = speed_along_xy(ta.obs_vel[i, 0], ta.obs_vel[i, 1], ta.obs_track[i, _PSI])


@njit(cache=True)
def _obs_speed_ref(ta, i, obs, j):
    obs[i, j] = ta.obs_track[i, _V_REF]


@njit(cache=True)
def _obs_lookahead(ta, i, obs, j):
    look = ta.obs_look
    for k in range(look.shape[1]):
        for c in range(3):
            obs[i, j + 3 * k + c] = look[i, k, c]


@njit(cache=True)
def _obs_prev_action(ta, i, obs, j):
    _row(ta.prev_action, i, obs, j)


class ObservationField(NamedTuple):
    """One field of the observation vector."""

    name: str
    #: its length, a multiple of 1, n (wheels) or K (look-ahead points): (constant, per wheel, per point)
    size: tuple[int, int, int]
    #: the upper bound of each element, repeated over the field (a look-ahead point: x, y, Δθ)
    high: tuple[float, ...]
    #: the lower bound is 0 (else −high)
    nonnegative: bool
    #: multiply ``high`` by the wheel speed limit φ̇_max (``ActuatorLimits.wheel_speed_max``)
    per_wheel_speed: bool
    unit: str
    doc: str
    #: ``numba.njit`` function ``(ta, i, obs, j)``: robot i's values into ``obs[i, j:]`` (the module docstring)
    function: Callable


_F = ObservationField
#: the observation vector, field by field, in order
OBSERVATION_FIELDS: tuple[ObservationField, ...] = (
    _F("lambda_hat", (3, 0, 0), (1.0,), False, False, "-",
       "IT-estimated ICR λ̂ (canonical: μ̂ ≥ 0, else w ≥ 0)", _obs_lambda_hat),
    _F("mu_hat", (1, 0, 0), (10.0,), False, False, "m/s",
       "μ̂ from the measured wheel speeds given λ̂ (least squares)", _obs_mu_hat),
    _F("beta", (0, 1, 0), (math.pi,), False, False, "rad",
       "measured steering angles (wheel side of the spring)", _obs_beta),
    _F("phidot", (0, 1, 0), (3.0,), False, True, "rad/s",
       "measured wheel spin rates (encoder counts per period)", _obs_phidot),
    _F("motor_angle", (0, 1, 0), (math.pi,), False, False, "rad", "measured steering motor angles", _obs_motor_angle),
    _F("lateral_error", (1, 0, 0), (10.0,), False, False, "m",
       "signed distance to the path, positive to its left", _obs_lateral_error),
    _F("heading_error", (1, 0, 0), (math.pi,), False, False, "rad", "θ − θ_ref, wrapped", _obs_heading_error),
    _F("speed_along", (1, 0, 0), (10.0,), False, False, "m/s",
       "chassis velocity along the path direction", _obs_speed_along),
    _F("speed_ref", (1, 0, 0), (10.0,), True, False, "m/s",
       "reference progress speed at the current progress", _obs_speed_ref),
    _F("lookahead", (0, 0, 3), (20.0, 20.0, math.pi), False, False, "m, rad",
       "K reference points ahead: (x, y) in the chassis frame, Δθ", _obs_lookahead),
    _F("prev_action", (0, 2, 0), (1.0,), False, False, "-", "the previous action", _obs_prev_action),
)
del _F


def _size(field: ObservationField, n: int, lookahead_count: int) -> int:
    c, w, k = field.size
    return c + w * n + k * lookahead_count


def observation_layout(n: int, lookahead_count: int) -> dict[str, slice]:
    """Names and slices of the observation vector for n wheels and K look-ahead points (see
    :class:`~azimut_env.env.AzimutEnv`, "Observation Space")."""
    out, i = {}, 0
    for f in OBSERVATION_FIELDS:
        size = _size(f, n, lookahead_count)
        out[f.name] = slice(i, i + size)
        i += size
    return out


def field_offsets(n: int, lookahead_count: int) -> np.ndarray:
    """(len(OBSERVATION_FIELDS) + 1,) int64: where each field starts in the vector, then its length."""
    starts = [sl.start for sl in observation_layout(n, lookahead_count).values()]
    return np.array(starts + [sum(_size(f, n, lookahead_count) for f in OBSERVATION_FIELDS)], dtype=np.int64)


def observation_bounds(n: int, lookahead_count: int, wheel_speed_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Finite (low, high) float32 bounds of the observation vector (the Box limits)."""
    layout = observation_layout(n, lookahead_count)
    size = max(s.stop for s in layout.values())
    lo, hi = np.zeros(size), np.zeros(size)
    for f in OBSERVATION_FIELDS:
        sl = layout[f.name]
        high = np.resize(np.array(f.high), sl.stop - sl.start)
        if f.per_wheel_speed:
            high = high * wheel_speed_max
        hi[sl] = high
        lo[sl] = 0.0 if f.nonnegative else -high
    return lo.astype(np.float32), hi.astype(np.float32)


def observation_table() -> str:
    """The Markdown table of the fields (name, size, content, unit) for the docs."""
    def size(f: ObservationField) -> str:
        c, w, k = f.size
        return " + ".join(p for p in (str(c) if c else "", f"{w if w > 1 else ''}n" if w else "",
                                      f"{k if k > 1 else ''}K" if k else "") if p)

    return markdown_table(("name", "size", "content", "unit"), [(f.name, size(f), f.doc, f.unit)
                                                               for f in OBSERVATION_FIELDS])


@njit(cache=True)
def clip_row(obs, i, lo, hi):
    """Non-finite values of observation row i as 0, then everything clipped to [lo, hi]."""
    for j in range(obs.shape[1]):
        x = obs[i, j]
        if not math.isfinite(x):
            x = 0.0
        obs[i, j] = min(max(x, lo[j]), hi[j])


def observe_kernel(fields: tuple[ObservationField, ...] | None = None, jit: bool = True) -> Callable:
    """The observation stage of the pipeline, ``observe(ta, rows, action)``, generated from the
    table (default: :data:`OBSERVATION_FIELDS` as it is now): for each robot of ``rows``, each
    field's function at its offset of ``ta.obs[i]`` (``ta.obs_offsets``), then :func:`clip_row`.
    ``jit=False``: the same source over the functions' ``py_func``."""
    fields = OBSERVATION_FIELDS if fields is None else fields
    check_table(fields, "observation fields", 4)
    body = [f"_field_{j}(ta, i, obs, off[{j}])  # {f.name}" for j, f in enumerate(fields)]
    namespace = {f"_field_{j}": f.function for j, f in enumerate(fields)}
    namespace["_clip"] = clip_row
    return row_stage("_observe", [*body, "_clip(obs, i, lo, hi)"], namespace, __file__, __name__, jit,
                     before=["off, obs, lo, hi = ta.obs_offsets, ta.obs, ta.obs_low, ta.obs_high"])
