"""The compiled batch follower computes PathFollower.step's twists (to rounding) on every built-in
track, robot by robot, with its own progress and integral state."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from azimut_env.tracks import TRACK_NAMES, make_track
from control.follow.batch import BatchFollower
from control.follow.path_follower import PathFollower
from control.icr.controller import reference_stop_mask
from estimation.geometry import RobotGeometry


@pytest.mark.parametrize("with_stops", [False, True])
def test_batch_follower_matches_path_follower(with_stops):
    geom = RobotGeometry.azimut3()
    mask = functools.partial(reference_stop_mask, geom=geom) if with_stops else None
    tracks = [make_track(name, rng=np.random.default_rng(3)) for name in TRACK_NAMES]
    singles = [PathFollower(t, stop_mask=mask) for t in tracks]
    batch = BatchFollower(len(tracks), stop_mask=mask)
    rng = np.random.default_rng(0)
    for i, (t, f) in enumerate(zip(tracks, singles)):
        f.reset(0.0)
        batch.reset(i, t, 0.0)
    rows = np.arange(len(tracks))
    for k in range(400):
        poses = np.array([np.asarray(t.sample(min(0.01 * k, 0.999 * t.length)))[:3] for t in tracks])
        poses += rng.normal(0.0, 0.02, poses.shape)
        got = batch.step(poses, rows)
        want = np.array([f.step(p).twist for f, p in zip(singles, poses)])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        np.testing.assert_allclose(batch.progress, [f.progress for f in singles], rtol=0, atol=1e-12)
