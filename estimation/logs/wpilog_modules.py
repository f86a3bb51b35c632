"""WPILib data logs (``.wpilog``) whose robot logs each module's steering angle and wheel speed as
entries of their own, each at its own times.

Real swerve robots log their modules this way as often as in one state array:

* SmartDashboard numbers recorded from NetworkTables, logged when they change (Team 364's
  BaseFalconSwerve: ``NT:/SmartDashboard/Mod {i} Cancoder`` [deg]; YAGSL:
  ``NT:/SmartDashboard/swerve/modules/{module}/Raw Absolute Encoder`` [deg]);
* ``DataLog`` entries of the robot code, every loop (``mod{i}/driveMotorSpeed``, motor units);
* AdvantageKit's module inputs (``/Drive/Module{i}/TurnPosition``, a ``struct:Rotation2d`` or a
  ``double`` [rad]; ``/Drive/Module{i}/DriveVelocityRadPerSec``, the wheel's rad/s).

:class:`WpiModuleLog` reads entries named by two patterns, ``{i}`` standing for the module's 0-based
index in the robot file and ``{module}`` for its name. The 2n signals are brought onto one clock,
that of the signal logged most often, by sample-and-hold (:func:`~estimation.logs.hold.sample_and_hold`:
each signal's latest value at the tick, a value logged up to half a clock period after the tick
counting for it, the same loop iteration); a tick where some value is older than ``max_age_s`` is
marked stale (:data:`~estimation.logs.source.BAD_STALE`) and skipped. Steering values become β through
``angle_unit`` and ``steer_convention`` (``heading``: WPILib's module angle, the rolling direction;
:func:`~estimation.logs.source.beta_from_heading`), wheel values φ̇ = value × ``wheel_scale`` / r_k
(``wheel_scale``: the logged unit to m/s at the wheel).
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterator

import numpy as np

from estimation.geometry import RobotGeometry
from estimation.logs.hold import DEFAULT_MAX_AGE_S, clock_of, sample_and_hold
from estimation.logs.source import BAD_STALE, STEER_CONVENTIONS, SampleChunk, beta_from_heading, fold_coaxial
from estimation.logs.wpilog import ANGLE_UNITS, NUMBER_TYPES, WpiLogFile, angle_to_rad

__all__ = ["WpiModuleLog", "STEER_TYPES", "WHEEL_TYPES", "expand_pattern"]

#: entry types a module's steering angle is read from, and its wheel speed
STEER_TYPES = NUMBER_TYPES + ("struct:Rotation2d",)
WHEEL_TYPES = NUMBER_TYPES


def expand_pattern(pattern: str, index: int, module: str) -> str:
    """``pattern`` with ``{i}`` replaced by ``index`` and ``{module}`` by ``module`` (other braces are
    left as they are: entry names may hold them)."""
    return pattern.replace("{i}", str(index)).replace("{module}", module)


class WpiModuleLog(WpiLogFile):
    """A ``.wpilog``'s per-module steering and wheel entries as wheel samples (see the module
    docstring).

    Args:
        steer_entry, wheel_entry: entry name patterns (``{i}``, ``{module}``); with several modules,
            each must hold one of them.
        angle_unit: ``rad``, ``deg`` or ``rot``: the unit of number steering entries (required for
            them; refused when every steering entry is a ``struct:Rotation2d``, which is in radians).
        steer_convention: ``heading`` (default: WPILib's module angle, the wheel's rolling direction)
            or ``beta`` (the paper's β).
        wheel_scale: the logged wheel value times this is the wheel's speed in m/s (finite, nonzero;
            negative for an inverted drive motor); default 1.0, m/s logged.
        max_age_s: a held value older than this [s] makes the tick stale (finite, > 0).
        truth_entry, yaw_entry, yaw_unit: as :class:`~estimation.logs.wpilog.WpiLogFile`.
    """

    def __init__(self, path, geom: RobotGeometry, modules, steer_entry: str, wheel_entry: str,
                 angle_unit: str | None = None, steer_convention: str = "heading", wheel_scale: float = 1.0,
                 max_age_s: float = DEFAULT_MAX_AGE_S, truth_entry: str | None = None, yaw_entry: str | None = None,
                 yaw_unit: str | None = None) -> None:
        if angle_unit is not None and angle_unit not in ANGLE_UNITS:
            raise ValueError(f"angle_unit must be one of {ANGLE_UNITS}, got {angle_unit!r}")
        if steer_convention not in STEER_CONVENTIONS:
            raise ValueError(f"steer_convention must be one of {STEER_CONVENTIONS}, got {steer_convention!r}")
        if isinstance(wheel_scale, bool) or not isinstance(wheel_scale, (int, float)) \
                or not math.isfinite(wheel_scale) or wheel_scale == 0:
            raise ValueError(f"wheel_scale must be a finite nonzero number (the logged unit to m/s at the wheel), "
                             f"got {wheel_scale!r}")
        if isinstance(max_age_s, bool) or not isinstance(max_age_s, (int, float)) \
                or not math.isfinite(max_age_s) or max_age_s <= 0:
            raise ValueError(f"max_age_s must be a finite number of seconds > 0, got {max_age_s!r}")
        for flag, pattern in (("steer_entry", steer_entry), ("wheel_entry", wheel_entry)):
            if not isinstance(pattern, str) or not pattern:
                raise ValueError(f"{flag} must be a non-empty entry name pattern, got {pattern!r}")
            if geom.n > 1 and "{i}" not in pattern and "{module}" not in pattern:
                raise ValueError(f"{flag} {pattern!r} names one entry for {geom.n} modules: put {{i}} (the module's "
                                 "index from 0) or {module} (its name) in it")
        super().__init__(path, geom, modules, truth_entry=truth_entry, yaw_entry=yaw_entry, yaw_unit=yaw_unit)
        self.steer_pattern, self.wheel_pattern = steer_entry, wheel_entry
        self.angle_unit, self.steer_convention = angle_unit, steer_convention
        self.wheel_scale, self.max_age_s = float(wheel_scale), float(max_age_s)
        self.steer_entries = self._resolve(steer_entry, STEER_TYPES, "steering angle", "--steer-entry")
        self.wheel_entries = self._resolve(wheel_entry, WHEEL_TYPES, "wheel speed", "--wheel-entry")
        steer_types = [self.types[e] for e in self.steer_entries]
        numbers = [e for e, t in zip(self.steer_entries, steer_types) if t in NUMBER_TYPES]
        if numbers and angle_unit is None:
            raise self.error(f"steering entry {numbers[0]!r} is a {self.types[numbers[0]]}, whose angle unit the log "
                             "does not say: give it (--angle-unit rad, deg or rot)")
        if not numbers and angle_unit is not None:
            raise self.error(f"steering entry {self.steer_entries[0]!r} is a struct:Rotation2d, in radians: an angle "
                             "unit does not apply")
        self._decode()

    def _resolve(self, pattern: str, accepted: tuple, what: str, flag: str) -> list[str]:
        """Each module's entry name of ``pattern``, checked to exist with one of the ``accepted`` types."""
        names = []
        for k, module in enumerate(self.modules):
            name = expand_pattern(pattern, k, module)
            if name not in self.types:
                near = difflib.get_close_matches(name, list(self.types), n=5, cutoff=0.6)
                raise self.error(f"no entry {name!r} for module {k} ({module})'s {what} ({flag} {pattern!r}); "
                                 + (f"near: {', '.join(repr(x) for x in near)}" if near else "no entry is near it"))
            if self.types[name] not in accepted:
                raise self.error(f"entry {name!r} (module {module}'s {what}) is {self.types[name]}, not one of "
                                 f"{', '.join(accepted)}")
            names.append(name)
        return names

    def _signal(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        t, v = self.rotations(name) if self.types[name] == "struct:Rotation2d" else self.numbers(name)
        if np.any(np.diff(t) < 0):
            raise self.error(f"entry {name!r}: timestamps decrease")
        return t, v

    def _decode(self) -> None:
        """Every signal held at the clock's ticks: β, φ̇ (T, n) and the stale ticks."""
        n = self.geom.n
        signals = [self._signal(e) for e in self.steer_entries + self.wheel_entries]
        empty = [e for e, (t, _) in zip(self.steer_entries + self.wheel_entries, signals) if t.size == 0]
        if empty:
            raise self.error(f"entry {empty[0]!r} has no value")
        times = [t for t, _ in signals]
        c = clock_of(times)
        self.clock_entry = (self.steer_entries + self.wheel_entries)[c]
        clock = np.unique(times[c])
        period = np.diff(clock)
        lookahead = int(np.median(period) // 2) if period.size else 0
        held, stale = sample_and_hold(clock, times, [v for _, v in signals], int(round(self.max_age_s * 1e9)),
                                      lookahead_ns=lookahead)
        steer, wheel = held[:, :n], held[:, n:]
        steer = np.column_stack([angle_to_rad(steer[:, k], self.angle_unit)
                                 if self.types[e] in NUMBER_TYPES else steer[:, k]
                                 for k, e in enumerate(self.steer_entries)]).reshape(-1, n)
        beta = beta_from_heading(steer, self.geom) if self.steer_convention == "heading" else steer
        phidot = wheel * self.wheel_scale / self.geom.r
        self._t = clock
        self._beta, self._phidot = fold_coaxial(beta, phidot, self.geom)
        self._bad = np.where(stale, BAD_STALE, 0).astype(np.int8)
        self.lookahead_ns = lookahead
        self.n_stale = int(stale.sum())
        self.n_samples = int(clock.size)

    def chunks(self, size: int) -> Iterator[SampleChunk]:
        for a in range(0, self._t.size, size):
            b = min(self._t.size, a + size)
            yield SampleChunk(self._t[a:b].copy(), self._beta[a:b].copy(), self._phidot[a:b].copy(),
                              self._bad[a:b].copy())

    def describe(self) -> dict:
        return {"format": self.format, "path": self.path, "steer_entries": self.steer_entries,
                "wheel_entries": self.wheel_entries, "clock_entry": self.clock_entry, "angle_unit": self.angle_unit,
                "steer_convention": self.steer_convention, "wheel_scale": self.wheel_scale,
                "max_age_s": self.max_age_s, "lookahead_ms": self.lookahead_ns / 1e6, "stale_ticks": self.n_stale,
                "truth_entry": self.truth_entry, "yaw_entry": self.yaw_entry, "yaw_unit": self.yaw_unit,
                "extra_header": self.extra_header}
