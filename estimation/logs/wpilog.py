"""WPILib data logs (``.wpilog``): swerve module states as WPILib and AdvantageKit log them.

The file format is the "WPILib Data Log File Format Specification, Version 1.0" (WPILib
developers, ``wpiutil/doc/datalog.adoc``, 2021)::

    header : "WPILOG" | u16 version 0x0100 | u32 extra-header length | extra header
    record : u8 lengths | entry id (1-4 B) | payload size (1-4 B) | timestamp [µs] (1-8 B) | payload
             lengths: bits 0-1 id length − 1, bits 2-3 size length − 1, bits 4-6 timestamp length − 1
    entry 0: control records: 0 start (u32 id, then name, type, metadata as u32 length + UTF-8),
             1 finish (u32 id), 2 set metadata; an id may be started again after its finish

This module reads it itself, in one compiled pass over the record headers (:func:`_walk`) and
NumPy gathers of the wanted payloads; it does not use robotpy-wpiutil's ``DataLogReader``
(the tests check both agree), for these reasons: that reader drops a record cut short at the end of
the file without saying so, where a truncated log must be refused; it decodes no struct by its
schema (``wpistruct`` needs a Python class per type); its wheels need glibc ≥ 2.35; and a Python
loop over its records is slower than one pass here.

What is read (``docs/logs.md``):

* module states: an entry of type ``struct:SwerveModuleState[]`` (``SwerveModuleVelocity[]`` in
  WPILib 2027), one element per module in the robot file's module order, ``speed`` [m/s] along the
  module's heading ``angle`` [rad]; or the older ``double[]`` layout ``[angle_0, speed_0, angle_1,
  ...]`` (AdvantageKit 2023, YAGSL), whose angle unit the caller must give. The heading becomes the
  paper's β (:func:`~estimation.logs.source.beta_from_heading`) and φ̇ = speed / r_k;
* an optional reference pose: ``struct:Pose2d`` or ``double[3]`` (x [m], y [m], θ [rad]);
* an optional gyro heading (:meth:`WpiLogFile.yaw`): a number (``double``, ``float``, ``int64``) in
  degrees or radians, a ``struct:Rotation2d``, a ``struct:Pose2d``'s rotation or a ``double[3]``
  pose's θ.

:class:`WpiLogFile` opens the file and reads what every layout shares (the struct schemas, the
reference pose, the gyro); :class:`WpiLog` adds the module-state arrays, and
:class:`~estimation.logs.wpilog_modules.WpiModuleLog` the per-module entries. Timestamps are the
robot's clock in µs.
"""

from __future__ import annotations

import mmap
import struct
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from numba import njit

from estimation.geometry import RobotGeometry
from estimation.logs.source import (
                                    BAD_WRONG_SIZE,
                                    GroundTruth,
                                    LogSource,
                                    SampleChunk,
                                    YawTrack,
                                    beta_from_heading,
                                    fold_coaxial,
)
from estimation.logs.wpistruct import StructRegistry

__all__ = ["WpiLogFile", "WpiLog", "read_wpilog_index", "STATE_TYPES", "ANGLE_UNITS", "NUMBER_TYPES", "YAW_TYPES",
           "YAW_UNITS", "angle_to_rad"]

#: entry types that hold swerve module states
STATE_TYPES = ("struct:SwerveModuleState[]", "struct:SwerveModuleVelocity[]", "double[]")
#: units of angles logged as plain numbers (a ``double[]`` module-state entry, per-module entries)
ANGLE_UNITS = ("rad", "deg", "rot")
#: entry types of one number per record, and their payloads (``int``: NetworkTables 3's name of int64)
NUMBER_TYPES = ("double", "float", "int64", "int")
_NUMBER_DTYPES = {"double": "<f8", "float": "<f4", "int64": "<i8", "int": "<i8"}
#: entry types a gyro heading is read from (``double[]``: an [x, y, θ] pose)
YAW_TYPES = NUMBER_TYPES + ("struct:Rotation2d", "struct:Pose2d", "double[]")
#: units of a gyro heading logged as a number
YAW_UNITS = ("deg", "rad")
_SCHEMA_PREFIXES = ("/.schema/struct:", "NT:/.schema/struct:")  # DataLog's own, and NetworkTables' recorded


def angle_to_rad(values: np.ndarray, unit: str) -> np.ndarray:
    """Angles in ``unit`` (one of :data:`ANGLE_UNITS`) in radians."""
    values = np.asarray(values, dtype=np.float64)
    if unit == "deg":
        return np.deg2rad(values)
    if unit == "rot":
        return values * (2.0 * np.pi)
    return values

_MAGIC = b"WPILOG"


@njit(cache=True)
def _walk(buf, pos, entry, ts, off, size):
    """Walk the records from byte ``pos``: fill entry id, timestamp, payload offset and size of
    each (when the arrays are not empty); return (records, byte where the walk stopped, 1 if the last
    record is cut short by the end of the file else 0)."""
    end = buf.shape[0]
    k = 0
    fill = entry.shape[0] > 0
    while pos < end:
        bf = buf[pos]
        il = (bf & 3) + 1
        sl = ((bf >> 2) & 3) + 1
        tl = ((bf >> 4) & 7) + 1
        p = pos + 1
        if p + il + sl + tl > end:
            return k, pos, 1
        e = 0
        for j in range(il):
            e |= np.int64(buf[p + j]) << (8 * j)
        p += il
        s = 0
        for j in range(sl):
            s |= np.int64(buf[p + j]) << (8 * j)
        p += sl
        t = np.uint64(0)
        for j in range(tl):
            t |= np.uint64(buf[p + j]) << np.uint64(8 * j)
        p += tl
        if p + s > end:
            return k, pos, 1
        if fill:
            entry[k] = e
            ts[k] = np.int64(t)
            off[k] = p
            size[k] = s
        k += 1
        pos = p + s
    return k, pos, 0


#: the largest record timestamp [µs] whose nanoseconds fit an int64
_MAX_TIMESTAMP_US = (2**63 - 1) // 1000


class _Index:
    """Every record of a log: entry id, timestamp [µs], payload offset and size (numpy arrays), and
    the entries' (name, type, first record, end record) spans from the control records."""

    def __init__(self, buf: np.ndarray, start: int, path: str) -> None:
        empty = np.zeros(0, np.int64)
        count, stop, cut = _walk(buf, start, empty, empty, empty, empty)
        if cut:
            raise ValueError(f"truncated: the record at byte {stop} of {buf.shape[0]} is cut short (a log that was "
                             "still being written, or a partial copy)")
        self.entry, self.ts, self.off, self.size = (np.empty(count, np.int64) for _ in range(4))
        _walk(buf, start, self.entry, self.ts, self.off, self.size)
        # µs as read: a signed 64-bit count (WPILib's DataLogReader reads it signed: NetworkTables values
        # from before the robot clock started come negative); as ns it must still fit an int64
        beyond = (self.ts > _MAX_TIMESTAMP_US) | (self.ts < -_MAX_TIMESTAMP_US)
        if beyond.any():
            i = int(np.flatnonzero(beyond)[0])
            stamp = (int(self.ts[i]) if self.ts[i] > 0
                     else f"{int(self.ts[i])} (or {int(self.ts[i].view(np.uint64))} unsigned)")
            raise ValueError(f"record {i} has the timestamp {stamp} µs, beyond the ±{_MAX_TIMESTAMP_US} µs "
                             "(292 years) a nanosecond clock holds: a corrupt file?")
        self.spans: list[tuple[str, str, int, int, int]] = []  # name, type, id, first record, end record
        open_: dict[int, int] = {}
        for i in np.flatnonzero(self.entry == 0):
            payload = bytes(buf[self.off[i]:self.off[i] + self.size[i]])
            if not payload:
                raise ValueError(f"control record {i} is empty")
            if payload[0] == 0:  # start
                eid, name, typ = _parse_start(payload, i)
                if eid in open_:
                    raise ValueError(f"control record {i} starts entry {eid} ({name!r}) while it is open")
                open_[eid] = len(self.spans)
                self.spans.append((name, typ, eid, int(i) + 1, count))
            elif payload[0] == 1 and len(payload) >= 5:  # finish
                (eid,) = struct.unpack_from("<I", payload, 1)
                if eid in open_:
                    j = open_.pop(eid)
                    self.spans[j] = self.spans[j][:4] + (int(i),)

    def records(self, name: str) -> tuple[str, np.ndarray] | None:
        """(type, indices of its data records) of entry ``name`` (None if absent); an entry started
        several times must keep its type."""
        picks, typ = [], None
        for n, t, eid, first, end in self.spans:
            if n != name:
                continue
            if typ is not None and t != typ:
                raise ValueError(f"entry {name!r} is started as {typ} and again as {t}")
            typ = t
            idx = np.flatnonzero(self.entry[first:end] == eid) + first
            picks.append(idx)
        return None if typ is None else (typ, np.concatenate(picks))

    def types(self) -> dict[str, str]:
        return {n: t for n, t, *_ in self.spans}


def _parse_start(payload: bytes, i: int) -> tuple[int, str, str]:
    try:
        (eid, nlen) = struct.unpack_from("<II", payload, 1)
        name = payload[9:9 + nlen].decode()
        q = 9 + nlen
        (tlen,) = struct.unpack_from("<I", payload, q)
        typ = payload[q + 4:q + 4 + tlen].decode()
    except (struct.error, UnicodeDecodeError):
        raise ValueError(f"control record {i} (start) is malformed") from None
    return eid, name, typ


def read_wpilog_index(path) -> tuple[np.ndarray, _Index, str]:
    """Map ``path`` and index its records: (bytes as uint8, index, extra header). ``ValueError``
    for a file that is not a wpilog, has another major version, or is truncated."""
    with open(path, "rb") as fh:
        size = Path(path).stat().st_size
        if size < 12:
            raise ValueError(f"not a WPILib data log ({size} bytes, no header)")
        mm = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    buf = np.frombuffer(mm, dtype=np.uint8)
    if bytes(buf[:6]) != _MAGIC:
        raise ValueError(f"not a WPILib data log (starts with {bytes(buf[:6])!r}, not {_MAGIC!r})")
    version, hlen = struct.unpack_from("<HI", bytes(buf[6:12]))
    if version >> 8 != 1:
        raise ValueError(f"data log version {version >> 8}.{version & 0xFF}; this reader reads 1.x")
    if 12 + hlen > buf.shape[0]:
        raise ValueError("truncated: the extra header runs past the end of the file")
    extra = bytes(buf[12:12 + hlen]).decode("utf-8", "replace")
    return buf, _Index(buf, 12 + hlen, str(path)), extra


def _gather(buf: np.ndarray, index: _Index, rec: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
    """The payloads of records ``rec`` that are ``width`` bytes long, as (m, width) uint8, and the
    mask of those records among ``rec``."""
    ok = index.size[rec] == width
    sel = rec[ok]
    data = buf[index.off[sel][:, None] + np.arange(width)[None, :]] if sel.size else np.zeros((0, width), np.uint8)
    return np.ascontiguousarray(data), ok


class WpiLogFile(LogSource):
    """A ``.wpilog`` opened: its record index, its struct schemas (``/.schema/struct:T`` and the
    ``NT:/.schema/struct:T`` entries NetworkTables recording writes), and what every layout of
    module data shares: the reference pose (``truth_entry``) and the gyro heading (``yaw_entry``, a
    number in ``yaw_unit`` deg or rad, a ``struct:Rotation2d``, a ``struct:Pose2d`` or a ``double[3]``
    pose). Subclasses read the module data (:class:`WpiLog`,
    :class:`~estimation.logs.wpilog_modules.WpiModuleLog`)."""

    format = "WPILib data log"

    def __init__(self, path, geom: RobotGeometry, modules, truth_entry: str | None = None,
                 yaw_entry: str | None = None, yaw_unit: str | None = None) -> None:
        super().__init__(path, geom, modules)
        if yaw_unit is not None and yaw_unit not in YAW_UNITS:
            raise ValueError(f"yaw_unit must be one of {YAW_UNITS}, got {yaw_unit!r}")
        p = Path(path)
        if not p.is_file():
            raise self.error("no such file" if not p.exists() else "not a file")
        try:
            self._buf, self._index, self.extra_header = read_wpilog_index(p)
        except ValueError as exc:
            raise self.error(str(exc)) from None
        self.types = self._index.types()
        self.structs = StructRegistry()
        for prefix in _SCHEMA_PREFIXES:  # the DataLog's own schemas last: they win
            for name, typ in self.types.items():
                if typ == "structschema" and name.startswith(prefix):
                    got = self._index.records(name)
                    if got is not None and got[1].size:
                        i = got[1][-1]
                        text = bytes(self._buf[self._index.off[i]:self._index.off[i] + self._index.size[i]])
                        self.structs.add(name.removeprefix(prefix), text.decode("utf-8", "replace"))
        self.truth_entry = truth_entry
        if truth_entry is not None:
            if truth_entry not in self.types:
                raise self.error(f"no entry {truth_entry!r} (reference pose); pose entries: "
                                 + (", ".join(n for n, t in self.types.items() if t in ("struct:Pose2d", "double[]"))
                                    or "none"))
            if self.types[truth_entry] not in ("struct:Pose2d", "double[]"):
                raise self.error(f"entry {truth_entry!r} is {self.types[truth_entry]}, not struct:Pose2d or double[]")
        self.yaw_entry, self.yaw_unit = yaw_entry, yaw_unit
        if yaw_entry is None:
            if yaw_unit is not None:
                raise ValueError("yaw_unit without yaw_entry")
        else:
            self._check_yaw_entry()

    def _check_yaw_entry(self) -> None:
        name, unit = self.yaw_entry, self.yaw_unit
        if name not in self.types:
            raise self.error(f"no entry {name!r} (gyro heading); entries of a heading's types: "
                             + (", ".join(n for n, t in self.types.items() if t in YAW_TYPES[4:]) or "none"))
        typ = self.types[name]
        if typ not in YAW_TYPES:
            raise self.error(f"entry {name!r} (gyro heading) is {typ}, not one of {', '.join(YAW_TYPES)}")
        if typ in NUMBER_TYPES and unit is None:
            raise self.error(f"entry {name!r} (gyro heading) is a {typ}, whose unit the log does not say: give it "
                             "(--yaw-unit deg or rad)")
        if typ not in NUMBER_TYPES and unit is not None:
            raise self.error(f"entry {name!r} (gyro heading) is a {typ}, in radians: a yaw unit does not apply")

    def numbers(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(t [ns], values as float64) of number entry ``name`` (one of :data:`NUMBER_TYPES`); records of
        another size are dropped."""
        typ, rec = self._index.records(name)
        dt = np.dtype(_NUMBER_DTYPES[typ])
        data, ok = _gather(self._buf, self._index, rec, dt.itemsize)
        return self._index.ts[rec[ok]] * 1000, data.view(dt).reshape(-1).astype(np.float64)

    def struct_values(self, name: str, type_name: str) -> tuple[np.ndarray, np.ndarray]:
        """(t [ns], structured values) of a ``struct:type_name`` entry; records of another size dropped."""
        try:
            dt = self.structs.dtype(type_name)
        except (KeyError, ValueError, NotImplementedError) as exc:
            raise self.error(f"entry {name!r}, struct {type_name}: {exc}") from None
        _, rec = self._index.records(name)
        data, ok = _gather(self._buf, self._index, rec, dt.itemsize)
        return self._index.ts[rec[ok]] * 1000, data.view(dt).reshape(-1)

    def rotations(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(t [ns], angle [rad]) of a ``struct:Rotation2d`` entry."""
        t, v = self.struct_values(name, "Rotation2d")
        return t, np.asarray(v["value"], dtype=np.float64)

    def ground_truth(self) -> GroundTruth | None:
        if self.truth_entry is None:
            return None
        typ, rec = self._index.records(self.truth_entry)
        if typ == "double[]":
            data, ok = _gather(self._buf, self._index, rec, 24)
            t, pose = self._index.ts[rec[ok]] * 1000, data.view("<f8").reshape(-1, 3)
        else:
            t, p = self.struct_values(self.truth_entry, "Pose2d")
            pose = np.column_stack([p["translation"]["x"], p["translation"]["y"], p["rotation"]["value"]])
        return GroundTruth(t, np.asarray(pose, dtype=np.float64), f"entry {self.truth_entry}")

    def yaw(self) -> YawTrack | None:
        """The gyro heading of ``yaw_entry`` [rad, CCW, unwrapped]: NaN values dropped, and of records
        with the same timestamp the last kept."""
        if self.yaw_entry is None:
            return None
        name = self.yaw_entry
        typ, rec = self._index.records(name)
        if typ in NUMBER_TYPES:
            t, yaw = self.numbers(name)
            yaw = angle_to_rad(yaw, self.yaw_unit)
        elif typ == "struct:Rotation2d":
            t, yaw = self.rotations(name)
        elif typ == "struct:Pose2d":
            t, p = self.struct_values(name, "Pose2d")
            yaw = np.asarray(p["rotation"]["value"], dtype=np.float64)
        else:
            data, ok = _gather(self._buf, self._index, rec, 24)
            t, yaw = self._index.ts[rec[ok]] * 1000, data.view("<f8").reshape(-1, 3)[:, 2].astype(np.float64)
        keep = np.isfinite(yaw)
        t, yaw = t[keep], yaw[keep]
        if np.any(np.diff(t) < 0):
            raise self.error(f"entry {name!r} (gyro heading): timestamps decrease")
        last = np.append(t[1:] != t[:-1], True) if t.size else np.zeros(0, bool)
        return YawTrack(t[last], np.unwrap(yaw[last]), f"entry {name}")

    def describe(self) -> dict:
        return {"format": self.format, "path": self.path, "truth_entry": self.truth_entry,
                "yaw_entry": self.yaw_entry, "yaw_unit": self.yaw_unit, "extra_header": self.extra_header}


class WpiLog(WpiLogFile):
    """A ``.wpilog``'s swerve module-state arrays as wheel samples (see the module docstring)."""

    def __init__(self, path, geom: RobotGeometry, modules, states_entry: str | None = None,
                 truth_entry: str | None = None, angle_unit: str | None = None, yaw_entry: str | None = None,
                 yaw_unit: str | None = None) -> None:
        if angle_unit is not None and angle_unit not in ANGLE_UNITS:
            raise ValueError(f"angle_unit must be one of {ANGLE_UNITS}, got {angle_unit!r}")
        super().__init__(path, geom, modules, truth_entry=truth_entry, yaw_entry=yaw_entry, yaw_unit=yaw_unit)
        types = self.types
        self.states_entry = states_entry if states_entry is not None else self._find_states(types)
        if self.states_entry not in types:
            raise self.error(f"no entry {self.states_entry!r} (module states)")
        self.states_type = types[self.states_entry]
        if self.states_type not in STATE_TYPES:
            raise self.error(f"entry {self.states_entry!r} is {self.states_type}, not one of {', '.join(STATE_TYPES)}")
        if self.states_type == "double[]" and angle_unit is None:
            raise self.error(f"entry {self.states_entry!r} is a double[] of [angle, speed] pairs, whose angle unit the "
                             "log does not say: give it (--angle-unit rad, deg or rot)")
        if self.states_type != "double[]" and angle_unit is not None:
            raise self.error(f"entry {self.states_entry!r} is a {self.states_type}, whose angles are Rotation2d in "
                             "radians: an angle unit does not apply (--angle-unit)")
        self.angle_unit = angle_unit
        self._states = self._decode_states()
        self.n_samples = int(self._states[0].size)

    def _find_states(self, types: dict) -> str:
        found = [n for n, t in types.items() if t in STATE_TYPES[:2]]
        measured = [n for n in found if n.endswith("Measured")]
        pick = measured if len(measured) == 1 else found
        if len(pick) == 1:
            return pick[0]
        if not found:
            raise self.error("no entry of type struct:SwerveModuleState[] (module states); name a double[] entry "
                             "with --states-entry, or per-module entries with --steer-entry and --wheel-entry")
        raise self.error(f"several module-state entries ({', '.join(found)}): name one with --states-entry")

    def _decode_states(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(t [ns], heading [rad], speed [m/s], bad) of every record of the states entry."""
        n = self.geom.n
        _, rec = self._index.records(self.states_entry)
        if self.states_type == "double[]":
            data, ok = _gather(self._buf, self._index, rec, 16 * n)
            pairs = data.view("<f8").reshape(-1, n, 2)
            heading, speed = angle_to_rad(pairs[..., 0], self.angle_unit), pairs[..., 1]
        else:
            type_name = self.states_type.removeprefix("struct:").removesuffix("[]")
            try:
                dt = self.structs.dtype(type_name)
            except (KeyError, ValueError, NotImplementedError) as exc:
                raise self.error(f"entry {self.states_entry!r}, struct {type_name}: {exc}") from None
            fields = [f for f in ("speed", "velocity") if f in (dt.names or ())]
            if not fields or "angle" not in dt.names:
                raise self.error(f"struct {type_name} ({self.structs.schemas[type_name]!r}) has no speed and angle")
            data, ok = _gather(self._buf, self._index, rec, dt.itemsize * n)
            states = data.view(dt).reshape(-1, n)
            angle = states["angle"]
            heading = angle["value"] if angle.dtype.names else angle
            speed = states[fields[0]]
        n_rec = rec.size
        full_h = np.full((n_rec, n), np.nan)
        full_s = np.full((n_rec, n), np.nan)
        full_h[ok], full_s[ok] = heading, speed
        bad = np.where(ok, 0, BAD_WRONG_SIZE).astype(np.int8)
        return self._index.ts[rec] * 1000, full_h, full_s, bad

    def chunks(self, size: int) -> Iterator[SampleChunk]:
        t, heading, speed, bad = self._states
        for a in range(0, t.size, size):
            b = min(t.size, a + size)
            beta, phidot = fold_coaxial(beta_from_heading(heading[a:b], self.geom), speed[a:b] / self.geom.r, self.geom)
            yield SampleChunk(t[a:b].copy(), beta, phidot, bad[a:b].copy())

    def describe(self) -> dict:
        return {"format": self.format, "path": self.path, "states_entry": self.states_entry,
                "states_type": self.states_type, "angle_unit": self.angle_unit, "truth_entry": self.truth_entry,
                "yaw_entry": self.yaw_entry, "yaw_unit": self.yaw_unit, "extra_header": self.extra_header}
