"""The one reader of robot description files: a file or a preset by name, read whole
(:func:`read_robot`), each package handed its part (:class:`RobotDescription`: the geometry and
the module names for estimation and the log readers, the ``RobotParams`` for the simulator).

A preset *is* a description file: ``azimut_env/robots/NAME.toml``, shipped in the package and
read by the same reader as a user's file. The file format (schema 1) is described in
``docs/robots.md``. :mod:`estimation.robot_file` reads the TOML, the header and the
``[geometry]`` table (the part it owns; it knows nothing of the simulator's tables); this module
names the rest and reads it: the parameter tables, one per group of ``RobotParams``
(``[chassis]``, ``[steering]``, ``[steer_motor]``, ``[wheel]``, ``[tire]``, ``[limits]``,
``[sensors]``, ``[imperfections]``: :func:`parameter_tables`, the fields of the class), whose
keys are the fields of the group's dataclass in its units (SI; angles in radians), and the
top-level ``gravity`` [m/s²]. ``[imperfections]`` may also name the imperfections preset the
robot carries, ``preset = "paper"`` or ``"ideal"`` (:mod:`azimut_env.imperfections`): the preset
sets its values first, and the file's own keys override them. A group or key the file leaves
out keeps the preset's value, or without one the default of ``RobotParams`` (the AZIMUT-3
stand-in without imperfections). The steering range of ``[limits]`` is not a key: it
comes from ``[geometry]`` (``steering``, ``steer_range_deg``); unlimited steering sets
``steer_min = −inf``, ``steer_max = +inf``.

This module does not import :mod:`azimut_env.params` (which calls it from
``RobotParams.from_file`` and ``RobotParams.preset``): it reads the groups' classes from the
fields of the ``RobotParams`` class it is given.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import MISSING, Field, dataclass, fields, is_dataclass, replace
from importlib import resources
from typing import Any

import numpy as np

from azimut_env.imperfections import IMPERFECTION_PRESETS, with_imperfections
from estimation.geometry import RobotGeometry
from estimation.robot_file import (
    RobotFileError,
    module_names,
    number,
    parse_robot_text,
    read_robot_file,
    unit_hint,
    where,
)

__all__ = ["PRESET_NAMES", "DEFAULT_PRESET", "PRESET_KEY", "GRAVITY_KEY", "RobotFileError", "RobotDescription",
           "read_robot", "parameter_tables", "params_from_file", "preset_params", "preset_source",
           "check_preset_name", "resolve_robot"]

#: the robots shipped with the package (``azimut_env/robots/NAME.toml``)
PRESET_NAMES = ("azimut3", "swerve", "tri", "hex")
#: the default robot of the envs (``Azimut-v2``): ``RobotParams()`` with the ``"paper"``
#: imperfections, which its file names
DEFAULT_PRESET = "azimut3"
#: the key of ``[imperfections]`` that names the robot's imperfections preset
PRESET_KEY = "preset"
#: the top-level key of the simulator's gravity [m/s²]
GRAVITY_KEY = "gravity"
#: plausibility bounds of parameter keys, ``(table, key): (bound, unit, what a value past it
#: likely is)``: a file past one is refused with the likely mistake (``docs/robots.md``)
PLAUSIBLE = {("chassis", "mass"): (2000.0, "kilograms", "grams"),
             ("steering", "module_mass"): (200.0, "kilograms", "grams"),
             ("chassis", "length"): (25.0, "metres", "millimetres"),
             ("chassis", "width"): (25.0, "metres", "millimetres"),
             ("chassis", "com_height"): (10.0, "metres", "millimetres")}
#: keys of ``[limits]`` that the file may not set (the steering range comes from ``[geometry]``)
_FROM_GEOMETRY = {"steer_min", "steer_max"}


def _default(f: Field) -> Any:
    return f.default if f.default is not MISSING else (f.default_factory() if f.default_factory is not MISSING
                                                       else MISSING)


def _value(default: Any, value: Any, source: str, key: str) -> Any:
    """A TOML value converted to the type of the field's default, or :class:`RobotFileError`."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise RobotFileError(f"{where(source, key)} = {value!r}: must be true or false")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise RobotFileError(f"{where(source, key)} = {value!r}: must be an integer")
        return value
    if isinstance(default, float):
        return number(value, source, key)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise RobotFileError(f"{where(source, key)} = {value!r}: must be a string")
        return value
    if isinstance(default, tuple):
        if not isinstance(value, list):
            raise RobotFileError(f"{where(source, key)} = {value!r}: must be a list")
        return tuple(_value(default[0] if default else 0.0, v, source, f"{key}[{j}]") for j, v in enumerate(value))
    raise RobotFileError(f"{where(source, key)}: this parameter cannot be set from a file")


def _group(base: Any, table: Any, source: str, section: str) -> Any:
    """The dataclass instance ``base`` with the keys of its table (missing keys keep ``base``'s
    values: the class's defaults, or the imperfections preset's)."""
    if not isinstance(table, dict):
        raise RobotFileError(f"{where(source, f'[{section}]')} = {table!r}: must be a table")
    known = {f.name: f for f in fields(base) if f.init}
    kwargs: dict[str, Any] = {}
    for key, value in table.items():
        if key == PRESET_KEY and section == "imperfections":
            continue  # read by _imperfections_preset
        if key in _FROM_GEOMETRY and section == "limits":
            raise RobotFileError(f"{where(source, f'[{section}].{key}')}: the steering range is set in [geometry] "
                                 "(steering = 'limited' with steer_range_deg, or 'unlimited')")
        if key not in known:
            names = ", ".join([k for k in known if not (section == "limits" and k in _FROM_GEOMETRY)]
                              + [PRESET_KEY] * (section == "imperfections"))
            raise RobotFileError(f"{where(source, f'[{section}]')}: unknown key {key!r} (known: {names})")
        default = _default(known[key])
        if is_dataclass(default):
            kwargs[key] = _group(getattr(base, key), value, source, f"{section}.{key}")
        else:
            kwargs[key] = _value(default, value, source, f"[{section}].{key}")
            if (section, key) in PLAUSIBLE and abs(kwargs[key]) > PLAUSIBLE[section, key][0]:
                bound, unit, smaller = PLAUSIBLE[section, key]
                raise RobotFileError(f"{where(source, f'[{section}].{key}')} = {kwargs[key]:g}: beyond {bound:g} is "
                                     f"implausible: {unit_hint(kwargs[key], unit, smaller=smaller)}")
    try:
        return replace(base, **kwargs)
    except (ValueError, TypeError) as exc:
        raise RobotFileError(f"{where(source, f'[{section}]')}: {exc}") from None


def _imperfections_preset(data: dict, source: str) -> str | None:
    """The imperfections preset the description names (``[imperfections]`` ``preset``), or None."""
    table = data.get("imperfections")
    if not isinstance(table, dict) or PRESET_KEY not in table:
        return None
    name = table[PRESET_KEY]
    if not isinstance(name, str) or name not in IMPERFECTION_PRESETS:
        raise RobotFileError(f"{where(source, f'[imperfections].{PRESET_KEY}')} = {name!r}: must be one of "
                             f"{', '.join(map(repr, IMPERFECTION_PRESETS))}")
    return name


@dataclass(frozen=True)
class RobotDescription:
    """A robot description read whole (:func:`read_robot`): each package's part of it."""

    #: how messages name the description: the file's path, or ``preset 'NAME' (...)``
    source: str
    #: estimation's part: the ``[geometry]`` table
    geometry: RobotGeometry
    #: the modules' names in module order (``module_k`` where unnamed): the log readers' and the
    #: bag exporter's
    module_names: tuple[str, ...]
    #: the simulator's part: the ``RobotParams`` (the geometry above included)
    params: Any


def parameter_tables(params_cls: type) -> tuple[str, ...]:
    """The parameter tables a file may hold: the fields of ``params_cls`` (``RobotParams``) other
    than ``geometry`` and ``gravity``, in their order."""
    return tuple(f.name for f in fields(params_cls) if f.name not in ("geometry", GRAVITY_KEY))


def read_robot(robot: str | os.PathLike, params_cls: type) -> RobotDescription:
    """The robot ``robot`` names, read whole: a preset's name (:data:`PRESET_NAMES`; read once,
    then cached: the parts are frozen) or the path of a description file (an ``os.PathLike``, or a
    ``str`` ending in ``.toml``). ``params_cls`` is ``RobotParams``. Every refusal of a file is a
    :class:`RobotFileError` naming the file, the key and the value."""
    if _is_file(robot):
        return _read_file(robot, params_cls)
    return _preset(check_preset_name(robot), params_cls)


def _read_file(path: str | os.PathLike, params_cls: type) -> RobotDescription:
    return _describe(read_robot_file(path, _others(params_cls)), params_cls)


def _is_file(robot: Any) -> bool:
    return isinstance(robot, os.PathLike) or (isinstance(robot, str) and robot.endswith(".toml"))


def _others(params_cls: type) -> tuple[str, ...]:
    """The top-level keys this module reads (``estimation.robot_file`` refuses any key that is
    neither these nor its own)."""
    return (GRAVITY_KEY,) + parameter_tables(params_cls)


def _describe(data: dict, params_cls: type) -> RobotDescription:
    """The parts of a description whose header :mod:`estimation.robot_file` has checked."""
    source = data["_source"]
    tables = parameter_tables(params_cls)
    if GRAVITY_KEY in data and not number(data[GRAVITY_KEY], source, GRAVITY_KEY) > 0:
        raise RobotFileError(f"{where(source, GRAVITY_KEY)} = {data[GRAVITY_KEY]!r}: must be > 0 [m/s²]")
    for key in tables:
        if key in data and not isinstance(data[key], dict):
            raise RobotFileError(f"{where(source, key)} = {data[key]!r}: must be a table ([{key}])")
    geometry = RobotGeometry.from_description(data)
    return RobotDescription(source=source, geometry=geometry, module_names=module_names(data),
                            params=_params(data, geometry, tables, params_cls))


def _params(data: dict, geometry: RobotGeometry, tables: tuple[str, ...], params_cls: type) -> Any:
    """The ``params_cls`` (``RobotParams``) of a description: its tables over the defaults (or
    over the imperfections preset it names)."""
    source = data["_source"]
    groups = {f.name: f for f in fields(params_cls) if f.name in tables}
    preset = _imperfections_preset(data, source)
    steer = (-math.inf, math.inf) if geometry.unlimited_steering else (geometry.steer_min, geometry.steer_max)
    limits = replace(_default(groups["limits"]), steer_min=steer[0], steer_max=steer[1])
    try:
        base = params_cls(geometry=geometry, limits=limits)
    except (ValueError, TypeError) as exc:
        raise RobotFileError(f"robot file {source}: {exc}") from None
    if preset is not None:
        base = with_imperfections(base, preset)
    kwargs: dict[str, Any] = {name: _group(getattr(base, name), data[name], source, name)
                              for name in groups if name in data}
    if GRAVITY_KEY in data:
        kwargs[GRAVITY_KEY] = number(data[GRAVITY_KEY], source, GRAVITY_KEY)
    table = data.get("chassis", {})
    kwargs["chassis"] = _outline(kwargs.get("chassis", base.chassis), table, geometry, source)
    try:
        params = replace(base, **kwargs)
    except (ValueError, TypeError) as exc:
        raise RobotFileError(f"robot file {source}: {exc}") from None
    _check_support(params, data, source)
    return params


def _outline(chassis: Any, table: dict, geometry: RobotGeometry, source: str) -> Any:
    """The chassis of a file: its ``length`` (along X) and ``width`` (along Y) must hold every
    steering axis (the chassis box is centred on the centre of mass, the frame's origin). A
    dimension the file leaves out keeps the default plate's (0.6 m: the presets azimut3, tri and
    hex) where that holds every axis, and is otherwise derived from the modules: twice the
    farthest axis plus the largest wheel radius. The plate's inertia follows
    (``ChassisParams.inertia``); the mass does not (``[chassis] mass``: the default 27 kg unless
    the file gives it)."""
    xy = geometry.axis_xy
    margin = float(np.max(geometry.r))
    changes = {}
    for axis, key in enumerate(("length", "width")):
        k = int(np.argmax(np.abs(xy[:, axis])))
        reach = float(abs(xy[k, axis]))
        size = getattr(chassis, key)
        if key in table:
            if 2.0 * reach > size * (1.0 + 1e-9):
                raise RobotFileError(f"{where(source, f'[chassis].{key}')} = {size:g}: module {k}'s steering axis at "
                                     f"{'xy'[axis]} = {xy[k, axis]:.6g} m lies outside the chassis ({key} >= "
                                     f"{2.0 * reach:.6g} m needed; leave {key} out to derive it from the modules)")
        elif 2.0 * reach > size:  # the default plate does not hold the axes: the axes' box plus a wheel radius
            changes[key] = 2.0 * (reach + margin)
    return replace(chassis, **changes) if changes else chassis


def _check_support(params: Any, data: dict, source: str) -> None:
    """The centre of mass (the chassis frame's origin) must be inside the modules' support: every
    wheel's static load (``RobotParams.static_normal_loads``, the least-norm loads on the axes)
    positive. Otherwise the robot would tip over; the simulator cannot load its wheels."""
    share = params.load_map()[:, 0]  # each axis's share of the weight
    k = int(np.argmin(share))
    if not share[k] > 1e-6:
        name = module_names(data)[k]
        raise RobotFileError(f"{where(source, f'[geometry.modules][{k}]')} ({name}): the centre of mass, the chassis "
                             f"frame's origin, is outside the modules' support (this wheel would carry "
                             f"{share[k]:.3g} of the weight): give the steering axes from the centre of mass "
                             "(x_m, y_m or alpha_deg, l_m around the origin)")


def params_from_file(path, params_cls: type) -> Any:
    """The ``params_cls`` (``RobotParams``) of a description file (whatever its suffix):
    :func:`read_robot`'s ``params``."""
    return _read_file(path, params_cls).params


def check_preset_name(name: Any) -> str:
    """``name`` if it is a preset's, else ``ValueError`` listing the presets."""
    if not isinstance(name, str) or name not in PRESET_NAMES:
        raise ValueError(f"unknown robot {name!r}; choose from {', '.join(PRESET_NAMES)} (or give a robot file)")
    return name


def preset_source(name: str) -> str:
    """The text of preset ``name``'s description file."""
    check_preset_name(name)
    return resources.files("azimut_env").joinpath("robots", f"{name}.toml").read_text(encoding="utf-8")


@functools.cache
def _preset(name: str, params_cls: type) -> RobotDescription:
    source = f"preset {name!r} (azimut_env/robots/{name}.toml)"
    return _describe(parse_robot_text(preset_source(name), source, _others(params_cls)), params_cls)


def preset_params(name: str, params_cls: type) -> Any:
    """The ``params_cls`` (``RobotParams``) of preset ``name`` (read once, then cached: the
    parameters are frozen)."""
    return _preset(check_preset_name(name), params_cls).params


def resolve_robot(robot: Any, params: Any, params_cls: type) -> Any:
    """The robot of an entry point that takes both ``robot`` and ``params``: one of them
    (``ValueError`` if both are given: a preset with parameters of its own is two robots), or
    None when neither is. ``robot`` is a preset's name or the path of a description file
    (a ``str`` ending in ``.toml``, or an ``os.PathLike``): a plain string, so it goes through
    JSON (campaign keys, ``run.json``) as it is."""
    if robot is None:
        return params
    is_file = _is_file(robot)
    if not is_file:
        if not isinstance(robot, str) or robot not in PRESET_NAMES:
            raise ValueError(f"unknown robot {robot!r}; choose from {', '.join(PRESET_NAMES)} or give the path of a "
                             ".toml robot file")
    if params is not None:
        raise ValueError(f"robot={robot!r} and params= both given: choose one (start from RobotParams.preset(...) or "
                         "RobotParams.from_file(...) and change it with dataclasses.replace)")
    return read_robot(robot, params_cls).params
