"""The ``info`` of ``Azimut-v2``: one table of keys that both envs build their info from.

:data:`INFO_FIELDS` is the single description of the info dict: each key's name, its value for
one robot (shape, with n the number of wheels), its unit and meaning, whether a step whose
physics blew up has it, and how it is read from :class:`~azimut_env.task.core.AzimutTask`. It drives

* :func:`robot_info`: the single env's info (per-robot shapes; scalars as Python ``float``/``bool``;
  ``reward_terms`` a dict of floats by term name; ``eta_true``, ``eta_hat`` pairs (λ (3,), μ));
* :func:`batch_info`: the vector env's info, Gymnasium's vector convention: each value with a
  leading ``num_envs`` axis (a pair: a pair of batched arrays; ``reward_terms``: a dict of (N,)
  arrays with their own masks) and a boolean mask ``"_key"`` saying which sub-envs have the key;
* :func:`sub_info`: sub-env i's entries of a batched info, which equal the single env's info of a
  robot in the same state, key by key and bit for bit;
* :func:`info_table`: the Markdown table of the docs (:mod:`azimut_env.doc_tables`).

The end conditions' keys (a bool each) come from the termination table
(:data:`~azimut_env.task.termination.TERMINATION_TERMS`, :func:`info_fields`).

Every value is ground truth or the robot's own estimate as named, whatever the observation's pose
source. On the step whose physics blew up (``error``) only the keys with ``at_error`` are given
(the robot is parked: its pose and forces would be those of the rest state, not of the failure).
**To add a key**: a row here, with its reader.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numba import njit

from azimut_env.physics.layout import RS, RS_POSE, RS_TWIST_BODY, WS, WS_FORCE
from azimut_env.task import termination
from azimut_env.task.codegen import markdown_table
from azimut_env.task.termination import EndCondition

if TYPE_CHECKING:
    from azimut_env.task.core import AzimutTask

__all__ = ["InfoField", "INFO_FIELDS", "INFO_KEYS", "KINDS", "info_fields", "robot_info", "batch_info", "sub_info",
           "info_table", "true_eta"]

# plain-int columns (numpy indexes with IntEnum members several µs slower, and this runs every step)
_RS_SLIP, _WS_BETA = int(RS.SLIP), int(WS.BETA)
_RS_ANTAGONISM, _RS_NULLSPACE = int(RS.ANTAGONISM), int(RS.NULLSPACE)
_RS_POSE = slice(int(RS_POSE.start), int(RS_POSE.stop))
_RS_TWIST = np.array([int(c) for c in RS_TWIST_BODY], dtype=np.intp)
_WS_FORCE = slice(int(WS_FORCE.start), int(WS_FORCE.stop))


@njit(cache=True)
def _canonical_lambda(twist, mu, lam):
    """λ ∝ (−ẏ, ẋ, θ̇) of each twist (N, 3) with its norm μ (N,) (λ = (0, 0, 1) at rest); below
    μ = 1e-3 the sign rule of ``canonical_eta(mu_tol=1e-3)``: the first nonzero of (w, u, v) ≥ 0,
    flipping μ with it. Writes ``lam`` (N, 3) and ``mu`` in place."""
    for i in range(twist.shape[0]):
        m = mu[i]
        if m > 0:
            lam[i, 0] = (-twist[i, 1]) / m
            lam[i, 1] = twist[i, 0] / m
            lam[i, 2] = twist[i, 2] / m
        else:
            lam[i, 0], lam[i, 1], lam[i, 2] = 0.0, 0.0, 1.0
        if m <= 1e-3:
            key = lam[i, 2] if lam[i, 2] != 0 else (lam[i, 0] if lam[i, 0] != 0 else lam[i, 1])
            if key < 0:
                lam[i, 0], lam[i, 1], lam[i, 2] = -lam[i, 0], -lam[i, 1], -lam[i, 2]
                mu[i] = -m


def true_eta(twist: np.ndarray) -> tuple[np.ndarray, Any]:
    """The true H state (λ, μ) of chassis twists ξ̇ = (ẋ, ẏ, θ̇) (3,) or (N, 3) in the chassis frame:
    ξ̇ = μ (v, −u, w), so λ ∝ (−ẏ, ẋ, θ̇) and μ = ‖ξ̇‖ ≥ 0, with the canonical sign at μ ≤ 1e-3 (as
    the estimate). Returns ((3,), float) or ((N, 3), (N,))."""
    tw = np.asarray(twist, dtype=np.float64)
    # ‖ξ̇‖² as the sum written out, one robot or a batch (a BLAS dot product may round differently on
    # some CPUs), so a robot's value is its row of the batch, bit for bit, on every CPU
    if tw.ndim == 1:  # one robot (the single env, every step): the operations of a row of the batch
        x, y, w = tw.tolist()
        mu = math.sqrt(x * x + y * y + w * w)
        u, v, w = (-y / mu, x / mu, w / mu) if mu > 0 else (0.0, 0.0, 1.0)
        if mu <= 1e-3 and (w if w != 0 else (u if u != 0 else v)) < 0:
            u, v, w, mu = -u, -v, -w, -mu
        return np.array([u, v, w]), mu
    mu = np.sqrt(tw[:, 0] * tw[:, 0] + tw[:, 1] * tw[:, 1] + tw[:, 2] * tw[:, 2])
    lam = np.empty_like(tw)
    _canonical_lambda(tw, mu, lam)
    return lam, mu


class InfoField(NamedTuple):
    """One key of the info dict: a row of :data:`INFO_FIELDS`."""

    name: str
    #: the value of one robot: ``()`` a scalar, ``(3,)``, ``(n,)``..., ``((3,), ())`` a pair (λ, μ),
    #: ``{term: ()}`` a dict by reward term
    shape: str
    unit: str
    doc: str
    #: present on the step whose physics blew up
    at_error: bool
    #: ``source(task, rows)``: the values of robot ``rows`` (an int) or of every robot (``slice(None)``,
    #: a leading robot axis), views where they can be; None for ``error``, which the env supplies
    source: Callable[[AzimutTask, Any], Any] | None
    #: how a robot's value and the batch are made from the source's: a key of :data:`KINDS`
    kind: str


def _copy(v):
    return v.copy()


def _one_pair(v):
    return v[0].copy(), float(v[1])


def _one_terms(v):
    names, terms = v
    return dict(zip(names, terms.tolist()))  # tolist: Python floats


def _all_terms(v):
    names, terms = v
    columns = terms.T.copy()
    return {name: columns[j] for j, name in enumerate(names)}


#: kind -> (one robot's value from its source value, the batch from the source's batch)
KINDS: dict[str, tuple[Callable, Callable]] = {
    "array": (_copy, _copy),
    "float": (float, _copy),
    "bool": (bool, _copy),
    "eta": (true_eta, true_eta),
    "pair": (_one_pair, lambda v: (v[0].copy(), v[1].copy())),
    "terms": (_one_terms, _all_terms),
    "error": (None, None),
}


def _twist(t: AzimutTask, r) -> np.ndarray:
    return t.physics.summary[r].take(_RS_TWIST, axis=-1)  # a copy (take: faster than fancy indexing)


def _pose_estimate(t: AzimutTask, r) -> np.ndarray:
    return t.odometry.pose[r] if t.odometry is not None else t.physics.summary[r, _RS_POSE]


_F = InfoField
#: the info dict, key by key
INFO_FIELDS: tuple[InfoField, ...] = (
    _F("pose", "(3,)", "m, m, rad", "true chassis pose (x, y, θ), world frame", False,
       lambda t, r: t.physics.summary[r, _RS_POSE], "array"),
    _F("pose_estimate", "(3,)", "m, m, rad", "the pose the observation used (pose_source)", False, _pose_estimate,
       "array"),
    _F("twist", "(3,)", "m/s, rad/s", "true chassis twist (ẋ, ẏ, θ̇), chassis frame", False, _twist, "array"),
    _F("eta_true", "((3,), ())", "-, m/s", "true H state (λ, μ) of the twist, canonical sign", False, _twist,
       "eta"),
    _F("eta_hat", "((3,), ())", "-, m/s", "IT estimate (λ̂, μ̂), the observation's", False,
       lambda t, r: (t.lam_hat[r], t.mu_hat[r]), "pair"),
    _F("beta_true", "(n,)", "rad", "true steering angles (wheel side of the spring)", False,
       lambda t, r: t.physics.wheel_summary[r, :, _WS_BETA], "array"),
    _F("beta_est", "(n,)", "rad", "S(λ̂): steering angles of the estimated ICR", False, lambda t, r: t.beta_est[r],
       "array"),
    _F("tire_forces", "(n, 2)", "N", "step-mean tire forces (F_x, F_y), chassis frame", False,
       lambda t, r: t.physics.wheel_summary[r, :, _WS_FORCE], "array"),
    _F("slip_power", "()", "W", "step-mean tire slip power Σ abs(F·v_slip)", False,
       lambda t, r: t.physics.summary[r, _RS_SLIP], "float"),
    _F("antagonism", "()", "N", "step-mean antagonism: stiffness-weighted internal force", False,
       lambda t, r: t.physics.summary[r, _RS_ANTAGONISM], "float"),
    _F("nullspace_force", "()", "N", "step-mean min-norm null-space force of the tires", False,
       lambda t, r: t.physics.summary[r, _RS_NULLSPACE], "float"),
    _F("qua", "()", "-", "qua of the measured steering angles (eq. 28–29)", False, lambda t, r: t.qua[r], "float"),
    _F("progress", "()", "m", "true progress along the track (unwrapped over laps)", False, lambda t, r: t.s[r],
       "float"),
    _F("lateral_error", "()", "m", "true distance to the path, positive to its left", False, lambda t, r: t.lat[r],
       "float"),
    _F("heading_error", "()", "rad", "true θ − θ_ref, wrapped", False, lambda t, r: t.head[r], "float"),
    _F("reward_terms", "{term: ()}", "-", "the reward terms of the step by name (0 at a reset)", True,
       lambda t, r: (t.reward_names, t.reward_terms[r]), "terms"),
    # then one bool key per end condition (info_fields), and the error
)
_ERROR_FIELD = _F("error", "()", "str", "the physics failure, only on the step that blew up", True, None, "error")
del _F


def _end_field(j: int, term: EndCondition) -> InfoField:
    return InfoField(term.name, "()", "bool", term.doc, True,
                     lambda t, r: t.ended[r, j], "bool")


def info_fields(terms: tuple[EndCondition, ...] | None = None) -> tuple[InfoField, ...]:
    """The info keys of a termination table (default: :data:`TERMINATION_TERMS` as it is now): the
    task's, one bool per end condition, and ``error``."""
    terms = termination.TERMINATION_TERMS if terms is None else terms
    return INFO_FIELDS[:_BASE] + tuple(_end_field(j, t) for j, t in enumerate(terms)) + (_ERROR_FIELD,)


_BASE = len(INFO_FIELDS)
#: the info dict, key by key (with the default end conditions)
INFO_FIELDS = info_fields()
#: the keys, in the order of the table
INFO_KEYS = tuple(f.name for f in INFO_FIELDS)
_ERROR = _ERROR_FIELD.name
_READERS_OF: dict[int, tuple] = {}


def _readers(task: AzimutTask) -> tuple:
    """(name, at_error, source, one robot's value, the batch) of the keys the task holds, in the
    table's order (its end conditions')."""
    key = task.termination_table
    entry = _READERS_OF.get(id(key))  # by identity: hashing the table every step costs a microsecond
    if entry is None or entry[0] is not key:
        entry = _READERS_OF[id(key)] = (key, tuple((f.name, f.at_error, f.source, *KINDS[f.kind])
                                                   for f in info_fields(key) if f.source is not None))
    return entry[1]


def robot_info(task: AzimutTask, i: int, error: str | None = None) -> dict[str, Any]:
    """Robot i's info as the single env gives it (per-robot shapes, scalars as Python ``float`` and
    ``bool``); with ``error`` (its physics blew up on this step) only the keys with ``at_error``,
    and ``error``."""
    out: dict[str, Any] = {}
    last, values = None, None
    for name, at_error, source, one, _ in _readers(task):
        if error is None or at_error:
            if source is not last:  # consecutive keys of one source (twist, eta_true) read it once
                last, values = source, source(task, i)
            out[name] = one(values)
    if error is not None:
        out[_ERROR] = error
    return out


def batch_info(task: AzimutTask, errors: list[str | None] | None = None) -> dict[str, Any]:
    """The info of every robot (the vector env's), each value with a leading robot axis and a mask
    ``"_key"``; ``errors`` (N,) the physics failure message of each robot whose physics blew up on
    this step (None elsewhere): those robots have only the keys with ``at_error``, and ``error``."""
    N = task.n_robots
    errored = None if errors is None else np.array([e is not None for e in errors], dtype=np.bool_)
    if errored is not None and not errored.any():
        errored = None
    readers = _readers(task)
    masks = iter(np.ones((len(readers) + len(task.reward_names), N), dtype=np.bool_))  # a row per mask
    out: dict[str, Any] = {}
    last, values, everyone = None, None, slice(None)
    for name, at_error, source, _, batch in readers:
        if source is not last:
            last, values = source, source(task, everyone)
        value = batch(values)
        if isinstance(value, dict):  # the reward terms, each with its mask
            for key in list(value):
                value["_" + key] = next(masks)
                if errored is not None and not at_error:
                    value["_" + key][:] = ~errored
        mask = next(masks)
        if errored is not None and not at_error:
            mask[:] = ~errored
        out[name] = value
        out["_" + name] = mask
    if errored is not None:
        err = np.full(N, None, dtype=object)
        for i in np.flatnonzero(errored):
            err[i] = errors[i]
        out[_ERROR] = err
        out["_" + _ERROR] = errored
    return out


def _item(value: Any, i: int) -> Any:
    if isinstance(value, tuple):
        return tuple(_item(v, i) for v in value)
    if isinstance(value, dict):
        return {k: _item(v, i) for k, v in value.items() if not k.startswith("_") and value["_" + k][i]}
    x = value[i]
    if isinstance(x, np.ndarray):
        return x.copy()
    return x.item() if isinstance(x, np.generic) else x


def sub_info(info: dict[str, Any], i: int) -> dict[str, Any]:
    """Sub-env i's entries of a batched info (:func:`batch_info`'s convention): the keys whose mask
    holds i, each value without the leading axis (NumPy scalars as Python ones)."""
    return {k: _item(v, i) for k, v in info.items()
            if not k.startswith("_") and f"_{k}" in info and info[f"_{k}"][i]}


def info_table() -> str:
    """The Markdown table of the keys (name, value of one robot, unit, content) for the docs."""
    return markdown_table(("key", "value", "unit", "content"), [(f.name, f.shape, f.unit, f.doc) for f in INFO_FIELDS])
