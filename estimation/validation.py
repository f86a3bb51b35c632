"""The input checks of every entry point: constructors, config dataclasses, function arguments,
``reset`` options (the ``azimut`` command line's own converters are in :mod:`jobs.args`).

They live here, in the lowest package, so that the estimators' entry points and every package
above use the same copy (:mod:`azimut_env.validation` re-exports them).

The project's rule: every input is validated where it enters, with a clear ``ValueError`` (or
``TypeError`` for a value of the wrong kind) naming the input, and a refused input changes no
state. The helpers return the value converted to its canonical Python type, so a caller writes
``self.n = check_int("substeps", substeps, min_value=1)`` and stores what they return.

What counts as a number, everywhere (:func:`real_scalar`):

* a Python ``int`` or ``float``, a NumPy integer or floating scalar, or a 0-d NumPy array of an
  integer or floating dtype, is a real number (converted to ``float``/``int``);
* ``bool`` and ``numpy.bool_`` (and 0-d bool arrays) are not numbers where a number is meant;
* strings, bytes, complex numbers (Python or NumPy), ``None``, arrays of one or more dimensions
  and other objects are not numbers (``TypeError``);
* an integer beyond the float range (``10**400``) is refused where a float is meant
  (``ValueError``: it is not finite as a float).

:func:`check_fields` applies the same rule to every field of a dataclass by its annotation
(``float``, ``int``, ``bool``, ``str``, each optionally ``| None``), so a config class that calls
it first in ``__post_init__`` stores canonical values in new fields without further code.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

__all__ = [
    "show", "real_scalar", "check_finite", "check_real", "check_range", "check_positive", "check_nonnegative",
    "check_int", "check_bool", "check_choice", "check_real_array", "check_index_list", "check_seed",
    "check_fields", "check_positive_fields",
]

_BOOLS = (bool, np.bool_)


def show(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters (an integer of 400 digits, a long string or a
    big array would otherwise fill the error message)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 10**40:
        return f"an integer of {len(str(abs(value)))} digits"
    try:
        text = repr(value)
    except Exception:  # a broken __repr__ must not hide the real error
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _kind(value: Any) -> str:
    return type(value).__name__


def _unwrap_0d(value: Any) -> Any:
    """A 0-d array's element (a NumPy scalar), anything else as it is."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return value[()]
    return value


def real_scalar(name: str, value: Any) -> float:
    """``value`` as a Python ``float`` if it is a real number (see the module docstring): NaN and
    ±inf are returned as they are; an integer beyond the float range raises ``ValueError``;
    anything that is not a real number raises ``TypeError``. Both name ``name``."""
    v = _unwrap_0d(value)
    if isinstance(v, _BOOLS) or not isinstance(v, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {show(value)} ({_kind(value)})")
    try:
        return float(v)
    except OverflowError:
        raise ValueError(f"{name} must be finite, got {show(value)} (beyond the float range)") from None


def check_real(name: str, value: Any, *, allow_inf: bool = False) -> float:
    """A real number as ``float``; NaN is refused, ±inf too unless ``allow_inf``."""
    v = real_scalar(name, value)
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise ValueError(f"{name} must be finite, got {show(value)}")
    return v


def check_finite(name: str, value: Any) -> float:
    """A finite real number (int, float, NumPy scalar or 0-d array; not bool, str, complex) as ``float``."""
    return check_real(name, value)


def check_range(name: str, value: Any, lo: float | None = None, hi: float | None = None, *,
                lo_open: bool = False, hi_open: bool = False) -> float:
    """A finite real number in [lo, hi] (``lo_open``/``hi_open`` exclude the bound) as ``float``."""
    v = check_finite(name, value)
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ValueError(f"{name} must be {'>' if lo_open else '>='} {lo}, got {show(value)}")
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise ValueError(f"{name} must be {'<' if hi_open else '<='} {hi}, got {show(value)}")
    return v


def check_positive(name: str, value: Any) -> float:
    """A finite real number > 0 as ``float``."""
    return check_range(name, value, 0.0, lo_open=True)


def check_nonnegative(name: str, value: Any) -> float:
    """A finite real number >= 0 as ``float``."""
    return check_range(name, value, 0.0)


def check_positive_fields(obj: Any, *names: str, allow_zero: bool = False) -> None:
    """The fields ``names`` of the frozen dataclass ``obj`` are finite and > 0 (>= 0 with
    ``allow_zero``), stored as ``float``; ``ValueError``/``TypeError`` naming ``Class.field``
    otherwise (the parameter dataclasses' ``__post_init__``)."""
    for name in names:
        label = f"{type(obj).__name__}.{name}"
        v = real_scalar(label, getattr(obj, name))
        if not (math.isfinite(v) and (v >= 0 if allow_zero else v > 0)):
            raise ValueError(f"{label} must be finite and {'>= 0' if allow_zero else '> 0'}, "
                             f"got {show(getattr(obj, name))}")
        object.__setattr__(obj, name, v)


def check_int(name: str, value: Any, min_value: int | None = None, max_value: int | None = None) -> int:
    """An integer (Python or NumPy int, a float with an integral value, or a 0-d array of either;
    not bool, str) in [min_value, max_value] as ``int``."""
    v = _unwrap_0d(value)
    if isinstance(v, _BOOLS) or not isinstance(v, numbers.Real):
        raise TypeError(f"{name} must be an integer, got {show(value)} ({_kind(value)})")
    if not isinstance(v, numbers.Integral):
        f = float(v)
        if not math.isfinite(f) or f != int(f):
            raise ValueError(f"{name} must be an integer, got {show(value)}")
    v = int(v)
    if min_value is not None and v < min_value:
        raise ValueError(f"{name} must be >= {min_value}, got {show(value)}")
    if max_value is not None and v > max_value:
        raise ValueError(f"{name} must be <= {max_value}, got {show(value)}")
    return v


def check_seed(name: str, value: Any) -> int | None:
    """A Gymnasium seed: ``None`` or an integer >= 0 (``seeding.np_random``'s rule; no floats)."""
    if value is None:
        return None
    v = _unwrap_0d(value)
    if isinstance(v, _BOOLS) or not isinstance(v, numbers.Integral):
        raise TypeError(f"{name} must be None or an integer >= 0, got {show(value)} ({_kind(value)})")
    return check_int(name, v, min_value=0)


def check_bool(name: str, value: Any) -> bool:
    """A bool (Python or NumPy, or a 0-d bool array) as ``bool``; never a number."""
    v = _unwrap_0d(value)
    if not isinstance(v, _BOOLS):
        raise TypeError(f"{name} must be a bool, got {show(value)} ({_kind(value)})")
    return bool(v)


def check_choice(name: str, value: Any, choices: Iterable[Any]) -> Any:
    """One of ``choices`` (same type and equal; ``True`` is not ``1``)."""
    choices = tuple(choices)
    for c in choices:
        if isinstance(value, type(c)) and not (isinstance(value, _BOOLS) and not isinstance(c, bool)) \
                and value == c:
            return value
    raise ValueError(f"{name} must be one of {list(choices)}, got {show(value)}")


def check_real_array(name: str, value: Any, shape: Sequence[int | None] | None = None, *,
                     finite: bool = False, dtype=np.float64, broadcast: tuple[int, ...] | None = None) -> np.ndarray:
    """An array of real numbers (bool, int or float dtype; never complex, object or strings; a
    scalar bool is refused as everywhere, an array of bools is read as 0/1), converted to
    ``dtype``; ``shape`` with ``None`` for any length; ``finite`` refuses NaN/inf (and values
    beyond ``dtype``'s range, which become inf); ``broadcast``: returned broadcast to that shape
    (a scalar, or an array that broadcasts; ``ValueError`` naming ``name`` otherwise)."""
    try:
        arr = np.asarray(value)
    except (ValueError, OverflowError) as exc:  # ragged nesting, integers beyond int64/object
        raise ValueError(f"{name} must be an array of real numbers: {exc}") from None
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    if arr.ndim == 0 and arr.dtype.kind == "b":  # a scalar bool is not a number (an array of them is 0/1)
        raise TypeError(f"{name} must be a real number or an array of them, got {show(value)} (bool)")
    with np.errstate(over="ignore"):
        arr = arr.astype(dtype, copy=False)
    if shape is not None:
        if arr.ndim != len(shape) or any(s is not None and a != s for a, s in zip(arr.shape, shape)):
            want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
            raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if finite and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    if broadcast is not None:
        try:
            return np.broadcast_to(arr, broadcast)
        except ValueError:
            raise ValueError(f"{name} must be a scalar or broadcast to shape {broadcast}, got shape {arr.shape}") \
                from None
    return arr


def check_index_list(name: str, value: Any, size: int, *, allow_empty: bool = True) -> list[int]:
    """A sequence of distinct integer indices in [0, size) (ints or NumPy ints; never floats,
    bools or strings) as a list of ``int``."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray, range)):
        raise TypeError(f"{name} must be a sequence of integers in 0..{size - 1}, got {show(value)}")
    out = []
    for k in value:
        k = _unwrap_0d(k)
        if isinstance(k, _BOOLS) or not isinstance(k, numbers.Integral):
            raise TypeError(f"{name} must hold integers, got {show(k)} ({_kind(k)})")
        if not 0 <= int(k) < size:
            raise ValueError(f"{name}: index {show(int(k))} out of range 0..{size - 1}")
        out.append(int(k))
    if len(set(out)) != len(out):
        raise ValueError(f"{name} must not repeat an index, got {out}")
    if not out and not allow_empty:
        raise ValueError(f"{name} must not be empty")
    return out


_FIELD_CHECKS = {
    "float": lambda name, value: _not_nan(name, real_scalar(name, value), value),
    "int": check_int,
    "bool": check_bool,
}


def _not_nan(name: str, v: float, value: Any) -> float:
    if math.isnan(v):
        raise ValueError(f"{name} must not be NaN, got {show(value)}")
    return v


def _check_str(name: str, value: Any) -> str:
    if not isinstance(value, str):
        raise TypeError(f"{name} must be a str, got {show(value)} ({_kind(value)})")
    return value


def check_fields(obj: Any) -> None:
    """Check the kind of every init field of the frozen dataclass ``obj`` by its annotation and
    store its canonical value: ``float`` (a real number, NaN refused, ±inf kept for the class's
    own range checks), ``int`` (:func:`check_int`), ``bool`` (:func:`check_bool`), ``str``; each
    may be ``X | None``. Other annotations are left to the class. Errors name
    ``ClassName.field``. Call it first in ``__post_init__``."""
    cls = type(obj).__name__
    for f in dataclasses.fields(obj):
        if not f.init:
            continue
        kinds = [k.strip() for k in str(f.type).split("|")]
        optional = "None" in kinds
        kinds = [k for k in kinds if k != "None"]
        if len(kinds) != 1 or kinds[0] not in ("float", "int", "bool", "str"):
            continue
        value = getattr(obj, f.name)
        if value is None and optional:
            continue
        name = f"{cls}.{f.name}"
        check = _check_str if kinds[0] == "str" else _FIELD_CHECKS[kinds[0]]
        object.__setattr__(obj, f.name, check(name, value))
