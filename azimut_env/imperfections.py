"""The imperfections preset: ``"paper"`` (the imperfections the paper names, with values from
their sources) or ``"ideal"`` (none: the physics of ``Azimut-v1``).

The paper (Clavien, Lauria, Michaud, "Estimation of the Instantaneous Centre of Rotation with
Nonholonomic Omnidirectional Mobile Robots", §1) says that "a real robot is always imperfect: it
has geometric imperfections, actuators with finite stiffness, stiction and limitations, as well
as sensors with noise and quantification", and that with compliant steering the departure of the
propulsion axes from a common intersection "is always perceptible". The series-elastic steering
(finite stiffness), the actuators' rate, acceleration and torque limits and the sensors' noise
and quantisation exist in both presets. ``"paper"`` adds, with the sources of the values (and it
sets the spring's stiffness, see below):

=======================  ==========================================  =====================================
parameter                value                                       source
=======================  ==========================================  =====================================
steering joint friction  τ_c = 0.45 N·m, τ_s = 0.675 N·m,            estimate: τ_c = 3% of the steering
(Coulomb, stiction,      ω_s = 0.02 rad/s                            torque limit (the no-load friction of
Stribeck)                                                            a maxon RE 40 is 2.4% of its nominal
                                                                     torque, maxon catalogue, and a
                                                                     planetary gearhead loses 10–30%);
                                                                     τ_s/τ_c = 1.5 as in the simulation
                                                                     example of Canudas de Wit et al.
                                                                     1995; ω_s small against the
                                                                     steering rates (Armstrong-Hélouvry
                                                                     et al. 1994). Dead band τ_s/k_s =
                                                                     1.9° at k_s = 20 N·m/rad
module mass, inertia     1.876 kg, 0.0151 kg·m² about the axis,      IntRoLab's public URDF of AZIMUT-3
about the steering       centre of mass 0.0714 m from the axis       (``introlab/IRL-1`` repository,
axis, its CoM offset     toward the wheel                            ``az3_wheel_group/wheel.urdf.xacro``,
                                                                     2011: steering link 0.936 kg + wheel
                                                                     0.940 kg, CAD export; not a
                                                                     publication)
drive motors             torque–speed line τ_stall = 59 N·m,         the class of a maxon RE 40 (150 W,
                         ω₀ = 22 rad/s at the wheel, current limit   24 V) behind 36:1 (``WheelParams``);
                         5 N·m                                       the paper: "standard stiff actuators"
wheel encoders           36,000 counts per wheel turn                IntRoLab's AZIMUT-2 propulsion
                         (steering: 4,096 per turn, as "ideal")      configuration (1,200 per motor turn
                                                                     × 30:1, ``introlab/IRL-1``
                                                                     ``az2_prop.yaml``; not a
                                                                     publication); steering: a 12-bit
                                                                     absolute magnetic encoder (ams
                                                                     AS5045 class, datasheet: 4,096 per
                                                                     turn)
steering-axis zero       δ = (−0.386, −0.336, +0.264, −0.226)°,      estimate: σ = 0.5° (homing and
offsets, rolling-radius  ε = (+0.544, +0.766, −0.004, +0.670)%;      assembly; absolute magnetic encoders
errors (fixed per        domain randomisation draws them from        are specified to ±0.2–0.6° before
robot)                   N(0, 0.5°) and N(0, 0.3%)                   mounting), σ = 0.3% (tread
                                                                     manufacturing and wear; unequal
                                                                     wheel diameters are a dominant
                                                                     systematic error, Borenstein & Feng
                                                                     1996); the fixed values are one draw
                                                                     (``numpy.random.default_rng(2010)``,
                                                                     clipped at 3σ)
=======================  ==========================================  =====================================

**The steering stiffness** is the one parameter no source gives: no figure of AZIMUT-3's
differential elastic actuator (Lauria, Legault, Lavoie, Michaud, "Differential elastic actuator
for robotic interaction tasks", IEEE ICRA 2008, motivated by the AZIMUT platform's vulnerability
to shocks) could be read. Comparable series-elastic actuators span 50–300 N·m/rad at the output
(ANYdrive 180.9 N·m/rad in ETH Zurich's public control-toolbox code; 272 N·m/rad, Int. J.
Advanced Robotic Systems, doi:10.5772/56927; 0.2–313 N·m/rad for the variable-stiffness Dyrac,
Aiple, Gregoor, Schiele, arXiv:1906.07669). ``"ideal"`` keeps v1's 60 N·m/rad (an assumption
made so that compliance is visible). ``"paper"`` uses **20 N·m/rad, identified from the paper's
own observation** (its Fig. 11: on the real robot's trajectory IT is the same as or better than NS,
with visible differences): it is the stiffest round value at which the simulated D2 (``azimut
record-d2``) separates the estimators by more than 0.1 point of qua on more than 5% of its
points (25 N·m/rad: 3.3%); at 60 N·m/rad, with every other imperfection above, they separate on
0.1% of them. It is a calibration to the paper's result, not a measurement: ``docs/results/physics-v3.md`` gives the
sweep of stiffness and friction and what each changes. The damper keeps v1's damping ratio
(c_s ∝ √k_s: 0.346 N·m·s/rad).

References: C. Canudas de Wit, H. Olsson, K. J. Åström, P. Lischinsky, "A new model for control
of systems with friction", IEEE Trans. Automatic Control 40(3):419–425, 1995. B.
Armstrong-Hélouvry, P. Dupont, C. Canudas de Wit, "A survey of models, analysis tools and
compensation methods for the control of machines with friction", Automatica 30(7):1083–1138,
1994. J. Borenstein, L. Feng, "Measurement and correction of systematic odometry errors in mobile
robots", IEEE Trans. Robotics and Automation 12(6):869–880, 1996.

:func:`with_imperfections` applies a preset to any :class:`~azimut_env.params.RobotParams`: it
sets the fields above and leaves every other one. The ``"paper"`` values are AZIMUT-3's (the
per-wheel offsets are four; a robot with another wheel count gets its own draw of the same
spread, ``numpy.random.default_rng(2010)``). A robot description file names the preset it carries
(``[imperfections]`` ``preset = "paper"``: the shipped ``azimut3`` does, so the preset ``azimut3``
and its file are the Azimut-v2 default robot; the other shipped robots name ``"ideal"``) and sets
its own values in its ``[steering]``, ``[wheel]``, ``[sensors]`` and ``[imperfections]`` tables
(they override the preset's: :func:`azimut_env.robot_file.read_robot`); the envs'
and the command line's ``imperfections`` apply a preset on top of the robot
(:func:`azimut_env.task.config.resolve_params`).

This module does not import :mod:`azimut_env.params` (the description reader, which
``RobotParams.from_file`` calls, applies a file's preset): it builds the ``ImperfectionParams``
from the class of the robot's own.
"""

from __future__ import annotations

import math
from dataclasses import is_dataclass, replace
from typing import TypeVar

import numpy as np

__all__ = ["IMPERFECTION_PRESETS", "DEFAULT_IMPERFECTIONS", "with_imperfections", "check_imperfections",
           "imperfections_of",
           "PAPER_SPRING", "IDEAL_SPRING", "PAPER_FRICTION", "PAPER_MODULE", "STEER_OFFSET_STD", "RADIUS_ERROR_STD",
           "PAPER_WHEEL_CPR", "IDEAL_WHEEL_CPR"]

#: the presets, by name
IMPERFECTION_PRESETS = ("paper", "ideal")
#: the default robot's (``Azimut-v2``'s: the preset ``azimut3`` names it in its file);
#: ``Azimut-v1`` is registered with ``"ideal"``
DEFAULT_IMPERFECTIONS = "paper"
#: the robot parameters' type (``azimut_env.params.RobotParams``, not imported here)
P = TypeVar("P")
#: the groups of RobotParams that a preset sets
_GROUPS = ("geometry", "steering", "wheel", "sensors", "imperfections")

#: the steering spring and damper of the "paper" preset [N·m/rad, N·m·s/rad] (identified, see above)
PAPER_SPRING = dict(stiffness=20.0, damping=0.6 * math.sqrt(20.0 / 60.0))
#: v1's (the "ideal" preset's)
IDEAL_SPRING = dict(stiffness=60.0, damping=0.6)
#: the steering joint's friction of the "paper" preset: τ_c, τ_s [N·m], ω_s [rad/s]
PAPER_FRICTION = dict(friction_coulomb=0.45, friction_static=0.675, stribeck_speed=0.02)
#: the module of the "paper" preset (IntRoLab's AZIMUT-3 URDF): mass [kg], CoM offset [m], inertia
#: about the axis [kg·m²]
PAPER_MODULE = dict(module_mass=1.876, com_offset=0.0714, module_inertia=0.0151)
#: spreads of the geometric imperfections: steering-axis zero offset [rad], rolling-radius error [-]
STEER_OFFSET_STD = math.radians(0.5)
RADIUS_ERROR_STD = 0.003
#: the wheel encoders of the "paper" preset [counts per wheel turn] and of "ideal" (v1's)
PAPER_WHEEL_CPR = 36_000
IDEAL_WHEEL_CPR = 4096

_IDEAL_STEERING = dict(friction_coulomb=0.0, friction_static=0.0, com_offset=0.0)
#: the steering fields "paper" sets to other values than v1's, and v1's values
_PAPER_STEERING = dict(**PAPER_SPRING, module_mass=PAPER_MODULE["module_mass"],
                       module_inertia=PAPER_MODULE["module_inertia"])
_V1_STEERING = dict(**IDEAL_SPRING, module_mass=2.0, module_inertia=0.02)


def check_imperfections(name) -> str:
    """``name`` if it is a preset (``ValueError`` naming the presets otherwise)."""
    if not isinstance(name, str) or name not in IMPERFECTION_PRESETS:
        raise ValueError(f"imperfections must be one of {', '.join(map(repr, IMPERFECTION_PRESETS))}, got {name!r}")
    return name


def _paper_draw(n: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The fixed steering offsets [rad] and radius errors of the "paper" robot with n wheels: one
    draw from N(0, σ), clipped at 3σ (rounded to 1e-5)."""
    rng = np.random.default_rng(2010)
    offsets = np.clip(rng.normal(0.0, STEER_OFFSET_STD, n), -3 * STEER_OFFSET_STD, 3 * STEER_OFFSET_STD)
    errors = np.clip(rng.normal(0.0, RADIUS_ERROR_STD, n), -3 * RADIUS_ERROR_STD, 3 * RADIUS_ERROR_STD)
    return tuple(np.round(offsets, 5).tolist()), tuple(np.round(errors, 5).tolist())


def with_imperfections(params: P, name: str) -> P:
    """``params`` with the imperfections preset ``name`` (module docstring): ``"ideal"`` turns
    friction, the module's centre-of-mass offset, the drive's torque–speed line and the geometric
    imperfections off and sets v1's 4,096-count wheel encoders (``RobotParams()`` is ideal
    already: ``with_imperfections(RobotParams(), "ideal") == RobotParams()``); ``"paper"`` sets
    them to the sourced values, with the steering spring at the identified 20 N·m/rad and the
    module of IntRoLab's URDF. Neither touches the other parameters (a robot's geometry, chassis,
    tire, limits, sensor noise); "ideal" puts back v1's spring (60 N·m/rad, 0.6 N·m·s/rad) and
    module (2 kg, 0.02 kg·m²) only where they hold the paper preset's values, so that
    ``with_imperfections(with_imperfections(p, "paper"), "ideal") == p`` for ``p = RobotParams()``
    and a robot with a spring or module of its own keeps it."""
    check_imperfections(name)
    if isinstance(params, type) or not is_dataclass(params) or not all(hasattr(params, g) for g in _GROUPS):
        raise TypeError(f"params must be RobotParams, got {type(params).__name__}")
    imperfection_params = type(params.imperfections)  # ImperfectionParams
    if name == "ideal":
        st = params.steering
        back = {k: v for k, v in _V1_STEERING.items() if getattr(st, k) == _PAPER_STEERING[k]}
        return replace(params, steering=replace(st, **_IDEAL_STEERING, **back),
                       wheel=replace(params.wheel, drive_model="current_limit"),
                       sensors=replace(params.sensors, wheel_cpr=IDEAL_WHEEL_CPR), imperfections=imperfection_params())
    offsets, errors = _paper_draw(params.n)
    return replace(params, steering=replace(params.steering, **PAPER_SPRING, **PAPER_FRICTION, **PAPER_MODULE),
                   wheel=replace(params.wheel, drive_model="dc"),
                   sensors=replace(params.sensors, wheel_cpr=PAPER_WHEEL_CPR),
                   imperfections=imperfection_params(steer_offset=offsets, radius_error=errors,
                                                     steer_offset_std=STEER_OFFSET_STD,
                                                     radius_error_std=RADIUS_ERROR_STD))


def imperfections_of(params) -> str | None:
    """The preset ``params`` carries: ``"paper"`` or ``"ideal"`` when applying it changes nothing,
    else None (a robot with imperfections of its own)."""
    for name in IMPERFECTION_PRESETS:
        if with_imperfections(params, name) == params:
            return name
    return None
