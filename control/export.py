"""Episodes out: an :class:`~control.episode.EpisodeLog` as a ROS 2 bag (MCAP by default), which
Foxglove opens and ``azimut estimate`` reads back (``docs/logs.md``; needs ``rosbags``, the
``logs`` extra).

Topics (every message's header stamp is its log time; t = 0 is the episode's reset):

* ``/joint_states`` (``sensor_msgs/msg/JointState``), after each control step: joint
  ``<module>_steer`` has the measured steering angle β [rad] (the paper's convention) as its
  position, joint ``<module>_drive`` the measured wheel spin rate φ̇ [rad/s] as its velocity (the
  other fields are NaN: the log holds no wheel angle and no measured steering rate);
* ``/azimut/icr_estimate`` (``geometry_msgs/msg/Vector3Stamped``, λ̂ = (u, v, w)) and
  ``/azimut/twist_estimate`` (``geometry_msgs/msg/TwistStamped``, μ̂ (v, −u, w)): the simulator's
  own IT estimate, stamped with the time of the measurement it was made from (the reset's at t = 0);
* ``/ground_truth/pose`` (``geometry_msgs/msg/PoseStamped``) and ``/tf`` (world -> base_link):
  the true pose after each step;
* ``/odom`` (``nav_msgs/msg/Odometry``): dead reckoning from the exported measurements
  (:func:`estimation.logs.estimate_log`, IT), started at the true pose of the first step.

``<module>`` are the module names of the robot's description file, so that ``azimut estimate
EPISODE --robot NAME`` (or ``--robot-file``) reads the bag back; it then reproduces the
simulator's estimates bit for bit.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from control.episode import EpisodeLog
from estimation.geometry import RobotGeometry
from estimation.hrep import twist_from_eta
from estimation.logs import ArrayLog, GroundTruth, estimate_log
from estimation.logs.ros import GEOMETRY_KEY, ROBOT_KEY, BagWriter

__all__ = ["EXPORT_FORMATS", "export_episode", "robot_description", "episode_stamps"]

#: what ``export_episode`` writes: a ROS 2 bag with MCAP storage (Foxglove), or SQLite3
EXPORT_FORMATS = ("mcap", "sqlite3")


def robot_description(robot: str = "azimut3") -> tuple[RobotGeometry, tuple[str, ...]]:
    """The geometry and module names of a preset's name or a robot file's path (``.toml``)."""
    from azimut_env.params import RobotParams
    from azimut_env.robot_file import read_robot

    description = read_robot(robot, RobotParams)
    return description.geometry, description.module_names


def episode_stamps(log: EpisodeLog) -> np.ndarray:
    """(T + 1,) int64 [ns]: the reset (0) and the end of each of the T logged steps."""
    return np.rint(log.dt * np.arange(log.pose.shape[0] + 1) * 1e9).astype(np.int64)


def _required(log: EpisodeLog) -> None:
    T = log.pose.shape[0]
    for key, shape in (("beta_meas", 2), ("phidot_meas", 2), ("lam_hat", 2), ("mu_hat", 1)):
        value = getattr(log, key, None)
        if value is None or np.ndim(value) != shape or len(value) != T:
            raise ValueError(f"EpisodeLog.{key} must hold one row per logged step ({T}) to export the episode")


def geometry_record(geom: RobotGeometry) -> dict:
    """The geometry an export records (``azimut.geometry``) and ``azimut estimate`` compares."""
    return {"n": int(geom.n), "alpha": np.asarray(geom.alpha, float).tolist(), "l": np.asarray(geom.l, float).tolist(),
            "b": np.broadcast_to(np.asarray(geom.b, float), (geom.n,)).tolist()}


def export_episode(log: EpisodeLog, path, robot: str = "azimut3", storage: str = "mcap") -> Path:
    """Write ``log`` as a ROS 2 bag directory ``path`` (see the module docstring); ``robot``: the
    episode's robot, a preset's name or a robot file's path (its module names name the joints).
    Returns ``path``. Refuses an existing ``path`` and a log without steps."""
    if storage not in EXPORT_FORMATS:
        raise ValueError(f"storage must be one of {EXPORT_FORMATS}, got {storage!r}")
    _required(log)
    T = log.pose.shape[0]
    if T == 0:
        raise ValueError("the episode has no logged step to export")
    geom, modules = robot_description(robot)
    if log.beta_meas.shape[1] != geom.n:
        raise ValueError(f"the episode's robot has {log.beta_meas.shape[1]} modules, robot {robot!r} {geom.n}")
    stamps = episode_stamps(log)
    t_meas, t_est = stamps[1:], stamps[:-1]
    nan = np.full((T, geom.n), np.nan)
    odo = estimate_log(ArrayLog(t_meas, log.beta_meas, log.phidot_meas, geom, modules,
                                truth=GroundTruth(t_meas, np.asarray(log.pose, dtype=np.float64), "true pose")),
                       methods=("IT",))
    w = BagWriter(path, storage=storage)
    w.set_custom_data(ROBOT_KEY, str(robot))  # azimut estimate checks its --robot against these
    w.set_custom_data(GEOMETRY_KEY, json.dumps(geometry_record(geom)))
    w.add_joint_states("/joint_states", t_meas, [f"{m}_steer" for m in modules] + [f"{m}_drive" for m in modules],
                       np.hstack([log.beta_meas, nan]), np.hstack([nan, log.phidot_meas]), frame="base_link")
    w.add_vector3_stamped("/azimut/icr_estimate", t_est, log.lam_hat)
    w.add_twist_stamped("/azimut/twist_estimate", t_est, twist_from_eta(log.lam_hat, log.mu_hat))
    w.add_pose_stamped("/ground_truth/pose", t_meas, log.pose)
    w.add_transforms("/tf", t_meas, log.pose)
    w.add_odometry("/odom", odo.t_ns, odo.pose, odo.odom_twist, frame="world")
    w.close()
    return Path(path)
