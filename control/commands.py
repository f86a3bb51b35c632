"""The set-points a controller sends for one control period: one type for every controller (the
ICR controller, single and batched, the twist baseline, the feed-forward driver, trained policies
and a user's own :class:`control.controller.Controller`), and :func:`checked_command`, the episode
loop's check of what a controller returned."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from control.icr.config import Mode

__all__ = ["WheelCommand", "checked_command"]


@dataclass(frozen=True)
class WheelCommand:
    """Set-points for one control period: (n,) arrays for one robot, (N, n) for a batch of N.

    Attributes:
        beta: steering set-points β_c [rad], inside the steering range.
        phidot: propulsion set-points φ̇_c [rad/s].
        beta_rate: β̇_c [rad/s] as the controller knows it (e.g. the finite difference of its
            steering set-points over the period), or None. The commanded-limit check of the
            episode loop differences the set-points themselves whatever the controller declares
            (:class:`control.limits.SetpointLimitCheck`); a declared rate over its limit counts
            too, and a NaN one is refused.
        beta_accel: β̈_c [rad/s²], or None.
        phiddot: φ̈_c [rad/s²], or None.
        info: diagnostics of the controller that made them (for the ICR controller: mode, κ, the
            target actually used, saturation flag, ...; Python scalars for one robot, (N, …)
            arrays for a batch).
        action: (N, 2n) float32 env action to send as it is, or None: the episode loop
            (:mod:`control.rollout`) then sends ``env.action_from_setpoints(beta, phidot)``.
            A trained policy gives its own action, so its rollouts stay what it was trained on;
            the commanded-limit check then reads the set-points back from the action
            (``env.setpoints_from_action``), what the env applies.
        mode: (N,) int :class:`~control.icr.config.Mode` values of the controller (its RUNNING,
            STOPPING and RECONFIGURING; None: always RUNNING). The metrics count a step as
            moving only while RUNNING.
        events: (N,) int, the stop-and-reconfigure sequences the controller has started since
            its robot's reset (None: none).
    """

    beta: np.ndarray
    phidot: np.ndarray
    beta_rate: np.ndarray | None = None
    beta_accel: np.ndarray | None = None
    phiddot: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    action: np.ndarray | None = None
    mode: np.ndarray | None = None
    events: np.ndarray | None = None


#: the set-point and rate fields of a command: (N, n) arrays of real numbers
ARRAY_FIELDS = ("beta", "phidot", "beta_rate", "beta_accel", "phiddot")
#: the declared rates among them (optional)
RATE_FIELDS = frozenset({"beta_rate", "beta_accel", "phiddot"})
#: the values a command's ``mode`` may take
_MODES = np.array([int(m) for m in Mode])


def _real_array(value, controller: str, key: str) -> np.ndarray:
    """``value`` as a float64 array, refusing what is not an array of real numbers: strings,
    bytes, complex numbers (the imaginary part would be dropped), booleans (``True`` would be read
    as 1), objects (``None``), ragged lists. The message names the controller and the field."""
    if isinstance(value, (str, bytes)):
        raise TypeError(f"controller {controller!r} returned {key} of type {type(value).__name__}, not an array "
                        "of real numbers")
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:  # a ragged list
        raise TypeError(f"controller {controller!r} returned {key} that is not an array of real numbers "
                        f"({' '.join(str(exc).split())})") from None
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"controller {controller!r} returned {key} of dtype {arr.dtype}, not an array of real "
                        "numbers (floats or integers; no bool, complex, string or object)")
    return arr.astype(np.float64, copy=True)


def checked_command(cmd, controller: str, num: int, n: int) -> WheelCommand:
    """``cmd`` checked as the command of ``num`` robots of ``n`` wheels from the controller named
    ``controller``, with its set-points and rates as float64 arrays (copies).

    Refused, with a message naming the controller and the field: not a :class:`WheelCommand`
    (``TypeError``); a set-point or rate that is not an array of real numbers (strings, complex,
    bool, object: ``TypeError``); a shape other than (num, n) ((num, 2n) for ``action``, (num,)
    for ``mode`` and ``events``), a NaN or infinite set-point, a NaN rate, a NaN or infinite
    action (``ValueError``). An infinite declared rate is a number, over its limit: the
    commanded-limit check counts it.
    """
    if not isinstance(cmd, WheelCommand):
        raise TypeError(f"controller {controller!r}: act() must return a WheelCommand, got {type(cmd).__name__}")
    out = {}
    for key in ARRAY_FIELDS:
        value = getattr(cmd, key)
        if value is None:
            out[key] = None
            continue
        arr = out[key] = _real_array(value, controller, key)
        if arr.shape != (num, n):
            raise ValueError(f"controller {controller!r}: command {key} must have shape ({num}, {n}), "
                             f"got {arr.shape}")
        rate = key in RATE_FIELDS
        bad = np.isnan(arr) if rate else ~np.isfinite(arr)
        if bad.any():
            i, k = (int(j) for j in np.argwhere(bad)[0])
            what = "NaN" if rate else "NaN or inf"
            raise ValueError(f"controller {controller!r} returned {key} with {what} ({arr[i, k]} at robot {i}, "
                             f"wheel {k}; {int(bad.sum())} value(s) in all)")
    action = cmd.action
    if action is not None:
        try:
            arr = np.asarray(action)
        except (TypeError, ValueError) as exc:  # a ragged list
            raise TypeError(f"controller {controller!r} returned action that is not an array of real numbers "
                            f"({' '.join(str(exc).split())})") from None
        if arr.dtype.kind not in "biuf":  # bools are 0/1, the env's convention for actions
            raise TypeError(f"controller {controller!r} returned action of dtype {arr.dtype}, not an array of real "
                            "numbers")
        if arr.shape != (num, 2 * n):
            raise ValueError(f"controller {controller!r}: command action must have shape ({num}, {2 * n}), "
                             f"got {arr.shape}")
        if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
            raise ValueError(f"controller {controller!r} returned action with NaN or inf")
    elif out["beta"] is None or out["phidot"] is None:
        missing = "beta" if out["beta"] is None else "phidot"
        raise TypeError(f"controller {controller!r} returned {missing} None: a WheelCommand needs beta and phidot "
                        "(or an action)")
    ints = {}
    for key in ("mode", "events"):
        value = getattr(cmd, key)
        if value is None:
            ints[key] = None
            continue
        try:
            arr = np.asarray(value)
        except (TypeError, ValueError):
            arr = np.asarray(value, dtype=object)
        if arr.dtype.kind not in "iu":
            raise TypeError(f"controller {controller!r} returned {key} of dtype {arr.dtype}, not integers")
        if arr.shape != (num,):
            raise ValueError(f"controller {controller!r}: command {key} must have shape ({num},), got {arr.shape}")
        valid = np.isin(arr, _MODES) if key == "mode" else arr >= 0
        if not valid.all():
            i = int(np.flatnonzero(~valid)[0])
            what = f"one of {', '.join(f'{int(m)} ({m.name})' for m in Mode)}" if key == "mode" else "a count >= 0"
            raise ValueError(f"controller {controller!r} returned {key} {arr[i]} at robot {i}, not {what}")
        ints[key] = arr.astype(np.int64)
    return WheelCommand(info=cmd.info, action=cmd.action, **ints, **out)
