"""The observation of ``Azimut-v2``: one layout table, and the compiled fill.

:data:`OBSERVATION_FIELDS` is the single description of the observation vector: each field's
name, size, bound, unit and meaning, in the order of the vector. It drives

* :func:`observation_layout` (the slices by name, ``env.observation_slices()``),
* :func:`observation_bounds` (the ``Box`` limits, where every value is clipped),
* :func:`field_offsets` (where :func:`fill_observation` writes each field; the field indices
  :class:`Obs` follow the table), and
* :func:`observation_table` (the Markdown table of the single env's docstring).

To add a field: a row in :data:`OBSERVATION_FIELDS`, a member of :class:`Obs` at the same
position, and its values in :func:`fill_row`.

Data flow (see :meth:`~azimut_env.task.core.AzimutTask.observe`): the sensors' measurements and the IT
estimate (λ̂, μ̂) of the robot, its track state and look-ahead seen from the pose source (the
true pose, or the odometry estimate), the world velocity of that source and the last action go
in; :func:`fill_observation` writes the float32 rows, non-finite values as 0, clipped to the bounds.
"""

from __future__ import annotations

import math
import unicodedata
from enum import IntEnum
from typing import NamedTuple

import numpy as np
from numba import njit

from azimut_env.tracks import TQ

__all__ = ["ObservationField", "OBSERVATION_FIELDS", "Obs", "observation_layout", "observation_bounds",
           "field_offsets", "observation_table", "fill_observation", "fill_row", "speed_along"]


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


_F = ObservationField
#: the observation vector, field by field, in order
OBSERVATION_FIELDS: tuple[ObservationField, ...] = (
    _F("lambda_hat", (3, 0, 0), (1.0,), False, False, "-", "IT-estimated ICR λ̂ (canonical: μ̂ ≥ 0, else w ≥ 0)"),
    _F("mu_hat", (1, 0, 0), (10.0,), False, False, "m/s", "μ̂ from the measured wheel speeds given λ̂ (least squares)"),
    _F("beta", (0, 1, 0), (math.pi,), False, False, "rad", "measured steering angles (wheel side of the spring)"),
    _F("phidot", (0, 1, 0), (3.0,), False, True, "rad/s", "measured wheel spin rates (encoder counts per period)"),
    _F("motor_angle", (0, 1, 0), (math.pi,), False, False, "rad", "measured steering motor angles"),
    _F("lateral_error", (1, 0, 0), (10.0,), False, False, "m", "signed distance to the path, positive to its left"),
    _F("heading_error", (1, 0, 0), (math.pi,), False, False, "rad", "θ − θ_ref, wrapped"),
    _F("speed_along", (1, 0, 0), (10.0,), False, False, "m/s", "chassis velocity along the path direction"),
    _F("speed_ref", (1, 0, 0), (10.0,), True, False, "m/s", "reference progress speed at the current progress"),
    _F("lookahead", (0, 0, 3), (20.0, 20.0, math.pi), False, False, "m, rad",
       "K reference points ahead: (x, y) in the chassis frame, Δθ"),
    _F("prev_action", (0, 2, 0), (1.0,), False, False, "-", "the previous action"),
)
del _F


class Obs(IntEnum):
    """Index of each field of :data:`OBSERVATION_FIELDS` (in compiled code: ``off[Obs.BETA]``)."""

    LAMBDA_HAT = 0
    MU_HAT = 1
    BETA = 2
    PHIDOT = 3
    MOTOR_ANGLE = 4
    LATERAL_ERROR = 5
    HEADING_ERROR = 6
    SPEED_ALONG = 7
    SPEED_REF = 8
    LOOKAHEAD = 9
    PREV_ACTION = 10


assert [f.name for f in OBSERVATION_FIELDS] == [m.name.lower() for m in Obs], "Obs must follow the table"


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
    """(len(Obs),) int64: where each field starts in the vector (indexed by :class:`Obs`)."""
    return np.array([sl.start for sl in observation_layout(n, lookahead_count).values()], dtype=np.int64)


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
    """The Markdown table of the fields (name, size, content, unit) for the env's docstring."""
    def size(f: ObservationField) -> str:
        c, w, k = f.size
        return " + ".join(p for p in (str(c) if c else "", f"{w if w > 1 else ''}n" if w else "",
                                      f"{k if k > 1 else ''}K" if k else "") if p)

    def width(text: str) -> int:  # combining marks (the hat of λ̂) take no column
        return sum(not unicodedata.combining(c) for c in text)

    rows = [("name", "size", "content", "unit")] + [(f.name, size(f), f.doc, f.unit) for f in OBSERVATION_FIELDS]
    widths = [max(width(r[j]) for r in rows) for j in range(4)]
    line = lambda r: "| " + " | ".join(x + " " * (w - width(x)) for x, w in zip(r, widths)) + " |"  # noqa: E731
    return "\n".join([line(rows[0]), "|" + "|".join("-" * (w + 2) for w in widths) + "|"] + [line(r) for r in rows[1:]])


@njit(cache=True)
def speed_along(vel_world, psi):
    """The velocity (v_x, v_y) [m/s] along the path direction ψ [rad]."""
    return vel_world[0] * math.cos(psi) + vel_world[1] * math.sin(psi)


@njit(cache=True)
def fill_row(obs, off, lam, mu, beta, phidot, motor, lat, head, v_along, v_ref, look, prev_action, lo, hi):
    """One observation row: each field at its offset ``off[Obs.*]``, then non-finite values as 0
    and everything clipped to [lo, hi]."""
    for j in range(3):
        obs[off[Obs.LAMBDA_HAT] + j] = lam[j]
    obs[off[Obs.MU_HAT]] = mu
    for j in range(beta.shape[0]):
        obs[off[Obs.BETA] + j] = beta[j]
        obs[off[Obs.PHIDOT] + j] = phidot[j]
        obs[off[Obs.MOTOR_ANGLE] + j] = motor[j]
    obs[off[Obs.LATERAL_ERROR]] = lat
    obs[off[Obs.HEADING_ERROR]] = head
    obs[off[Obs.SPEED_ALONG]] = v_along
    obs[off[Obs.SPEED_REF]] = v_ref
    i = off[Obs.LOOKAHEAD]
    for k in range(look.shape[0]):
        for j in range(3):
            obs[i] = look[k, j]
            i += 1
    for j in range(prev_action.shape[0]):
        obs[off[Obs.PREV_ACTION] + j] = prev_action[j]
    for j in range(obs.shape[0]):
        x = obs[j]
        if not math.isfinite(x):
            x = 0.0
        obs[j] = min(max(x, lo[j]), hi[j])


@njit(cache=True)
def fill_observation(rows, off, lam, mu, beta, phidot, motor, track_state, look, vel_world, prev_action, lo, hi,
                     obs):
    """The observation rows (N, D) float32 of the robots where ``rows`` is True.

    ``lam`` (N, 3), ``mu`` (N,): the IT estimate; ``beta``, ``phidot``, ``motor`` (N, n): the
    measurements; ``track_state`` (N, 5) (columns :class:`~azimut_env.tracks.TQ`), ``look``
    (N, K, 3) and ``vel_world`` (N, 2): the track state, look-ahead and world velocity of the pose
    source; ``prev_action`` (N, 2n) float32."""
    for i in range(rows.shape[0]):
        if rows[i]:
            ts = track_state[i]
            fill_row(obs[i], off, lam[i], mu[i], beta[i], phidot[i], motor[i], ts[TQ.LATERAL], ts[TQ.HEADING],
                     speed_along(vel_world[i], ts[TQ.PSI]), ts[TQ.V_REF], look[i], prev_action[i], lo, hi)
