"""Names of the columns of the physics arrays: the one place where a column has a number.

Every array of :class:`~azimut_env.physics.engine.AzimutPhysics` with a trailing axis of quantities
(the per-wheel parameters, joint and motor states, the force accumulator, the robot and wheel
summaries) is indexed through the :class:`~enum.IntEnum` of this module, in Python and in the
compiled kernels alike (numba folds ``IntEnum`` members into integer constants, so a named index
costs nothing). The array of ``n_columns`` columns has ``len(Enum)`` columns. The set-points' columns
:class:`CMD` are the action map's (:mod:`azimut_env.action_map`), re-exported here. The tire state's
columns are :class:`azimut_env.physics.tire.TS`, next to the tire model.

Multi-column reads have named selections: :data:`RS_POSE`, :data:`RS_VEL_WORLD`,
:data:`RS_TWIST_BODY`, :data:`WS_FORCE`, :data:`WS_CONTACT`.
"""

from __future__ import annotations

from enum import IntEnum

# the set-points' columns, the physics' input: defined by the action map that writes them, a floor
# below the physics (azimut_env.params imports it), and named here with the physics' own columns
from azimut_env.action_map import CMD

__all__ = ["CS", "FT", "BODY", "CMD", "WP", "JS", "MS", "ACC", "RS", "WS", "RS_POSE", "RS_VEL_WORLD",
           "RS_TWIST_BODY", "WS_FORCE", "WS_CONTACT"]


class CS(IntEnum):
    """Columns of the chassis state rows read from and written to pymunk (rows, len(CS)): the
    pose (X, Y [m], TH [rad]) and velocity (VX, VY [m/s], W [rad/s]) in the world, in the order of
    ``pymunk.batch``'s position, angle, velocity and angular velocity fields."""

    X, Y, TH, VX, VY, W = range(6)


class FT(IntEnum):
    """Columns of the force rows written to pymunk (rows, len(FT)): the force (FX, FY) [N] and the
    torque TAU [N·m] on a body, in the world."""

    FX, FY, TAU = range(3)


class BODY(IntEnum):
    """Columns of ``body_inertia`` (N, len(BODY)): the robot body's mass M [kg] and its moment
    I [kg·m²] about the centre (the modules' masses at their steering axes)."""

    MASS, MOMENT = range(2)


class WP(IntEnum):
    """Columns of the per-wheel parameter array ``wheel_params`` (N, n, len(WP)).

    Geometry (``estimation.RobotGeometry``): B the sidewise offset b [m], R the wheel radius r [m],
    ALPHA the angle α of the module at β = 0 [rad]. LOAD the static normal load of the robot's
    current mass [N]. MU the friction coefficient μ. Steering (``params.SteeringParams``): K_S,
    C_S the series spring [N·m/rad] and damper [N·m·s/rad], KP the motor's position gain [1/s],
    I_MOD the module's inertia about its axis [kg·m²]. Propulsion (``params.WheelParams``): I_W
    the wheel's spin inertia [kg·m²], KV the velocity-loop gain [N·m·s/rad], BEARING the bearing
    damping [N·m·s/rad]. RR_TORQUE the rolling resistance coefficient C_rr (torque C_rr N r) and
    RR_KNEE the surface speed below which it fades [m/s]. Limits (``params.ActuatorLimits``): STEER_RATE [rad/s],
    STEER_ACCEL [rad/s²], STEER_TORQUE [N·m], WHEEL_ACCEL [rad/s²], WHEEL_TORQUE [N·m],
    STEER_MIN, STEER_MAX the hard stops [rad]. Tire (``params.TireParams``): C_KAPPA, C_ALPHA the
    slip stiffnesses per unit load, SIGMA_LONG, SIGMA_LAT the relaxation lengths [m], HALF_LEN the
    contact half-length a [m], DAMP_TIME the bristle damping time τ_d [s]. DC steering motor
    (``params.SteeringMotorParams``, used when its model is "dc"): MOTOR_STALL the stall torque
    [N·m], MOTOR_NO_LOAD the no-load speed [rad/s], MOTOR_INERTIA the reflected rotor inertia
    [kg·m²]. Steering joint friction (``params.SteeringParams``): FRIC_C the sliding torque τ_c,
    FRIC_S the breakaway torque τ_s [N·m] (0: no friction), STRIBECK the Stribeck speed [rad/s].
    The module's centre of mass: M_MOD its mass [kg], COM its offset c from the axis [m] (0: on
    the axis). Drive motor (``params.WheelParams``, "dc" model): DRIVE_STALL τ_stall [N·m],
    DRIVE_NO_LOAD ω₀ [rad/s] at the wheel.

    ALPHA and R are the wheel's true values: the geometry's plus the robot's imperfections
    (``params.ImperfectionParams``: steering-axis zero offset, rolling-radius error)."""

    B, R, ALPHA, LOAD, MU, K_S, C_S, KP, I_W, KV, BEARING, RR_TORQUE, RR_KNEE, \
        STEER_RATE, STEER_ACCEL, STEER_TORQUE, WHEEL_ACCEL, WHEEL_TORQUE, STEER_MIN, STEER_MAX, I_MOD, \
        C_KAPPA, C_ALPHA, SIGMA_LONG, SIGMA_LAT, HALF_LEN, DAMP_TIME, \
        MOTOR_STALL, MOTOR_NO_LOAD, MOTOR_INERTIA, \
        FRIC_C, FRIC_S, STRIBECK, M_MOD, COM, DRIVE_STALL, DRIVE_NO_LOAD = range(37)


class JS(IntEnum):
    """Columns of the per-wheel joint state ``joint_state`` (N, n, len(JS)): the steering angle
    β [rad] and the module's absolute angular velocity ω = θ̇ + β̇ [rad/s]."""

    BETA, OMEGA = range(2)


class MS(IntEnum):
    """Columns of the per-wheel motor state ``motor_state`` (N, n, len(MS)): the steering motor's
    angle θ_m [rad] and rate θ̇_m [rad/s], the propulsion loop's ramped set-point φ̇_ref [rad/s],
    the wheel's spin rate φ̇ [rad/s] and its accumulated angle φ [rad] (what the encoder counts)."""

    THETA, OMEGA, PHIDOT_REF, PHIDOT, PHI = range(5)


class ACC(IntEnum):
    """Columns of the per-wheel accumulator over one step's substeps (N, n, len(ACC)): the tire
    force on the robot in the world (FX, FY) [N], the slip power |F · v_slip| [W], the normal
    load LOAD [N] and the rolling speed over the ground ROLL = |v(P)·d| [m/s] (the last two for
    the slip dampings of the antagonism, :mod:`azimut_env.physics.antagonism`), and WORK [J], the
    work the wheel's two motors did on the robot over the step (the steering motor's τ_s Δθ_m
    through the series spring, the drive's τ_m φ̇ dt; the energy check of
    :meth:`~azimut_env.physics.engine.AzimutPhysics.step`)."""

    FX, FY, SLIP, LOAD, ROLL, WORK = range(6)


class RS(IntEnum):
    """Columns of the robot summary ``summary`` (N, len(RS)), computed after each step: the pose
    (X, Y [m], TH [rad]) and velocity (VX, VY [m/s], W [rad/s]) in the world (the columns of
    :class:`CS`, in the same order), the velocity in the
    chassis frame (BX, BY [m/s]), the step-mean slip power SLIP [W], the null-space force
    NULLSPACE [N] (the minimum-norm internal force of the step-mean tire forces) and the
    antagonism ANTAGONISM [N] (their stiffness-weighted internal force,
    :mod:`azimut_env.physics.antagonism`), and the blow-up code CODE (a
    :class:`azimut_env.physics.blowup.BlowUp`, 0 when fine)."""

    X, Y, TH, VX, VY, W, BX, BY, SLIP, NULLSPACE, ANTAGONISM, CODE = range(12)


class WS(IntEnum):
    """Columns of the wheel summary ``wheel_summary`` (N, n, len(WS)): β [rad], β̇ [rad/s], the
    step-mean tire force in the chassis frame (FX, FY) [N] and the contact point P_k in the
    chassis frame (PX, PY) [m]."""

    BETA, BETA_DOT, FX, FY, PX, PY = range(6)


assert [m.name for m in RS][: len(CS)] == [m.name for m in CS], "the summary starts with the chassis state"

#: the pose (x, y, θ) in a robot summary row
RS_POSE = slice(RS.X, RS.TH + 1)
#: the world velocity (v_x, v_y)
RS_VEL_WORLD = slice(RS.VX, RS.VY + 1)
#: the chassis twist ξ̇ = (ẋ, ẏ, θ̇) in the chassis frame R (a list: fancy indexing, a copy)
RS_TWIST_BODY = [RS.BX, RS.BY, RS.W]
#: the tire force (F_x, F_y) in the chassis frame in a wheel summary
WS_FORCE = slice(WS.FX, WS.FY + 1)
#: the contact point (P_x, P_y) in the chassis frame
WS_CONTACT = slice(WS.PX, WS.PY + 1)
