"""The C library's ``atan2`` and ``hypot`` as NumPy ufuncs: the same bits on every CPU.

NumPy dispatches ``np.arctan2`` and ``np.hypot`` (and other transcendental functions) to SIMD
implementations chosen at run time from the CPU's features: on a CPU with AVX-512, the SVML
routines NumPy bundles, whose results differ from the C library's by one unit in the last place
on some inputs (about 8% of random ``arctan2`` arguments); elsewhere, the C library's. A NumPy
computation that calls them is then not reproducible bit for bit across machines, and a compiled
(numba) kernel, which calls the C library, cannot reproduce it.

:func:`atan2` and :func:`hypot` are numba-compiled ufuncs that call the C library's functions
element by element (broadcasting as NumPy's do): the NumPy reference implementations that must
agree bit for bit with their compiled twins (the ICR controller, the target shaping, the twist
baseline) use them. ``np.sin``, ``np.cos``, ``np.sqrt`` and the arithmetic operators need no such
twin (NumPy's float64 ``sin``/``cos`` match the C library's here, and ``sqrt`` and the operators
are correctly rounded everywhere).
"""

from __future__ import annotations

import math

from numba import vectorize

__all__ = ["atan2", "hypot"]


@vectorize(["float64(float64, float64)"], cache=True)
def atan2(y, x):
    """atan2(y, x) [rad] of the C library, element by element."""
    return math.atan2(y, x)


@vectorize(["float64(float64, float64)"], cache=True)
def hypot(x, y):
    """hypot(x, y) = sqrt(x² + y²) of the C library, element by element."""
    return math.hypot(x, y)
