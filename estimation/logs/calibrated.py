"""A calibration applied to a log: ``calibration.json`` (what ``azimut calibrate`` writes) read and
checked against the robot, and :class:`CalibratedLog`, a log whose samples come out corrected.

``steer_offset_deg`` is what to **add** to the logged angle (β or heading alike: both turn with
the module), ``wheel_scale`` the factor to apply to the logged wheel speed. A calibration is bound
to the robot it was fitted for: the module names and the geometry must match.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from estimation.geometry import RobotGeometry
from estimation.logs.source import GroundTruth, LogError, LogSource, SampleChunk, YawTrack, fold_coaxial

__all__ = ["CALIBRATION_SCHEMA", "CalibratedLog", "robot_record", "read_calibration"]

#: the version of calibration.json's layout
CALIBRATION_SCHEMA = 1


def robot_record(geom: RobotGeometry, modules) -> dict:
    """The robot a calibration is bound to: module names and geometry (degrees and metres)."""
    return {"modules": list(modules), "n": int(geom.n), "alpha_deg": np.rad2deg(geom.alpha).round(9).tolist(),
            "l_m": np.asarray(geom.l, float).round(9).tolist(), "b_m": np.asarray(geom.b, float).round(9).tolist(),
            "r_m": np.asarray(geom.r, float).round(9).tolist(), "unlimited_steering": bool(geom.unlimited_steering)}


def _robot_difference(a: dict, b: dict) -> str | None:
    """What differs between the recorded robot ``a`` and the given one ``b`` (None: the same)."""
    if a.get("modules") != b["modules"] or a.get("n") != b["n"]:
        return f"modules {a.get('modules')}, not {b['modules']}"
    for key in ("alpha_deg", "l_m", "b_m", "r_m"):
        try:
            x = np.asarray(a.get(key, []), float)
        except (TypeError, ValueError):
            return f"{key} unreadable"
        y = np.asarray(b[key], float)
        if x.shape != y.shape or not np.allclose(x, y, rtol=0.0, atol=1e-6):
            return f"{key} {np.round(x, 4).tolist()}, not {np.round(y, 4).tolist()}"
    if bool(a.get("unlimited_steering")) != b["unlimited_steering"]:
        return "another steering range"
    return None


def read_calibration(path, geom: RobotGeometry, modules) -> tuple[np.ndarray, np.ndarray]:
    """(steer offsets [rad], wheel factors) of ``calibration.json`` at ``path`` for this robot.
    ``ValueError`` (one line naming the file) for a file that cannot be read, is not a
    calibration, holds a bad value, or was made for another robot."""
    where = f"calibration {path}"
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{where}: cannot be read ({getattr(exc, 'strerror', None) or exc})") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{where}: not JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(data, dict) or data.get("schema") != CALIBRATION_SCHEMA or not isinstance(data.get("modules"),
                                                                                               list):
        raise ValueError(f"{where}: not a calibration of schema {CALIBRATION_SCHEMA} (azimut calibrate writes one)")
    mine = robot_record(geom, modules)
    theirs = data.get("robot")
    diff = "no robot recorded" if not isinstance(theirs, dict) else _robot_difference(theirs, mine)
    if diff is not None:
        raise ValueError(f"{where}: made for another robot than the one given ({diff}); pass the robot file it was "
                         "fitted with")
    offsets, scales = [], []
    for k, (entry, name) in enumerate(zip(data["modules"], mine["modules"])):
        if not isinstance(entry, dict) or entry.get("name") != name:
            raise ValueError(f"{where}: module {k} is {entry.get('name') if isinstance(entry, dict) else entry!r}, "
                             f"not {name!r}")
        off, sc = entry.get("steer_offset_deg"), entry.get("wheel_scale")
        for field, value in (("steer_offset_deg", off), ("wheel_scale", sc)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{where}: module {name}'s {field} must be a finite number, got {value!r}")
        if abs(off) > 360.0:
            raise ValueError(f"{where}: module {name}'s steer_offset_deg {off} is outside ±360")
        if not 0.5 <= sc <= 2.0:
            raise ValueError(f"{where}: module {name}'s wheel_scale {sc} is outside [0.5, 2]")
        offsets.append(math.radians(off))
        scales.append(float(sc))
    return np.array(offsets), np.array(scales)


class CalibratedLog(LogSource):
    """``source``'s samples with the steering offsets added (coaxial modules folded back into the
    steering range) and the wheel speeds scaled; everything else is ``source``'s."""

    def __init__(self, source: LogSource, steer_offset, wheel_scale, label: str = "") -> None:
        super().__init__(source.path, source.geom, source.modules)
        self.format = source.format
        self.source = source
        self.steer_offset = np.asarray(steer_offset, dtype=np.float64)
        self.wheel_scale = np.asarray(wheel_scale, dtype=np.float64)
        if self.steer_offset.shape != (source.geom.n,) or self.wheel_scale.shape != (source.geom.n,):
            raise LogError(f"{source.path}: a calibration of {self.steer_offset.size} modules for a robot of "
                           f"{source.geom.n} ({', '.join(source.modules)}): pass the calibration made for this robot")
        self.label = label
        self.n_samples = source.n_samples

    def chunks(self, size: int) -> Iterator[SampleChunk]:
        for ch in self.source.chunks(size):
            beta, phidot = fold_coaxial(ch.beta + self.steer_offset, ch.phidot * self.wheel_scale, self.geom)
            yield SampleChunk(ch.t_ns, beta, phidot, ch.bad)

    def ground_truth(self) -> GroundTruth | None:
        return self.source.ground_truth()

    def yaw(self) -> YawTrack | None:
        return self.source.yaw()

    def describe(self) -> dict:
        return {**self.source.describe(), "calibration": self.label or "given",
                "calibration_steer_offset_deg": np.rad2deg(self.steer_offset).round(4).tolist(),
                "calibration_wheel_scale": self.wheel_scale.round(6).tolist()}
