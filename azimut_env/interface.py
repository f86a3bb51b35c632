"""The controller interface of the envs, as ``typing.Protocol`` classes.

What a controller (``control``'s ICR controller and swerve baseline, the controller-in-the-loop
action wrappers, ``azimut eval``) reads from and writes to ``env.unwrapped``. Both envs implement
it through :class:`~azimut_env.frontend.AzimutFrontEnd`: the single env with per-robot shapes
((n,), (3,), floats), the vector env with a leading robot axis ((N, n), (N, 3), (N,)).

A wrapper checks its env with :func:`missing_members` (the names the env lacks), or with
``isinstance(env.unwrapped, ControllerInterface)`` (the protocols are runtime-checkable).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["ControllerInterface", "VectorControllerInterface", "missing_members"]


@runtime_checkable
class _Common(Protocol):
    """The members both envs share (shapes: single env / vector env)."""

    #: ``RobotParams`` of the robot(s); ``geometry`` and ``limits`` are parts of it
    params: Any
    #: seconds per step [s]
    control_period: float

    @property
    def geometry(self) -> Any:
        """:class:`~estimation.geometry.RobotGeometry`."""

    @property
    def limits(self) -> Any:
        """:class:`~azimut_env.params.ActuatorLimits`."""

    @property
    def measured_beta(self) -> np.ndarray:
        """Measured steering angles [rad], (n,) / (N, n)."""

    @property
    def measured_phidot(self) -> np.ndarray:
        """Measured wheel spin rates [rad/s], (n,) / (N, n)."""

    @property
    def measured_motor_angles(self) -> np.ndarray:
        """Measured steering motor angles [rad], (n,) / (N, n)."""

    @property
    def estimated_eta(self) -> tuple[np.ndarray, Any]:
        """IT-estimated H state (λ̂, μ̂ [m/s]): (3,), float / (N, 3), (N,)."""

    @property
    def estimated_pose(self) -> np.ndarray:
        """The pose (x, y, θ) the observation was computed from, (3,) / (N, 3)."""

    @property
    def progress(self) -> Any:
        """Progress along the track [m]: float / (N,)."""

    @property
    def true_pose(self) -> np.ndarray:
        """Ground-truth pose (x, y, θ), for evaluation only: (3,) / (N, 3)."""

    @property
    def true_twist(self) -> np.ndarray:
        """Ground-truth chassis-frame twist (ẋ, ẏ, θ̇), for evaluation only: (3,) / (N, 3)."""

    def setpoints_from_action(self, action: Any) -> tuple[np.ndarray, np.ndarray]:
        """Normalised action(s) -> (β_cmd [rad], φ̇_cmd [rad/s])."""

    def action_from_setpoints(self, beta_cmd: Any, phidot_cmd: Any) -> np.ndarray:
        """(β_cmd [rad], φ̇_cmd [rad/s]) -> normalised float32 action(s), clipped to [−1, 1]."""


@runtime_checkable
class ControllerInterface(_Common, Protocol):
    """The single env's controller interface (``Azimut-v2``, ``env.unwrapped``)."""

    @property
    def track(self) -> Any:
        """The :class:`~azimut_env.tracks.Track` of the current episode."""


@runtime_checkable
class VectorControllerInterface(_Common, Protocol):
    """The vector env's controller interface (:class:`~azimut_env.vector_env.AzimutVectorEnv`)."""

    @property
    def tracks(self) -> list:
        """Each robot's :class:`~azimut_env.tracks.Track` of the current episode."""


def missing_members(obj: Any, protocol: type) -> list[str]:
    """The members of ``protocol`` (one of the classes above) that ``obj`` lacks, in a stable order."""
    names: list[str] = []
    for klass in reversed(protocol.__mro__):
        if klass is object or klass is Protocol or not getattr(klass, "_is_protocol", False):
            continue
        for name in list(getattr(klass, "__annotations__", {})) + [k for k in vars(klass) if not k.startswith("_")]:
            if name not in names:
                names.append(name)
    return [name for name in names if not hasattr(obj, name)]
