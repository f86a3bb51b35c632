"""Episodes out: simulate -> export (MCAP, SQLite3) -> estimate reproduces the simulator's own
estimates bit for bit; every topic holds what the episode log holds."""

from __future__ import annotations

import numpy as np
import pytest

from azimut_env.env import AzimutEnv
from control.episode import EpisodeLog
from control.export import episode_stamps, export_episode, robot_description
from estimation.logs import estimate_log, open_log

pytest.importorskip("rosbags")


def _episode(robot: str = "azimut3", steps: int = 120) -> tuple[EpisodeLog, AzimutEnv]:
    """An episode driven by open-loop wheel commands (turning while crabbing), logged as the
    episode loop logs it: λ̂, μ̂ read before each step, the measurements and the pose after it."""
    env = AzimutEnv("circle", robot=robot)
    _, info = env.reset(seed=3)
    geom = env.geometry
    rec = {k: [] for k in ("lam_hat", "mu_hat", "beta_meas", "phidot_meas", "pose")}
    for k in range(steps):
        lam, mu = env.estimated_eta
        rec["lam_hat"].append(lam)
        rec["mu_hat"].append(mu)
        beta_cmd = np.full(geom.n, 0.3 * np.sin(0.05 * k))
        _, _, terminated, truncated, info = env.step(env.action_from_setpoints(beta_cmd, np.full(geom.n, 6.0)))
        rec["beta_meas"].append(env.measured_beta)
        rec["phidot_meas"].append(env.measured_phidot)
        rec["pose"].append(info["pose"])
        assert not (terminated or truncated)
    log = EpisodeLog("open-loop", env.track, env.control_period)
    for key, values in rec.items():
        setattr(log, key, np.asarray(values))
    log.t = env.control_period * np.arange(1, steps + 1)
    return log, env


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_simulate_export_estimate_reproduces_the_simulators_estimates_bit_for_bit(tmp_path, storage):
    log, env = _episode()
    path = export_episode(log, tmp_path / "episode", robot="azimut3", storage=storage)
    geom, modules = robot_description("azimut3")
    assert geom == env.geometry
    r = estimate_log(open_log(path, geom, modules, truth_topic="/ground_truth/pose"))
    stamps = episode_stamps(log)
    assert np.array_equal(r.t_ns, stamps[1:]) and r.skipped == {}
    # the estimate of the measurement after step k is what the controller read before step k + 1
    assert np.array_equal(r.lam["IT"][:-1], log.lam_hat[1:])
    assert np.array_equal(r.mu["IT"][:-1], log.mu_hat[1:])
    np.testing.assert_allclose(r.truth.pose, log.pose, atol=1e-12)


def test_every_topic_holds_the_log(tmp_path):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    log, env = _episode(steps=40)
    path = export_episode(log, tmp_path / "episode")
    stamps = episode_stamps(log)
    got: dict[str, list] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        times = [t for _, t, _ in reader.messages()]
        assert times == sorted(times)  # merged in time order
        for conn, t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            stamp = msg.transforms[0].header.stamp if conn.topic == "/tf" else msg.header.stamp
            assert stamp.sec * 10**9 + stamp.nanosec == t
            got.setdefault(conn.topic, []).append((t, msg))
    js = got["/joint_states"]
    assert [t for t, _ in js] == stamps[1:].tolist()
    assert list(js[0][1].name) == [f"{m}_steer" for m in ("front_left", "rear_left", "rear_right", "front_right")] + \
        [f"{m}_drive" for m in ("front_left", "rear_left", "rear_right", "front_right")]
    assert np.array_equal(np.array([m.position[:4] for _, m in js]), log.beta_meas)
    assert np.array_equal(np.array([m.velocity[4:] for _, m in js]), log.phidot_meas)
    icr = got["/azimut/icr_estimate"]
    assert [t for t, _ in icr] == stamps[:-1].tolist()
    assert np.array_equal(np.array([[m.vector.x, m.vector.y, m.vector.z] for _, m in icr]), log.lam_hat)
    tw = np.array([[m.twist.linear.x, m.twist.linear.y, m.twist.angular.z] for _, m in got["/azimut/twist_estimate"]])
    np.testing.assert_allclose(tw, log.mu_hat[:, None] * np.column_stack([log.lam_hat[:, 1], -log.lam_hat[:, 0],
                                                                          log.lam_hat[:, 2]]), atol=1e-15)
    gt = np.array([[m.pose.position.x, m.pose.position.y] for _, m in got["/ground_truth/pose"]])
    assert np.array_equal(gt, log.pose[:, :2])
    assert len(got["/tf"]) == len(got["/odom"]) == 40
    odo = got["/odom"][0][1].pose.pose.position
    assert (odo.x, odo.y) == tuple(log.pose[0, :2])  # dead reckoning starts at the true pose


def test_export_refusals(tmp_path):
    log, _ = _episode(steps=5)
    export_episode(log, tmp_path / "a")
    with pytest.raises(ValueError, match="exists already"):
        export_episode(log, tmp_path / "a")
    with pytest.raises(ValueError, match="storage"):
        export_episode(log, tmp_path / "b", storage="bag")
    with pytest.raises(ValueError, match="6 modules|4 modules"):
        export_episode(log, tmp_path / "c", robot="hex")
    empty = EpisodeLog("x", log.track, log.dt)
    with pytest.raises(ValueError, match="phidot_meas|no logged step"):
        export_episode(empty, tmp_path / "d")
