"""Checks of the controllers' array inputs (refused where they enter, with the argument's name)."""

from __future__ import annotations

import numpy as np

__all__ = ["check_unit", "check_unit_batch", "check_finite_array"]


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
