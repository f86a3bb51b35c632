"""ROS 2 bags whose steering and drive joints come in separate JointState messages (one topic or
two, each group at its own rate and offset) merged onto one clock by sample-and-hold; a gyro heading
from an Imu or a pose topic; and the refusals."""

from __future__ import annotations

import numpy as np
import pytest
from logs_data import MODULES4, motion

from estimation.logs import LogError, estimate_log, open_log
from estimation.logs.hold import DEFAULT_MAX_AGE_S

pytest.importorskip("rosbags")

from estimation.logs.ros import BagWriter  # noqa: E402

T0 = 10**18
STEER = [f"{x}_steer" for x in MODULES4]
DRIVE = [f"{x}_drive" for x in MODULES4]
MS = 1_000_000


def _truth(geom, n=2000):
    """A known motion sampled every millisecond (the truth each group samples at its own times)."""
    return motion(geom, n, dt=0.001)


def _groups_bag(path, m, *, steer_every=10, drive_every=20, drive_offset=3, gap=None, topics=("/joint_states",) * 2,
                extra=None):
    """Steering joints (positions; velocities empty) every ``steer_every`` ms from 0, drive joints
    (wheel angles, speeds) every ``drive_every`` ms from ``drive_offset``, without the drive messages
    in ``gap`` (ms, ms); returns the message indices of each group."""
    n = m.t_ns.size
    si = np.arange(0, n, steer_every)
    di = np.arange(drive_offset, n, drive_every)
    if gap is not None:
        di = di[(di < gap[0]) | (di >= gap[1])]
    w = BagWriter(path)
    w.add_joint_states(topics[0], T0 + m.t_ns[si], STEER, m.beta[si], np.zeros((si.size, 0)))
    w.add_joint_states(topics[1], T0 + m.t_ns[di], DRIVE[::-1], np.cumsum(m.phidot, 0)[di][:, ::-1] * 1e-3,
                       m.phidot[di][:, ::-1])  # another joint order: found by name
    if extra is not None:
        extra(w)
    w.close()
    return si, di


def _expected(m, si, di, lookahead_ms, max_age_ms):
    """Per steering tick: the latest drive sample at or before it (plus the look-ahead) and whether
    the tick is stale, by a plain loop."""
    phidot, stale = np.full((si.size, 4), np.nan), np.zeros(si.size, bool)
    for k, i in enumerate(si):
        before = di[di <= i + lookahead_ms]
        if before.size == 0 or i - before[-1] > max_age_ms:
            stale[k] = True
        if before.size:
            phidot[k] = m.phidot[before[-1]]
    return phidot, stale


@pytest.mark.parametrize("topics", [("/joint_states",) * 2, ("/steer/joint_states", "/drive/joint_states")])
def test_groups_merged_onto_the_steering_clock(tmp_path, geom, topics):
    m = _truth(geom)
    si, di = _groups_bag(tmp_path / "bag", m, topics=topics)
    src = open_log(tmp_path / "bag", geom, MODULES4, fmt="ros", topic=list(dict.fromkeys(topics)))
    assert src.merged and src.clock_joint == STEER[0] and src.n_samples == si.size
    r = estimate_log(src, chunk_size=37)
    phidot, stale = _expected(m, si, di, lookahead_ms=5, max_age_ms=DEFAULT_MAX_AGE_S * 1000)
    assert not stale.any() and r.n_read == si.size and r.skipped == {}
    assert np.array_equal(r.t_ns, T0 + m.t_ns[si])
    assert np.array_equal(r.beta, m.beta[si])  # the steering clock: its own values
    assert np.array_equal(r.phidot, phidot)  # the latest drive sample, held
    d = r.source
    assert d["merged"] and d["clock_joint"] == STEER[0] and d["max_age_s"] == DEFAULT_MAX_AGE_S
    assert d["stale_ticks"] == 0
    assert d["topic"] == (topics[0] if topics[0] == topics[1] else list(topics))


def test_a_drive_group_faster_than_the_steering_makes_the_clock(tmp_path, geom):
    m = _truth(geom, 1000)
    si, di = _groups_bag(tmp_path / "bag", m, steer_every=20, drive_every=8, drive_offset=1)
    r = estimate_log(open_log(tmp_path / "bag", geom, MODULES4, fmt="ros"))
    assert r.source["clock_joint"] == DRIVE[0]
    assert np.array_equal(r.t_ns, T0 + m.t_ns[di]) and np.array_equal(r.phidot, m.phidot[di])
    # steering held: its latest sample at or before the tick + 4 ms (half the drive's 8 ms period)
    want = np.array([m.beta[si[si <= i + 4][-1]] for i in di])
    assert np.array_equal(r.beta, want)


def test_ticks_older_than_max_age_are_stale_and_counted(tmp_path, geom):
    m = _truth(geom)
    si, di = _groups_bag(tmp_path / "bag", m, gap=(500, 1100))  # 600 ms without a drive message
    for max_age in (0.2, DEFAULT_MAX_AGE_S):
        src = open_log(tmp_path / "bag", geom, MODULES4, fmt="ros", max_age_s=max_age)
        r = estimate_log(src, chunk_size=64)
        phidot, stale = _expected(m, si, di, lookahead_ms=5, max_age_ms=max_age * 1000)
        assert 0 < stale.sum() < si.size
        assert r.skipped == {"a module's steering angle or wheel speed is older than the maximum age (a signal logged "
                             "on change that stopped, or a gap)": int(stale.sum())}
        assert r.source["stale_ticks"] == stale.sum() and src.stale_ticks == stale.sum()
        assert np.array_equal(r.t_ns, T0 + m.t_ns[si[~stale]]) and np.array_equal(r.phidot, phidot[~stale])
    assert estimate_log(open_log(tmp_path / "bag", geom, MODULES4, fmt="ros", max_age_s=np.inf)).skipped == {}


def test_complete_messages_keep_the_per_message_path(tmp_path, geom):
    m = motion(geom, 300)
    w = BagWriter(tmp_path / "bag")
    t = T0 + m.t_ns
    w.add_joint_states("/joint_states", t, STEER + DRIVE, np.hstack([m.beta, np.zeros((300, 4))]),
                       np.hstack([np.zeros((300, 4)), m.phidot]))
    w.add_joint_states("/other", t[::3] + 7, ["arm"], np.zeros((100, 1)), np.zeros((100, 1)))
    w.close()
    src = open_log(tmp_path / "bag", geom, MODULES4, fmt="ros")
    assert not src.merged and src.n_samples == 300
    r = estimate_log(src, chunk_size=50)
    assert np.array_equal(r.t_ns, t) and np.array_equal(r.beta, m.beta) and np.array_equal(r.phidot, m.phidot)
    assert not r.source["merged"] and r.source["clock_joint"] is None and r.source["stale_ticks"] == 0
    # the same messages merged (two topics given): every joint sampled at every tick, the same samples
    merged = open_log(tmp_path / "bag", geom, MODULES4, fmt="ros", topic=["/joint_states", "/other"])
    assert merged.merged
    rm = estimate_log(merged, chunk_size=64)
    assert np.array_equal(rm.t_ns, r.t_ns) and np.array_equal(rm.beta, r.beta) and np.array_equal(rm.phidot, r.phidot)
    for meth in r.methods:
        assert np.array_equal(rm.lam[meth], r.lam[meth]) and np.array_equal(rm.mu[meth], r.mu[meth])


def _yaw_series(n=400):
    t = T0 + np.arange(n, dtype=np.int64) * 10 * MS
    yaw = 0.5 + 2.0 * np.arange(n) * 0.01  # 8.5 rad: crosses ±π twice
    return t, yaw


def test_yaw_from_imu_and_from_a_pose_topic(tmp_path, geom):
    m = _truth(geom, 1000)
    t, yaw = _yaw_series()
    pose = np.column_stack([np.zeros((t.size, 2)), yaw])

    def extra(w):
        w.add_imu("/imu/data", t, yaw, yaw_rate=np.full(t.size, 2.0))
        w.add_pose_stamped("/mocap/pose", t[::2], pose[::2])
        w.add_odometry("/odom", t, pose, np.zeros((t.size, 3)))

    _groups_bag(tmp_path / "bag", m, extra=extra)
    for topic, every in (("/imu/data", 1), ("/mocap/pose", 2), ("/odom", 1)):
        src = open_log(tmp_path / "bag", geom, MODULES4, fmt="ros", yaw_topic=topic)
        track = src.yaw()
        assert np.array_equal(track.t_ns, t[::every]) and topic in track.source
        np.testing.assert_allclose(track.yaw, yaw[::every], rtol=0, atol=1e-12)  # unwrapped
        assert src.describe()["yaw_topic"] == topic
        assert open_log(tmp_path / "bag", geom, MODULES4, fmt="ros", yaw_topic=topic, time="log").yaw().t_ns.size
    assert open_log(tmp_path / "bag", geom, MODULES4, fmt="ros").yaw() is None


def _refused(path, geom, match, **options):
    with pytest.raises(LogError, match=match) as info:
        open_log(path, geom, MODULES4, fmt="ros", **options).yaw()
    assert "\n" not in str(info.value) and str(path) in str(info.value)
    return str(info.value)


def test_refusals(tmp_path, geom):
    m = _truth(geom, 200)
    t, yaw = _yaw_series(20)

    def extra(w):
        w.add_imu("/imu/no_orientation", t, None)
        w.add_imu("/imu/data", t, yaw)
        w.add_vector3_stamped("/icr", t, np.zeros((t.size, 3)))

    bag = tmp_path / "bag"
    _groups_bag(bag, m, extra=extra)
    msg = _refused(bag, geom, "no yaw topic /gyro", yaw_topic="/gyro")
    assert "/imu/data [sensor_msgs/msg/Imu]" in msg and "/icr" not in msg  # the usable topics only
    _refused(bag, geom, "yaw topic /icr holds geometry_msgs/msg/Vector3Stamped, not sensor_msgs/msg/Imu",
             yaw_topic="/icr")
    _refused(bag, geom, "yaw topic /imu/no_orientation: its first Imu message has no orientation",
             yaw_topic="/imu/no_orientation")
    _refused(bag, geom, "no topic /nope", topic=["/joint_states", "/nope"])
    _refused(bag, geom, "topic /imu/data holds sensor_msgs/msg/Imu", topic=["/joint_states", "/imu/data"])
    _refused(bag, geom, "no joint 'front_left_wheel' for module 'front_left' in any message",
             drive_joint="{module}_wheel")
    for bad in (0, -1.0, float("nan"), "1"):
        with pytest.raises(ValueError, match="max_age_s"):
            open_log(bag, geom, MODULES4, fmt="ros", max_age_s=bad)
    for bad in ([], ["/a", "/a"], [""]):
        with pytest.raises(ValueError, match="topic"):
            open_log(bag, geom, MODULES4, fmt="ros", topic=bad)


def test_imu_losing_its_orientation_later_is_refused(tmp_path, geom):
    m = _truth(geom, 200)
    t, yaw = _yaw_series(20)

    def extra(w):
        w.add_imu("/imu", t[:10], yaw[:10])
        w.add_imu("/imu", t[10:], None)

    _groups_bag(tmp_path / "bag", m, extra=extra)
    _refused(tmp_path / "bag", geom, "10 of its 20 Imu messages have no orientation", yaw_topic="/imu")


def test_a_drive_joint_without_velocities_is_refused(tmp_path, geom):
    m = _truth(geom, 200)
    w = BagWriter(tmp_path / "bag")
    w.add_joint_states("/joint_states", T0 + m.t_ns[::10], STEER, m.beta[::10], np.zeros((20, 0)))
    w.add_joint_states("/joint_states", T0 + m.t_ns[5::10], DRIVE, m.phidot[5::10], np.zeros((20, 0)))
    w.close()
    _refused(tmp_path / "bag", geom, "joint 'front_left_drive' of module 'front_left' has no velocity")
