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
* off track −w on the step that leaves the track; a stall pays it too (:func:`charge_penalty`,
  called by the termination stage), and a physics blow-up gets it as its reward.

**To add a term**: write its function and add its row to :data:`REWARD_TERMS`. A term that reads a
quantity no term reads yet also adds a column to :class:`RewardInput` (and its value to
:func:`fill_reward_inputs`) or to :class:`RewardConstant` (and to :func:`reward_constants`).

Data flow (:meth:`~azimut_env.task.core.AzimutTask.observe`): one call of :func:`reward_kernel`'s
compiled function, generated from the table: :func:`fill_reward_inputs` writes each robot's
inputs, then each term's function per robot, then the sum, into the terms and the reward.
"""

from __future__ import annotations

import hashlib
import inspect
import math
from collections.abc import Callable, Iterator, Mapping
from enum import IntEnum
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from azimut_env.task.observation import speed_along
from azimut_env.tracks import TQ
from azimut_env.validation import real_scalar, show

__all__ = ["RewardTerm", "REWARD_TERMS", "current_reward_terms", "RewardInput", "RewardConstant", "RewardWeights",
           "OFF_TRACK", "RENAMED_TERMS", "reward_term_names", "default_reward_weights", "check_reward_weights",
           "reward_weight_array",
           "reward_constants", "reward_table", "fill_reward_inputs", "reward_kernel", "charge_penalty"]


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
    OFF_TRACK = 11       # 1.0 on the step that leaves the track, else 0.0


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
    """The Markdown table of the terms (name, default weight, unit, term) for the env's docstring."""
    rows = [("name", "weight", "unit", "term (per step)")]
    rows += [(t.name, f"{t.weight:g}", t.unit, t.doc.replace("|", "\\|")) for t in _table(terms)]
    widths = [max(len(r[j]) for r in rows) for j in range(4)]
    line = lambda r: "| " + " | ".join(x.ljust(w) for x, w in zip(r, widths)) + " |"  # noqa: E731
    return "\n".join([line(rows[0]), "|" + "|".join("-" * (w + 2) for w in widths) + "|"] + [line(r) for r in rows[1:]])


@njit(cache=True)
def fill_reward_inputs(rows, track_state, s_prev, vel_world, max_speeds, slip, antagonism, nullspace, action,
                       prev_action, off_track, v_along, x):
    """For the robots where ``rows`` is True: the speed along the path ``v_along`` (N,) and the
    reward inputs ``x`` (N, len(RewardInput)).

    ``track_state`` (N, 5) (columns :class:`~azimut_env.tracks.TQ`) and ``vel_world`` (N, 2) are
    the true ones, ``s_prev`` the progress before the step, ``max_speeds`` each track's top
    reference speed, ``slip`` [W], ``antagonism`` and ``nullspace`` [N] the physics' step means, ``action`` and
    ``prev_action`` (N, 2n) float32, ``off_track`` the termination flags of this step."""
    for i in range(rows.shape[0]):
        if not rows[i]:
            continue
        ts = track_state[i]
        va = speed_along(vel_world[i], ts[TQ.PSI])
        v_along[i] = va
        da2 = 0.0
        for j in range(action.shape[1]):
            d = action[i, j] - prev_action[i, j]  # float32, as the actions
            da2 += d * d
        xi = x[i]
        xi[_X.PROGRESS] = ts[TQ.S]
        xi[_X.PROGRESS_BEFORE] = s_prev[i]
        xi[_X.LATERAL_ERROR] = ts[TQ.LATERAL]
        xi[_X.HEADING_ERROR] = ts[TQ.HEADING]
        xi[_X.SPEED_REF] = ts[TQ.V_REF]
        xi[_X.SPEED_ALONG] = va
        xi[_X.TOP_SPEED] = max(max_speeds[i], 1e-3)
        xi[_X.SLIP_POWER] = slip[i]
        xi[_X.ANTAGONISM] = antagonism[i]
        xi[_X.NULLSPACE_FORCE] = nullspace[i]
        xi[_X.ACTION_CHANGE] = da2
        xi[_X.OFF_TRACK] = 1.0 if off_track[i] else 0.0


def _check_table(terms: tuple[RewardTerm, ...]) -> None:
    names = [t.name for t in terms]
    if len(set(names)) != len(names):
        raise ValueError(f"reward terms must have distinct names, got {names}")
    for t in terms:
        if not isinstance(t, RewardTerm) or not t.name.isidentifier():
            raise ValueError(f"a reward term must be a RewardTerm named by an identifier, got {t!r}")
        py_func = getattr(t.function, "py_func", None)
        if py_func is None or len(inspect.signature(py_func).parameters) != 3:
            raise TypeError(f"reward term {t.name!r}: its function must be numba.njit-compiled and take (x, k, w)")
    if OFF_TRACK not in names:
        raise ValueError(f"the reward terms must include {OFF_TRACK!r} (the termination stage charges it)")


_KERNELS: dict[tuple, Callable] = {}


def reward_kernel(terms: tuple[RewardTerm, ...] | None = None) -> Callable:
    """The compiled reward stage of a table (default: the module's :data:`REWARD_TERMS` as it is
    now), ``kernel(rows, <the inputs of fill_reward_inputs>, x, k, weights, terms_out, reward)``:
    :func:`fill_reward_inputs` into ``x``, then for the robots where ``rows`` is True each term's
    function on the robot's inputs ``x[i]`` into ``terms_out[i, j]`` (N, len(terms)), and their sum
    in the table's order into ``reward[i]``; one compiled call per step.

    Its source is generated from the table (one line per term), so that adding a term is a row and
    a function. It is cached on disk by numba as if it were defined in this file, under a name that
    hashes its source and the source of every function it calls: an edited term gets a new kernel,
    never a stale one (a function without retrievable source is compiled without the disk cache)."""
    terms = _table(terms)
    key = tuple((t.name, t.function) for t in terms)
    kernel = _KERNELS.get(key)
    if kernel is None:
        _check_table(terms)
        kernel = _KERNELS[key] = _compile_kernel(terms)
    return kernel


_FILL_ARGS = ("rows, track_state, s_prev, vel_world, max_speeds, slip, antagonism, nullspace, action, prev_action, "
              "off_track, v_along, x")


def _compile_kernel(terms: tuple[RewardTerm, ...]) -> Callable:
    body = [f"({_FILL_ARGS}, k, weights, terms, reward):",
            f"    _fill_inputs({_FILL_ARGS})",
            "    for i in range(rows.shape[0]):",
            "        if not rows[i]:",
            "            continue",
            "        xi = x[i]"]
    body += [f"        terms[i, {j}] = _term_{j}(xi, k, weights[{j}])  # {t.name}" for j, t in enumerate(terms)]
    body += ["        total = 0.0  # the sum in the order of the table",
             "        for j in range(terms.shape[1]):",
             "            total += terms[i, j]",
             "        reward[i] = total"]
    body_src = "\n".join(body)
    called = [fill_reward_inputs, speed_along] + [t.function for t in terms]
    try:
        sources = [inspect.getsource(f.py_func) for f in called]
        cache = True
    except (OSError, TypeError):
        sources, cache = [], False
    digest = hashlib.sha256("\n".join([body_src, *sources]).encode()).hexdigest()[:16]
    name = f"_reward_kernel_{digest}"
    namespace = {f"_term_{j}": t.function for j, t in enumerate(terms)}
    namespace["_fill_inputs"] = fill_reward_inputs
    namespace["__name__"] = __name__
    # compiled under this file's name: numba's disk cache needs a source file to key its index on
    exec(compile(f"def {name}{body_src}\n", __file__, "exec"), namespace)
    return njit(cache=cache)(namespace[name])


def charge_penalty(mask: np.ndarray, penalty: float, reward: np.ndarray, terms: np.ndarray, column: int) -> None:
    """The robots of ``mask`` pay the off-track ``penalty`` once (a stall): their off-track term
    (``terms[:, column]``) becomes −penalty and their reward changes by the difference."""
    reward[mask] += -penalty - terms[mask, column]
    terms[mask, column] = -penalty
