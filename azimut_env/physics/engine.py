"""Rigid-body physics of N AZIMUT-3-like robots (top-down 2D): one rigid body per robot in a
pymunk Space, the steering modules as joint coordinates in a compiled substep.

One :class:`AzimutPhysics` simulates ``n_robots`` robots (the single env is ``n_robots=1``; the
vector env uses the same class with many). Robots do not collide with each other, only with
static obstacles. The pieces:

* :mod:`azimut_env.physics.kernels`: the model (Newton–Euler equations of chassis and modules,
  tires, actuators, hard stops, load transfer) and its compiled substep and summary kernels;
* :mod:`azimut_env.physics.modules`: the steering joint's friction, the coupling of a module whose
  centre of mass is off its axis, and the mechanical energy;
* :mod:`azimut_env.physics.wheel_params`: the per-wheel parameter arrays (imperfections included)
  and their domain randomisation;
* :mod:`azimut_env.physics.layout`: the names of the columns of every state and parameter array;
* :mod:`azimut_env.physics.stability`: the stability budget that bounds the substep (checked here at
  construction and on a change of mass);
* :mod:`azimut_env.physics.body_io`, ``contacts``, ``obstacles``: the batched reads and writes of
  the pymunk bodies, the substeps through pymunk's contact solver, the obstacles and shapes;
* :mod:`azimut_env.physics.blowup`, ``energy_check``: the blow-up limits and codes of :meth:`AzimutPhysics.check`.

Without obstacles the whole control period (all substeps, all robots) is one compiled call
(:func:`~azimut_env.physics.kernels.step_kernel`, blocks of robots on ``num_threads`` threads)
that integrates the chassis too; pymunk's bodies are read before it and written after it. With
obstacles (and only then do robots have collision shapes) pymunk integrates the chassis: each
substep the kernel's velocity change is handed to pymunk as a force and torque, and
``space.step`` integrates them and resolves the contacts (Chipmunk moves the position with the
velocity of the start of the substep, then updates the velocity: explicit Euler for the chassis).

Per-robot parameters live in arrays (``wheel_params``, columns :class:`WP`) so that domain
randomisation can vary them robot by robot (:meth:`AzimutPhysics.set_wheel_params`,
:meth:`AzimutPhysics.set_chassis_mass`). After each step, ``summary`` (N, len(RS)) and
``wheel_summary`` (N, n, len(WS)) hold the derived per-robot quantities (pose, twists, slip power,
null-space force, antagonism, blow-up code; β, β̇, tire forces and contact points in the chassis frame),
computed by one compiled call for all robots. Other modules read them by the column names of
:mod:`azimut_env.physics.layout` and change the physics only through its methods.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from functools import partial

import numpy as np
import pymunk

from azimut_env.params import RobotParams
from azimut_env.physics.antagonism import SLIP_MEMORY_TIME, slip_damping
from azimut_env.physics.blowup import BLOWUP_MESSAGES, BlowUp, BlowUpLimits
from azimut_env.physics.body_io import BodyIO
from azimut_env.physics.contacts import lap, step_with_contacts
from azimut_env.physics.energy_check import EnergyCheck
from azimut_env.physics.kernels import STEP_BLOCKS, SUMMARY_BLOCKS, step_kernel, summary_kernel
from azimut_env.physics.layout import ACC, BODY, CMD, CS, FT, JS, MS, RS, RS_POSE, RS_TWIST_BODY, WP, WS, WS_FORCE
from azimut_env.physics.modules import mechanical_energy, module_impulse_response
from azimut_env.physics.obstacles import Obstacle, add_obstacle_shape, add_robot_shape, overlapping_shapes
from azimut_env.physics.stability import check_load_scale, check_stability, stability_figures
from azimut_env.physics.tire import TS
from azimut_env.physics.wheel_params import default_wheel_params
from estimation.threads import check_threads

__all__ = ["AzimutPhysics", "Obstacle", "BlowUpLimits", "BlowUp", "default_wheel_params", "WP", "MS", "JS", "TS",
           "ACC", "BODY", "CMD", "CS", "FT", "RS", "WS"]

class AzimutPhysics:
    """N robots in one pymunk Space, stepped at ``control_period`` with ``substeps`` substeps.

    Args:
        params: the robot's physical parameters (shared by all robots; per-robot variations go
            through :meth:`set_wheel_params` and :meth:`set_chassis_mass`).
        n_robots: number of robots N (1 for the single env).
        control_period: duration of one :meth:`step` [s].
        substeps: physics substeps per step; the substep is ``control_period / substeps``.
        blowup: thresholds of :meth:`check`.
        solver_iterations: pymunk solver iterations per substep (obstacle contacts only since the
            steering modules left pymunk; kept as a knob).
        num_threads: threads of the compiled substeps and summary, blocks of robots (:mod:`estimation.threads`;
            None: the cores this process may use); any count gives the same bits.

    State accessors return arrays with a leading robot axis N. The state of record between steps
    is the pymunk chassis bodies (pose, velocity) plus ``joint_state`` (β, module rates),
    ``motor_state`` and ``chassis_accel``; all of it pickles.
    """

    def __init__(self, params: RobotParams | None = None, n_robots: int = 1, control_period: float = 0.02,
                 substeps: int = 8, blowup: BlowUpLimits | None = None, solver_iterations: int = 20,
                 num_threads: int | None = None) -> None:
        self.params = params if params is not None else RobotParams()
        for name, value in (("n_robots", n_robots), ("substeps", substeps), ("solver_iterations", solver_iterations)):
            if int(value) != value or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if not (math.isfinite(control_period) and control_period > 0):
            raise ValueError(f"control_period must be > 0 [s], got {control_period!r}")
        self.n_robots, self.substeps, self.solver_iterations = int(n_robots), int(substeps), int(solver_iterations)
        self.n = self.params.n
        self.control_period = float(control_period)
        self.num_threads = min(check_threads(num_threads), self.n_robots)  # at most one per robot
        self._serial = self.num_threads == 1  # the kernels called directly
        self.dt = self.control_period / self.substeps
        self.blowup = blowup if blowup is not None else BlowUpLimits()
        self._energy_check = EnergyCheck(self.n_robots, self.blowup)
        check_stability(self.params, self.dt)
        p = self.params
        #: (n, 2) load change on each axis per unit moment (M_x, M_y) about the centre [1/m]
        self._load_transfer = np.ascontiguousarray(p.load_map()[:, 1:3])
        #: (N, n, len(WP)) per-wheel parameters (change them with set_wheel_params/set_chassis_mass)
        self.wheel_params = default_wheel_params(p, self.n_robots)
        self.motor_state = np.zeros((self.n_robots, self.n, len(MS)))
        self.joint_state = np.zeros((self.n_robots, self.n, len(JS)))
        #: (N, n, len(TS)) tire states (contact patch deflections u_long, u_lat [m], twist [rad])
        self.tire_state = np.zeros((self.n_robots, self.n, len(TS)))
        self.commands = np.zeros((self.n_robots, self.n, len(CMD)))
        self.enabled = np.ones(self.n_robots, dtype=np.bool_)
        self.acc = np.zeros((self.n_robots, self.n, len(ACC)))
        #: (N, len(BODY)) body mass M [kg] and moment I [kg·m²] about the centre (modules at their axes)
        self.body_inertia = np.tile(p.body_inertia(), (self.n_robots, 1))
        #: (N, 2) chassis acceleration in R from the tire forces of the last substep [m/s²]
        self.chassis_accel = np.zeros((self.n_robots, 2))
        self.obstacles: tuple[Obstacle, ...] = ()
        self.summary = np.zeros((self.n_robots, len(RS)))
        self.wheel_summary = np.zeros((self.n_robots, self.n, len(WS)))
        self._axis_xy = np.ascontiguousarray(self.params.geometry.axis_xy)
        #: a dict that :meth:`step` adds its stage times to when set (``azimut bench-env``), or None
        self.stage_times: dict[str, float] | None = None
        self._build_space()

    # ------------------------------------------------------------------ construction

    def stability_figures(self) -> dict[str, tuple[float, float]]:
        """``{name: (value, bound)}`` of the stability budget for these parameters and substep (stability.py)."""
        return stability_figures(self.params, self.dt)

    def _build_space(self) -> None:
        p = self.params
        space = pymunk.Space()
        space.iterations = self.solver_iterations
        space.gravity = (0.0, 0.0)
        # Collision shapes only matter against obstacles; without obstacles the bodies carry their
        # mass and inertia alone and pymunk is not stepped at all.
        self.chassis: list[pymunk.Body] = []
        for i in range(self.n_robots):
            mass, moment = self.body_inertia[i]
            ch = pymunk.Body(float(mass), float(moment))
            space.add(ch)
            if self.obstacles:
                add_robot_shape(space, ch, p.chassis.length, p.chassis.width)
            self.chassis.append(ch)
        self.space = space
        self._obstacle_shapes = [add_obstacle_shape(space, ob) for ob in self.obstacles]
        self._setup_buffers()

    def _setup_buffers(self) -> None:
        """(Re)create the batched body I/O for the current Space and read the bodies."""
        self._io = BodyIO(self.space, self.chassis)
        self._state = self._io.state
        self._before = np.zeros((self.n_robots, len(CS)))
        self._read_state()

    def _summarize(self, sl: slice = slice(None)) -> None:
        """The summary rows ``sl`` (all robots by default) from the state (:func:`summary_kernel`)."""
        lim, out = self.blowup, self.summary[sl]
        args = (self._state[sl], self.joint_state[sl], self.motor_state[sl], self.acc[sl], self.wheel_params[sl],
                self.enabled[sl], self._axis_xy, self.n, 1.0 / self.substeps, SLIP_MEMORY_TIME, lim.speed,
                lim.yaw_rate, lim.spin, lim.position, out, self.wheel_summary[sl])
        if self._serial:
            summary_kernel(*args, 0, out.shape[0])
        else:
            SUMMARY_BLOCKS.run(self.num_threads, out.shape[0], *args)

    def _read_state(self) -> np.ndarray:
        self._io.read()
        self._summarize()
        return self._state

    def _read_robot_state(self, robot: int) -> None:
        """Re-read one robot's body and recompute its summary row (after a reset or a kick), in
        O(1) of the robot count."""
        b = self.chassis[robot]
        p, v = b.position, b.velocity
        self._state[robot] = (p.x, p.y, b.angle, v.x, v.y, b.angular_velocity)
        self._summarize(slice(robot, robot + 1))

    def _build_space_keep_state(self) -> None:
        """Rebuild the Space and copy every robot body's state over."""
        saved = [(b.position, b.angle, b.velocity, b.angular_velocity) for b in self.chassis]
        self._build_space()
        for body, (pos, ang, vel, w) in zip(self.chassis, saved):
            body.angle = ang
            body.position, body.velocity, body.angular_velocity = pos, vel, w
        self._read_state()

    def rebuild(self, obstacles: Sequence | None = None) -> None:
        """Recreate the pymunk Space (same robots, bodies at the origin) with ``obstacles``
        (Obstacle, (x, y, radius) or vertex lists; default: the current ones).

        pymunk keeps contact caches between steps, so with obstacles two episodes reset to the
        same state only replay bit-for-bit from a fresh Space. The single env rebuilds on every
        reset; call :meth:`reset_robot` after."""
        if obstacles is not None:
            self.obstacles = tuple(Obstacle.coerce(o) for o in obstacles)
        self._build_space()

    def set_obstacles(self, obstacles: Sequence = ()) -> None:
        """Replace the static obstacles (Obstacle, (x, y, radius) or vertex lists)."""
        obs = tuple(Obstacle.coerce(o) for o in obstacles)
        for shapes in self._obstacle_shapes:
            self.space.remove(*shapes)
        self._obstacle_shapes = []
        had_shapes = bool(self.obstacles)
        self.obstacles = obs
        if bool(obs) != had_shapes:  # robots need (or no longer need) collision shapes
            self._build_space_keep_state()
            return
        self._obstacle_shapes = [add_obstacle_shape(self.space, ob) for ob in obs]
        self._setup_buffers()

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        d.pop("_io", None)  # pymunk.batch buffers: rebuilt for the unpickled Space
        return d

    def __setstate__(self, d: dict) -> None:
        self.__dict__.update(d)
        state = self._state.copy()
        self._setup_buffers()
        self._state[:] = state

    # ------------------------------------------------------------------ reset and commands

    def _robot_index(self, robot) -> int:
        """``robot`` as an index 0..N−1 (``ValueError`` otherwise)."""
        if isinstance(robot, bool) or not isinstance(robot, (int, np.integer)) or not 0 <= robot < self.n_robots:
            raise ValueError(f"robot index {robot!r} out of range 0..{self.n_robots - 1}")
        return int(robot)

    def set_wheel_params(self, wheel_params: np.ndarray, robot: int | None = None) -> None:
        """Replace the per-wheel parameters (columns :class:`WP`), e.g. randomised: of every robot
        (``wheel_params`` (N, n, len(WP))), or of robot ``robot`` alone ((n, len(WP)))."""
        wp = np.asarray(wheel_params, dtype=np.float64)
        shape = self.wheel_params.shape if robot is None else self.wheel_params.shape[1:]
        finite = np.isfinite(np.delete(wp, [WP.STEER_MIN, WP.STEER_MAX], axis=-1))
        stops = wp[..., [WP.STEER_MIN, WP.STEER_MAX]]
        if wp.shape != shape or not np.all(finite) or np.any(np.isnan(stops)):
            raise ValueError(f"wheel_params must be finite with shape {shape} (the steering stops may be -inf/+inf: "
                             "unlimited steering)")
        if robot is None:
            self.wheel_params = np.ascontiguousarray(wp)
        else:
            self.wheel_params[self._robot_index(robot)] = wp

    def set_chassis_mass(self, robot: int, mass: float) -> None:
        """Change robot ``robot``'s chassis mass [kg] (without the modules; the plate's inertia
        scales with it). The body's mass and moment and the wheels' static normal loads follow."""
        if not (math.isfinite(mass) and mass > 0):
            raise ValueError(f"mass must be > 0, got {mass!r}")
        robot = self._robot_index(robot)
        check_load_scale(self.params, self.dt, mass)
        m_tot, moment = self.params.body_inertia(mass)
        self.body_inertia[robot] = (m_tot, moment)
        ch = self.chassis[robot]
        ch.moment = float(moment)
        ch.mass = float(m_tot)
        self.wheel_params[robot, :, WP.LOAD] = self.params.static_normal_loads(m_tot)

    def normal_loads(self) -> np.ndarray:
        """(N, n) normal loads N_k now [N]: the static share of each robot's current mass plus,
        with ``com_height`` > 0, the load transfer of the last substep's acceleration."""
        loads = self.wheel_params[..., WP.LOAD].copy()
        h = self.params.chassis.com_height
        if h > 0:
            m = self.body_inertia[:, BODY.MASS, None]
            a = self.chassis_accel
            lt = self._load_transfer
            loads -= h * m * (lt[None, :, 0] * a[:, 0:1] + lt[None, :, 1] * a[:, 1:2])
            np.maximum(loads, 0.0, out=loads)
        return loads

    def reset_robot(self, robot: int, pose=(0.0, 0.0, 0.0), beta=None, twist=(0.0, 0.0, 0.0)) -> None:
        """Place robot ``robot`` at pose (x, y, θ) [m, m, rad] in the world, wheels at steering
        angles ``beta`` (n,) [rad] (default 0, clipped into the steering range; unlimited steering:
        taken modulo 2π into ]−π, π]), moving with the
        chassis twist (ẋ, ẏ, θ̇) given in the chassis frame, wheels rolling without slip and motors
        at rest on their set-points."""
        robot = self._robot_index(robot)
        g = self.params.geometry
        pose = np.asarray(pose, dtype=np.float64)
        twist = np.asarray(twist, dtype=np.float64)
        beta = np.zeros(self.n) if beta is None else np.asarray(beta, dtype=np.float64)
        if pose.shape != (3,) or twist.shape != (3,) or beta.shape != (self.n,):
            raise ValueError("reset_robot needs pose (3,), twist (3,) and beta (n,)")
        if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(twist)) and np.all(np.isfinite(beta))):
            raise ValueError("reset_robot: non-finite pose, twist or beta")
        beta = (np.pi - np.mod(np.pi - beta, 2 * np.pi) if g.unlimited_steering
                else np.clip(beta, g.steer_min + 1e-9, g.steer_max))
        x, y, th = pose
        c, s = math.cos(th), math.sin(th)
        v_world = np.array([c * twist[0] - s * twist[1], s * twist[0] + c * twist[1]])
        w = float(twist[2])
        ch = self.chassis[robot]
        ch.angle = float(th)  # the angle first: the position setter uses the (maybe non-finite) transform
        ch.position = (float(x), float(y))
        ch.velocity = tuple(v_world)
        ch.angular_velocity = w
        ch.force = (0.0, 0.0)
        ch.torque = 0.0
        self.joint_state[robot, :, JS.BETA] = beta
        self.joint_state[robot, :, JS.OMEGA] = w
        self.tire_state[robot] = 0.0  # unloaded patches: a rolling start builds its slip by distance
        self.chassis_accel[robot] = 0.0
        # wheel spins that roll without slip: r φ̇ = v(P)·d (the true wheels: imperfections included)
        wp = self.wheel_params[robot]
        gam = th + wp[:, WP.ALPHA] + beta
        px = x + c * g.axis_xy[:, 0] - s * g.axis_xy[:, 1] + wp[:, WP.B] * np.cos(gam)
        py = y + s * g.axis_xy[:, 0] + c * g.axis_xy[:, 1] + wp[:, WP.B] * np.sin(gam)
        vpx = v_world[0] - w * (py - y)
        vpy = v_world[1] + w * (px - x)
        phidot = (vpx * np.sin(gam) - vpy * np.cos(gam)) / wp[:, WP.R]
        ms = self.motor_state[robot]
        ms[:, MS.THETA] = beta
        ms[:, MS.OMEGA] = 0.0
        ms[:, MS.PHIDOT_REF] = phidot
        ms[:, MS.PHIDOT] = phidot
        ms[:, MS.PHI] = 0.0
        self.commands[robot, :, CMD.BETA] = beta
        self.commands[robot, :, CMD.PHIDOT] = phidot
        self.enabled[robot] = True
        self._energy_check.clear(robot)
        self.acc[robot] = 0.0
        self._read_robot_state(robot)

    def overlapping_obstacles(self, robot: int = 0) -> list[int]:
        """Indices of the obstacles that overlap robot ``robot``'s chassis now."""
        return overlapping_shapes(self.space, self.chassis[robot], self._obstacle_shapes) if self.obstacles else []

    def set_commands(self, beta_cmd, phidot_cmd) -> None:
        """Set-points for all robots: β_cmd (N, n) [rad], φ̇_cmd (N, n) [rad/s] (clipped to limits)."""
        lim = self.params.limits
        beta_cmd = np.asarray(beta_cmd, dtype=np.float64).reshape(self.n_robots, self.n)
        phidot_cmd = np.asarray(phidot_cmd, dtype=np.float64).reshape(self.n_robots, self.n)
        if not (np.all(np.isfinite(beta_cmd)) and np.all(np.isfinite(phidot_cmd))):
            raise ValueError("set_commands: set-points contain NaN or inf")
        self.commands[..., CMD.BETA] = np.clip(beta_cmd, lim.steer_min, lim.steer_max)
        self.commands[..., CMD.PHIDOT] = np.clip(phidot_cmd, -lim.wheel_speed_max, lim.wheel_speed_max)

    def set_setpoints(self, setpoints: np.ndarray, rows: np.ndarray | None = None) -> None:
        """Copy checked set-points (N, n, len(CMD)) into the motors' set-points, for every robot or
        for those where ``rows`` (N,) is True (the others keep theirs). No clipping and no checks:
        the fast path for a caller that has produced them finite and within the limits (the
        task's compiled action map); :meth:`set_commands` checks and clips."""
        if rows is None:
            np.copyto(self.commands, setpoints)
        else:
            np.copyto(self.commands, setpoints, where=rows[:, None, None])

    def set_motors_enabled(self, enabled) -> None:
        """Motors on (True) or off (False) per robot: off means zero propulsion torque and the
        steering motors braked at their current angle."""
        self.enabled[:] = np.broadcast_to(np.asarray(enabled, dtype=np.bool_), (self.n_robots,))

    def kick(self, robot: int, wheels: Sequence[int], impulse: float) -> None:
        """An angular impulse [N·m·s] on the modules ``wheels`` of robot ``robot``, about their
        steering axes (like a collision knocking the wheels to other angles)."""
        robot = self._robot_index(robot)
        if not math.isfinite(impulse):
            raise ValueError(f"kick impulse must be finite, got {impulse!r}")
        if any(not 0 <= int(k) < self.n for k in wheels):
            raise ValueError(f"kick: a wheel index of {list(wheels)} is out of range 0..{self.n - 1}")
        wp = self.wheel_params[robot]
        if not np.any(wp[:, WP.COM]):
            for k in wheels:
                self.joint_state[robot, int(k), JS.OMEGA] += impulse / wp[int(k), WP.I_MOD]
        else:  # a module off its axis: the impulse moves the body and the other modules too, Δq̇ = M⁻¹ J
            z = np.zeros(self.n)
            for k in wheels:
                z[int(k)] += impulse
            dq = module_impulse_response(self.body_inertia[robot], self._state[robot, CS.TH], self._axis_xy, wp,
                                         self.joint_state[robot, :, JS.BETA], z)
            body = self.chassis[robot]
            v = body.velocity
            body.velocity = (v.x + dq[0], v.y + dq[1])
            body.angular_velocity = body.angular_velocity + dq[2]
            self.joint_state[robot, :, JS.OMEGA] += dq[3:]
        self._read_robot_state(robot)

    def step(self, times: dict[str, float] | None = None) -> None:
        """Advance all robots by one control period (``substeps`` substeps). Timing hook: with ``times`` given
        (else :attr:`stage_times`, when set), each stage's seconds are added under ``read``, ``force`` (the
        compiled kernel), ``write``, ``space_step``, ``summary`` (bench-env's split)."""
        self.acc[:] = 0.0
        p = self.params
        args = (self.joint_state, self.motor_state, self.tire_state, self.commands, self.wheel_params, self.enabled,
                self.acc, self.body_inertia, self.chassis_accel, self._axis_xy, self._load_transfer,
                float(p.chassis.com_height), float(p.steering.stop_restitution), bool(p.steer_motor.is_dc),
                bool(p.wheel.is_dc), self.n, self.dt)
        tm = times if times is not None else self.stage_times
        t = time.perf_counter() if tm is not None else 0.0
        self._io.read()
        self._energy_check.before(self)
        if tm is not None:
            t = lap(tm, "read", t)
        if not self.obstacles:  # the whole control period in one compiled call
            if self._serial:  # one robot or one thread: the kernel itself, no dispatch
                step_kernel(self._state, *args, self.substeps, True, 0, self.n_robots)
            else:
                STEP_BLOCKS.run(self.num_threads, self.n_robots, self._state, *args, self.substeps, True)
            if tm is not None:
                t = lap(tm, "force", t)
            self._io.write()
            if tm is not None:
                t = lap(tm, "write", t)
        else:  # pymunk integrates the bodies (forces from the kernel's velocity change) and resolves contacts
            t = step_with_contacts(self.space, self._io, self._before, self.body_inertia, self.substeps, self.dt,
                                   partial(STEP_BLOCKS.run, self.num_threads, self.n_robots), args, tm, t)
        self._summarize()
        self._energy_check.after(self)
        if tm is not None:
            lap(tm, "summary", t)

    # ------------------------------------------------------------------ state

    def chassis_pose(self) -> np.ndarray:
        """(N, 3) chassis pose (x, y, θ) in the world [m, m, rad]."""
        return self.summary[:, RS_POSE].copy()

    def chassis_twist(self) -> np.ndarray:
        """(N, 3) chassis twist ξ̇ = (ẋ, ẏ, θ̇) in the chassis frame R [m/s, m/s, rad/s]."""
        return self.summary[:, RS_TWIST_BODY]

    def steering_angles(self) -> np.ndarray:
        """(N, n) true steering angles β (wheel side of the spring) [rad]."""
        return self.wheel_summary[..., WS.BETA].copy()

    def steering_rates(self) -> np.ndarray:
        """(N, n) true steering rates β̇ [rad/s]."""
        return self.wheel_summary[..., WS.BETA_DOT].copy()

    def motor_angles(self) -> np.ndarray:
        """(N, n) steering motor angles θ_m [rad]."""
        return self.motor_state[..., MS.THETA].copy()

    def wheel_speeds(self) -> np.ndarray:
        """(N, n) true wheel spin rates φ̇ [rad/s]."""
        return self.motor_state[..., MS.PHIDOT].copy()

    def axis_points(self) -> np.ndarray:
        """(N, n, 2) steering axes A_k in the world [m]."""
        x, y, th = (self.summary[:, col, None] for col in (RS.X, RS.Y, RS.TH))
        c, s = np.cos(th), np.sin(th)
        a = self._axis_xy
        return np.stack([x + c * a[:, 0] - s * a[:, 1], y + s * a[:, 0] + c * a[:, 1]], axis=-1)

    def contact_points(self) -> np.ndarray:
        """(N, n, 2) contact points P_k = A_k + b_k (cos γ, sin γ) in the world [m]."""
        gam = self.summary[:, RS.TH, None] + self.wheel_params[..., WP.ALPHA] + self.joint_state[..., JS.BETA]
        b = self.wheel_params[..., WP.B]
        return self.axis_points() + b[..., None] * np.stack([np.cos(gam), np.sin(gam)], axis=-1)

    def tire_forces_body(self) -> np.ndarray:
        """(N, n, 2) tire forces in the chassis frame, averaged over the last step [N]."""
        return self.wheel_summary[..., WS_FORCE].copy()

    def slip_power(self) -> np.ndarray:
        """(N,) power dissipated by tire slip Σ_k |F_k · v_slip,k|, averaged over the last step [W]."""
        return self.summary[:, RS.SLIP].copy()

    def nullspace_force(self) -> np.ndarray:
        """(N,) ‖F − Gᵀ(G Gᵀ)⁻¹ G F‖, step mean [N]: the minimum-norm null-space part of the tire forces F
        (2n, chassis frame; G F the net wrench). It has an acceleration floor: wheels rolling at different
        speeds or loads share a wrench unequally even on one ICR (:meth:`antagonism` takes it out)."""
        return self.summary[:, RS.NULLSPACE].copy()

    def antagonism(self) -> np.ndarray:
        """(N,) ‖F − D J (Jᵀ D J)⁻¹ Jᵀ F‖, step mean [N]: the tire forces minus the distribution of their
        net wrench that a common rigid slip would give, D the slip dampings of :meth:`slip_dampings`
        (:mod:`azimut_env.physics.antagonism`; 0 for any rigid slip field)."""
        return self.summary[:, RS.ANTAGONISM].copy()

    def slip_dampings(self) -> np.ndarray:
        """(N, n, 2) (d_long, d_lat) [N·s/m] of the last step: c N/(|v_x| + σ/τ) of each wheel's step-mean load
        and speed, in series with the drive loop along d (:func:`~azimut_env.physics.antagonism.slip_damping`)."""
        inv, wp = 1.0 / self.substeps, self.wheel_params
        gain = np.where(self.enabled[:, None], wp[..., WP.KV], wp[..., WP.BEARING])
        return slip_damping(self.acc[..., ACC.LOAD] * inv, self.acc[..., ACC.ROLL] * inv, wp[..., WP.C_KAPPA],
                            wp[..., WP.C_ALPHA], wp[..., WP.SIGMA_LONG], wp[..., WP.SIGMA_LAT], wp[..., WP.R], gain,
                            SLIP_MEMORY_TIME)

    def energy(self) -> np.ndarray:
        """(N,) kinetic plus elastic energy [J] (:func:`~azimut_env.physics.modules.mechanical_energy`)."""
        return mechanical_energy(self._state, self.body_inertia, self.joint_state, self.motor_state, self.tire_state,
                                 self.wheel_params, self._axis_xy, self.normal_loads())

    def check(self) -> tuple[np.ndarray, list[str]]:
        """Blow-up detection: (ok (N,) bool, reason per robot, '' where ok)."""
        codes = self.summary[:, RS.CODE]
        ok = codes == BlowUp.NONE.value  # a plain int: an array against the IntEnum member is slow
        if ok.all():
            return ok, [""] * self.n_robots
        return ok, [BLOWUP_MESSAGES.get(int(c), "") if c else "" for c in codes]

