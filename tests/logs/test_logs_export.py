"""Episodes out: simulate -> export (MCAP, SQLite3) -> estimate reproduces the simulator's own
estimates bit for bit; every topic holds what the episode log holds."""

from __future__ import annotations

import numpy as np
import pytest

from azimut_env.params import RobotParams
from control.episode import EpisodeLog
from control.export import episode_stamps, export_episode, robot_description
from control.rollout import run_episode
from estimation.logs import estimate_log, open_log

pytest.importorskip("rosbags")


def _episode(controller: str = "icr", steps_s: float = 4.0) -> tuple[EpisodeLog, None]:
    """An episode of the episode loop (``control.rollout.run_episode``) on ``circle``."""
    log = run_episode(controller, "circle", seed=3, max_time=steps_s)
    assert log.error is None and log.beta_meas.shape[0] == round(steps_s / log.dt)
    return log, None


@pytest.mark.parametrize("controller, storage", [("icr", "mcap"), ("twist", "sqlite3")])
def test_simulate_export_estimate_reproduces_the_simulators_estimates_bit_for_bit(tmp_path, controller, storage):
    log, _ = _episode(controller)
    path = export_episode(log, tmp_path / "episode", robot="azimut3", storage=storage)
    geom, modules = robot_description("azimut3")
    assert geom == RobotParams().geometry
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

    log, _ = _episode(steps_s=0.8)
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
    log, _ = _episode(steps_s=0.1)
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


def test_eval_export_then_estimate(tmp_path, capsys):
    from jobs.cli import main

    out = tmp_path / "eval"
    assert main(["eval", "--tracks", "circle", "--controllers", "twist", "--max-time", "1", "--no-plots",
                 "--export", "mcap", "--out", str(out)]) == 0
    bag = out / "exports" / "twist-circle-s0"
    assert any(bag.glob("*.mcap")) and "exports/twist-circle-s0" in (out / "report.md").read_text()
    capsys.readouterr()
    assert main(["estimate", str(bag), "--truth-topic", "/ground_truth/pose", "--no-plots", "--out",
                 str(tmp_path / "est")]) == 0
    assert "estimated 50 samples of 50 (0 skipped)" in capsys.readouterr().out
    # the command line's round trip reproduces the simulator's own estimates bit for bit: the same
    # episode (deterministic; azimut eval's batch equals the episode run alone) read what estimate wrote
    log = run_episode("twist", "circle", seed=0, max_time=1.0)
    with np.load(tmp_path / "est" / "samples.npz") as z:
        assert np.array_equal(z["lam_IT"][:-1], log.lam_hat[1:]) and np.array_equal(z["mu_IT"][:-1], log.mu_hat[1:])


def test_estimate_refuses_a_bag_of_another_robot(tmp_path, capsys):
    """An export records its robot (metadata.yaml's custom_data); azimut estimate with another
    robot's geometry is refused in one line naming the right flag (it read a swerve bag with
    azimut3's geometry: 76% odometry drift, exit 0), and runs with it."""
    from jobs.cli import main

    out = tmp_path / "eval"
    assert main(["eval", "--robot", "swerve", "--tracks", "circle", "--controllers", "icr", "--max-time", "0.5",
                 "--no-plots", "--export", "mcap", "--out", str(out)]) == 0
    bag = out / "exports" / "icr-circle-s0"
    capsys.readouterr()
    argv = ["estimate", str(bag), "--truth-topic", "/ground_truth/pose", "--no-plots", "--out", str(tmp_path / "est")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exported from the robot swerve" in err[0] and "--robot swerve" in err[0]
    assert not (tmp_path / "est").exists()
    assert main([*argv, "--robot", "swerve"]) == 0
