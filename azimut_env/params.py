"""Physical parameters of the simulated AZIMUT-3, as frozen dataclasses with units.

The actuator limits and the map between the env's normalised actions and the actuator
set-points are in :mod:`azimut_env.action_map` (re-exported here: ``ActuatorLimits``,
:func:`setpoints_from_action`, :func:`action_from_setpoints`).

Default values are assumptions for a robot of AZIMUT-3's size (the paper does not publish them);
they are chosen so that the steering compliance is visible (a few degrees of deflection under the
largest tire force) while the simulation stays stable at the default substep. The defaults of the
imperfections (steering friction, module centre-of-mass offset, drive torque–speed line,
geometric imperfections) are "none": the ``"paper"`` preset of :mod:`azimut_env.imperfections`
sets them from their sources, and the envs use it by default (``Azimut-v2``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from azimut_env.action_map import ActuatorLimits, action_from_setpoints, setpoints_from_action
from azimut_env.validation import check_fields, check_real_array
from azimut_env.validation import check_positive_fields as _check_positive
from estimation.geometry import RobotGeometry

__all__ = [
    "ActuatorLimits",
    "SteeringParams",
    "SteeringMotorParams",
    "WheelParams",
    "TireParams",
    "ChassisParams",
    "SensorParams",
    "ImperfectionParams",
    "RobotParams",
    "setpoints_from_action",
    "action_from_setpoints",
]


@dataclass(frozen=True)
class SteeringParams:
    """Series-elastic steering module (motor -> spring + damper -> module about A_k).

    Attributes:
        stiffness: spring stiffness k_s [N·m/rad] between motor and module.
        damping: damper c_s [N·m·s/rad] in parallel with the spring.
        position_gain: motor position loop gain [1/s] (desired rate = gain · error, before limits).
        module_mass: mass of one steering module with its wheel [kg].
        module_inertia: moment of inertia I_A of a module about its steering axis A_k [kg·m²]
            (its inertia about its own centre of mass is I_A − m c², which must be positive).
        stop_restitution: coefficient of restitution e ∈ [0, 1] of the hard steering stops (0: the
            module stops dead at the stop, as a rubber-padded end stop; 1: elastic bounce).
        friction_coulomb: τ_c, the sliding (Coulomb) friction torque of the steering joint [N·m]
            (module against chassis; 0: none).
        friction_static: τ_s ≥ τ_c, its breakaway (static) torque [N·m]: a joint at rest stays at
            rest while the torque on it is at most τ_s. With the spring in series, the motor must
            wind the spring by τ_s / k_s before the module moves: the dead band of the steering.
        stribeck_speed: ω_s, the Stribeck speed [rad/s]: sliding at |β̇| the friction is
            τ_c + (τ_s − τ_c) exp(−(β̇/ω_s)²) (Canudas de Wit et al. 1995, eq. 3; the
            velocity-weakening of Armstrong-Hélouvry et al. 1994). See
            :mod:`azimut_env.physics.modules` for the integration (a velocity-level impulse that
            cannot chatter or add energy).
        com_offset: c, the distance of the module's centre of mass from its steering axis, along the
            propulsion axis toward the wheel [m] (0: on the axis, the v1/v2 model). The module then
            couples to the chassis through the mass matrix (:mod:`azimut_env.physics.modules`).
    """

    stiffness: float = 60.0
    damping: float = 0.6
    position_gain: float = 20.0
    module_mass: float = 2.0
    module_inertia: float = 0.02
    stop_restitution: float = 0.0
    friction_coulomb: float = 0.0
    friction_static: float = 0.0
    stribeck_speed: float = 0.02
    com_offset: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self)
        _check_positive(self, "stiffness", "position_gain", "module_mass", "module_inertia", "stribeck_speed")
        _check_positive(self, "damping", "friction_coulomb", "friction_static", "com_offset", allow_zero=True)
        if not (math.isfinite(self.stop_restitution) and 0.0 <= self.stop_restitution <= 1.0):
            raise ValueError(f"SteeringParams.stop_restitution must be in [0, 1], got {self.stop_restitution!r}")
        if self.friction_static < self.friction_coulomb:
            raise ValueError(f"SteeringParams.friction_static ({self.friction_static!r}) must be >= friction_coulomb "
                             f"({self.friction_coulomb!r}): the breakaway torque is not below the sliding one")
        if not self.module_inertia > self.module_mass * self.com_offset ** 2:
            raise ValueError(f"SteeringParams.module_inertia ({self.module_inertia!r} kg·m² about the steering axis) "
                             f"must exceed module_mass · com_offset² ({self.module_mass * self.com_offset ** 2:.4g}): "
                             "the inertia about the module's own centre of mass would not be positive")

    @property
    def has_friction(self) -> bool:
        """True when the steering joint has friction (``friction_static`` > 0)."""
        return self.friction_static > 0.0


@dataclass(frozen=True)
class SteeringMotorParams:
    """How the steering motor is modelled (``model``) and its DC-motor data for the "dc" model.

    * ``"kinematic"`` (default): a position source with rate and acceleration limits whose
      spring torque is clipped at ``ActuatorLimits.steer_torque_max`` (the motor stalls there).
    * ``"dc"``: a torque source with inertia that follows the same rate profile while its torque
      allows, under the torque–speed line of a DC motor, τ ≤ τ_stall (1 − |ω|/ω₀) while motoring,
      and the current limit ``ActuatorLimits.steer_torque_max``
      (:func:`~azimut_env.physics.actuators.steer_dc_motor_kernel`). Under a load τ_L the steering slows
      to ω₀ (1 − τ_L/τ_stall); the kinematic model keeps its rate.

    Defaults are an assumption of the class of a ~20 W brushed DC motor (e.g. a Maxon RE 25:
    no-load speed ≈ 9,000–10,000 rpm, stall torque ≈ 0.3 N·m, rotor inertia ≈ 1e-6 kg·m²) behind a
    1:150 planetary gearhead at ~70% efficiency, seen at the output: ω₀ ≈ 6.5 rad/s, τ_stall ≈
    30 N·m, J ≈ 150² · 1.1e-6 ≈ 0.025 kg·m². The paper does not give AZIMUT-3's steering motors.

    Attributes:
        model: ``"kinematic"`` or ``"dc"``.
        stall_torque: τ_stall, output torque at zero speed and full voltage [N·m].
        no_load_speed: ω₀, output speed at zero torque and full voltage [rad/s].
        rotor_inertia: J, motor and gearhead inertia reflected to the output [kg·m²].
    """

    model: str = "kinematic"
    stall_torque: float = 30.0
    no_load_speed: float = 6.5
    rotor_inertia: float = 0.025

    def __post_init__(self) -> None:
        check_fields(self)
        if self.model not in ("kinematic", "dc"):
            raise ValueError(f"SteeringMotorParams.model must be 'kinematic' or 'dc', got {self.model!r}")
        _check_positive(self, "stall_torque", "no_load_speed", "rotor_inertia")

    @property
    def is_dc(self) -> bool:
        """True for the DC-motor model."""
        return self.model == "dc"


@dataclass(frozen=True)
class WheelParams:
    """Propulsion: the wheel spin DOF and its velocity-controlled motor.

    The drive motor (``drive_model``):

    * ``"current_limit"`` (default): the loop's torque is clipped at the driver's current limit
      ``ActuatorLimits.wheel_torque_max`` at every speed;
    * ``"dc"``: a DC motor at its supply voltage as well: the torque–speed line
      τ_stall (1 − |φ̇|/ω₀) while motoring, then the current limit, as the steering's "dc" model
      (Hughes & Drury, *Electric Motors and Drives*, 5th ed., Ch. 3;
      :func:`~azimut_env.physics.actuators.dc_torque_limits_kernel`). A wheel runs free at ω₀ and
      stalls at τ_stall (or the current limit, the smaller).

    The "dc" defaults are those of the class of a maxon RE 40 (150 W, 24 V, no-load speed
    7,580 rpm, stall torque 2.29 N·m, from the maxon catalogue's data of part 148877) behind a
    36:1 planetary gearhead at ~72% efficiency (an assumption; the paper says only that the
    propulsion "uses standard stiff actuators"), seen at the wheel: ω₀ = 7580 · 2π/60 / 36 =
    22.0 rad/s (above the 20 rad/s propulsion limit, so that every set-point is reachable
    unloaded) and τ_stall = 2.29 · 36 · 0.72 = 59 N·m.

    Attributes:
        inertia: spin inertia of wheel + reflected rotor [kg·m²].
        velocity_gain: propulsion velocity loop gain [N·m·s/rad] (τ = gain · (φ̇_ref − φ̇), clipped).
        bearing_damping: viscous friction on the spin [N·m·s/rad].
        drive_model: ``"current_limit"`` or ``"dc"`` (above).
        drive_stall_torque: τ_stall at the wheel [N·m] ("dc" only).
        drive_no_load_speed: ω₀ at the wheel [rad/s] ("dc" only).
    """

    inertia: float = 0.03
    velocity_gain: float = 8.0
    bearing_damping: float = 0.005
    drive_model: str = "current_limit"
    drive_stall_torque: float = 59.0
    drive_no_load_speed: float = 22.0

    def __post_init__(self) -> None:
        check_fields(self)
        _check_positive(self, "inertia", "velocity_gain", "drive_stall_torque", "drive_no_load_speed")
        _check_positive(self, "bearing_damping", allow_zero=True)
        if self.drive_model not in ("current_limit", "dc"):
            raise ValueError(f"WheelParams.drive_model must be 'current_limit' or 'dc', got {self.drive_model!r}")

    @property
    def is_dc(self) -> bool:
        """True for the DC drive model (torque–speed line)."""
        return self.drive_model == "dc"


@dataclass(frozen=True)
class TireParams:
    """Tire-ground contact: the brush tire with relaxation lengths of :mod:`azimut_env.physics.tire`.

    Defaults describe a 0.16 m solid-rubber-tread wheel carrying about 86 N (a quarter of the
    35 kg robot). No tire data of AZIMUT-3 are published; the values are assumptions of the right
    order, each with its reasoning below. Stiffnesses are per unit load (C = c N), so that the tire
    follows the normal load when the mass is randomised.

    Attributes:
        friction: friction coefficient μ [-] (rubber on dry indoor floors: 0.6–1.0; assumption).
        cornering_stiffness: c_α = C_α/N [1/rad], slope of F_y against the slip angle. Pneumatic
            car tires measure C_α/F_z ≈ 10–20 /rad (Pacejka 2012, Ch. 1); 12 /rad is an
            assumption in that range. Full sliding starts at α_sl = 3μ/c_α (11.5° by default).
        longitudinal_stiffness: c_κ = C_κ/N [-], slope of F_x against the slip ratio (15,
            assumption; the brush model with isotropic bristles gives C_κ ≈ C_α, tires measure a
            somewhat larger C_κ, Pacejka 2012, Ch. 1).
        relaxation_length: lateral relaxation length σ_α [m]: the distance rolled to build
            1 − 1/e of the steady lateral force; with C_α it sets the lateral contact stiffness
            k_y = C_α/σ_α. Pneumatic tires measure σ_α of the order of the wheel radius (Pacejka
            2012, Ch. 7); a solid tread on a rigid hub is much stiffer: 0.02 m (= r/4) is an
            assumption (k_y ≈ 52 N/mm at the default load). Also relaxes the patch twist.
        longitudinal_relaxation_length: σ_κ [m] (0.02, assumption, as σ_α).
        contact_half_length: a [m], half-length (radius) of the contact patch: sets the pneumatic
            trail a/3 at small slip, the scrub torque limit (2/3) μ N a and the torsional stiffness
            k_y a²/2. 0.01 m (a 2 cm patch, a soft tread under 86 N) is an assumption: a Hertz line
            contact of a 30 mm wide rubber tread (E ≈ 5 MPa) gives ≈ 7 mm (Johnson 1985, Ch. 4).
        damping_time: τ_d [s], bristle damping per unit contact stiffness (c = k τ_d, the LuGre
            σ₁ of Canudas de Wit et al. 1995): damps the stuck tread at rest and at low speed
            (0.005 s, assumption: ζ ≈ 0.2 for a quarter of the robot on one tire laterally, ≈ 0.5
            for the fastest contact mode, spin and module against the tread at ω ≈ 210 rad/s).
            It is explicit: with ω_max the fastest contact mode, ω_max² dt (dt + 2τ_d) < 4.
        rolling_resistance: rolling resistance coefficient C_rr [-] (torque C_rr N r on the spin).
        rolling_knee: spin surface speed below which rolling resistance fades linearly [m/s].
    """

    friction: float = 0.8
    cornering_stiffness: float = 12.0
    longitudinal_stiffness: float = 15.0
    relaxation_length: float = 0.02
    longitudinal_relaxation_length: float = 0.02
    contact_half_length: float = 0.01
    damping_time: float = 0.005
    rolling_resistance: float = 0.015
    rolling_knee: float = 0.02

    def __post_init__(self) -> None:
        check_fields(self)
        _check_positive(self, "friction", "cornering_stiffness", "longitudinal_stiffness", "relaxation_length",
                        "longitudinal_relaxation_length", "contact_half_length", "rolling_knee")
        _check_positive(self, "rolling_resistance", "damping_time", allow_zero=True)

    @property
    def saturation_slip_angle(self) -> float:
        """Slip angle [rad] at which the brush tire slides fully: atan(3μ/c_α)."""
        return math.atan(3.0 * self.friction / self.cornering_stiffness)


@dataclass(frozen=True)
class ChassisParams:
    """The chassis rigid body (a square plate).

    The robot's centre of mass (chassis plus modules) is at the origin of the chassis frame R,
    at height ``com_height`` above the ground.

    Attributes:
        mass: chassis mass without the modules [kg] (total robot = mass + n · module_mass).
        length: footprint along X_R [m]. width: footprint along Y_R [m].
        com_height: height h of the centre of mass above the ground [m]. 0 (default) keeps the
            normal loads static; h > 0 adds the load transfer of the chassis acceleration a
            (Σ_k N_k x_k = −h M a_x, Σ_k N_k y_k = −h M a_y; Gillespie, *Fundamentals of Vehicle
            Dynamics*, 1992, §2).
    """

    mass: float = 27.0
    length: float = 0.6
    width: float = 0.6
    com_height: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self)
        _check_positive(self, "mass", "length", "width")
        _check_positive(self, "com_height", allow_zero=True)

    @property
    def inertia(self) -> float:
        """Moment of inertia of the plate about its centre [kg·m²]."""
        return self.mass * (self.length**2 + self.width**2) / 12.0


@dataclass(frozen=True)
class SensorParams:
    """Sensor noise and quantisation. Noise is drawn from the env's RNG.

    Attributes:
        steer_noise: standard deviation of measured β (wheel side of the spring) [rad].
        steer_resolution: quantum of the steering and motor-angle encoders [rad] (0: none).
        motor_noise: standard deviation of measured motor angles [rad].
        wheel_cpr: wheel encoder counts per revolution; φ̇ is counts per control period (0: exact).
        wheel_speed_noise: standard deviation added to measured φ̇ [rad/s].
        steer_bias: standard deviation of a constant per-wheel offset of the steering encoders,
            drawn at each reset [rad] (calibration error, one of the paper's "geometric
            imperfections"; 0 by default).
    """

    steer_noise: float = 0.002
    steer_resolution: float = 2 * math.pi / 4096
    motor_noise: float = 0.001
    wheel_cpr: int = 4096
    wheel_speed_noise: float = 0.02
    steer_bias: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self)
        _check_positive(self, "steer_noise", "steer_resolution", "motor_noise", "wheel_speed_noise", "steer_bias",
                        allow_zero=True)
        if int(self.wheel_cpr) != self.wheel_cpr or self.wheel_cpr < 0:
            raise ValueError(f"SensorParams.wheel_cpr must be a non-negative integer, got {self.wheel_cpr!r}")

    @classmethod
    def ideal(cls) -> SensorParams:
        """Noise-free, unquantised sensors."""
        return cls(0.0, 0.0, 0.0, 0, 0.0, 0.0)


def _per_wheel(obj, name: str, bound: float) -> None:
    """Freeze the per-wheel tuple ``name`` of ``obj`` (finite, |x| <= bound) in place."""
    raw = getattr(obj, name)
    if isinstance(raw, (str, bytes)):
        raise ValueError(f"{type(obj).__name__}.{name} must be a sequence of numbers, got {raw!r}")
    values = tuple(check_real_array(f"{type(obj).__name__}.{name}", raw).reshape(-1).tolist())  # 10**400: refused
    if not all(math.isfinite(x) and abs(x) <= bound for x in values):
        raise ValueError(f"{type(obj).__name__}.{name} must be finite and within ±{bound}, got {values}")
    object.__setattr__(obj, name, values)


@dataclass(frozen=True)
class ImperfectionParams:
    """Geometric imperfections of each wheel, fixed for a robot (the paper's "geometric
    imperfections"), and their spread when domain randomisation draws a new robot.

    * The **steering-axis zero offset** δ_k: the wheel's propulsion axis sits at γ_k = α_k + β_k + δ_k
      while the encoders (motor and wheel side) and the controller count β_k from the nominal
      zero (a module homed or assembled off by δ_k). The commanded configuration is on the
      constraining surface; the true one is not, so the wheels fight (internal force) and the
      tire moments deflect the springs.
    * The **rolling-radius error** ε_k: the wheel rolls with r_k (1 + ε_k) while the controller
      and the odometry assume r_k (tread wear, manufacturing, load): at a commanded φ̇ the wheel's
      surface speed is off by the factor 1 + ε_k (Borenstein & Feng, "Measurement and correction
      of systematic odometry errors in mobile robots", IEEE Trans. Robotics and Automation 12(6),
      1996: unequal wheel diameters are one of the two dominant systematic errors).

    Attributes:
        steer_offset: δ_k per wheel [rad] (empty: none), |δ_k| <= 0.1.
        radius_error: ε_k per wheel [-] (empty: none), |ε_k| <= 0.1.
        steer_offset_std: standard deviation [rad] of δ_k drawn at each reset under domain
            randomisation (``domain_randomization`` > 0; the draws replace ``steer_offset``).
        radius_error_std: standard deviation [-] of ε_k drawn likewise.
    """

    steer_offset: tuple[float, ...] = ()
    radius_error: tuple[float, ...] = ()
    steer_offset_std: float = 0.0
    radius_error_std: float = 0.0

    def __post_init__(self) -> None:
        check_fields(self)
        _per_wheel(self, "steer_offset", 0.1)
        _per_wheel(self, "radius_error", 0.1)
        _check_positive(self, "steer_offset_std", "radius_error_std", allow_zero=True)
        if self.steer_offset_std > 0.03 or self.radius_error_std > 0.03:
            raise ValueError("ImperfectionParams: steer_offset_std and radius_error_std must be <= 0.03 (draws are "
                             f"clipped at 3 standard deviations, within ±0.1), got {self.steer_offset_std!r}, "
                             f"{self.radius_error_std!r}")

    @property
    def randomised(self) -> bool:
        """True when domain randomisation draws imperfections (a spread is set)."""
        return self.steer_offset_std > 0.0 or self.radius_error_std > 0.0

    def offsets(self, n: int) -> np.ndarray:
        """δ (n,) [rad] (zeros when none are set)."""
        return np.asarray(self.steer_offset, dtype=np.float64) if self.steer_offset else np.zeros(n)

    def radius_errors(self, n: int) -> np.ndarray:
        """ε (n,) [-] (zeros when none are set)."""
        return np.asarray(self.radius_error, dtype=np.float64) if self.radius_error else np.zeros(n)


@dataclass(frozen=True)
class RobotParams:
    """All physical parameters of one robot.

    Attributes:
        geometry: wheel layout (``RobotGeometry``; default the AZIMUT-3 stand-in).
        chassis, steering, steer_motor, wheel, tire, limits, sensors, imperfections: see their
            classes (the imperfections preset of :mod:`azimut_env.imperfections` sets several).
        gravity: g [m/s²], used only for the static normal loads N_k.
    """

    geometry: RobotGeometry = field(default_factory=RobotGeometry.azimut3)
    chassis: ChassisParams = field(default_factory=ChassisParams)
    steering: SteeringParams = field(default_factory=SteeringParams)
    steer_motor: SteeringMotorParams = field(default_factory=SteeringMotorParams)
    wheel: WheelParams = field(default_factory=WheelParams)
    tire: TireParams = field(default_factory=TireParams)
    limits: ActuatorLimits = field(default_factory=ActuatorLimits)
    sensors: SensorParams = field(default_factory=SensorParams)
    imperfections: ImperfectionParams = field(default_factory=ImperfectionParams)
    gravity: float = 9.81

    def __post_init__(self) -> None:
        check_fields(self)
        _check_positive(self, "gravity")
        g = self.geometry
        if not isinstance(g, RobotGeometry):
            raise ValueError(f"RobotParams.geometry must be a RobotGeometry, got {type(g).__name__}")
        for name, kind in (("chassis", ChassisParams), ("steering", SteeringParams),
                           ("steer_motor", SteeringMotorParams), ("wheel", WheelParams), ("tire", TireParams),
                           ("limits", ActuatorLimits), ("sensors", SensorParams),
                           ("imperfections", ImperfectionParams)):
            if not isinstance(getattr(self, name), kind):
                raise TypeError(f"RobotParams.{name} must be {kind.__name__}, got {type(getattr(self, name)).__name__}")
        for name in ("steer_offset", "radius_error"):
            count = len(getattr(self.imperfections, name))
            if count not in (0, g.n):
                raise ValueError(f"RobotParams.imperfections.{name} has {count} values for {g.n} wheels")
        if g.unlimited_steering:
            if not self.limits.unlimited_steering:
                raise ValueError("RobotParams: the geometry has unlimited steering: limits.steer_min/steer_max must "
                                 "be -inf/+inf (ActuatorLimits(steer_min=-math.inf, steer_max=math.inf))")
        elif not (np.isclose(g.steer_max, self.limits.steer_max) and np.isclose(g.steer_min, self.limits.steer_min)):
            raise ValueError("RobotParams: limits.steer_min/steer_max must equal the geometry's steering range")

    @classmethod
    def from_file(cls, path) -> RobotParams:
        """The robot of a description file (TOML, schema in ``docs/robots.md``): the ``[geometry]``
        table and the parameter groups it gives; the groups and keys it leaves out keep their
        defaults. Raises :class:`estimation.robot_file.RobotFileError` (a ``ValueError``) naming
        the file, the key and the value."""
        from azimut_env.robot_file import params_from_file

        return params_from_file(path, cls)

    @classmethod
    def preset(cls, name: str) -> RobotParams:
        """A robot shipped with the package, by name (``azimut_env.robot_file.PRESET_NAMES``:
        ``azimut3`` = ``RobotParams()``, ``swerve``, ``tri``, ``hex``); each is a description file
        in ``azimut_env/robots/``, read like a user's. ``ValueError`` for an unknown name."""
        from azimut_env.robot_file import preset_params

        return preset_params(name, cls)

    @property
    def n(self) -> int:
        """Number of wheels."""
        return self.geometry.n

    @property
    def total_mass(self) -> float:
        """Chassis plus modules [kg]."""
        return self.chassis.mass + self.n * self.steering.module_mass

    @property
    def max_surface_speed(self) -> float:
        """Largest wheel surface speed r φ̇_max [m/s] (smallest wheel)."""
        return float(np.min(self.geometry.r) * self.limits.wheel_speed_max)

    def body_inertia(self, chassis_mass: float | None = None) -> np.ndarray:
        """(M, I): the robot body's mass [kg] and moment about the centre [kg·m²] with a chassis of
        mass ``chassis_mass`` (default ``chassis.mass``; the plate's inertia scales with it) and
        the modules' masses at their steering axes (parallel axis: m_m Σ_k l_k²)."""
        ch = self.chassis
        m = ch.mass if chassis_mass is None else float(chassis_mass)
        return np.array([m + self.n * self.steering.module_mass,
                         ch.inertia * m / ch.mass + self.steering.module_mass * float(np.sum(self.geometry.l ** 2))])

    def load_map(self) -> np.ndarray:
        """(n, 3) matrix L with N = L (W, M_x, M_y): the least-norm normal loads N_k on the steering
        axes carrying a vertical force W [N] with moments Σ N_k x_k = M_x and Σ N_k y_k = M_y
        [N·m] about the chassis centre (L = Gᵀ(G Gᵀ)⁻¹, G = [1; x_k; y_k]). For four symmetric
        wheels the weight alone gives W/4 each."""
        xy = self.geometry.axis_xy
        G = np.vstack([np.ones(self.n), xy[:, 0], xy[:, 1]])
        return np.linalg.pinv(G)

    def static_normal_loads(self, total_mass: float | None = None) -> np.ndarray:
        """N_k [N]: least-norm loads on the steering axes balancing the weight of ``total_mass``
        [kg] (default :attr:`total_mass`; centre of mass at the origin). Equal loads for a
        symmetric robot."""
        mass = self.total_mass if total_mass is None else float(total_mass)
        loads = self.load_map()[:, 0] * mass * self.gravity
        if np.any(loads <= 0):
            raise ValueError(f"RobotParams: the static load of some wheel is not positive ({loads})")
        return loads
