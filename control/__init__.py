"""control: controllers for AZIMUT-3-like robots, and ``azimut eval``.

Modules (the maths comes from ``estimation``; the robot from ``azimut_env``):

* ``icr_controller``: the ICR-based reference controller (coordinated, time-scaled H-state
  motion with a RUNNING -> STOPPING -> RECONFIGURING state machine; derivations in
  ``docs/icr-controller.md``), built from ``icr_config`` (modes, tuning), ``icr_state`` (the
  batched state; one robot is a batch of one), ``feasibility`` (speed bounds, steering axes,
  arcs, stops), ``motion`` (coordinated and in-place steps), ``icr_modes`` (mode transitions
  and each mode's commands);
* ``commands``: the set-points type shared by every controller;
* ``swerve``: the WPILib-style twist baseline;
* ``path_follower``: Track + pose -> twist / (λ_d, μ_d) targets, shared by both;
* ``limits``: the commanded-limit checks (limits are ``azimut_env.params.ActuatorLimits``);
* ``wrappers``: ICR-target and twist action spaces for RL;
* ``episode``: one episode of a controller on a track (:func:`run_episode`) and its metrics;
* ``evaluate`` (``azimut eval``), ``robustness`` (kick study), ``record_d2`` (``azimut record-d2``),
  ``phenomenon`` (``azimut sim-paper``: qua while moving, motor lag vs compliance);
* ``kinematic_model``: a rigid kinematic test bench.
"""

from control.follow.path_follower import PathFollower, PathFollowerConfig
from control.icr.controller import ICRController, ICRControllerConfig, Mode
from control.twist.wpilib import SwerveConfig, SwerveController

__all__ = ["ICRController", "ICRControllerConfig", "Mode", "PathFollower", "PathFollowerConfig", "SwerveConfig",
           "SwerveController"]
