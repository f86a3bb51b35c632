"""AzimutVectorEnv: equivalence with N single envs, the Gymnasium vector API (autoreset, seeding,
options, masks), per-sub-env blow-up, make_vec, rendering and the batched controller interface."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import azimut_env  # noqa: F401  (registers Azimut-v1)
from azimut_env.env import AzimutEnv
from azimut_env.vector_env import AzimutVectorEnv


def _run_equivalence(n_envs: int, steps: int, max_steps: int, seed: int, **kwargs) -> dict:
    """Step a vector env and n single envs (NEXT_STEP autoreset done by hand on the singles) with
    the same seeds and actions; assert exact equality at every step. Returns counts."""
    venv = AzimutVectorEnv(num_envs=n_envs, max_episode_steps=max_steps, **kwargs)
    envs = [AzimutEnv(**kwargs) for _ in range(n_envs)]
    vobs, _ = venv.reset(seed=seed)
    sobs = [e.reset(seed=seed + i)[0] for i, e in enumerate(envs)]
    assert np.array_equal(vobs, np.stack(sobs))
    rng = np.random.default_rng(seed)
    elapsed = [0] * n_envs
    pending = [False] * n_envs
    counts = {"terminated": 0, "truncated": 0, "resets": 0}
    for _ in range(steps):
        # drive straight ahead with noisy set-points: the robots leave their tracks at times
        actions = np.clip(rng.normal(0.0, 0.3, (n_envs, 8)) + np.r_[np.zeros(4), np.full(4, 0.6)], -1, 1)
        actions = actions.astype(np.float32)
        vobs, vrew, vterm, vtrunc, _ = venv.step(actions)
        for i, env in enumerate(envs):
            if pending[i]:
                obs, _ = env.reset()
                rew, term, trunc = 0.0, False, False
                elapsed[i] = 0
                counts["resets"] += 1
            else:
                obs, rew, term, _, _ = env.step(actions[i])
                elapsed[i] += 1
                trunc = elapsed[i] >= max_steps
            pending[i] = term or trunc
            counts["terminated"] += int(term)
            counts["truncated"] += int(trunc and not term)
            assert np.array_equal(obs, vobs[i])
            assert rew == vrew[i]
            assert (term, trunc) == (vterm[i], vtrunc[i])
    return counts


def test_equivalence_with_single_envs_500_steps_with_resets():
    # random tracks (one per sub-env and episode), domain randomisation, a tight lateral limit so
    # that random actions go off the track: terminations, truncations and resets all happen
    counts = _run_equivalence(3, 500, 90, seed=11, track="random", domain_randomization=0.2, max_lateral_error=0.15)
    assert counts["terminated"] > 0 and counts["truncated"] > 0 and counts["resets"] >= 6


def test_equivalence_with_odometry_pose_source():
    # the pose estimate (dead reckoning + a noisy fix every 5 steps) replays bit for bit, resets included
    from azimut_env.task.localisation import LocalisationParams

    counts = _run_equivalence(3, 300, 60, seed=4, track="random", max_lateral_error=0.15, pose_source="odometry",
                              localisation=LocalisationParams(fix_period_s=0.1))
    assert counts["resets"] >= 3


@pytest.mark.slow
def test_equivalence_many_envs_paper_track():
    counts = _run_equivalence(16, 500, 150, seed=5, track="paper", max_lateral_error=0.2)
    assert counts["resets"] > 16


def test_make_vec_returns_the_vector_env():
    venv = gym.make_vec("Azimut-v2", num_envs=3, vectorization_mode="vector_entry_point", track="circle")
    assert isinstance(venv.unwrapped, AzimutVectorEnv)
    assert venv.num_envs == 3 and venv.unwrapped.max_episode_steps is None  # per-track limit (time_limit_factor)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    obs, info = venv.reset(seed=0)
    assert obs.shape == (3, venv.single_observation_space.shape[0])
    venv.close()


def test_vector_api_spaces_dtypes_and_determinism():
    a, b = AzimutVectorEnv(num_envs=4), AzimutVectorEnv(num_envs=4)
    assert a.action_space.shape == (4, 8) and a.observation_space.shape[0] == 4
    oa, ia = a.reset(seed=3)
    ob, _ = b.reset(seed=3)
    assert oa.dtype == np.float32 and oa in a.observation_space and np.array_equal(oa, ob)
    assert set(ia) >= {"progress", "_progress", "reward_terms", "qua"}
    a.action_space.seed(0)
    for _ in range(20):
        act = a.action_space.sample()
        ra, rb = a.step(act), b.step(act)
        obs, rew, term, trunc, info = ra
        assert obs in a.observation_space
        assert rew.dtype == np.float64 and rew.shape == (4,)
        assert term.dtype == np.bool_ and trunc.dtype == np.bool_
        assert info["reward_terms"]["progress"].shape == (4,)
        for x, y in zip(ra[:4], rb[:4]):
            assert np.array_equal(x, y)
    with pytest.raises(RuntimeError, match="reset"):
        AzimutVectorEnv(num_envs=2).step(np.zeros((2, 8), dtype=np.float32))


def test_seeds_match_single_env_streams_and_seed_lists():
    venv = AzimutVectorEnv(num_envs=3, track="random")
    obs, _ = venv.reset(seed=[7, None, 9])
    assert np.array_equal(obs[0], AzimutEnv(track="random").reset(seed=7)[0])
    assert np.array_equal(obs[2], AzimutEnv(track="random").reset(seed=9)[0])
    with pytest.raises(ValueError, match="seed"):
        venv.reset(seed=[1, 2])


def test_next_step_autoreset_semantics():
    venv = AzimutVectorEnv(num_envs=2, max_episode_steps=3)
    first, _ = venv.reset(seed=0)
    act = np.zeros((2, 8), dtype=np.float32)
    for _ in range(2):
        _, _, term, trunc, _ = venv.step(act)
        assert not (term.any() or trunc.any())
    _, _, term, trunc, _ = venv.step(act)
    assert trunc.all() and not term.any()
    obs, rew, term, trunc, info = venv.step(act)  # the reset step: action ignored
    assert np.all(rew == 0) and not term.any() and not trunc.any()
    assert np.all(info["progress"] == venv.progress)
    # the same RNG stream goes on: a single env reset after its episode gives the same observation
    single = AzimutEnv()
    single.reset(seed=1)
    for _ in range(3):
        single.step(act[1])
    assert np.array_equal(single.reset()[0], obs[1])


def test_same_step_autoreset_final_obs():
    venv = AzimutVectorEnv(num_envs=2, max_episode_steps=2, autoreset_mode="SameStep")
    venv.reset(seed=0)
    act = np.zeros((2, 8), dtype=np.float32)
    venv.step(act)
    obs, _, _, trunc, info = venv.step(act)
    assert trunc.all() and info["_final_obs"].all()
    assert info["final_obs"][0].shape == obs[0].shape and not np.array_equal(info["final_obs"][0], obs[0])
    assert "progress" in info["final_info"]
    obs2, _, _, trunc2, _ = venv.step(act)
    assert not trunc2.any()


def test_reset_mask_and_per_sub_env_options():
    venv = AzimutVectorEnv(num_envs=3, track="circle")
    venv.reset(seed=0, options=[None, {"start_progress": 2.0}, {"kick": {"step": 0, "wheels": [0], "impulse": 0.5}}])
    assert venv.progress[0] == pytest.approx(0.0, abs=0.1) and venv.progress[1] == pytest.approx(2.0, abs=0.1)
    venv.step(np.zeros((3, 8), dtype=np.float32))
    beta = venv.physics.steering_angles()
    assert abs(beta[2, 0] - beta[0, 0]) > 0.01  # sub-env 2 was kicked
    before = venv.true_pose
    for _ in range(5):
        venv.step(np.full((3, 8), 0.3, dtype=np.float32))
    mask = np.array([False, True, False])
    obs, _ = venv.reset(options={"reset_mask": mask, "start_progress": 1.0})
    assert venv.progress[1] == pytest.approx(1.0, abs=0.1)
    assert not np.allclose(venv.true_pose[0], before[0])  # not reset
    with pytest.raises(ValueError, match="unknown reset options"):
        venv.reset(options={"bogus": 1})
    with pytest.raises(ValueError, match="obstacles"):
        venv.reset(options={"obstacles": [(5.0, 5.0, 0.2)]})


def test_nan_action_raises_without_changing_state(make_vector_env):
    venv = make_vector_env(num_envs=3)
    venv.reset(seed=0)
    pose = venv.true_pose
    act = np.zeros((3, 8), dtype=np.float32)
    act[1, 2] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        venv.step(act)
    assert np.array_equal(venv.true_pose, pose)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((2, 8), dtype=np.float32))


def test_one_blow_up_ends_only_its_own_episode(make_vector_env):
    ref = make_vector_env(num_envs=3)
    venv = make_vector_env(num_envs=3)
    ref.reset(seed=4)
    venv.reset(seed=4)
    act = np.full((3, 8), 0.2, dtype=np.float32)
    ref.step(act)
    venv.step(act)
    venv.physics.chassis[1].velocity = (float("nan"), 0.0)
    obs, rew, term, trunc, info = venv.step(act)
    r_obs, r_rew, *_ = ref.step(act)
    assert term[1] and not term[0] and not term[2]
    assert "non-finite" in info["error"][1] and info["_error"].tolist() == [False, True, False]
    assert rew[1] == -venv.config.off_track_penalty and np.all(np.isfinite(obs)) and np.all(np.isfinite(rew))
    assert np.array_equal(obs[[0, 2]], r_obs[[0, 2]]) and np.array_equal(rew[[0, 2]], r_rew[[0, 2]])
    assert np.all(np.isfinite(venv.physics.summary))  # the broken robot was parked
    obs, rew, term, trunc, info = venv.step(act)  # sub-env 1 autoresets, the others go on
    r_obs, *_ = ref.step(act)
    assert rew[1] == 0 and not term.any() and "error" not in info
    assert np.array_equal(obs[[0, 2]], r_obs[[0, 2]])
    for _ in range(20):
        obs, *_ = venv.step(act)
        r_obs, *_ = ref.step(act)
    assert np.array_equal(obs[[0, 2]], r_obs[[0, 2]]) and np.all(np.isfinite(obs))


def test_render_one_chosen_sub_env():
    venv = AzimutVectorEnv(num_envs=3, render_mode="rgb_array", render_index=2)
    venv.reset(seed=0)
    venv.step(np.zeros((3, 8), dtype=np.float32))
    img = venv.render()
    assert img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8
    venv.render_index = 0
    assert venv.render().shape == img.shape
    venv.close()


def test_batched_controller_interface():
    venv = AzimutVectorEnv(num_envs=4)
    venv.reset(seed=0)
    lam, mu = venv.estimated_eta
    assert lam.shape == (4, 3) and mu.shape == (4,)
    assert np.allclose(np.linalg.norm(lam, axis=1), 1.0)
    assert venv.measured_beta.shape == (4, 4) and venv.measured_phidot.shape == (4, 4)
    beta_cmd, phidot_cmd = venv.setpoints_from_action(np.full((4, 8), 0.5))
    act = venv.action_from_setpoints(beta_cmd, phidot_cmd)
    assert act.shape == (4, 8) and np.allclose(act, 0.5)
    dec = venv.decode_observation(venv.task.obs)
    assert dec["lookahead"].shape == (4, 5, 3) and np.allclose(dec["lambda_hat"], lam, atol=1e-6)
    info = venv.sub_env_info(2)
    assert set(info) >= {"pose", "eta_true", "tire_forces", "reward_terms"}
    assert len(venv.tracks) == 4 and venv.true_pose.shape == (4, 3)


def test_solver_iterations_knob():
    venv = AzimutVectorEnv(num_envs=2, solver_iterations=10)
    assert venv.physics.space.iterations == 10
    assert AzimutEnv(solver_iterations=12).physics.space.iterations == 12
    with pytest.raises(ValueError, match="solver_iterations"):
        AzimutVectorEnv(num_envs=2, solver_iterations=0)


def test_constructor_validation():
    with pytest.raises(ValueError, match="num_envs"):
        AzimutVectorEnv(num_envs=0)
    with pytest.raises(ValueError, match="max_episode_steps"):
        AzimutVectorEnv(num_envs=2, max_episode_steps=0)
    with pytest.raises(ValueError, match="autoreset_mode"):
        AzimutVectorEnv(num_envs=2, autoreset_mode="sometimes")
    with pytest.raises(ValueError, match="lateral"):
        AzimutVectorEnv(num_envs=2, max_lateral_error=0.0)


def test_gymnasium_vector_wrappers_work():
    from gymnasium.wrappers.vector import NormalizeObservation, RecordEpisodeStatistics

    venv = NormalizeObservation(RecordEpisodeStatistics(AzimutVectorEnv(num_envs=3, max_episode_steps=5)))
    venv.reset(seed=0)
    episodes = 0
    for _ in range(12):
        obs, rew, term, trunc, info = venv.step(np.zeros((3, 8), dtype=np.float32))
        assert np.all(np.isfinite(obs))
        if "episode" in info:
            episodes += int(info["_episode"].sum())
            assert np.all(info["episode"]["l"][info["_episode"]] == 5)
    assert episodes == 6


def test_query_tracks_matches_track_query_per_robot():
    from numba.typed import List

    from azimut_env.tracks import make_track, query_tracks

    rng = np.random.default_rng(0)
    tracks = [make_track("paper"), make_track("circle"), make_track("random", rng=rng), make_track("crab")]
    s = np.array([1.0, 7.0, 3.0, 0.5])
    poses = np.stack([t.sample(si)[:3] for t, si in zip(tracks, s)]) + rng.normal(0, 0.05, (4, 3))
    out, look = query_tracks(List([t.packed() for t in tracks]), np.array([t.closed for t in tracks]),
                             np.array([t.length for t in tracks]), np.array([t.progress_radius for t in tracks]),
                             poses, s, 5, 0.3)
    for i, t in enumerate(tracks):
        ref = t.query(poses[i], s[i], 5, 0.3)
        assert np.array_equal(out[i], np.array(ref[:5])) and np.array_equal(look[i], ref[5])
