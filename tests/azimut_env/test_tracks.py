"""Tracks: built-ins, waypoints, progress with rotation in place, the compiled query against the
numpy reference."""

from __future__ import annotations

import numpy as np
import pytest

from azimut_env.tracks import TRACK_NAMES, Track, make_track, wrap_angle


@pytest.mark.parametrize("name", TRACK_NAMES)
def test_builtin_tracks_are_well_formed(name):
    t = make_track(name, rng=np.random.default_rng(0))
    assert t.length > 1.0
    assert np.all(np.diff(t.s) > 0)
    assert np.all(t.speed >= 0) and t.max_speed > 0
    assert np.all(np.isfinite(t.curvature)) and np.all(np.isfinite(t.dxy_ds))
    tw = t.reference_twist(np.linspace(0, t.length, 50))
    assert tw.shape == (50, 3) and np.all(np.isfinite(tw))


@pytest.mark.parametrize("name", TRACK_NAMES)
def test_query_matches_numpy_reference(name):
    t = make_track(name, rng=np.random.default_rng(1))
    rng = np.random.default_rng(2)
    for _ in range(100):
        s0 = rng.uniform(0, 1.5 * t.length if t.closed else t.length)
        pose = t.sample(s0)[:3] + rng.normal(0, 0.05, 3)
        hint = s0 + rng.uniform(-0.2, 0.2)
        s = t.project(pose, s_hint=hint)
        lat, head = t.errors(pose, s)
        q = t.query(pose, hint, 5, 0.3)
        assert q[0] == pytest.approx(s, abs=1e-9)
        assert q[1] == pytest.approx(lat, abs=1e-9) and q[2] == pytest.approx(head, abs=1e-9)
        assert np.allclose(q[5], t.lookahead(pose, s, 5, 0.3), atol=1e-9)


def test_projection_recovers_progress_and_counts_laps():
    t = make_track("circle")
    for s in np.linspace(0.1, t.length - 0.1, 20):
        assert t.project(t.sample(s)[:3], s_hint=s - 0.05) == pytest.approx(s, abs=1e-3)
    # crossing the start of a closed track continues the progress into the next lap
    s_next = t.project(t.sample(0.05)[:3], s_hint=t.length - 0.05)
    assert s_next == pytest.approx(t.length + 0.05, abs=1e-3)


def test_a_pose_past_a_corner_on_its_outside_projects_onto_the_corner():
    """A robot that overran the square's first corner (3, 0) by 1.7 cm and drifted 2.7 cm to the
    outside is at the corner, not 2 cm before it along the old leg (the refinement used to step
    back along the next leg's direction, and the robot stalled there); the compiled window
    projection gives the same. On a smooth path (no sample turns by 5°) the refinement is as it
    was: the step along the segment that starts at the nearest sample, clipped to its length."""
    from azimut_env.tracks.query import project_window_kernel

    t = Track.from_waypoints([[0.0, 0.0], [3.0, 0.0], [3.0, 3.0]], spacing=0.02)
    pose = np.array([3.0172, -0.0273, 0.0])
    corner = float(t.s[np.argmin(np.hypot(t.xy[:, 0] - 3.0, t.xy[:, 1]))])
    assert t.project(pose, s_hint=corner - 0.02) == corner
    assert project_window_kernel(t.s, t._x, t._y, t.heading, False, t.length, t.progress_radius, *pose,
                                 corner - 0.02, 0.5, 1.0, True) == corner
    c = make_track("circle")
    rng = np.random.default_rng(3)
    for _ in range(200):
        s0 = rng.uniform(0, c.length)
        pose = c.sample(s0)[:3] + rng.normal(0, 0.03, 3)
        d = (c.xy[:-1, 0] - pose[0]) ** 2 + (c.xy[:-1, 1] - pose[1]) ** 2 \
            + (c.progress_radius * wrap_angle(c.heading[:-1] - pose[2])) ** 2
        i = int(np.argmin(d))
        seg = np.array([*(c.xy[i + 1] - c.xy[i]), c.progress_radius * (c.heading[i + 1] - c.heading[i])])
        rel = np.array([*(pose[:2] - c.xy[i]), c.progress_radius * wrap_angle(pose[2] - c.heading[i])])
        n = np.linalg.norm(seg)
        expected = c.s[i] + np.clip(rel @ seg / n, -n, n)
        assert c.project(pose) == pytest.approx(expected, abs=1e-12)


def test_rotation_in_place_has_progress():
    t = make_track("crab")
    # the rotation segment: position fixed, heading turns, progress grows by ρ·Δθ
    still = np.all(np.abs(np.diff(t.xy, axis=0)) < 1e-12, axis=1)
    assert still.sum() > 5
    ds = np.diff(t.s)[still]
    assert np.allclose(ds, t.progress_radius * np.abs(np.diff(t.heading)[still]))
    s_mid = t.s[np.argmax(still) + 3]
    tw = t.reference_twist(s_mid, speed=0.3)
    assert np.hypot(tw[0], tw[1]) < 1e-9 and abs(tw[2]) == pytest.approx(0.3 / t.progress_radius)


def test_square_stops_at_corners():
    t = make_track("square")
    corners = [np.argmin(np.hypot(t.xy[:, 0] - cx, t.xy[:, 1] - cy)) for cx, cy in ((3, 0), (3, 3), (0, 3))]
    assert np.all(t.speed[corners] < 0.05)


def test_errors_sign_convention():
    t = Track.from_waypoints([(0, 0), (5, 0)], heading=0.3, speed=0.5, ramp=0)
    lat, head = t.errors((2.0, 0.2, 0.5), 2.0)
    assert lat == pytest.approx(0.2) and head == pytest.approx(0.2)
    look = t.lookahead((0.0, 0.0, np.pi / 2), 0.0, 2, 1.0)
    assert np.allclose(look[:, :2], [[0, -1], [0, -2]], atol=1e-9)


def test_from_waypoints_options_and_validation():
    t = Track.from_waypoints([(0, 0), (1, 0), (1, 1)], heading="tangent", speed=[0.2, 0.4, 0.4])
    assert t.heading[0] == pytest.approx(0.0) and t.heading[-1] == pytest.approx(np.pi / 2)
    assert t.speed[-1] == 0.0  # ramped down at the end of an open track
    c = Track.from_waypoints(np.array([(0, 0, 0), (2, 0, 1), (2, 2, 2)]), closed=True)
    assert c.closed and c.length > 6
    with pytest.raises(ValueError):
        Track.from_waypoints([(0, 0)])
    with pytest.raises(ValueError):
        Track.from_waypoints([(0, 0), (np.nan, 1)])
    with pytest.raises(ValueError):
        make_track("nope")


def test_random_tracks_are_seeded():
    a = make_track("random", rng=np.random.default_rng(5))
    b = make_track("random", rng=np.random.default_rng(5))
    c = make_track("random", rng=np.random.default_rng(6))
    assert np.array_equal(a.xy, b.xy) and not np.array_equal(a.xy, c.xy)


def test_wrap_angle():
    assert np.allclose(wrap_angle([np.pi, -np.pi, 3 * np.pi, 0.1]), [np.pi, np.pi, np.pi, 0.1])


def test_query_batch_matches_query_and_the_old_name_warns():
    t = make_track("figure8")
    rng = np.random.default_rng(4)
    s0 = rng.uniform(0, t.length, 16)
    poses = t.sample(s0)[:, :3] + rng.normal(0, 0.05, (16, 3))
    scal, look = t.query_batch(poses, s0, 4, 0.3)
    for i in range(16):
        q = t.query(poses[i], s0[i], 4, 0.3)
        assert np.array_equal(scal[i], q[:5]) and np.array_equal(look[i], q[5])
        s = t.project(poses[i], s_hint=s0[i])
        assert scal[i, 0] == pytest.approx(s, abs=1e-9)
    with pytest.deprecated_call():
        old = t.query_many(poses, s0, 4, 0.3)
    assert np.array_equal(old[0], scal) and np.array_equal(old[1], look)
    with pytest.raises(ValueError, match="one s_hint per pose"):
        t.query_batch(poses, s0[:3], 4, 0.3)
