"""The C library's ``atan2``, ``hypot`` and ``log1p`` as NumPy ufuncs: the same bits on every CPU.

NumPy dispatches its transcendental ufuncs to SIMD implementations chosen at run time from the
CPU's features: on a CPU with AVX-512, the SVML routines NumPy bundles for float64 ``arctan2``,
``arctan``, ``exp``, ``expm1``, ``log``, ``log1p`` and ``tan``, whose results differ from the C
library's by one unit in the last place on some inputs (about 8% of random ``arctan2``
arguments, 5% of ``log1p``'s); ``tanh`` on AVX2 CPUs too; elsewhere, the C library's. A NumPy
computation that calls them is then not reproducible bit for bit across machines, and a compiled
(numba) kernel, which calls the C library, cannot reproduce it.

:func:`atan2`, :func:`hypot` and :func:`log1p` are numba-compiled ufuncs that call the C
library's functions element by element (broadcasting as NumPy's do): the simulation's NumPy code
(the tracks' headings, the quality metric, the NumPy references that must agree bit for bit with
their compiled twins: the ICR controller, the target shaping, the twist baseline) uses them.
``np.sin``, ``np.cos``, ``np.hypot``, ``np.sqrt`` and the arithmetic operators need no such twin
(NumPy 2's float64 ``sin``, ``cos`` and ``hypot`` call the C library at every SIMD level, and
``sqrt`` and the operators are correctly rounded everywhere). ``tests/test_cpu_independence.py``
runs ``azimut eval`` with NumPy's SIMD levels above the baseline switched off and requires the
same metrics to the bit.

What stays machine-dependent is the C library itself: its version and, in glibc, the variant of
``sin``, ``cos``, ``exp``, ``atan2``, ... it selects for the CPU (an FMA build on CPUs with FMA
and AVX2, a plain one elsewhere, which differ in the last place on some inputs). The compiled
kernels, pymunk and these ufuncs all call it, so trajectories are bit-for-bit reproducible on
machines with the same C library and FMA support (every x86-64 CPU since 2013 has FMA), and agree
to rounding elsewhere.
"""

from __future__ import annotations

import math

from numba import vectorize

__all__ = ["atan2", "hypot", "log1p"]


@vectorize(["float64(float64, float64)"], cache=True)
def atan2(y, x):
    """atan2(y, x) [rad] of the C library, element by element."""
    return math.atan2(y, x)


@vectorize(["float64(float64, float64)"], cache=True)
def hypot(x, y):
    """hypot(x, y) = sqrt(x² + y²) of the C library, element by element."""
    return math.hypot(x, y)


@vectorize(["float64(float64)"], cache=True)
def log1p(x):
    """log(1 + x) of the C library, element by element."""
    return math.log1p(x)
