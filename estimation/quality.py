"""The estimation quality metric of §4.1, eq. (28)–(29)."""

from __future__ import annotations

import numpy as np

__all__ = ["QUALITY_F", "quality", "joint_distance_metric"]

#: Scaling factor f of eq. (29) used for every result of the paper.
QUALITY_F = 500.0


def _pair(beta_est, q) -> tuple[np.ndarray, np.ndarray]:
    beta_est = np.asarray(beta_est, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    if beta_est.shape != q.shape or beta_est.ndim == 0:
        raise ValueError(f"beta_est and q must have the same shape (n,) or (N, n), got {beta_est.shape} and {q.shape}")
    if not (np.all(np.isfinite(beta_est)) and np.all(np.isfinite(q))):
        raise ValueError("beta_est and q must be finite")
    return beta_est, q


def joint_distance_metric(beta_est, q) -> np.ndarray:
    """m(β_e, q) = (q − β_e)·(q − β_e) / (n π²), eq. (28).

    q − β_e is a plain difference, both angles in the steering range: the wheel cannot cross its
    stops, so |q_k − β_k| < π. Returns a scalar (0-d) or (N,)."""
    beta_est, q = _pair(beta_est, q)
    d = q - beta_est
    return np.sum(d * d, axis=-1) / (q.shape[-1] * np.pi**2)


def quality(beta_est, q, f: float = QUALITY_F) -> np.ndarray:
    """qua(β_e, q) = 1 − ln(f m + 1) / ln(f + 1), eq. (29), in [0, 1]; 1 means q is on the surface.

    Args:
        beta_est: (n,) or (N, n) steering configuration of the estimate, S(λ̂) [rad].
        q: same shape, the measured steering angles [rad], in the steering range.
        f: scaling factor (f ≥ 1); the paper uses 500.
    """
    if not (np.isfinite(f) and f >= 1):
        raise ValueError(f"f must be >= 1, got {f}")
    m = joint_distance_metric(beta_est, q)
    return 1.0 - np.log(f * m + 1.0) / np.log(f + 1.0)
