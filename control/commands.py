"""The set-points a controller sends for one control period: one type for every controller (the
ICR controller, single and batched, and the twist baseline)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["WheelCommand"]


@dataclass(frozen=True)
class WheelCommand:
    """Set-points for one control period: (n,) arrays for one robot, (N, n) for a batch of N.

    Attributes:
        beta: steering set-points β_c [rad], inside the steering range.
        phidot: propulsion set-points φ̇_c [rad/s].
        beta_rate: β̇_c [rad/s] (finite difference of the steering set-points over the period).
        beta_accel: β̈_c [rad/s²].
        phiddot: φ̈_c [rad/s²].
        info: diagnostics of the controller that made them (for the ICR controller: mode, κ, the
            target actually used, saturation flag, ...; Python scalars for one robot, (N, …)
            arrays for a batch).
    """

    beta: np.ndarray
    phidot: np.ndarray
    beta_rate: np.ndarray
    beta_accel: np.ndarray
    phiddot: np.ndarray
    info: dict = field(default_factory=dict)
