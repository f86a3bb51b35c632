"""control: controllers for AZIMUT-3-like robots, one interface for all of them, and the episode loop.

The maths comes from ``estimation``; the robot from ``azimut_env`` (through its controller
interface, :mod:`azimut_env.interface`).

* ``controller``: :class:`Controller`, the protocol every controller implements (``name``,
  ``reset(env, rows)``, ``act(env, obs) -> WheelCommand`` for the N robots of an env), and the
  registry by name (:func:`register_controller`, :func:`make_controller`) that ``azimut eval
  --controllers`` reads;
* ``rollout``: the one episode loop (:func:`control.rollout.run_episodes`, N episodes as one
  batch; :func:`control.rollout.run_episode`, one); ``episode``: its per-step log and metrics;
* ``commands``: :class:`WheelCommand`, the set-points every controller returns;
* ``path_controllers``: the controllers of ``azimut eval``, ``icr`` (path follower + ICR
  controller), ``twist`` (path follower + WPILib-style baseline) and ``twist-setpoint`` (path
  follower + setpoint generator); ``feedforward``: the
  kinematic feed-forward of ``azimut sim-paper``;
* ``icr/``: the ICR-based reference controller (``controller``: entry points; ``batch``: N
  robots as one stateful object; ``config``, ``state``, ``feasibility``, ``motion``, ``modes``;
  derivations in ``docs/icr-controller.md``);
* ``twist/wpilib.py``: the WPILib-style twist baseline; ``twist/setpoint.py``: the setpoint
  generator (``twist-setpoint``); ``follow/``: the path follower (Python
  and compiled);
* ``action_spaces/``: the RL action spaces (``controller``: the action-driven controller shared by
  the single and vector wrappers and a trained policy's controller; ``single``, ``vector``,
  ``shaping``);
* ``limits``, ``checks``: commanded-limit checks and input checks.
"""

import estimation.numba_cache  # noqa: F401, I001 (first: numba's cache keyed by the sources, before any kernel)
from control.commands import WheelCommand
from control.controller import Controller, ControllerSpecError, make_controller, register_controller
from control.follow.path_follower import PathFollower, PathFollowerConfig
from control.icr.controller import ICRController, ICRControllerConfig, Mode
from control.twist.wpilib import SwerveConfig, SwerveController

__all__ = ["Controller", "ControllerSpecError", "ICRController", "ICRControllerConfig", "Mode", "PathFollower",
           "PathFollowerConfig", "SwerveConfig", "SwerveController", "WheelCommand", "make_controller",
           "register_controller"]
