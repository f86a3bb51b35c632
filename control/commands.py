"""The set-points a controller sends for one control period: one type for every controller (the
ICR controller, single and batched, the twist baseline, the feed-forward driver, trained policies
and a user's own :class:`control.controller.Controller`)."""

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
        beta_rate: β̇_c [rad/s] (finite difference of the steering set-points over the period);
            None where the controller does not know it (the commanded-limit check then leaves
            β̇ out, as it does β̈ and φ̈ when they are None).
        beta_accel: β̈_c [rad/s²], or None.
        phiddot: φ̈_c [rad/s²], or None.
        info: diagnostics of the controller that made them (for the ICR controller: mode, κ, the
            target actually used, saturation flag, ...; Python scalars for one robot, (N, …)
            arrays for a batch).
        action: (N, 2n) float32 env action to send as it is, or None: the episode loop
            (:mod:`control.rollout`) then sends ``env.action_from_setpoints(beta, phidot)``.
            A trained policy gives its own action, so its rollouts stay what it was trained on.
        mode: (N,) int :class:`~control.icr.config.Mode` values of the controller (its RUNNING,
            STOPPING and RECONFIGURING; None: always RUNNING). The metrics count a step as
            moving only while RUNNING.
        events: (N,) int, the stop-and-reconfigure sequences the controller has started since
            its robot's reset (None: none).
    """

    beta: np.ndarray
    phidot: np.ndarray
    beta_rate: np.ndarray | None = None
    beta_accel: np.ndarray | None = None
    phiddot: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    action: np.ndarray | None = None
    mode: np.ndarray | None = None
    events: np.ndarray | None = None
