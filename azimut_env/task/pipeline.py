"""One pipeline: the stages after the physics, for a step and for a reset, compiled or not.

A stage is a function ``stage(ta, rows, action)``: it reads and writes the task's struct ``ta``
(:mod:`azimut_env.task.arrays`) for the robots where ``rows`` (N,) is True. Each lives in the
module of its concern:

=================  ==================================================  ===========================
stage              module                                              step / reset
=================  ==================================================  ===========================
sense              :mod:`azimut_env.task.sensors` (``SENSOR_STAGES``)   both
estimate           :mod:`azimut_env.task.icr_estimate`                 both
odometry           :mod:`azimut_env.task.localisation` (Python)        both, ``pose_source="odometry"``
track              :mod:`azimut_env.task.track_state`                  both
terminate          :mod:`azimut_env.task.termination` (its table)      step
start_episode      :mod:`azimut_env.task.termination`                  reset
reward             :mod:`azimut_env.task.reward` (its table)           step
remember_action    :mod:`azimut_env.task.actions`                      step
observe            :mod:`azimut_env.task.observation` (its table)      both
=================  ==================================================  ===========================

(the ``info`` dict is built afterwards from its table, :mod:`azimut_env.task.info`). A
:class:`Pipeline` runs the stages in order for any mask of rows: the consecutive compiled stages
as one generated compiled function (a step of the single env with the true pose: one call), a
Python stage (odometry) between them. The compiled function runs the robots in contiguous blocks,
one per thread (:class:`estimation.threads.BlockKernel`: each block every stage in order on its
rows; a stage touches only the rows it is given, so any thread count gives the same bits). With
``jit=False`` it runs the same stages as plain Python (their ``py_func``, the generated ones from
the same source): the reference the tests compare the compiled path with, bit for bit
(``tests/azimut_env/test_compiled_step.py``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numba import njit

from azimut_env.task import sensors
from azimut_env.task.actions import remember_action
from azimut_env.task.codegen import generated_function, py_func
from azimut_env.task.icr_estimate import estimate
from azimut_env.task.observation import observe_kernel
from azimut_env.task.reward import reward_kernel
from azimut_env.task.termination import start_episode, terminate_kernel
from azimut_env.task.track_state import track
from estimation.threads import BlockKernel

__all__ = ["Pipeline", "step_stages", "reset_stages"]


def step_stages(task: Any, jit: bool = True) -> tuple[Callable, ...]:
    """The stages of a step, in order."""
    odometry = () if task.odometry is None else (task.odometry.step_stage,)
    return (*sensors.SENSOR_STAGES, estimate, *odometry, track, terminate_kernel(task.termination_table, jit),
            reward_kernel(task.reward_table, jit), remember_action, observe_kernel(task.observation_fields, jit))


def reset_stages(task: Any, jit: bool = True) -> tuple[Callable, ...]:
    """The stages of a reset, in order (the episode's start already drawn and set: pose,
    steering, sensor bias and noise, ``prev_action``, the start progress in ``ta.s``)."""
    odometry = () if task.odometry is None else (task.odometry.start_stage,)
    return (*sensors.SENSOR_STAGES, estimate, *odometry, track, start_episode,
            observe_kernel(task.observation_fields, jit))


def _is_compiled(stage: Callable) -> bool:
    return hasattr(stage, "py_func")


@njit(cache=True)
def block_rows(rows, lo, hi):
    """The row mask ``rows`` (N,) restricted to robots ``lo`` to ``hi - 1`` (``rows`` itself when
    that is all of them)."""
    if lo == 0 and hi == rows.shape[0]:
        return rows
    block = np.zeros_like(rows)
    block[lo:hi] = rows[lo:hi]
    return block


def _fuse(stages: Sequence[Callable]) -> Callable:
    """One compiled function ``(ta, rows, action, lo, hi)`` calling the compiled ``stages`` in
    order on the rows of ``rows`` from ``lo`` to ``hi - 1``."""
    lines = ["def _f(ta, rows, action, lo, hi):", "    block = _block_rows(rows, lo, hi)"] + \
        [f"    _stage_{j}(ta, block, action)" for j in range(len(stages))]
    namespace = {"_block_rows": block_rows, **{f"_stage_{j}": s for j, s in enumerate(stages)}}
    return generated_function("_pipeline", "\n".join(lines) + "\n", namespace, __file__, __name__)


#: the fewest robots a thread takes in a pipeline call (a block must outweigh waking a thread)
MIN_BLOCK_ROWS = 4


class Pipeline:
    """The ``stages`` run in order on a task's arrays: ``pipeline(rows, action)``.

    Args:
        stages: the stage functions (:func:`step_stages`, :func:`reset_stages`).
        ta: the compiled struct (None with ``jit=False``); ns: the same fields by name.
        jit: False: every stage as plain Python (``py_func``), the reference path.
        num_threads: threads of the compiled stages (blocks of at least :data:`MIN_BLOCK_ROWS`
            robots; checked where it entered, :class:`~azimut_env.task.config.TaskConfig`).
        n_rows: the robots N (the length of every ``rows``).
    """

    def __init__(self, stages: Sequence[Callable], ta: Any, ns: Any, jit: bool = True, num_threads: int = 1,
                 n_rows: int = 1) -> None:
        self.stages = tuple(stages)
        self.ta, self.ns, self.jit = ta, ns, jit
        self.num_threads = num_threads
        # (function, arrays, how): "block" a BlockKernel run on the threads, "serial" its kernel
        # called once on all rows (one thread or a batch too small to split: no dispatch on the
        # single env's path), "python" a stage as plain Python
        calls: list[tuple[Any, Any, str]] = []
        group: list[Callable] = []
        for stage in (*self.stages, None):
            if jit and stage is not None and _is_compiled(stage):
                group.append(stage)
                continue
            if group:
                blocks = BlockKernel(_fuse(group), MIN_BLOCK_ROWS)
                serial = blocks.serial(num_threads, n_rows)
                calls.append((blocks.kernel if serial else blocks, ta, "serial" if serial else "block"))
                group = []
            if stage is not None:
                calls.append((py_func(stage), ns, "python"))
        self._calls = tuple(calls)

    def __call__(self, rows: np.ndarray, action: np.ndarray) -> None:
        for fn, arrays, how in self._calls:
            if how == "serial":
                fn(arrays, rows, action, 0, rows.shape[0])
            elif how == "block":
                fn.run(self.num_threads, rows.shape[0], arrays, rows, action)
            else:
                fn(arrays, rows, action)

    def run_timed(self, rows: np.ndarray, action: np.ndarray, times: dict[str, float],
                  label: Callable[[Callable], str]) -> None:
        """The stages one by one (each compiled stage its own call), adding each one's wall time
        [s] to ``times[label(stage)]`` (``azimut bench-env``'s breakdown)."""
        clock = time.perf_counter
        for stage in self.stages:
            compiled = _is_compiled(stage) and self.ta is not None
            fn, arrays = (stage, self.ta) if compiled else (py_func(stage), self.ns)
            t0 = clock()
            fn(arrays, rows, action)
            key = label(stage)
            times[key] = times.get(key, 0.0) + clock() - t0
