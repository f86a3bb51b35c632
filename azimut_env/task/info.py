"""The ``info`` of ``Azimut-v1``: one table of keys that both envs build their info from.

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
* :func:`info_table`: the Markdown table of the envs' docstrings.

Every value is ground truth or the robot's own estimate as named, whatever the observation's pose
source. On the step whose physics blew up (``error``) only the keys with ``at_error`` are given
(the robot is parked: its pose and forces would be those of the rest state, not of the failure).
To add a key: a row here, with its reader.
"""

from __future__ import annotations

import unicodedata
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numba import njit

from azimut_env.physics.layout import RS, RS_POSE, RS_TWIST_BODY, WS, WS_FORCE

if TYPE_CHECKING:
    from azimut_env.task.core import AzimutTask

__all__ = ["InfoField", "INFO_FIELDS", "INFO_KEYS", "robot_info", "batch_info", "sub_info", "info_table", "true_eta"]

_RS_SLIP, _RS_INTERNAL, _WS_BETA = int(RS.SLIP), int(RS.INTERNAL), int(WS.BETA)


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
    batch = np.atleast_2d(tw)
    mu = np.sqrt((batch[:, None, :] @ batch[:, :, None])[:, 0, 0])  # the dot product of ``twist @ twist``
    lam = np.empty_like(batch)
    _canonical_lambda(batch, mu, lam)
    return (lam[0], float(mu[0])) if tw.ndim == 1 else (lam, mu)


class InfoField(NamedTuple):
    """One key of the info dict: a row of :data:`INFO_FIELDS`."""

    name: str
    #: the value of one robot: ``()`` a scalar, ``(3,)``, ``(n,)``..., ``(λ (3,), μ ())`` a pair,
    #: ``{term: ()}`` a dict by reward term
    shape: str
    unit: str
    doc: str
    #: present on the step whose physics blew up
    at_error: bool
    #: ``read(task, rows)``: the value of robot ``rows`` (an int) or of every robot (``slice(None)``,
    #: a leading axis); None for ``error``, which the env supplies
    read: Callable[[AzimutTask, Any], Any] | None


def _reward_terms(task: AzimutTask, rows) -> dict[str, Any]:
    if isinstance(rows, slice):
        columns = task.reward_terms.T.copy()
        return {name: columns[j] for j, name in enumerate(task.reward_names)}
    return dict(zip(task.reward_names, task.reward_terms[rows].tolist()))


_F = InfoField
#: the info dict, key by key
INFO_FIELDS: tuple[InfoField, ...] = (
    _F("pose", "(3,)", "m, m, rad", "true chassis pose (x, y, θ), world frame", False,
       lambda t, r: t.physics.summary[r, RS_POSE].copy()),
    _F("pose_estimate", "(3,)", "m, m, rad", "the pose the observation used (pose_source)", False,
       lambda t, r: t.pose_estimates()[r]),
    _F("twist", "(3,)", "m/s, rad/s", "true chassis twist (ẋ, ẏ, θ̇), chassis frame", False,
       lambda t, r: t.physics.summary[r, RS_TWIST_BODY]),
    _F("eta_true", "((3,), ())", "-, m/s", "true H state (λ, μ) of the twist, canonical sign", False,
       lambda t, r: true_eta(t.physics.summary[r, RS_TWIST_BODY])),
    _F("eta_hat", "((3,), ())", "-, m/s", "IT estimate (λ̂, μ̂), the observation's", False,
       lambda t, r: (t.lam_hat[r].copy(), t.mu_hat[r].copy() if isinstance(r, slice) else float(t.mu_hat[r]))),
    _F("beta_true", "(n,)", "rad", "true steering angles (wheel side of the spring)", False,
       lambda t, r: t.physics.wheel_summary[r, :, _WS_BETA].copy()),
    _F("beta_est", "(n,)", "rad", "S(λ̂): steering angles of the estimated ICR", False,
       lambda t, r: t.beta_est[r].copy()),
    _F("tire_forces", "(n, 2)", "N", "step-mean tire forces (F_x, F_y), chassis frame", False,
       lambda t, r: t.physics.wheel_summary[r, :, WS_FORCE].copy()),
    _F("slip_power", "()", "W", "step-mean tire slip power Σ abs(F·v_slip)", False,
       lambda t, r: t.physics.summary[r, _RS_SLIP].copy()),
    _F("internal_force", "()", "N", "step-mean internal force of the wheels", False,
       lambda t, r: t.physics.summary[r, _RS_INTERNAL].copy()),
    _F("qua", "()", "-", "qua of the measured steering angles (eq. 28–29)", False,
       lambda t, r: t.qua[r].copy()),
    _F("progress", "()", "m", "true progress along the track (unwrapped over laps)", False,
       lambda t, r: t.s[r].copy()),
    _F("lateral_error", "()", "m", "true distance to the path, positive to its left", False,
       lambda t, r: t.lat[r].copy()),
    _F("heading_error", "()", "rad", "true θ − θ_ref, wrapped", False, lambda t, r: t.head[r].copy()),
    _F("reward_terms", "{term: ()}", "-", "the reward terms of the step by name (0 at a reset)", True,
       _reward_terms),
    _F("off_track", "()", "bool", "the step left the track (terminated)", True, lambda t, r: t.off_track[r].copy()),
    _F("finished", "()", "bool", "the step finished the track (terminated)", True, lambda t, r: t.finished[r].copy()),
    _F("stalled", "()", "bool", "the step ended a stall (terminated)", True, lambda t, r: t.stalled[r].copy()),
    _F("error", "()", "str", "the physics failure, only on the step that blew up", True, None),
)
del _F

#: the keys, in the order of the table
INFO_KEYS = tuple(f.name for f in INFO_FIELDS)


def _python(value: Any) -> Any:
    """NumPy scalars (0-d) as Python ``float``/``bool``, inside pairs too."""
    if isinstance(value, tuple):
        return tuple(_python(v) for v in value)
    if (isinstance(value, np.ndarray) and value.ndim == 0) or isinstance(value, np.generic):
        return value.item()
    return value


def robot_info(task: AzimutTask, i: int, error: str | None = None) -> dict[str, Any]:
    """Robot i's info as the single env gives it (per-robot shapes); with ``error`` (its physics
    blew up on this step) only the keys with ``at_error``, and ``error``."""
    out: dict[str, Any] = {}
    for f in INFO_FIELDS:
        if f.read is None:
            if error is not None:
                out[f.name] = error
        elif error is None or f.at_error:
            out[f.name] = _python(f.read(task, i))
    return out


def batch_info(task: AzimutTask, errors: list[str | None] | None = None) -> dict[str, Any]:
    """The info of every robot (the vector env's), each value with a leading robot axis and a mask
    ``"_key"``; ``errors`` (N,) the physics failure message of each robot whose physics blew up on
    this step (None elsewhere): those robots have only the keys with ``at_error``, and ``error``."""
    N = task.n_robots
    errored = np.zeros(N, dtype=np.bool_)
    if errors is not None:
        errored = np.array([e is not None for e in errors], dtype=np.bool_)
    fine = ~errored
    every = np.ones(N, dtype=np.bool_)
    out: dict[str, Any] = {}
    for f in INFO_FIELDS:
        if f.read is None:
            if errored.any():
                err = np.full(N, None, dtype=object)
                for i in np.flatnonzero(errored):
                    err[i] = errors[i]
                out[f.name] = err
                out["_" + f.name] = errored
            continue
        value = f.read(task, slice(None))
        mask = every.copy() if f.at_error else fine.copy()
        if isinstance(value, dict):
            for name in list(value):
                value["_" + name] = mask.copy()
        out[f.name] = value
        out["_" + f.name] = mask
    return out


def _item(value: Any, i: int) -> Any:
    if isinstance(value, tuple):
        return tuple(_item(v, i) for v in value)
    if isinstance(value, dict):
        return {k: _item(v, i) for k, v in value.items() if not k.startswith("_") and value["_" + k][i]}
    x = value[i]
    return x.copy() if isinstance(x, np.ndarray) else _python(x)


def sub_info(info: dict[str, Any], i: int) -> dict[str, Any]:
    """Sub-env i's entries of a batched info (:func:`batch_info`'s convention): the keys whose mask
    holds i, each value without the leading axis (0-d values as Python scalars)."""
    return {k: _item(v, i) for k, v in info.items() if not k.startswith("_") and f"_{k}" in info and info[f"_{k}"][i]}


def info_table() -> str:
    """The Markdown table of the keys (name, value of one robot, unit, content) for the docstrings."""
    def width(text: str) -> int:  # combining marks (the hat of λ̂, the dot of θ̇) take no column
        return sum(not unicodedata.combining(c) for c in text)

    rows = [("key", "value", "unit", "content")]
    rows += [(f.name, f.shape, f.unit, f.doc) for f in INFO_FIELDS]
    widths = [max(width(r[j]) for r in rows) for j in range(4)]
    line = lambda r: "| " + " | ".join(x + " " * (w - width(x)) for x, w in zip(r, widths)) + " |"  # noqa: E731
    return "\n".join([line(rows[0]), "|" + "|".join("-" * (w + 2) for w in widths) + "|"] + [line(r) for r in rows[1:]])
