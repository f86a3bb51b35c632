"""Robot description files: the file format's header and its ``[geometry]`` table, the part
:mod:`estimation` owns.

The schema (``docs/robots.md`` shows it whole, with examples)::

    schema = 1                       # the file format's version (required)
    name = "swerve"                  # a label (optional)
    description = "..."              # free text (optional)
    sources = ["...", "..."]         # where the values come from (optional)

    [geometry]                       # required
    steering = "unlimited"           # "limited" (hard stops, the default) or "unlimited"
    steer_range_deg = [-90.0, 90.0]  # limited only: ]β_min, β_max] [deg], width 180 (default ±90)
    b_m = 0.0                        # sidewise offset b of every module [m] (default 0)
    r_m = 0.0502                     # wheel radius r of every module [m] (required here or per module)

    [[geometry.modules]]             # one table per module, n >= 3
    name = "front_left"              # optional, unique (log readers map joint names to it)
    x_m = 0.308                      # steering axis A_k in the chassis frame [m] ...
    y_m = 0.308
    # ... or alpha_deg = 45.0 and l_m = 0.30 (the paper's α_k [deg] and l_k [m])
    # b_m, r_m: this module's own values (override the [geometry] ones)

The file's other keys belong to the packages that read them (the simulator's parameter tables
and ``gravity``: ``azimut_env.robot_file``, the one reader of a whole file, which names them
here as ``others``); this module knows none of them. It reads the TOML and checks the header
(:func:`read_robot_file`, :func:`parse_robot_text`) and reads the geometry
(:func:`geometry_kwargs`, which ``RobotGeometry.from_file`` and ``RobotGeometry.from_description``
call; this module does not import the geometry, so that the geometry can import it).

Every refusal is a :class:`RobotFileError` (a ``ValueError``) whose message names the file, the
key (``[geometry.modules][2].x_m``) and the value.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10: the tomli backport (a core dependency there)
    import tomli as tomllib

__all__ = ["SCHEMA_VERSION", "HEADER_KEYS", "GEOMETRY_TABLE", "RobotFileError", "read_robot_file",
           "check_description", "parse_robot_text", "geometry_kwargs", "module_names", "number", "where",
           "MAX_LENGTH_M", "MAX_RADIUS_M", "MAX_OFFSET_M", "unit_hint"]

#: the version of the file format this code reads (the ``schema`` key)
SCHEMA_VERSION = 1
#: the file's header: the top-level keys that describe the file, not the robot
HEADER_KEYS = ("schema", "name", "description", "sources")
#: the table this module reads
GEOMETRY_TABLE = "geometry"

#: plausibility bounds of the geometry (a robot file in millimetres, not metres, is refused by
#: them with a hint): |x|, |y|, l of a steering axis [m], the wheel radius r [m], |b| [m]
MAX_LENGTH_M = 10.0
MAX_RADIUS_M = 1.0
MAX_OFFSET_M = 1.0

_GEOMETRY_KEYS = ("steering", "steer_range_deg", "b_m", "r_m", "modules")
_MODULE_KEYS = ("name", "x_m", "y_m", "alpha_deg", "l_m", "b_m", "r_m")


class RobotFileError(ValueError):
    """A robot description file that cannot be used; the message names the file, key and value."""


def where(source: str, key: str) -> str:
    """``"robot file SOURCE: KEY"``, the prefix of every message about a key of a file."""
    return f"robot file {source}: {key}"


def number(value: Any, source: str, key: str) -> float:
    """A finite TOML number (int or float, not bool) as a float, else :class:`RobotFileError`."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RobotFileError(f"{where(source, key)} = {value!r}: must be a number")
    if not math.isfinite(value):
        raise RobotFileError(f"{where(source, key)} = {value!r}: must be finite")
    return float(value)


def unit_hint(value: float, unit: str, factor: float = 1000.0, smaller: str = "millimetres") -> str:
    """The likely-mistake tail of a refusal of an implausibly large value: ``"metres expected
    (millimetres?); 0.3?"``."""
    return f"{unit} expected ({smaller}?); {value / factor:.6g}?"


def _bounded(value: float, bound: float, source: str, key: str, what: str, unit: str = "metres") -> float:
    """``value`` if ``|value| <= bound``, else :class:`RobotFileError` naming the likely mistake."""
    if abs(value) > bound:
        raise RobotFileError(f"{where(source, key)} = {value:g}: {what} beyond {bound:g} m is implausible: "
                             + unit_hint(value, unit))
    return value


def _check_keys(table: Any, allowed: tuple[str, ...], source: str, key: str) -> dict:
    if not isinstance(table, dict):
        raise RobotFileError(f"{where(source, key)} = {table!r}: must be a table")
    unknown = [k for k in table if k not in allowed]
    if unknown:
        raise RobotFileError(f"{where(source, key)}: unknown key {unknown[0]!r} (known: {', '.join(allowed)})")
    return table


def read_robot_file(path, others: tuple[str, ...] | None = None) -> dict:
    """Parse a robot description file and check its header (:func:`check_description`).
    Returns the parsed dict with the file's path as a string under ``"_source"``; the geometry is
    read by :func:`geometry_kwargs`, the other tables by their own readers."""
    p = Path(path)
    source = str(path)
    try:
        with p.open("rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise RobotFileError(f"robot file {source}: no such file") from None
    except IsADirectoryError:
        raise RobotFileError(f"robot file {source}: is a directory, not a file") from None
    except OSError as exc:
        raise RobotFileError(f"robot file {source}: cannot be read ({exc.strerror or exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise RobotFileError(f"robot file {source}: not valid TOML ({exc})") from None
    except UnicodeDecodeError as exc:
        raise RobotFileError(f"robot file {source}: not UTF-8 text ({exc.reason})") from None
    return check_description(data, source, others)


def parse_robot_text(text: str, source: str, others: tuple[str, ...] | None = None) -> dict:
    """:func:`read_robot_file` on the text of a description (``source`` names it in messages)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RobotFileError(f"robot file {source}: not valid TOML ({exc})") from None
    return check_description(data, source, others)


def check_description(data: dict, source: str, others: tuple[str, ...] | None = None) -> dict:
    """The header of a parsed description: ``schema`` = :data:`SCHEMA_VERSION`, ``name``,
    ``description`` and ``sources`` of their kinds, a ``[geometry]`` table. ``others``: the
    top-level keys the caller reads besides these (the simulator's: ``azimut_env.robot_file``),
    any other key refused; None: the keys outside the header and ``[geometry]`` are left unchecked
    (``RobotGeometry.from_file`` reads the geometry of a file whose other tables are the
    simulator's). Returns a copy of ``data`` with ``"_source"``."""
    if others is not None:
        allowed = HEADER_KEYS + (GEOMETRY_TABLE,) + tuple(others)
        unknown = [k for k in data if k not in allowed]
        if unknown:
            raise RobotFileError(f"robot file {source}: unknown key {unknown[0]!r} (known: {', '.join(allowed)})")
    if "schema" not in data:
        raise RobotFileError(f"robot file {source}: missing key 'schema' (this reader reads schema = {SCHEMA_VERSION})")
    if isinstance(data["schema"], bool) or data["schema"] != SCHEMA_VERSION:
        raise RobotFileError(f"{where(source, 'schema')} = {data['schema']!r}: this reader reads schema = "
                             f"{SCHEMA_VERSION}")
    for key in ("name", "description"):
        if key in data and not isinstance(data[key], str):
            raise RobotFileError(f"{where(source, key)} = {data[key]!r}: must be a string")
    sources = data.get("sources", [])
    if not (isinstance(sources, list) and all(isinstance(x, str) for x in sources)):
        raise RobotFileError(f"{where(source, 'sources')} = {data['sources']!r}: must be a list of strings")
    if GEOMETRY_TABLE not in data:
        raise RobotFileError(f"robot file {source}: missing table [geometry]")
    if not isinstance(data[GEOMETRY_TABLE], dict):
        raise RobotFileError(f"{where(source, GEOMETRY_TABLE)} = {data[GEOMETRY_TABLE]!r}: must be a table "
                             "([geometry])")
    out = dict(data)
    out["_source"] = source
    return out


def _module_axis(mod: dict, source: str, key: str) -> tuple[float, float]:
    """(α [rad], l [m]) of one module table: from (x_m, y_m) or (alpha_deg, l_m)."""
    cart = [k for k in ("x_m", "y_m") if k in mod]
    polar = [k for k in ("alpha_deg", "l_m") if k in mod]
    if cart and polar:
        raise RobotFileError(f"{where(source, key)}: give the steering axis as x_m, y_m or as alpha_deg, l_m, "
                             f"not both (got {', '.join(cart + polar)})")
    if len(cart) == 2:
        x, y = (_bounded(number(mod[k], source, f"{key}.{k}"), MAX_LENGTH_M, source, f"{key}.{k}",
                         "a steering axis") for k in ("x_m", "y_m"))
        if x == 0.0 and y == 0.0:
            raise RobotFileError(f"{where(source, key)}: x_m = 0, y_m = 0: a steering axis at the chassis centre "
                                 "(l = 0) is not supported")
        return math.atan2(y, x), math.hypot(x, y)
    if len(polar) == 2:
        alpha = number(mod["alpha_deg"], source, f"{key}.alpha_deg")
        l = number(mod["l_m"], source, f"{key}.l_m")
        if l <= 0:
            raise RobotFileError(f"{where(source, key + '.l_m')} = {mod['l_m']!r}: must be > 0 [m]")
        _bounded(l, MAX_LENGTH_M, source, f"{key}.l_m", "a steering axis")
        return float(np.deg2rad(alpha)), l
    have = cart + polar
    raise RobotFileError(f"{where(source, key)}: the steering axis needs x_m and y_m, or alpha_deg and l_m"
                         + (f" (got only {have[0]})" if have else ""))


def _steer_range(geo: dict, unlimited: bool, source: str) -> tuple[float, float]:
    """``[geometry].steer_range_deg`` checked: (β_min, β_max) [rad], ±π/2 when not given."""
    smin, smax = -np.pi / 2, np.pi / 2
    if "steer_range_deg" in geo:
        rng = geo["steer_range_deg"]
        key = "[geometry].steer_range_deg"
        if unlimited:
            raise RobotFileError(f"{where(source, key)} = {rng!r}: unlimited steering has no range (remove the key, "
                                 "or set steering = 'limited')")
        if not (isinstance(rng, list) and len(rng) == 2):
            raise RobotFileError(f"{where(source, key)} = {rng!r}: must be [min, max] in degrees")
        lo, hi = (number(v, source, f"{key}[{j}]") for j, v in enumerate(rng))
        if not (lo < 0 < hi) or not math.isclose(hi - lo, 180.0, rel_tol=0, abs_tol=1e-9):
            raise RobotFileError(f"{where(source, key)} = {rng!r}: must hold 0 inside and span 180 degrees "
                                 "(]β_min, β_max] of width π, the range where the ICR -> steering map is a bijection)")
        smin, smax = float(np.deg2rad(lo)), float(np.deg2rad(hi))
    return smin, smax


def _wheel_radius(raw, source: str, key: str) -> float:
    """A wheel radius ``r_m`` at ``key``: a number > 0, within :data:`MAX_RADIUS_M`."""
    r = number(raw, source, key)
    if r <= 0:
        raise RobotFileError(f"{where(source, key)} = {raw!r}: must be > 0 [m]")
    _bounded(r, MAX_RADIUS_M, source, key, "a wheel radius")
    return r


def _check_module_name(name, names: list, source: str, key: str) -> None:
    """A module's ``name``: a non-empty string that no earlier module has."""
    if not isinstance(name, str) or not name:
        raise RobotFileError(f"{where(source, key + '.name')} = {name!r}: must be a non-empty string")
    if name in names:
        raise RobotFileError(f"{where(source, key + '.name')} = {name!r}: two modules have this name")


def geometry_kwargs(data: dict, source: str | None = None) -> dict:
    """The ``RobotGeometry`` keyword arguments of a parsed description (:func:`read_robot_file`):
    alpha, l, b, r (n,) arrays, steer_min, steer_max [rad] and unlimited_steering."""
    source = source if source is not None else data.get("_source", "<description>")
    geo = _check_keys(data.get("geometry"), _GEOMETRY_KEYS, source, "[geometry]")
    steering = geo.get("steering", "limited")
    if steering not in ("limited", "unlimited"):
        raise RobotFileError(f"{where(source, '[geometry].steering')} = {steering!r}: must be 'limited' or 'unlimited'")
    unlimited = steering == "unlimited"
    smin, smax = _steer_range(geo, unlimited, source)
    b_default = _bounded(number(geo["b_m"], source, "[geometry].b_m"), MAX_OFFSET_M, source, "[geometry].b_m",
                         "an offset b") if "b_m" in geo else 0.0
    r_default = _wheel_radius(geo["r_m"], source, "[geometry].r_m") if "r_m" in geo else None
    mods = geo.get("modules")
    if not isinstance(mods, list) or not mods:
        raise RobotFileError(f"robot file {source}: [geometry] needs its modules ([[geometry.modules]] tables, "
                             "one per module)")
    if len(mods) < 3:
        raise RobotFileError(f"{where(source, '[[geometry.modules]]')}: {len(mods)} module(s); a robot needs n >= 3 "
                             "steerable wheels")
    alpha, l, b, r, names = [], [], [], [], []
    for k, mod in enumerate(mods):
        key = f"[geometry.modules][{k}]"
        _check_keys(mod, _MODULE_KEYS, source, key)
        a_k, l_k = _module_axis(mod, source, key)
        b_k = _bounded(number(mod["b_m"], source, f"{key}.b_m"), MAX_OFFSET_M, source, f"{key}.b_m",
                       "an offset b") if "b_m" in mod else b_default
        if "r_m" in mod:
            r_k = _wheel_radius(mod["r_m"], source, f"{key}.r_m")
        elif r_default is not None:
            r_k = r_default
        else:
            raise RobotFileError(f"{where(source, key)}: no wheel radius (r_m here or in [geometry])")
        if "name" in mod:
            _check_module_name(mod["name"], names, source, key)
            names.append(mod["name"])
        alpha.append(a_k)
        l.append(l_k)
        b.append(b_k)
        r.append(r_k)
    _check_layout(mods, np.array(alpha), np.array(l), np.array(r), source)
    return dict(alpha=np.array(alpha), l=np.array(l), b=np.array(b), r=np.array(r), steer_min=smin, steer_max=smax,
                unlimited_steering=unlimited)


def _check_layout(mods: list, alpha: np.ndarray, l: np.ndarray, r: np.ndarray, source: str) -> None:
    """Layouts no robot has, refused with the likely mistake: every ``alpha_deg`` within ±2π (the
    angles given in radians: the modules then sit in a wedge of at most 12.6° on one side of the
    centre), and two steering axes closer than the larger of their wheels' radii (the wheels would
    overlap: e.g. nearly equal ``alpha_deg`` at one ``l_m``)."""
    given = [float(m["alpha_deg"]) for m in mods if "alpha_deg" in m]
    if len(given) == len(mods) and max(abs(a) for a in given) <= 2 * math.pi:
        k = int(np.argmax(np.abs(given)))
        raise RobotFileError(f"{where(source, f'[geometry.modules][{k}].alpha_deg')} = {given[k]:g}: degrees "
                             f"expected (every |alpha_deg| <= 2π: radians?); {math.degrees(given[k]):.6g}?")
    xy = np.column_stack([l * np.cos(alpha), l * np.sin(alpha)])
    for k in range(len(l)):
        for j in range(k):
            gap = float(np.hypot(*(xy[k] - xy[j])))
            if 0.0 < gap < max(r[k], r[j]):  # 0: RobotGeometry's own refusal (one point, one line)
                raise RobotFileError(f"{where(source, f'[geometry.modules][{k}]')}: its steering axis is {gap:.3g} m "
                                     f"from module {j}'s, closer than the wheel radius {max(r[k], r[j]):g} m (the "
                                     "wheels would overlap; alpha_deg in degrees, x_m, y_m, l_m in metres?)")


def module_names(data: dict) -> tuple[str, ...]:
    """The modules' names of a parsed description, in module order (``module_k`` where unnamed)."""
    mods = data.get("geometry", {}).get("modules", [])
    return tuple(m.get("name", f"module_{k}") if isinstance(m, dict) else f"module_{k}" for k, m in enumerate(mods))
