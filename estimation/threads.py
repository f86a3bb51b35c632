"""Threads for the batched kernels: how many, and the blocks of rows each one takes.

A batched kernel (the physics substeps, the env's step pipeline, the controllers' steps, IT over
samples) loops over rows (robots or samples) that do not depend on each other. Such a kernel is
written once as ``kernel(*args, lo, hi)``, doing rows ``lo`` to ``hi - 1`` with its own work
space; :class:`BlockKernel` runs it either in one call (``lo, hi = 0, n``: one thread, exactly the
serial kernel) or as contiguous blocks of rows, one block per thread, in one compiled
``numba.prange`` over the blocks (its parallel twin, generated from the kernel's signature and
compiled on first use).

**Results do not depend on the thread count.** A row's arithmetic is the same whichever block
holds it and whichever thread runs it: no sum runs across rows, no work space is shared between
blocks, and the random streams are per robot (their generators are the caller's, drawn before
the kernels). So 1, 2 or N threads give the same bits (``tests/estimation/test_threads.py``,
``tests/azimut_env/test_threads_env.py`` and ``tests/control/test_threads_control.py`` check it).

**How many.** ``num_threads=None`` takes the cores this process may run on
(``os.sched_getaffinity``), at most numba's thread count for the calling thread
(``numba.get_num_threads()``: ``NUMBA_NUM_THREADS``, by default the machine's cores, or what
``numba.set_num_threads`` set, as a campaign's worker does). An explicit count may go up to
numba's pool; :func:`set_default_threads` (a command's ``--threads``) sets the default of the
whole process. A batch gets at most one block per
``min_rows`` rows (a kernel's own figure: a block must outweigh the few microseconds it costs to
wake a thread), so a small batch runs on fewer threads, or serially, and is never slower than on
one thread.
"""

from __future__ import annotations

import hashlib
import inspect
import os
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["available_cores", "max_threads", "default_threads", "set_default_threads", "check_threads", "block_bounds",
           "BlockKernel"]


def available_cores() -> int:
    """The CPU cores this process may run on (its affinity mask; ``os.cpu_count()`` where the
    platform has none)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # macOS, Windows
        return os.cpu_count() or 1


def max_threads() -> int:
    """numba's thread pool size (``NUMBA_NUM_THREADS``): the most threads a kernel can use."""
    from numba import config

    return int(config.NUMBA_NUM_THREADS)


_DEFAULT: int | None = None


def set_default_threads(num_threads: int | None) -> None:
    """Make ``num_threads`` (checked) the count every ``num_threads=None`` of this process takes
    (a command's ``--threads``); None: back to :func:`available_cores` capped by numba's count."""
    global _DEFAULT
    _DEFAULT = None if num_threads is None else check_threads(num_threads)


def default_threads() -> int:
    """The default thread count: :func:`set_default_threads`' count, else :func:`available_cores`
    at most ``numba.get_num_threads()``."""
    if _DEFAULT is not None:
        return _DEFAULT
    from numba import get_num_threads

    return max(1, min(available_cores(), get_num_threads()))


def check_threads(num_threads: Any, name: str = "num_threads") -> int:
    """``num_threads`` checked (an integer, as :func:`estimation.validation.check_int` takes one,
    from 1 to :func:`max_threads`), or None: the default (:func:`default_threads`). ``name``: the
    argument as the error message names it (``--threads`` for a CLI flag)."""
    from estimation.validation import check_int

    if num_threads is None:
        return default_threads()
    limit = max_threads()
    v = check_int(name, num_threads, min_value=1)
    if v > limit:
        raise ValueError(f"{name} must be at most {limit}, the threads of numba's pool on this machine "
                         f"(NUMBA_NUM_THREADS), got {v}")
    return v


def block_bounds(n_rows: int, threads: int, min_rows: int = 1) -> np.ndarray:
    """(B + 1,) int64 bounds of B contiguous blocks of ``n_rows`` rows, as equal as can be:
    B = min(threads, n_rows // min_rows), at least 1. Block b is rows bounds[b] to bounds[b+1] - 1."""
    blocks = max(1, min(int(threads), int(n_rows) // max(1, int(min_rows))))
    return (np.arange(blocks + 1, dtype=np.int64) * int(n_rows)) // blocks


_TWINS: dict[Callable, Callable] = {}


def _parallel_twin(kernel: Callable) -> Callable:
    """``twin(*args, bounds)``: ``kernel(*args, bounds[b], bounds[b + 1])`` for every block b in
    numba's ``prange`` (:func:`_run_blocks` sets the pool's thread count). Compiled with numba's
    disk cache under a name that hashes its source."""
    twin = _TWINS.get(kernel)
    if twin is not None:
        return twin
    from numba import njit, prange

    py = getattr(kernel, "py_func", kernel)
    params = list(inspect.signature(py).parameters)[:-2]
    args = ", ".join(params)
    if "_block" in params or "_bounds" in params:
        raise ValueError(f"{py.__name__}: a parameter is named _block or _bounds (the parallel twin's own names)")
    src = (f"def _twin({args}, _bounds):\n"
           "    for _block in _prange(_bounds.shape[0] - 1):\n"
           f"        _kernel({args}, _bounds[_block], _bounds[_block + 1])\n")
    name = f"_blocks_{py.__name__.lstrip('_')}_{hashlib.sha256(src.encode()).hexdigest()[:12]}"
    scope = {"_kernel": kernel, "_prange": prange, "__name__": py.__module__}
    exec(compile(src.replace("def _twin(", f"def {name}("), inspect.getfile(py), "exec"), scope)
    twin = njit(cache=True, parallel=True)(scope[name])
    _TWINS[kernel] = twin
    return twin


class BlockKernel:
    """A kernel ``kernel(*args, lo, hi)`` over rows, run on one thread or as blocks on several.

    ``run(threads, n_rows, *args)``: rows 0 to ``n_rows - 1`` in :func:`block_bounds`' blocks of
    at least ``min_rows`` rows; one block is the kernel itself, called with (0, n_rows). Several
    run in its parallel twin (compiled on first use). ``threads`` is trusted here (checked by
    :func:`check_threads` where it entered).
    """

    def __init__(self, kernel: Callable, min_rows: int = 1, twin_on_one_thread: bool = False) -> None:
        self.kernel = kernel
        self.min_rows = int(min_rows)
        #: run a batch of at least ``min_rows`` rows through the parallel twin on one thread too (as
        #: one block): inside the twin numba passes the arrays without their reference counts, which
        #: a kernel that makes views in its inner loop (IT) otherwise updates at every view (IT on D2:
        #: 0.65 M points/s called directly, 0.79 M through the twin, the same bits)
        self.twin_on_one_thread = bool(twin_on_one_thread)
        self._bounds: dict[tuple[int, int], np.ndarray] = {}

    def bounds(self, threads: int, n_rows: int) -> np.ndarray:
        key = (threads, n_rows)
        b = self._bounds.get(key)
        if b is None:
            b = self._bounds[key] = block_bounds(n_rows, threads, self.min_rows)
        return b

    def serial(self, threads: int, n_rows: int) -> bool:
        """True where ``run(threads, n_rows, ...)`` is one call of the kernel itself (a caller on a
        hot path of one robot may call ``kernel(*args, 0, n_rows)`` directly)."""
        if self.twin_on_one_thread and n_rows >= self.min_rows:
            return False
        return threads <= 1 or self.bounds(threads, n_rows).shape[0] <= 2

    def run(self, threads: int, n_rows: int, *args: Any) -> None:
        if self.serial(threads, n_rows):
            self.kernel(*args, 0, n_rows)
        else:
            _run_blocks(_parallel_twin(self.kernel), args, self.bounds(threads, n_rows), threads)


def _run_blocks(twin: Callable, args: tuple, bounds: np.ndarray, threads: int) -> None:
    """``twin(*args, bounds)`` with numba's pool at ``threads`` threads, at most one per block (the
    calling thread's setting, restored after: numba's thread count is per calling thread)."""
    from numba import get_num_threads, set_num_threads

    before = get_num_threads()
    want = min(threads, bounds.shape[0] - 1)
    if before != want:
        set_num_threads(want)
    try:
        twin(*args, bounds)
    finally:
        if before != want:
            set_num_threads(before)
