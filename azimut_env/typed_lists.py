"""Numba typed lists built and changed through cached compiled functions.

A ``numba.typed.List`` made or changed from Python (``List([...])``, ``lst[i] = x``,
``lst.append(x)``) compiles its methods for the element type in every new process (about a
second for the three element types the envs and controllers use), since numba does not cache
them on disk. The functions here do the same work inside ``@njit(cache=True)`` functions, which
load from the cache: the envs' per-robot tracks, the path followers' tracks, stops and holds,
and the vector env's generators are built with them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit, types
from numba.core.types.npytypes import NumPyRandomGeneratorType
from numba.typed import List

__all__ = ["array_list", "set_item", "generator_list"]

_F1, _F2 = types.float64[::1], types.float64[:, ::1]
_GEN = NumPyRandomGeneratorType("NumPyRandomGeneratorType")


@njit(cache=True)
def _empty_1d():
    return List.empty_list(_F1)


@njit(cache=True)
def _empty_2d():
    return List.empty_list(_F2)


@njit(cache=True)
def _empty_generators():
    return List.empty_list(_GEN)


@njit(cache=True)
def _append(lst, x) -> None:
    lst.append(x)


@njit(cache=True)
def _setitem(lst, i, x) -> None:
    lst[i] = x


def array_list(arrays: Sequence[np.ndarray]) -> List:
    """A typed list of C-contiguous float64 arrays, all 1-D or all 2-D (copies where an array is
    not C-contiguous float64 already)."""
    arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in arrays]
    ndim = arrays[0].ndim if arrays else 2
    if ndim not in (1, 2) or any(a.ndim != ndim for a in arrays):
        raise ValueError("array_list takes 1-D or 2-D arrays, all of one dimension")
    lst = _empty_1d() if ndim == 1 else _empty_2d()
    for a in arrays:
        _append(lst, a)
    return lst


def set_item(lst: List, i: int, x: np.ndarray) -> None:
    """``lst[i] = x`` (an array of the list's element type)."""
    _setitem(lst, int(i), x)


def generator_list(generators: Sequence[np.random.Generator]) -> List:
    """A typed list of NumPy generators (the same objects: drawing from the list advances them)."""
    lst = _empty_generators()
    for g in generators:
        _append(lst, g)
    return lst
