"""Input checks shared by every entry point: constructors, config dataclasses, ``reset`` options
(the ``azimut`` command line's own checks are in :mod:`jobs.args`).

The numeric, array and index checks are :mod:`estimation.validation`'s, re-exported here (one
copy, in the lowest package, so the estimators' entry points use them too); this module adds the
env's :class:`ResetNeeded`.
"""

from __future__ import annotations

from gymnasium import error as gymnasium_error

from estimation.validation import (
    check_bool,
    check_choice,
    check_fields,
    check_finite,
    check_index_list,
    check_int,
    check_nonnegative,
    check_positive,
    check_positive_fields,
    check_range,
    check_real,
    check_real_array,
    check_seed,
    real_scalar,
    show,
)

__all__ = [
    "check_finite", "check_real", "check_range", "check_positive", "check_nonnegative", "check_int", "check_bool",
    "check_choice", "check_real_array", "check_index_list", "check_seed", "check_fields", "check_positive_fields",
    "real_scalar", "show", "ResetNeeded",
]


class ResetNeeded(gymnasium_error.ResetNeeded, RuntimeError):
    """``step`` (or ``kick``) before a successful ``reset``: Gymnasium's ``ResetNeeded`` (also a
    ``RuntimeError``). Raised after no reset, after a reset that failed, and after a physics
    failure that ended the episode."""
