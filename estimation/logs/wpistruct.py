"""WPILib struct schemas as NumPy dtypes, to decode ``struct:T`` and ``struct:T[]`` values at once.

A WPILib struct schema is a ``;``-separated list of declarations ``type name``, ``type name[N]``,
``enum {...} type name`` or ``type name:bits`` (bit-fields, not supported here), where ``type`` is a
primitive (``bool``, ``char``, ``int8`` ... ``uint64``, ``float``/``float32``, ``double``/``float64``)
or another struct. Values are packed little-endian with no padding, and a ``struct:T[]`` value is
its elements back to back with no count (WPILib, "Struct serialization", in the wpiutil
documentation of the ``wpi::Struct`` API, 2024).

The schemas of the WPILib types a swerve log holds are :data:`WPILIB_SCHEMAS`; a log carries its
own on ``/.schema/struct:T`` entries, which take precedence.
"""

from __future__ import annotations

import re

import numpy as np

__all__ = ["StructRegistry", "WPILIB_SCHEMAS"]

#: WPILib's schemas of the geometry and kinematics types (WPILib 2024+; ``SwerveModuleVelocity`` is
#: the 2027 name of ``SwerveModuleState``)
WPILIB_SCHEMAS = {
    "Rotation2d": "double value",
    "Translation2d": "double x;double y",
    "Pose2d": "Translation2d translation;Rotation2d rotation",
    "SwerveModuleState": "double speed;Rotation2d angle",
    "SwerveModuleVelocity": "double velocity;Rotation2d angle",
}

_PRIMITIVES = {"bool": "?", "char": "S1", "int8": "i1", "int16": "<i2", "int32": "<i4", "int64": "<i8",
               "uint8": "u1", "uint16": "<u2", "uint32": "<u4", "uint64": "<u8",
               "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8"}
_DECL = re.compile(r"^(?:enum\s*\{[^}]*\}\s*)?(\w+)\s+(\w+)\s*(?:\[\s*(\d+)\s*\])?\s*(?::\s*(\d+))?$")


def _wpilib_dtype(type_name: str) -> np.dtype:
    """The dtype of a WPILib type by WPILib's own schemas."""
    if type_name not in _WPILIB_DTYPES:
        _WPILIB_DTYPES[type_name] = StructRegistry().dtype(type_name, ("",))
    return _WPILIB_DTYPES[type_name]


_WPILIB_DTYPES: dict[str, np.dtype] = {}


def _lies(registry: StructRegistry, type_name: str) -> bool:
    """The log's own schema of WPILib type ``type_name`` (its parts by WPILib's) differs from WPILib's."""
    try:
        own = StructRegistry({**WPILIB_SCHEMAS, type_name: registry.schemas[type_name]})._build(type_name, ())
    except (KeyError, ValueError, NotImplementedError):
        return True
    return own != _wpilib_dtype(type_name)


class StructRegistry:
    """Struct schemas by type name -> packed little-endian NumPy dtypes (nested structs nest)."""

    def __init__(self, schemas: dict[str, str] | None = None) -> None:
        self.schemas: dict[str, str] = dict(WPILIB_SCHEMAS if schemas is None else schemas)
        self._dtypes: dict[str, np.dtype] = {}

    def add(self, type_name: str, schema: str) -> None:
        """Register (or replace) the schema of ``type_name``."""
        self.schemas[type_name] = schema
        self._dtypes.clear()

    def dtype(self, type_name: str, _seen: tuple = ()) -> np.dtype:
        """The dtype of ``type_name``; ``KeyError`` for an unknown type, ``ValueError`` for a schema
        that does not parse or refers to itself, or a WPILib type whose schema in the log has other
        field types than WPILib's (``int64 speed`` for ``double speed`` has the same size and would
        decode as nonsense), ``NotImplementedError`` for bit-fields."""
        dt = self._build(type_name, _seen)
        if not _seen and type_name in WPILIB_SCHEMAS and dt != _wpilib_dtype(type_name):
            liars = [t for t in WPILIB_SCHEMAS if t in self.schemas and _lies(self, t)] or [type_name]
            part = liars[0]
            holds = f", and {type_name} holds it" if part != type_name else ""
            raise ValueError(f"the log's schema of {part} ({self.schemas[part]!r}) is not WPILib's "
                             f"({WPILIB_SCHEMAS[part]!r}){holds}: its values would be misread")
        return dt

    def _build(self, type_name: str, _seen: tuple) -> np.dtype:
        if type_name in self._dtypes:
            return self._dtypes[type_name]
        if type_name not in self.schemas:
            raise KeyError(f"no struct schema for {type_name!r} (known: {', '.join(sorted(self.schemas))})")
        if type_name in _seen:
            raise ValueError(f"struct {type_name!r} contains itself")
        fields = []
        for decl in filter(None, (d.strip() for d in self.schemas[type_name].split(";"))):
            m = _DECL.match(decl)
            if not m:
                raise ValueError(f"struct {type_name}: cannot parse the declaration {decl!r}")
            ftype, fname, count, bits = m.groups()
            if bits is not None:
                raise NotImplementedError(f"struct {type_name}.{fname}: bit-fields are not supported")
            if ftype == "char" and count:
                dt: np.dtype | str = f"S{count}"
                count = None
            else:
                dt = _PRIMITIVES.get(ftype) or self.dtype(ftype, _seen + (type_name,))
            fields.append((fname, dt, (int(count),)) if count else (fname, dt))
        self._dtypes[type_name] = np.dtype(fields)  # a list of fields: packed, no alignment (WPILib's layout)
        return self._dtypes[type_name]
