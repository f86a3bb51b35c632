"""Robot geometry: where the steering axes are and how the wheels hang from them.

Notation follows the paper (§3, Fig. 4, eq. (7)): wheel k has its steering axis A_k at
``l_k (cos α_k, sin α_k)`` in the chassis frame R. Its contact point sits ``b_k`` from A_k along
the propulsion axis (the AZIMUT "sidewise" wheel), whose direction makes ``γ_k = α_k + β_k`` with
X_R. The steering angle β_k is limited to the half-open range ``]β_min, β_max]`` of width π, which
makes the map ICR -> steering configuration a bijection (§3.1).

**Unlimited steering** (``unlimited_steering=True``, most swerve modules): the module has no stop
and turns any number of times. β and β + π put the propulsion axis on the same line (the wheel
then rolls the other way), so a module always takes the one of the two nearer to where it is and
never has to cross a stop. ``]β_min, β_max]`` is then only the *representative* range in which
F(λ) is written (the estimators' canonical chart); measured angles may be any real, and the
distance between a measured angle q and a surface angle β is the difference modulo π,
:meth:`RobotGeometry.steering_difference`.

Per-wheel vectors used everywhere, eq. (7):

* ``a_k  = (cos α_k, sin α_k, 0)``
* ``a⊥_k = (−sin α_k, cos α_k, 0)``
* ``s_k  = (l_k cos α_k, l_k sin α_k, 1)`` (the steering axis on the w = 1 plane)
* ``l_k  = (0, 0, l_k)``, so ``a_k − l_k = (cos α_k, sin α_k, −l_k)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["RobotGeometry", "AZIMUT3_ASSUMPTIONS"]

#: AZIMUT-3's published dimensions are not available to us. This is the single place where the
#: default robot is assumed: a symmetric square layout, steering axes at the corners.
AZIMUT3_ASSUMPTIONS = {
    "alpha_deg": (45.0, 135.0, -135.0, -45.0),
    "l_m": 0.30,
    "b_m": 0.08,
    "r_m": 0.08,
    "note": (
        "AZIMUT-3's exact dimensions are not published in the paper; this symmetric layout "
        "(α = ±45°, ±135°, l = 0.30 m, b = 0.08 m, r = 0.08 m) is an assumption."
    ),
}


def _as_wheel_array(name: str, value, n: int | None) -> np.ndarray:
    arr = np.array(value, dtype=np.float64)
    if arr.ndim == 0 and n is not None:
        arr = np.full(n, float(arr))
    if arr.ndim != 1:
        raise ValueError(f"RobotGeometry.{name} must be a scalar or a 1-D array, got shape {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise ValueError(f"RobotGeometry.{name} has {arr.shape[0]} entries, expected {n} (one per wheel)")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"RobotGeometry.{name} must be finite, got {arr}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class RobotGeometry:
    """Frozen, validated per-wheel parameters of a robot with n >= 3 steerable wheels.

    Attributes:
        alpha: (n,) angle α_k of steering axis A_k from X_R [rad].
        l: (n,) distance l_k = ‖R A_k‖ of steering axis k from the chassis centre [m], > 0.
        b: (n,) sidewise offset b_k of the contact point from A_k along the propulsion axis [m];
            0 for a centred wheel. May be negative (offset on the other side).
        r: (n,) wheel radius r_k [m], > 0.
        steer_min: lower steering stop β_min [rad] (excluded from the range).
        steer_max: upper steering stop β_max [rad] (included); β_max − β_min must equal π.
        unlimited_steering: no steering stops (see the module docstring); ``steer_min``/``steer_max``
            are then the representative range of F(λ) only.

    Scalars for ``l``, ``b``, ``r`` are broadcast to every wheel. Raises ``ValueError`` for n < 3,
    all steering axes on one line, non-finite values, or a steering range not of width π.
    """

    alpha: np.ndarray
    l: np.ndarray
    b: np.ndarray = 0.0  # type: ignore[assignment]
    r: np.ndarray = 0.08  # type: ignore[assignment]
    steer_min: float = -np.pi / 2
    steer_max: float = np.pi / 2
    unlimited_steering: bool = False
    # Derived per-wheel vectors (n, 3); filled in __post_init__.
    a: np.ndarray = field(init=False, repr=False)
    a_perp: np.ndarray = field(init=False, repr=False)
    a_minus_l: np.ndarray = field(init=False, repr=False)
    s: np.ndarray = field(init=False, repr=False)
    s_unit: np.ndarray = field(init=False, repr=False)
    axis_xy: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        alpha = _as_wheel_array("alpha", self.alpha, None)
        n = alpha.shape[0]
        if n < 3:
            raise ValueError(f"RobotGeometry needs n >= 3 steerable wheels, got n = {n}")
        l = _as_wheel_array("l", self.l, n)
        b = _as_wheel_array("b", self.b, n)
        r = _as_wheel_array("r", self.r, n)
        if np.any(l <= 0):
            raise ValueError(f"RobotGeometry.l must be > 0 (steering axis off the chassis centre), got {l}")
        if np.any(r <= 0):
            raise ValueError(f"RobotGeometry.r must be > 0, got {r}")
        if not isinstance(self.unlimited_steering, (bool, np.bool_)):
            raise ValueError(f"RobotGeometry.unlimited_steering must be a bool, got {self.unlimited_steering!r}")
        smin, smax = float(self.steer_min), float(self.steer_max)
        if not (np.isfinite(smin) and np.isfinite(smax)):
            raise ValueError("RobotGeometry steering range must be finite")
        if not np.isclose(smax - smin, np.pi, rtol=0, atol=1e-12):
            raise ValueError(
                f"RobotGeometry steering range ]{smin}, {smax}] must have width π "
                "(the bijective case of §3.1); other ranges are not supported"
            )
        axis_xy = np.stack([l * np.cos(alpha), l * np.sin(alpha)], axis=1)
        # All steering axes on one line <=> the points A_k are collinear.
        centred = axis_xy - axis_xy.mean(axis=0)
        sv = np.linalg.svd(centred, compute_uv=False)
        if sv[1] <= 1e-9 * max(1.0, sv[0]):
            raise ValueError("RobotGeometry steering axes are all on one line: the ICR is not observable")
        if np.unique(np.round(axis_xy, 12), axis=0).shape[0] != n:
            raise ValueError("RobotGeometry has two wheels on the same steering axis")

        zeros = np.zeros(n)
        a = np.stack([np.cos(alpha), np.sin(alpha), zeros], axis=1)
        a_perp = np.stack([-np.sin(alpha), np.cos(alpha), zeros], axis=1)
        a_minus_l = np.stack([np.cos(alpha), np.sin(alpha), -l], axis=1)
        s = np.stack([axis_xy[:, 0], axis_xy[:, 1], np.ones(n)], axis=1)
        s_unit = s / np.linalg.norm(s, axis=1, keepdims=True)
        derived = dict(a=a, a_perp=a_perp, a_minus_l=a_minus_l, s=s, s_unit=s_unit, axis_xy=axis_xy)
        for arr in derived.values():
            arr.setflags(write=False)
        for name, value in dict(alpha=alpha, l=l, b=b, r=r, steer_min=smin, steer_max=smax,
                                unlimited_steering=bool(self.unlimited_steering), **derived).items():
            object.__setattr__(self, name, value)

    @property
    def n(self) -> int:
        """Number of wheels."""
        return int(self.alpha.shape[0])

    @classmethod
    def azimut3(cls) -> RobotGeometry:
        """The default robot, a stand-in for AZIMUT-3 (see ``AZIMUT3_ASSUMPTIONS``)."""
        A = AZIMUT3_ASSUMPTIONS
        return cls(
            alpha=np.deg2rad(np.array(A["alpha_deg"])),
            l=A["l_m"],
            b=A["b_m"],
            r=A["r_m"],
        )

    @classmethod
    def regular(cls, n: int, l: float = 0.3, b: float = 0.0, r: float = 0.08,
                unlimited_steering: bool = False) -> RobotGeometry:
        """n wheels evenly spaced on a circle of radius ``l`` [m], the first at α = 0."""
        return cls(alpha=2 * np.pi * np.arange(n) / n, l=l, b=b, r=r, unlimited_steering=unlimited_steering)

    @classmethod
    def from_file(cls, path) -> RobotGeometry:
        """The geometry of a robot description file (TOML; the schema is in ``docs/robots.md`` and
        :mod:`estimation.robot_file`). Only the header and the ``[geometry]`` table are read and
        checked; the rest of the file is the simulator's, read and checked by
        ``azimut_env.robot_file.read_robot`` (``RobotParams.from_file``). Raises
        :class:`~estimation.robot_file.RobotFileError` (a ``ValueError``) naming the file, the key and
        the value."""
        from estimation.robot_file import read_robot_file

        return cls.from_description(read_robot_file(path))

    @classmethod
    def from_description(cls, data: dict) -> RobotGeometry:
        """The geometry of a parsed robot description (:func:`estimation.robot_file.read_robot_file`)."""
        from estimation.robot_file import RobotFileError, geometry_kwargs

        kwargs = geometry_kwargs(data)
        try:
            return cls(**kwargs)
        except ValueError as exc:
            raise RobotFileError(f"robot file {data.get('_source', '<description>')}: [geometry]: {exc}") from None

    def wrap_steering(self, beta: np.ndarray) -> np.ndarray:
        """Wrap angles modulo π into the steering range ]β_min, β_max] (β and β+π: same axis)."""
        beta = np.asarray(beta, dtype=np.float64)
        return self.steer_max - np.mod(self.steer_max - beta, np.pi)

    def measured_steering(self, beta: np.ndarray) -> np.ndarray:
        """The steering angles a controller starts from, given measured ones (a copy): as measured
        with unlimited steering; with stops, clipped into [β_max − π, β_max]. A wheel measured a
        little past its stop (the sensor's noise, the stop's compliance) is at that stop: wrapped
        modulo π instead it would be at the other stop, and the first command would turn it by π."""
        beta = np.array(beta, dtype=np.float64)
        if self.unlimited_steering:
            return beta
        return np.clip(beta, self.steer_max - np.pi, self.steer_max)

    def steering_difference(self, q, beta) -> np.ndarray:
        """q − β [rad], the joint-space difference the quality metric and the estimators use.

        Limited steering: the plain difference (both angles in the steering range; the wheel
        cannot cross its stops). Unlimited steering: the difference modulo π, in [−π/2, π/2[
        (β and β + π are the same propulsion axis, and the module takes the nearer one)."""
        d = np.asarray(q, dtype=np.float64) - np.asarray(beta, dtype=np.float64)
        if not self.unlimited_steering:
            return d
        return np.mod(d + np.pi / 2, np.pi) - np.pi / 2

    def nearest_steering(self, beta, reference) -> np.ndarray:
        """The angle of β's propulsion axis that a module at ``reference`` takes [rad].

        Limited steering: β itself (the one representative inside the stops). Unlimited steering:
        the one of β + kπ nearest to ``reference`` (so a module never turns more than π/2 to
        reach an axis; the wheel speed changes sign with each π)."""
        beta = np.asarray(beta, dtype=np.float64)
        if not self.unlimited_steering:
            return beta.copy()
        reference = np.asarray(reference, dtype=np.float64)
        return reference + (np.mod(beta - reference + np.pi / 2, np.pi) - np.pi / 2)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RobotGeometry):
            return NotImplemented
        return (
            np.array_equal(self.alpha, other.alpha)
            and np.array_equal(self.l, other.l)
            and np.array_equal(self.b, other.b)
            and np.array_equal(self.r, other.r)
            and self.steer_min == other.steer_min
            and self.steer_max == other.steer_max
            and self.unlimited_steering == other.unlimited_steering
        )

    def __hash__(self) -> int:
        return hash((self.alpha.tobytes(), self.l.tobytes(), self.b.tobytes(), self.r.tobytes(),
                     self.steer_min, self.steer_max, self.unlimited_steering))
