"""The estimation quality metric of §4.1, eq. (28)–(29)."""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numba import njit

from estimation.libm import log1p
from estimation.validation import check_range

__all__ = ["QUALITY_F", "quality", "joint_distance_metric"]

#: Scaling factor f of eq. (29) used for every result of the paper.
QUALITY_F = 500.0


@njit(cache=True)
def _quality_from_d2(d2: float, n: int, f: float) -> float:
    """qua of eq. (29) from the squared joint-space distance d2 = ‖q − β_e‖² of n wheels."""
    return 1.0 - math.log1p(f * d2 / (n * math.pi * math.pi)) / math.log1p(f)


class _MetricCheck(IntEnum):
    """What :func:`_metric_kernel` found in its input."""

    OK = 0
    NON_FINITE = 1  #: a value is NaN or infinite
    OUT_OF_RANGE = 2  #: some |q_k − β_k| > π: the angles are not in one steering range of width π


@njit(cache=True)
def _metric_kernel(beta, q, out, periodic=False):
    """m of eq. (28) per row into ``out``; returns the :class:`_MetricCheck` value of the first problem
    met (``OK``: none). ``periodic``: each difference modulo π into [−π/2, π/2[ (unlimited steering)."""
    n = q.shape[1]
    scale = 1.0 / (n * math.pi * math.pi)
    for i in range(q.shape[0]):
        d = 0.0
        for k in range(n):
            a = beta[i, k]
            b = q[i, k]
            if not (math.isfinite(a) and math.isfinite(b)):
                return _MetricCheck.NON_FINITE.value
            diff = b - a
            if periodic:
                diff = (diff + 0.5 * math.pi) % math.pi - 0.5 * math.pi
            if abs(diff) > math.pi:
                return _MetricCheck.OUT_OF_RANGE.value
            d += diff * diff
        out[i] = d * scale
    return _MetricCheck.OK.value


def _real(x, name: str) -> np.ndarray:
    arr = np.asarray(x)
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    return arr.astype(np.float64, copy=False)


def _metric(beta_est, q, periodic: bool = False) -> tuple[np.ndarray, tuple[int, ...]]:
    beta_est = _real(beta_est, "beta_est")
    q = _real(q, "q")
    if beta_est.shape != q.shape or beta_est.ndim == 0:
        raise ValueError(f"beta_est and q must have the same shape (n,) or (N, n), got {beta_est.shape} and {q.shape}")
    batch = q.shape[:-1]
    n = q.shape[-1]
    out = np.empty(int(np.prod(batch, dtype=np.int64)))
    code = _metric_kernel(np.ascontiguousarray(beta_est.reshape(-1, n)), np.ascontiguousarray(q.reshape(-1, n)), out,
                          bool(periodic))
    if code == _MetricCheck.NON_FINITE:
        raise ValueError("beta_est and q must be finite")
    if code == _MetricCheck.OUT_OF_RANGE:
        raise ValueError("beta_est and q must lie in one steering range of width π (|q_k − β_k| <= π): "
                         "wrap them first (RobotGeometry.wrap_steering)")
    return out, batch


def joint_distance_metric(beta_est, q, *, periodic: bool = False) -> np.ndarray:
    """m(β_e, q) = (q − β_e)·(q − β_e) / (n π²), eq. (28).

    q − β_e is a plain difference, both angles in the steering range: the wheel cannot cross its
    stops, so |q_k − β_k| <= π and m <= 1; a larger difference raises ``ValueError``, as do
    non-finite, complex or object inputs. Returns a scalar (0-d) or (N,).

    ``periodic`` (unlimited steering, ``RobotGeometry.unlimited_steering``): q_k − β_k is taken
    modulo π into [−π/2, π/2[, since β and β + π are one propulsion axis and a module without
    stops takes the nearer; the angles may then be anywhere, and m <= 1/4 (the normalisation is
    the paper's, so that one angular departure reads the same on both kinds of robot)."""
    out, batch = _metric(beta_est, q, periodic)
    return out.reshape(batch)


def quality(beta_est, q, f: float = QUALITY_F, *, periodic: bool = False) -> np.ndarray:
    """qua(β_e, q) = 1 − ln(f m + 1) / ln(f + 1), eq. (29), in [0, 1]; 1 means q is on the surface.

    Args:
        beta_est: (n,) or (N, n) steering configuration of the estimate, S(λ̂) [rad].
        q: same shape, the measured steering angles [rad], in the steering range.
        f: scaling factor (f ≥ 1); the paper uses 500.
        periodic: unlimited steering (see :func:`joint_distance_metric`): the angles' differences
            modulo π; qua then lies in [1 − ln(f/4 + 1)/ln(f + 1), 1] (0.22 for f = 500).

    Returns a 0-d array for one configuration, (N,) for a batch.
    """
    f = check_range("f", f, 1.0)
    m, batch = _metric(beta_est, q, periodic)
    return np.clip(1.0 - log1p(f * m) / math.log1p(f), 0.0, 1.0).reshape(batch)
