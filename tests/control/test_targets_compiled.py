"""The compiled RL targets (control.action_spaces.targets) against the NumPy shaping functions
(control.action_spaces.shaping), bit for bit on random batches: many rows cross a steering stop
or enter an axis cap, some push past a stop long enough to cross it."""

from __future__ import annotations

import numpy as np
import pytest

from control.action_spaces.shaping import advance_target, exp_step, initial_frame, shape_target, transport_frame
from control.action_spaces.targets import RATE_TARGETS, RESIDUAL_TARGETS, SHAPED_TARGETS
from estimation.hrep import eta_from_twist
from estimation.threads import max_threads

#: the blocked kernels on 2 threads where numba's pool has them (the same bits as on one)
THREADS = min(2, max_threads())

MARGIN = np.deg2rad(3.0)


@pytest.fixture(params=["azimut3", "swerve"])
def geom(request):
    """The default robot (steering stops) and the swerve preset (unlimited steering)."""
    from azimut_env.params import RobotParams

    return RobotParams.preset(request.param).geometry


def _shape_args(geom):
    return (geom.a_minus_l, geom.a_perp, float(geom.steer_max), geom.s_unit, float(np.cos(MARGIN)),
            bool(geom.unlimited_steering))


def _unit_rows(rng, m):
    x = rng.standard_normal((m, 3))
    return x / np.linalg.norm(x, axis=1, keepdims=True)


@pytest.mark.parametrize("seed", range(3))
def test_residual_targets(geom, seed):
    rng = np.random.default_rng(seed)
    m = 400
    twists = rng.standard_normal((m, 3)) * [0.5, 0.5, 1.0]
    twists[:5] = 0.0  # at rest: λ = (0, 0, 1)
    a = rng.uniform(-1, 1, (m, 3))
    lam_d, mu_d, held = np.empty((m, 3)), np.empty(m), np.empty(m, dtype=np.bool_)
    RESIDUAL_TARGETS.run(THREADS, m, twists, a, 0.6, 0.1, *_shape_args(geom), lam_d, mu_d, held)
    lam_f, mu_f = eta_from_twist(twists)
    prop = exp_step(lam_f, initial_frame(lam_f), a[:, :2] * 0.6, 1.0)
    want, _, want_held = advance_target(lam_f, prop, np.zeros(m), geom, MARGIN, np.inf)
    np.testing.assert_array_equal(lam_d, want)
    np.testing.assert_array_equal(mu_d, mu_f + a[:, 2] * 0.1)
    np.testing.assert_array_equal(held, want_held)
    assert held.sum() < m


def test_rate_targets_over_many_steps(geom):
    """200 steps of the ICR-rate target of 64 robots, half of them stepped each time."""
    rng = np.random.default_rng(7)
    N, dt = 64, 0.02
    lam = _unit_rows(rng, N)
    state = [lam.copy(), initial_frame(lam), np.zeros(N), np.zeros(N)]  # λ_s, e₁, push, μ_s
    ref = [x.copy() for x in state]
    n_held = 0
    for _ in range(200):
        rows = np.flatnonzero(rng.random(N) < 0.5).astype(np.int64)
        a = rng.uniform(-1, 1, (rows.size, 3))
        lam_d, mu_d, held = np.empty((rows.size, 3)), np.empty(rows.size), np.empty(rows.size, dtype=np.bool_)
        RATE_TARGETS.run(THREADS, rows.size, rows, a, *state, 8.0, 2.0, 1.0, dt, 0.6, *_shape_args(geom), lam_d, mu_d,
                         held)
        lam_s, e1 = ref[0][rows], ref[1][rows]
        prop = exp_step(lam_s, e1, a[:, :2] * 8.0, dt)
        new, push, want_held = advance_target(lam_s, prop, ref[2][rows], geom, MARGIN, 0.6)
        ref[0][rows], ref[2][rows] = new, push
        ref[1][rows] = transport_frame(e1, new)
        ref[3][rows] = np.clip(ref[3][rows] + a[:, 2] * 2.0 * dt, -1.0, 1.0)
        np.testing.assert_array_equal(lam_d, new)
        np.testing.assert_array_equal(mu_d, ref[3][rows])
        np.testing.assert_array_equal(held, want_held)
        for got, want in zip(state, ref):
            np.testing.assert_array_equal(got, want)
        n_held += int(held.sum())
    assert n_held > 0


@pytest.mark.parametrize("nearer", [True, False])
def test_shaped_targets_over_many_steps(geom, nearer):
    rng = np.random.default_rng(11)
    N = 64
    lam_ref = _unit_rows(rng, N)
    push, push_ref = np.zeros(N), np.zeros(N)
    n_held = 0
    for _ in range(100):
        rows = np.flatnonzero(rng.random(N) < 0.7).astype(np.int64)
        lam_t, mu_t = _unit_rows(rng, rows.size), rng.uniform(-1, 1, rows.size)
        lam_d, mu_d, held = np.empty((rows.size, 3)), np.empty(rows.size), np.empty(rows.size, dtype=np.bool_)
        SHAPED_TARGETS.run(THREADS, rows.size, rows, lam_ref, lam_t, mu_t, push, nearer, 0.06, 0.6, *_shape_args(geom),
                           lam_d, mu_d, held)
        want, want_mu, p, want_held = shape_target(lam_ref[rows], lam_t, mu_t, push_ref[rows], geom, MARGIN, 0.06, 0.6,
                                                   nearer=nearer)
        push_ref[rows] = p
        np.testing.assert_array_equal(lam_d, want)
        np.testing.assert_array_equal(mu_d, want_mu)
        np.testing.assert_array_equal(held, want_held)
        np.testing.assert_array_equal(push, push_ref)
        lam_ref[rows] = lam_d  # the controller follows its target
        n_held += int(held.sum())
    assert n_held > 0
