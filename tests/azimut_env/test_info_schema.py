"""One ``info`` schema for both envs (``azimut_env.task.info.INFO_FIELDS``): sub-env i of the vector
env's info equals the single env's info for the same seed, key by key and bit for bit, at resets,
steps, terminations and a physics blow-up; the docstrings list the keys from the table."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

from azimut_env.env import AzimutEnv
from azimut_env.task.info import INFO_FIELDS, INFO_KEYS, info_table, sub_info, true_eta
from azimut_env.vector_env import AzimutVectorEnv
from estimation import canonical_eta


def assert_same(a, b, path: str = "info") -> None:
    """``a`` and ``b`` hold the same keys, types and bits (NaN equal to NaN)."""
    assert type(a) is type(b), f"{path}: {type(a).__name__} vs {type(b).__name__}"
    if isinstance(a, dict):
        assert list(a) == list(b), f"{path}: keys {list(a)} vs {list(b)}"
        for k in a:
            assert_same(a[k], b[k], f"{path}[{k!r}]")
    elif isinstance(a, tuple):
        assert len(a) == len(b), path
        for j, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{path}[{j}]")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), path
    elif isinstance(a, float):
        assert np.float64(a).tobytes() == np.float64(b).tobytes(), f"{path}: {a!r} vs {b!r}"
    else:
        assert a == b, f"{path}: {a!r} vs {b!r}"


def _ordered(info: dict) -> dict:
    """The keys in the table's order (the vector env's sub-info is built in that order too)."""
    return {k: info[k] for k in INFO_KEYS if k in info}


def test_sub_env_info_equals_the_single_env_info_key_by_key():
    n, seed, max_steps = 3, 5, 60
    kw = dict(track="random", max_lateral_error=0.15, stall_time=0.4, domain_randomization=0.1)
    venv = AzimutVectorEnv(num_envs=n, max_episode_steps=max_steps, **kw)
    envs = [AzimutEnv(**kw) for _ in range(n)]
    _, vinfo = venv.reset(seed=seed)
    for i, env in enumerate(envs):
        _, info = env.reset(seed=seed + i)
        assert list(info) == [k for k in INFO_KEYS if k != "error"]
        assert_same(_ordered(info), sub_info(vinfo, i), f"reset, sub-env {i}")
    rng = np.random.default_rng(seed)
    pending, elapsed = [False] * n, [0] * n
    ends = resets = 0
    for t in range(250):
        actions = np.clip(rng.normal(0.0, 0.3, (n, 8)) + np.r_[np.zeros(4), np.full(4, 0.5)], -1, 1)
        actions = actions.astype(np.float32)
        _, _, vterm, _, vinfo = venv.step(actions)
        for i, env in enumerate(envs):
            if pending[i]:  # the vector env's NEXT_STEP autoreset: its info is the reset's
                _, info = env.reset()
                elapsed[i], pending[i] = 0, False
                resets += 1
            else:
                _, _, term, _, info = env.step(actions[i])
                elapsed[i] += 1
                pending[i] = term or elapsed[i] >= max_steps
                ends += int(term)
            assert_same(_ordered(info), sub_info(vinfo, i), f"step {t}, sub-env {i}")
            assert_same(_ordered(info), _ordered(venv.sub_env_info(i)), f"sub_env_info, step {t}, sub-env {i}")
    assert ends > 0 and resets > 0


def test_a_blow_up_gives_the_same_keys_in_both_envs():
    env, venv = AzimutEnv(), AzimutVectorEnv(num_envs=2)
    env.reset(seed=4)
    venv.reset(seed=[4, 9])
    act = np.full(8, 0.2, dtype=np.float32)
    env.step(act)
    venv.step(np.stack([act, act]))
    env.physics.chassis[0].velocity = (float("nan"), 0.0)
    venv.physics.chassis[0].velocity = (float("nan"), 0.0)
    _, _, term, _, info = env.step(act)
    _, _, vterm, _, vinfo = venv.step(np.stack([act, act]))
    assert term and vterm[0] and not vterm[1]
    assert set(info) == {f.name for f in INFO_FIELDS if f.at_error}
    assert_same(_ordered(info), sub_info(vinfo, 0))
    assert set(sub_info(vinfo, 1)) == set(INFO_KEYS) - {"error"}  # the other robot goes on
    assert vinfo["_pose"].tolist() == [False, True] and vinfo["_error"].tolist() == [True, False]


def test_every_key_is_in_the_table_and_the_docstrings():
    env, venv = AzimutEnv(), AzimutVectorEnv(num_envs=2)
    env.reset(seed=0)
    _, _, _, _, info = env.step(env.action_space.sample())
    assert list(info) == [k for k in INFO_KEYS if k != "error"]
    venv.reset(seed=0)
    _, _, _, _, vinfo = venv.step(venv.action_space.sample())
    assert {k for k in vinfo if not k.startswith("_")} == set(info)
    for key in info:
        assert vinfo["_" + key].dtype == np.bool_ and vinfo["_" + key].shape == (2,)
    assert vinfo["pose"].shape == (2, 3) and vinfo["tire_forces"].shape == (2, 4, 2)
    assert vinfo["eta_true"][0].shape == (2, 3) and vinfo["eta_true"][1].shape == (2,)
    assert vinfo["reward_terms"]["slip"].shape == (2,) and vinfo["reward_terms"]["_slip"].all()
    assert info_table() in textwrap.dedent(AzimutEnv.__doc__)  # generated (azimut_env.doc_tables)
    assert "AzimutEnv" in AzimutVectorEnv.__doc__  # the vector env's refers to the single env's table


@pytest.mark.parametrize("twist", [(0.3, -0.2, 0.5), (0.0, 0.0, 0.0), (-1e-4, 0.0, -2e-4), (0.0, -5e-4, 0.0),
                                   (2.0, 0.0, 0.0)])
def test_true_eta_is_the_canonical_h_state_of_the_twist(twist):
    """ξ̇ = μ (v, −u, w): λ ∝ (−ẏ, ẋ, θ̇), μ = ‖ξ̇‖, with estimation's canonical sign below 1e-3."""
    lam, mu = true_eta(np.array(twist))
    tw = np.array(twist)
    if np.linalg.norm(tw) > 0:
        ref_lam, ref_mu = canonical_eta(np.array([-tw[1], tw[0], tw[2]]) / np.linalg.norm(tw), np.linalg.norm(tw),
                                        mu_tol=1e-3)
        np.testing.assert_allclose(lam, ref_lam, atol=1e-15)
        assert mu == pytest.approx(ref_mu, abs=1e-15)
    else:
        assert lam.tolist() == [0.0, 0.0, 1.0] and mu == 0.0
    batch_lam, batch_mu = true_eta(np.array([twist, twist]))
    assert batch_lam.shape == (2, 3) and np.array_equal(batch_lam[1], lam) and batch_mu[1] == mu


def test_true_eta_of_one_robot_is_its_row_of_the_batch_bit_for_bit():
    """The single env's path (one twist) and the vector env's (a batch) are two codings of one
    formula; they must give the same bits, tiny twists (the sign rule) and zeros included."""
    rng = np.random.default_rng(0)
    tw = np.concatenate([rng.normal(size=(2000, 3)), 1e-4 * rng.normal(size=(2000, 3)),
                         np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1e-5], [-1e-5, 0.0, 0.0], [0.0, -2e-4, 0.0]])])
    lam, mu = true_eta(tw)
    for i in range(tw.shape[0]):
        one_lam, one_mu = true_eta(tw[i])
        assert one_lam.tobytes() == lam[i].tobytes() and np.float64(one_mu).tobytes() == mu[i].tobytes(), tw[i]
