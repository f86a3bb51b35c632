"""The reward of ``Azimut-v2``: one table of terms, one compiled function per term.

:data:`REWARD_TERMS` is the single description of the reward, like
:data:`~azimut_env.task.observation.OBSERVATION_FIELDS` is of the observation: each row
(:class:`RewardTerm`) names a term, gives its default weight and the weight's unit, its
function and what it prices. The reward of a step is the sum of the terms in the order of the
table; each term is in ``info["reward_terms"]`` under its name, and ``reward_weights={name: w}``
(a keyword of both envs, :class:`~azimut_env.task.config.TaskConfig`) sets the weights by name.

A term's function is ``_reward_<name>(x, k, w) -> float``, compiled with ``numba.njit``: the
term of one robot from its inputs ``x`` (columns :class:`RewardInput`, the ground truth, whatever
the observation's pose source), the constants ``k`` (columns :class:`RewardConstant`) and the
term's weight ``w``. With v_max the track's top reference speed and dt the control period:

* progress w·clip(Δs, −v_max dt, v_ref dt)/(v_max dt) (backward jumps of the projection clipped to
  one step at full speed);
* lateral and heading −w·(1 − exp(−|e|/scale)) (bounded, steepest at zero error);
* overspeed −w·max(0, v_along − v_ref)/v_max;
* slip −min(w·P_slip, cap) and antagonism −min(w·F_ant, cap): the actuator antagonism that
  Clavien, Lauria, Michaud (RAS 2018) is about, the tire slip power and the stiffness-weighted
  internal force of the physics summary (``AzimutPhysics.slip_power``, ``antagonism``;
  :mod:`azimut_env.physics.antagonism`); nullspace_force −min(w·F_null, cap), the minimum-norm
  null-space force (``AzimutPhysics.nullspace_force``), weight 0 by default: ``Azimut-v1``'s
  internal-force term, priced by that id (:data:`~azimut_env.task.config.V1_REWARD_WEIGHTS`);
* action rate −w‖a − a_prev‖² (the normalised set-point actions);
* off track −w on the step that ends the episode by a failure (the end conditions of
  :data:`~azimut_env.task.termination.TERMINATION_TERMS` marked as failures: off the track,
  stalled); a physics blow-up gets it as its reward.

**To add a term**: write its function and add its row to :data:`REWARD_TERMS` (this module only). A
term that reads a quantity no term reads yet also adds a column to :class:`RewardInput` (and its
value to :func:`fill_reward_inputs`) or to :class:`RewardConstant` (and to :func:`reward_constants`).

Data flow: the reward stage of the pipeline (:mod:`azimut_env.task.pipeline`) is
:func:`reward_kernel`'s function, generated from the table: for each robot,
:func:`fill_reward_inputs` writes its inputs from the task's struct, then each term's function,
then the sum, into the terms and the reward.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from enum import IntEnum
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from azimut_env.physics.layout import RS
from azimut_env.task.codegen import check_table, markdown_table, row_stage
from azimut_env.tracks import TQ
from azimut_env.validation import real_scalar, show

__all__ = ["RewardTerm", "REWARD_TERMS", "current_reward_terms", "RewardInput", "RewardConstant", "RewardWeights",
           "OFF_TRACK", "RENAMED_TERMS", "reward_term_names", "default_reward_weights", "check_reward_weights",
           "reward_weight_array",
           "reward_constants", "reward_table", "fill_reward_inputs", "reward_kernel"]


class RewardInput(IntEnum):
    """Columns of a robot's reward inputs ``x`` (:func:`fill_reward_inputs`), all ground truth."""

    PROGRESS = 0         # s after the step [m]
    PROGRESS_BEFORE = 1  # s before the step [m]
    LATERAL_ERROR = 2    # e_lat [m]
    HEADING_ERROR = 3    # e_θ [rad]
    SPEED_REF = 4        # v_ref [m/s]
    SPEED_ALONG = 5      # chassis velocity along the path [m/s]
    TOP_SPEED = 6        # v_max, the track's top reference speed (at least 1 mm/s) [m/s]
    SLIP_POWER = 7       # Σ|F·v_slip|, step mean [W]
    ANTAGONISM = 8       # F_ant, step mean [N]
    NULLSPACE_FORCE = 9  # F_null, step mean [N]
    ACTION_CHANGE = 10   # ‖a − a_prev‖² (the normalised actions)
    OFF_TRACK = 11       # 1.0 on the step that ends the episode by a failure (off the track, stalled), else 0.0


class RewardConstant(IntEnum):
    """Columns of the constants ``k`` the terms share (:func:`reward_constants`)."""

    CONTROL_PERIOD = 0  # dt [s]
    LATERAL_SCALE = 1   # [m]
    HEADING_SCALE = 2   # [rad]
    ANTAGONISM_CAP = 3  # the largest per-step cost of each of the slip, antagonism and null-space terms


_X, _K = RewardInput, RewardConstant


@njit(cache=True)
def _reward_progress(x, k, w):
    dt, v_max = k[_K.CONTROL_PERIOD], x[_X.TOP_SPEED]
    ds = min(max(x[_X.PROGRESS] - x[_X.PROGRESS_BEFORE], -v_max * dt), x[_X.SPEED_REF] * dt + 1e-3 * dt)
    return w * ds / (v_max * dt)


@njit(cache=True)
def _reward_lateral(x, k, w):
    return -w * (1.0 - math.exp(-abs(x[_X.LATERAL_ERROR]) / k[_K.LATERAL_SCALE]))


@njit(cache=True)
def _reward_heading(x, k, w):
    return -w * (1.0 - math.exp(-abs(x[_X.HEADING_ERROR]) / k[_K.HEADING_SCALE]))


@njit(cache=True)
def _reward_overspeed(x, k, w):
    return -w * max(0.0, x[_X.SPEED_ALONG] - x[_X.SPEED_REF]) / x[_X.TOP_SPEED]


@njit(cache=True)
def _reward_slip(x, k, w):
    return -min(w * x[_X.SLIP_POWER], k[_K.ANTAGONISM_CAP])


@njit(cache=True)
def _reward_antagonism(x, k, w):
    return -min(w * x[_X.ANTAGONISM], k[_K.ANTAGONISM_CAP])


@njit(cache=True)
def _reward_nullspace_force(x, k, w):
    return -min(w * x[_X.NULLSPACE_FORCE], k[_K.ANTAGONISM_CAP])


@njit(cache=True)
def _reward_action_rate(x, k, w):
    return -w * x[_X.ACTION_CHANGE]


@njit(cache=True)
def _reward_off_track(x, k, w):
    return -w if x[_X.OFF_TRACK] != 0.0 else 0.0


class RewardTerm(NamedTuple):
    """One term of the reward: a row of :data:`REWARD_TERMS`."""

    name: str
    #: the default weight (≥ 0; ``reward_weights={name: w}`` overrides it)
    weight: float
    #: the unit of the weight (the term itself is dimensionless, per step)
    unit: str
    #: ``numba.njit`` function ``(x, k, w) -> float`` (see the module docstring)
    function: Callable
    doc: str


_T = RewardTerm
#: the reward, term by term, in the order of the sum and of ``info["reward_terms"]``
REWARD_TERMS: tuple[RewardTerm, ...] = (
    _T("progress", 3.0, "-", _reward_progress, "w·clip(Δs, −v_max·dt, v_ref·dt)/(v_max·dt)"),
    _T("lateral", 0.5, "-", _reward_lateral, "−w·(1 − exp(−abs(e_lat)/lateral_scale))"),
    _T("heading", 0.3, "-", _reward_heading, "−w·(1 − exp(−abs(e_θ)/heading_scale))"),
    _T("overspeed", 2.0, "-", _reward_overspeed, "−w·max(0, v_along − v_ref)/v_max"),
    _T("slip", 0.02, "1/W", _reward_slip, "−min(w·P_slip, antagonism_cap), P_slip the tire slip power"),
    _T("antagonism", 0.01, "1/N", _reward_antagonism,
       "−min(w·F_ant, antagonism_cap), F_ant the wheels' antagonism"),
    _T("nullspace_force", 0.0, "1/N", _reward_nullspace_force,
       "−min(w·F_null, antagonism_cap), F_null the null-space force"),
    _T("action_rate", 0.05, "-", _reward_action_rate, "−w·‖a − a_prev‖² (normalised actions)"),
    _T("off_track", 10.0, "-", _reward_off_track, "−w on the step that leaves the track or stalls"),
)
del _T

#: the term whose weight is the penalty of leaving the track, stalling and a physics blow-up
OFF_TRACK = "off_track"
#: terms of earlier versions -> what replaced them (``reward_weights`` refuses the old name with this)
RENAMED_TERMS = {"internal_force": "'antagonism' (the stiffness-weighted internal force, Azimut-v2); "
                                   "'nullspace_force' is the old minimum-norm quantity"}


def current_reward_terms() -> tuple[RewardTerm, ...]:
    """:data:`REWARD_TERMS` as it is now (read at call time, so that a test may extend the table)."""
    return REWARD_TERMS


def _table(terms: tuple[RewardTerm, ...] | None) -> tuple[RewardTerm, ...]:
    return current_reward_terms() if terms is None else terms


def reward_term_names(terms: tuple[RewardTerm, ...] | None = None) -> tuple[str, ...]:
    """The terms' names, in the order of the table (the columns of ``AzimutTask.reward_terms``)."""
    return tuple(t.name for t in _table(terms))


def default_reward_weights() -> RewardWeights:
    """The weights of :data:`REWARD_TERMS`' rows, by name."""
    return RewardWeights({t.name: float(t.weight) for t in REWARD_TERMS})


class RewardWeights(Mapping):
    """A read-only, hashable and picklable mapping term name -> weight (``TaskConfig.reward_weights``)."""

    __slots__ = ("_items",)

    def __init__(self, weights: Mapping[str, float]) -> None:
        object.__setattr__(self, "_items", tuple((str(k), float(v)) for k, v in weights.items()))

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("RewardWeights is read-only")

    def __getitem__(self, name: str) -> float:
        for k, v in self._items:
            if k == name:
                return v
        raise KeyError(name)

    def __iter__(self) -> Iterator[str]:
        return (k for k, _ in self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __hash__(self) -> int:
        return hash(self._items)

    def __reduce__(self):
        return RewardWeights, (dict(self._items),)

    def __repr__(self) -> str:
        return repr(dict(self._items))


def check_reward_weights(overrides: Mapping[str, Any] | None = None) -> RewardWeights:
    """The weight of every term of :data:`REWARD_TERMS`: its row's default, or its value in
    ``overrides`` (a partial mapping by term name). Refuses, with one line naming it, a mapping
    that is not one, a name that is not a term's, and a weight that is not a finite number ≥ 0."""
    names = reward_term_names()
    if overrides is None:
        overrides = {}
    if not isinstance(overrides, Mapping):
        raise TypeError(f"reward_weights must be a mapping term name -> weight, got {type(overrides).__name__}")
    renamed = [k for k in overrides if k in RENAMED_TERMS]
    if renamed:
        raise ValueError(f"reward_weights: the term {renamed[0]!r} is now {RENAMED_TERMS[renamed[0]]}")
    unknown = [k for k in overrides if k not in names]
    if unknown:
        raise ValueError(f"reward_weights: unknown term(s) {unknown}; the terms are {list(names)}")
    weights = dict(default_reward_weights())
    for name, w in overrides.items():  # the one numeric check: 10**400 raised OverflowError here
        label = f"reward_weights[{name!r}]"
        v = real_scalar(label, w)
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{label} must be finite and >= 0, got {show(w)}")
        weights[name] = v
    return RewardWeights(weights)


def reward_weight_array(weights: Mapping[str, float], terms: tuple[RewardTerm, ...] | None = None) -> np.ndarray:
    """(len(terms),) the weights in the order of the table, as the kernel takes them."""
    return np.array([weights[name] for name in reward_term_names(terms)], dtype=np.float64)


def reward_constants(control_period: float, lateral_scale: float, heading_scale: float,
                     antagonism_cap: float) -> np.ndarray:
    """(len(RewardConstant),) the constants ``k`` of the terms."""
    k = np.zeros(len(RewardConstant))
    k[RewardConstant.CONTROL_PERIOD] = control_period
    k[RewardConstant.LATERAL_SCALE] = lateral_scale
    k[RewardConstant.HEADING_SCALE] = heading_scale
    k[RewardConstant.ANTAGONISM_CAP] = antagonism_cap
    return k


def reward_table(terms: tuple[RewardTerm, ...] | None = None) -> str:
    """The Markdown table of the terms (name, default weight, unit, term) for the docs."""
    return markdown_table(("name", "weight", "unit", "term (per step)"),
                          [(t.name, f"{t.weight:g}", t.unit, t.doc) for t in _table(terms)])


_SLIP, _ANTAGONISM, _NULLSPACE = int(RS.SLIP), int(RS.ANTAGONISM), int(RS.NULLSPACE)


@njit(cache=True)
def fill_reward_inputs(ta, i, action, x):
    """Robot i's reward inputs ``x`` (len(RewardInput),) from the task's struct (the true track
    state of the track stage, the progress before the step ``ta.s_prev``, the physics' step
    means, the failure flag of the termination stage) and the step's clipped ``action`` (N, 2n)
    float32 against ``ta.prev_action``."""
    ts, summary = ta.track_out[i], ta.summary[i]
    da2 = 0.0
    for j in range(action.shape[1]):
        d = action[i, j] - ta.prev_action[i, j]  # float32, as the actions
        da2 += float(d * d)
    x[_X.PROGRESS] = ts[TQ.S]
    x[_X.PROGRESS_BEFORE] = ta.s_prev[i]
    x[_X.LATERAL_ERROR] = ts[TQ.LATERAL]
    x[_X.HEADING_ERROR] = ts[TQ.HEADING]
    x[_X.SPEED_REF] = ts[TQ.V_REF]
    x[_X.SPEED_ALONG] = ta.v_along[i]
    x[_X.TOP_SPEED] = max(ta.track_max_speed[i], 1e-3)
    x[_X.SLIP_POWER] = summary[_SLIP]
    x[_X.ANTAGONISM] = summary[_ANTAGONISM]
    x[_X.NULLSPACE_FORCE] = summary[_NULLSPACE]
    x[_X.ACTION_CHANGE] = da2
    x[_X.OFF_TRACK] = 1.0 if ta.failed[i] else 0.0


def _check_table(terms: tuple[RewardTerm, ...]) -> None:
    odd = [t for t in terms if not isinstance(t, RewardTerm)]
    if odd:
        raise ValueError(f"a reward term must be a RewardTerm, got {odd[0]!r}")
    check_table(terms, "reward terms", 3)
    if OFF_TRACK not in [t.name for t in terms]:
        raise ValueError(f"the reward terms must include {OFF_TRACK!r} (the failures' penalty)")


def reward_kernel(terms: tuple[RewardTerm, ...] | None = None, jit: bool = True) -> Callable:
    """The reward stage of the pipeline, ``reward(ta, rows, action)``, generated from a table
    (default: the module's :data:`REWARD_TERMS` as it is now): for each robot of ``rows``,
    :func:`fill_reward_inputs` into ``ta.reward_inputs[i]``, each term's function on them into
    ``ta.reward_terms[i, j]``, and their sum in the table's order into ``ta.reward[i]``.

    Its source is generated from the table (one line per term), so that adding a term is a row and
    a function (:func:`~azimut_env.task.codegen.generated_function`: cached on disk under a name
    that hashes its source and its terms'). ``jit=False``: the same source over the ``py_func``
    of the same functions (the reference path)."""
    terms = _table(terms)
    _check_table(terms)
    body = ["xi = ta.reward_inputs[i]", "_fill_inputs(ta, i, action, xi)"]
    body += [f"ta.reward_terms[i, {j}] = _term_{j}(xi, k, weights[{j}])  # {t.name}" for j, t in enumerate(terms)]
    body += ["total = 0.0  # the sum in the order of the table",
             "for j in range(ta.reward_terms.shape[1]):",
             "    total += ta.reward_terms[i, j]",
             "ta.reward[i] = total"]
    namespace = {f"_term_{j}": t.function for j, t in enumerate(terms)}
    namespace["_fill_inputs"] = fill_reward_inputs
    return row_stage("_reward", body, namespace, __file__, __name__, jit,
                     before=["k, weights = ta.reward_constants, ta.weights"])
