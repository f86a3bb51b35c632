"""What every log reader gives the estimation pipeline: chunks of wheel samples, an optional
ground-truth pose, and the refusals they share.

A **sample** is one instant of the robot's wheel sensors: a timestamp [ns], the steering angles
β_k [rad] of the paper's convention (§3, eq. (7): the propulsion axis makes γ_k = α_k + β_k with
X_R) and the wheel spin rates φ̇_k [rad/s], in the robot's module order. Readers convert their
format's own convention into this one (:func:`beta_from_heading` for module headings, as WPILib's
``SwerveModuleState`` and most URDF steering joints give them) and mark the samples they could not
read (:data:`BAD_REASONS`); the pipeline skips those and counts them.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from estimation.geometry import RobotGeometry

__all__ = ["LogError", "SampleChunk", "GroundTruth", "YawTrack", "LogSource", "ArrayLog", "BAD_REASONS",
           "BAD_NONFINITE", "BAD_MISSING_JOINT", "BAD_NO_VELOCITY", "BAD_WRONG_SIZE", "BAD_STALE", "BAD_IMPLAUSIBLE",
           "MAX_ANGLE_RAD", "MAX_WHEEL_RATE", "mark_bad_values", "STEER_CONVENTIONS", "beta_from_heading",
           "fold_coaxial", "default_module_names", "check_module_names"]


class LogError(ValueError):
    """A log that cannot be estimated: missing topics, entries or columns, names that do not match
    the robot, unsorted timestamps, a truncated or unreadable file. The message is one line that
    names the file and what is wrong."""


#: why a sample was skipped: code -> what the report says (code 0: a good sample)
BAD_NONFINITE = 1
BAD_MISSING_JOINT = 2
BAD_NO_VELOCITY = 3
BAD_WRONG_SIZE = 4
BAD_STALE = 5
BAD_IMPLAUSIBLE = 6
#: beyond these a logged value is no measurement (a corrupt cell, a unit far off): skipped and counted
MAX_ANGLE_RAD = 1e6
MAX_WHEEL_RATE = 1e5
BAD_REASONS = {
    BAD_NONFINITE: "a steering angle or wheel speed is NaN or infinite",
    BAD_MISSING_JOINT: "a module's steering or drive joint is missing from the message",
    BAD_NO_VELOCITY: "the message has no wheel velocities",
    BAD_WRONG_SIZE: "the record does not hold one value per module",
    BAD_STALE: "a module's steering angle or wheel speed is older than the maximum age (a signal logged on change "
               "that stopped, or a gap)",
    BAD_IMPLAUSIBLE: f"a steering angle beyond ±{MAX_ANGLE_RAD:g} rad or a wheel speed beyond "
                     f"±{MAX_WHEEL_RATE:g} rad/s (no measurement: a corrupt value, or a unit far off)",
}


def mark_bad_values(bad: np.ndarray, beta: np.ndarray, phidot: np.ndarray) -> np.ndarray:
    """``bad`` (m,) with the read samples (code 0) whose values are NaN or infinite marked
    :data:`BAD_NONFINITE`, and those beyond :data:`MAX_ANGLE_RAD` or :data:`MAX_WHEEL_RATE`
    :data:`BAD_IMPLAUSIBLE`: the one check of the pipeline and of calibration."""
    bad = bad.copy()
    with np.errstate(invalid="ignore"):
        finite = np.isfinite(beta).all(axis=1) & np.isfinite(phidot).all(axis=1)
        huge = (np.abs(beta) > MAX_ANGLE_RAD).any(axis=1) | (np.abs(phidot) > MAX_WHEEL_RATE).any(axis=1)
    bad[(bad == 0) & ~finite] = BAD_NONFINITE
    bad[(bad == 0) & huge] = BAD_IMPLAUSIBLE
    return bad

#: how a log gives steering angles: ``beta``, the paper's β_k (the propulsion axis at α_k + β_k
#: from X_R); ``heading``, the module's rolling direction from X_R (WPILib's
#: ``SwerveModuleState.angle``; a URDF steering joint whose zero points the wheel forward)
STEER_CONVENTIONS = ("beta", "heading")


def default_module_names(n: int) -> tuple[str, ...]:
    """``module_0`` ... ``module_{n-1}``: the names of modules a robot description leaves unnamed."""
    return tuple(f"module_{k}" for k in range(n))


def check_module_names(names, geom: RobotGeometry) -> tuple[str, ...]:
    """``names`` as a tuple of ``geom.n`` distinct non-empty strings, else ``ValueError``."""
    names = tuple(names)
    if len(names) != geom.n:
        raise ValueError(f"{len(names)} module names for a robot of {geom.n} modules: {', '.join(names)}")
    if not all(isinstance(s, str) and s and s == s.strip() and "," not in s for s in names):
        raise ValueError(f"module names must be non-empty strings without commas or surrounding spaces, got {names}")
    if len(set(names)) != len(names):
        raise ValueError(f"module names must be distinct, got {names}")
    return names


def beta_from_heading(heading: np.ndarray, geom: RobotGeometry) -> np.ndarray:
    """β_k [rad] of a module whose wheel rolls toward ``heading`` [rad] (from X_R, CCW).

    The rolling direction of wheel k is d_k = (sin γ_k, −cos γ_k) (see
    :func:`~estimation.kinematics.twist_from_wheels`), the direction at angle γ_k − π/2; so
    β_k = heading_k − α_k + π/2, and a positive wheel speed rolls the wheel toward ``heading``.
    (..., n) -> (..., n), not wrapped (see :func:`fold_coaxial`).
    """
    return np.asarray(heading, dtype=np.float64) - geom.alpha + np.pi / 2


def fold_coaxial(beta: np.ndarray, phidot: np.ndarray, geom: RobotGeometry) -> tuple[np.ndarray, np.ndarray]:
    """Bring the angles of coaxial wheels (b_k = 0) into the steering range ]β_min, β_max]
    exactly: β + jπ with φ̇ (−1)^j is the same wheel state when b_k = 0 (the contact point stays
    on the steering axis and the rolling direction reverses). In range angles, non-finite values
    and wheels with b_k ≠ 0 are left as they are (for those β + π puts the contact point on the
    other side of the axis: not the same state). (N, n) -> two new (N, n) arrays."""
    beta = np.array(beta, dtype=np.float64)
    phidot = np.array(phidot, dtype=np.float64)
    coaxial = geom.b == 0.0
    if not coaxial.any():
        return beta, phidot
    with np.errstate(invalid="ignore"):
        outside = (((beta > geom.steer_max) | (beta <= geom.steer_min)) & coaxial & np.isfinite(beta)
                   & (np.abs(beta) <= MAX_ANGLE_RAD))  # beyond: no measurement, the pipeline skips it
    if outside.any():
        wrapped = geom.wrap_steering(beta[outside])
        turns = np.rint((beta[outside] - wrapped) / np.pi).astype(np.int64)
        beta[outside] = wrapped
        phidot[outside] = np.where(turns % 2 == 0, phidot[outside], -phidot[outside])
    return beta, phidot


@dataclass
class SampleChunk:
    """Consecutive samples of a log, in the robot's module order.

    Attributes:
        t_ns: (m,) int64 timestamps [ns] (any origin: Unix time, the robot's clock).
        beta: (m, n) steering angles β [rad], the paper's convention.
        phidot: (m, n) wheel spin rates φ̇ [rad/s].
        bad: (m,) int8 reason code (:data:`BAD_REASONS`) of a sample the reader could not read, 0
            for a read sample (which the pipeline still checks for NaN).
    """

    t_ns: np.ndarray
    beta: np.ndarray
    phidot: np.ndarray
    bad: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        m = len(self.t_ns)
        if self.bad is None:
            self.bad = np.zeros(m, dtype=np.int8)
        if not (self.beta.shape == self.phidot.shape and self.beta.shape[0] == m and self.bad.shape == (m,)):
            raise ValueError(f"SampleChunk shapes disagree: t_ns {self.t_ns.shape}, beta {self.beta.shape}, "
                             f"phidot {self.phidot.shape}, bad {self.bad.shape}")


@dataclass
class GroundTruth:
    """A reference pose over time (motion capture, a simulator's true pose, a fused localisation):
    ``t_ns`` (M,) int64 [ns] on the samples' clock, ``pose`` (M, 3) (x [m], y [m], θ [rad]) in a
    fixed world frame; ``source`` says where it comes from (a topic, a column set, an entry)."""

    t_ns: np.ndarray
    pose: np.ndarray
    source: str


@dataclass
class YawTrack:
    """The robot's heading over time from a gyro (or a pose's rotation): ``t_ns`` (M,) int64 [ns]
    on the samples' clock, strictly increasing; ``yaw`` (M,) [rad], counter-clockwise, unwrapped
    (continuous across ±π); ``source`` says where it comes from (an entry, a topic)."""

    t_ns: np.ndarray
    yaw: np.ndarray
    source: str


class LogSource:
    """A log opened for estimation. Subclasses read one format; opening checks everything that
    can be checked without reading the samples (the file, its topics, entries or columns, the
    names against the robot), so that a bad log is refused before any work.

    Attributes:
        path: the log; format: its format's name; geom: the robot; modules: its module names;
        n_samples: how many samples :meth:`chunks` will give (an upper bound where a format only
        knows its message count), for the progress bar; None when unknown.
    """

    format = "log"

    def __init__(self, path, geom: RobotGeometry, modules) -> None:
        self.path = str(path)
        self.geom = geom
        self.modules = check_module_names(modules, geom)
        self.n_samples: int | None = None

    def chunks(self, size: int) -> Iterator[SampleChunk]:
        """The samples in time order, ``size`` at a time (the last chunk may be shorter)."""
        raise NotImplementedError

    def ground_truth(self) -> GroundTruth | None:
        """The reference pose, if the log has one (and the reader was told where)."""
        return None

    def yaw(self) -> YawTrack | None:
        """The gyro's heading, if the log has one (and the reader was told where)."""
        return None

    def describe(self) -> dict:
        """What was read, for the report: the format and the topics, entries or columns used."""
        return {"format": self.format, "path": self.path}

    def error(self, what: str) -> LogError:
        """A :class:`LogError` naming this log."""
        return LogError(f"{self.format} {self.path}: {what}")


class ArrayLog(LogSource):
    """Samples already in memory as a log: ``t_ns`` (N,) int64 [ns], ``beta`` and ``phidot`` (N, n)
    (the paper's β [rad], φ̇ [rad/s]), an optional reference ``truth`` (:class:`GroundTruth`) and gyro
    ``yaw`` (:class:`YawTrack`)."""

    format = "arrays"

    def __init__(self, t_ns, beta, phidot, geom: RobotGeometry, modules=None, truth: GroundTruth | None = None,
                 yaw: YawTrack | None = None) -> None:
        super().__init__("<arrays>", geom, default_module_names(geom.n) if modules is None else modules)
        self._t = np.asarray(t_ns, dtype=np.int64)
        self._beta = np.asarray(beta, dtype=np.float64)
        self._phidot = np.asarray(phidot, dtype=np.float64)
        if self._t.ndim != 1 or self._beta.shape != (self._t.size, geom.n) or self._phidot.shape != self._beta.shape:
            raise ValueError(f"t_ns (N,), beta and phidot (N, {geom.n}) expected, got {self._t.shape}, "
                             f"{self._beta.shape}, {self._phidot.shape}")
        self._truth = truth
        self._yaw = yaw
        self.n_samples = int(self._t.size)

    def chunks(self, size: int) -> Iterator[SampleChunk]:
        for a in range(0, self._t.size, size):
            b = min(self._t.size, a + size)
            yield SampleChunk(self._t[a:b].copy(), self._beta[a:b].copy(), self._phidot[a:b].copy())

    def ground_truth(self) -> GroundTruth | None:
        return self._truth

    def yaw(self) -> YawTrack | None:
        return self._yaw
