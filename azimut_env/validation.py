"""Input checks shared by every entry point: constructors, config dataclasses, ``reset`` options
(the ``azimut`` command line's own checks are in :mod:`jobs.args`).

The project's rule: every input is validated where it enters, with a clear ``ValueError`` (or
``TypeError`` for a value of the wrong kind) naming the input, and a refused input changes no
state. These helpers return the value converted to its canonical Python type, so a caller writes
``self.n = check_int("substeps", substeps, min_value=1)`` and stores what they return.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from gymnasium import error as gymnasium_error

__all__ = [
    "check_finite", "check_range", "check_positive", "check_nonnegative", "check_int", "check_bool",
    "check_choice", "check_real_array", "check_index_list",
    "check_seed", "check_positive_fields",
    "ResetNeeded",
]


def _is_real_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def check_finite(name: str, value: Any) -> float:
    """A finite real number (int, float or NumPy scalar; not bool, str, complex) as ``float``."""
    if not _is_real_number(value):
        raise TypeError(f"{name} must be a real number, got {value!r} ({type(value).__name__})")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def check_range(name: str, value: Any, lo: float | None = None, hi: float | None = None, *,
                lo_open: bool = False, hi_open: bool = False) -> float:
    """A finite real number in [lo, hi] (``lo_open``/``hi_open`` exclude the bound) as ``float``."""
    v = check_finite(name, value)
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ValueError(f"{name} must be {'>' if lo_open else '>='} {lo}, got {value!r}")
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise ValueError(f"{name} must be {'<' if hi_open else '<='} {hi}, got {value!r}")
    return v


def check_positive(name: str, value: Any) -> float:
    """A finite real number > 0 as ``float``."""
    return check_range(name, value, 0.0, lo_open=True)


def check_nonnegative(name: str, value: Any) -> float:
    """A finite real number >= 0 as ``float``."""
    return check_range(name, value, 0.0)


def check_positive_fields(obj: Any, *names: str, allow_zero: bool = False) -> None:
    """The fields ``names`` of the dataclass ``obj`` are finite and > 0 (>= 0 with ``allow_zero``):
    ``ValueError`` naming ``Class.field`` otherwise (the parameter dataclasses' ``__post_init__``)."""
    for name in names:
        value = getattr(obj, name)
        ok = _is_real_number(value) and math.isfinite(value) and (value >= 0 if allow_zero else value > 0)
        if not ok:
            rel = ">= 0" if allow_zero else "> 0"
            raise ValueError(f"{type(obj).__name__}.{name} must be finite and {rel}, got {value!r}")


def check_int(name: str, value: Any, min_value: int | None = None, max_value: int | None = None) -> int:
    """An integer (Python or NumPy int, or a float with an integral value; not bool, str) in
    [min_value, max_value] as ``int``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, float, np.floating)):
        raise TypeError(f"{name} must be an integer, got {value!r} ({type(value).__name__})")
    if isinstance(value, (float, np.floating)):
        if not math.isfinite(value) or value != int(value):
            raise ValueError(f"{name} must be an integer, got {value!r}")
    v = int(value)
    if min_value is not None and v < min_value:
        raise ValueError(f"{name} must be >= {min_value}, got {value!r}")
    if max_value is not None and v > max_value:
        raise ValueError(f"{name} must be <= {max_value}, got {value!r}")
    return v


def check_seed(name: str, value: Any) -> int | None:
    """A Gymnasium seed: ``None`` or an integer >= 0 (``seeding.np_random``'s rule)."""
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be None or an integer >= 0, got {value!r} ({type(value).__name__})")
    return check_int(name, value, min_value=0)


def check_bool(name: str, value: Any) -> bool:
    """A bool (Python or NumPy) as ``bool``."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be a bool, got {value!r} ({type(value).__name__})")
    return bool(value)


def check_choice(name: str, value: Any, choices: Iterable[Any]) -> Any:
    """One of ``choices`` (same type and equal; ``True`` is not ``1``)."""
    choices = tuple(choices)
    for c in choices:
        if isinstance(value, type(c)) and not (isinstance(value, (bool, np.bool_)) and not isinstance(c, bool)) \
                and value == c:
            return value
    raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")


def check_real_array(name: str, value: Any, shape: Sequence[int | None] | None = None, *,
                     finite: bool = False, dtype=np.float64) -> np.ndarray:
    """An array of real numbers (bool, int or float dtype; never complex, object or strings),
    converted to ``dtype``; ``shape`` with ``None`` for any length; ``finite`` refuses NaN/inf."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    arr = arr.astype(dtype, copy=False)
    if shape is not None:
        if arr.ndim != len(shape) or any(s is not None and a != s for a, s in zip(arr.shape, shape)):
            want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
            raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if finite and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    return arr


def check_index_list(name: str, value: Any, size: int, *, allow_empty: bool = True) -> list[int]:
    """A sequence of distinct integer indices in [0, size) (ints or NumPy ints; never floats,
    bools or strings) as a list of ``int``."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray, range)):
        raise TypeError(f"{name} must be a sequence of integers in 0..{size - 1}, got {value!r}")
    out = []
    for k in value:
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, numbers.Integral):
            raise TypeError(f"{name} must hold integers, got {k!r} ({type(k).__name__})")
        if not 0 <= int(k) < size:
            raise ValueError(f"{name}: index {int(k)} out of range 0..{size - 1}")
        out.append(int(k))
    if len(set(out)) != len(out):
        raise ValueError(f"{name} must not repeat an index, got {out}")
    if not out and not allow_empty:
        raise ValueError(f"{name} must not be empty")
    return out


class ResetNeeded(gymnasium_error.ResetNeeded, RuntimeError):
    """``step`` (or ``kick``) before a successful ``reset``: Gymnasium's ``ResetNeeded`` (also a
    ``RuntimeError``). Raised after no reset, after a reset that failed, and after a physics
    failure that ended the episode."""
