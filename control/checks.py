"""Checks of the controllers' array inputs (refused where they enter, with the argument's name),
and :func:`check_batch_independence`, a check a user runs on a controller of theirs (every row of
a batch must be what that robot gets alone)."""

from __future__ import annotations

import numpy as np

__all__ = ["check_unit", "check_unit_batch", "check_finite_array", "check_batch_independence", "BatchDependenceError"]


def check_unit(x, name: str) -> np.ndarray:
    """A (3,) non-zero finite vector, normalised (a point of Λ given by any representative)."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    norm = np.linalg.norm(arr)
    if norm == 0:
        raise ValueError(f"{name} is the zero vector, not a point of Λ")
    return arr / norm


def check_unit_batch(x, name: str) -> np.ndarray:
    """(N, 3) non-zero finite rows, normalised row by row."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    norm = np.linalg.norm(arr, axis=-1)
    if np.any(norm == 0):
        raise ValueError(f"{name} is the zero vector, not a point of Λ")
    return arr / norm[:, None]


def check_finite_array(x, name: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """A finite float64 array, of ``shape`` if given."""
    arr = np.asarray(x, dtype=np.float64)
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    return arr


class BatchDependenceError(AssertionError):
    """A controller whose command for a robot depends on the other robots of its batch (raised by
    :func:`check_batch_independence`; an ``AssertionError``, so a test that calls it fails)."""


def check_batch_independence(controller, tracks=("paper", "square"), seeds=(0, 1), *, max_time: float = 2.0,
                             env_kwargs: dict | None = None, atol: float = 0.0) -> None:
    """Check that ``controller`` treats the robots of a batch independently: run the robots
    (``tracks[i]``, ``seeds[i]``: by default two different robots, on ``paper`` and ``square``)
    for ``max_time`` [s] as one batch with :func:`control.rollout.run_episodes`, then each alone,
    and compare every robot's commands (β_c, φ̇_c) step by step.

    ``azimut eval`` runs the episodes of one controller as batches, split over its workers, and
    assumes each robot's episode is the one it gets alone: a controller that is not independent
    (one shared state, a mean over the batch, a random generator drawn for all robots in turn)
    gives results that depend on ``--workers`` and on which episodes share a batch.

    Args:
        controller: a :class:`~control.controller.Controller` (the same object runs every
            run: its ``reset`` must restart the robots it is given, in an env of any size) or a spec of
            :func:`~control.controller.make_controller` (a fresh controller per run).
        tracks, seeds: one per robot, at least two robots.
        max_time: each run's length [s]; env_kwargs: as :func:`~control.rollout.run_episodes`.
        atol: the largest difference tolerated [rad, rad/s] (0: bit for bit, what the built-in
            controllers give; a neural network may round a batch differently, in the last bits).

    Raises:
        BatchDependenceError: naming the controller, the first robot and step whose commands
            differ, and by how much.
    """
    from control.controller import make_controller
    from control.rollout import run_episodes

    tracks, seeds = list(tracks), [int(s) for s in seeds]
    if len(tracks) != len(seeds) or len(seeds) < 2:
        raise ValueError(f"give one track per seed and at least two robots, got {len(tracks)} tracks and "
                         f"{len(seeds)} seeds")
    if isinstance(atol, bool) or not isinstance(atol, (int, float)) or not (atol >= 0 and np.isfinite(atol)):
        raise ValueError(f"atol must be a finite number >= 0, got {atol!r}")

    def made():
        return make_controller(controller) if isinstance(controller, str) else controller

    batch = run_episodes(made(), tracks, seeds, max_time=max_time, env_kwargs=env_kwargs)
    name = batch[0].controller
    for i, (track, seed) in enumerate(zip(tracks, seeds)):
        alone = run_episodes(made(), [track], [seed], max_time=max_time, env_kwargs=env_kwargs)[0]
        together = batch[i]
        steps = min(alone.t.size, together.t.size)
        for key in ("beta_cmd", "phidot_cmd"):
            a, b = getattr(alone, key)[:steps], getattr(together, key)[:steps]
            diff = np.abs(a - b)
            bad = np.flatnonzero(np.any(~(diff <= atol), axis=-1))
            if bad.size:
                k = int(bad[0])
                raise BatchDependenceError(
                    f"controller {name!r} is not independent across the robots of a batch: robot {i} (track "
                    f"{together.track.name!r}, seed {seed}) got other {key} in a batch of {len(seeds)} than alone "
                    f"from step {k} on ({bad.size} of {steps} steps, largest difference {float(np.max(diff)):.3g}); "
                    "azimut eval's results would depend on --workers and on which episodes share a batch")
        if alone.t.size != together.t.size:
            raise BatchDependenceError(
                f"controller {name!r} is not independent across the robots of a batch: robot {i} (track "
                f"{together.track.name!r}, seed {seed}) ran {together.t.size} steps in a batch of {len(seeds)} and "
                f"{alone.t.size} alone")
