"""Stepping robots through pymunk's contact solver (when there are obstacles), and the stage
timer of :meth:`~azimut_env.physics.engine.AzimutPhysics.step`.

Without obstacles the compiled kernel integrates the whole control period, chassis included.
With obstacles pymunk integrates the chassis bodies: each substep the kernel computes the
velocity change (tires, springs, modules, with ``integrate=False``) and hands it to pymunk as
the force and torque that give it, and ``space.step`` integrates them and resolves the contacts
(Chipmunk moves the position with the velocity of the start of the substep, then updates the
velocity: explicit Euler for the chassis pose while in contact with obstacles). The body's
mass and moment are those of ``body_inertia`` (with a module whose centre of mass is off its
axis, the kernel's velocity change already holds the coupling; pymunk's contact response uses
the body alone).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from azimut_env.physics.body_io import BodyIO
from azimut_env.physics.layout import BODY, CS, FT

__all__ = ["step_with_contacts", "lap"]


def lap(times: dict[str, float], key: str, t0: float) -> float:
    """Add the time since ``t0`` to ``times[key]``; return now."""
    t = time.perf_counter()
    times[key] = times.get(key, 0.0) + t - t0
    return t


def step_with_contacts(space, io: BodyIO, before: np.ndarray, body_inertia: np.ndarray, substeps: int, dt: float,
                       kernel: Callable, args: tuple, times: dict[str, float] | None, t: float) -> float:
    """``substeps`` substeps of N robots, each one kernel substep (``kernel(state, *args, 1, False)``)
    then one ``space.step(dt)`` with the kernel's velocity change as force and torque. The
    bodies have been read into ``io.state``; they are read again after the last substep.
    ``before`` (N, len(CS)) is scratch. ``times``/``t``: the stage timer (:func:`lap`); returns
    the time of the last lap."""
    state, forces = io.state, io.forces
    N = body_inertia.shape[0]
    mass, moment = body_inertia[:, BODY.MASS], body_inertia[:, BODY.MOMENT]
    for j in range(substeps):
        if j:
            io.read()
            if times is not None:
                t = lap(times, "read", t)
        before[:] = state[:N]
        kernel(state, *args, 1, False)
        # the same velocity change, as the force and torque pymunk applies in its step
        forces[:N, FT.FX] = (state[:N, CS.VX] - before[:, CS.VX]) * (mass / dt)
        forces[:N, FT.FY] = (state[:N, CS.VY] - before[:, CS.VY]) * (mass / dt)
        forces[:N, FT.TAU] = (state[:N, CS.W] - before[:, CS.W]) * (moment / dt)
        io.write_forces()
        if times is not None:
            t = lap(times, "force", t)
        space.step(dt)
        if times is not None:
            t = lap(times, "space_step", t)
    io.read()
    if times is not None:
        t = lap(times, "read", t)
    return t
