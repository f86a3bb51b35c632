"""Trained agents over seeds: IQM and stratified bootstrap (against rliable), the seeds-folder
expansion and agent groups of ``azimut eval``, the raw bar, the residual's correction cost, and
the refusals of ``azimut train --engine`` / ``azimut tune`` at entry."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jobs.campaign.statistics import iqm, stratified_bootstrap_iqm
from jobs.cli import main

#: a fixed example (5 runs × 3 tasks) and what rliable 1.2.0 gives for it
#: (``metrics.aggregate_iqm``; ``library.get_interval_estimates(..., reps=200000)``, percentile
#: method; run in a scratch venv with arch 7.2.0, pandas 2.x)
SCORES = np.array([[0.10, 1.2, 3.0], [0.35, 0.9, 2.5], [0.20, 1.8, 4.1], [0.90, 1.1, 2.2], [0.15, 0.7, 3.6]])
RLIABLE = {"iqm": 1.2944444444444443, "all": (1.08888889, 1.58333333), "task0": (0.23333333, 0.11666667, 0.71666667)}


def test_iqm_and_stratified_interval_match_rliable_on_a_fixed_example():
    assert iqm(SCORES) == pytest.approx(RLIABLE["iqm"], abs=1e-12)
    one = stratified_bootstrap_iqm([SCORES[:, 0]], n_resamples=200_000)
    assert (one["iqm"], one["lo"], one["hi"]) == pytest.approx(RLIABLE["task0"], abs=1e-6)
    allt = stratified_bootstrap_iqm(SCORES.T, n_resamples=200_000)  # strata = tasks (columns)
    assert allt["iqm"] == pytest.approx(RLIABLE["iqm"], abs=1e-12) and allt["n"] == 15
    assert (allt["lo"], allt["hi"]) == pytest.approx(RLIABLE["all"], abs=1e-6)


def test_iqm_is_scipy_trim_mean():
    assert iqm([1, 2, 3, 4, 5]) == 3.0  # floor(5/4) = 1 cut at each end
    assert iqm([1, 2, 3, 4, 100, 6, 7, 8]) == 5.0  # 2 cut at each end: the outlier is gone
    assert iqm([7.0]) == 7.0 and np.isnan(iqm([])) and iqm([np.nan, 2.0, np.inf]) == 2.0


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=4), st.integers(1, 6), st.integers(0, 2**16))
def test_stratified_bootstrap_never_mixes_strata(levels, runs, seed):
    """Every stratum constant: each resample draws the same scores, so the interval is a point;
    the interval always holds the point estimate otherwise."""
    strata = [[v] * runs for v in levels]
    s = stratified_bootstrap_iqm(strata, n_resamples=200, seed=seed)
    assert s["lo"] == s["hi"] == pytest.approx(s["iqm"]) or s["lo"] <= s["iqm"] <= s["hi"]
    rng = np.random.default_rng(seed)
    noisy = [list(v + rng.normal(size=runs)) for v in levels]
    t = stratified_bootstrap_iqm(noisy, n_resamples=500, seed=seed)
    assert t["lo"] - 1e-9 <= t["iqm"] <= t["hi"] + 1e-9 or runs * len(levels) == 1
    assert stratified_bootstrap_iqm(noisy, n_resamples=500, seed=seed) == t  # seeded


def _fake_run(folder, complete=True):
    folder.mkdir(parents=True)
    (folder / "model.zip").write_bytes(b"PK\x05\x06" + b"\0" * 18)  # an empty zip archive
    (folder / "run.json").write_text(json.dumps({"algo": "ppo", "action": "raw", "complete": complete}))


def test_a_seeds_folder_expands_to_its_complete_seeds(tmp_path, capsys):
    from jobs.eval.agents import agent_groups, expand_seed_folders

    for s, ok in ((0, True), (1, True), (3, False), (10, True)):
        _fake_run(tmp_path / "runs" / f"seed_{s}", ok)
    out = expand_seed_folders(["icr", f"ppo:raw={tmp_path / 'runs'}", f"sac:{tmp_path / 'runs' / 'seed_0'}"])
    assert out == ["icr"] + [f"ppo:raw.s{s}={tmp_path / 'runs' / f'seed_{s}' / 'model.zip'}" for s in (0, 1, 10)] \
        + [f"sac:{tmp_path / 'runs' / 'seed_0'}"]
    assert "seed_3 left out" in capsys.readouterr().err
    assert agent_groups(["icr", "raw.s0", "raw.s1", "raw.s10", "x.s1"]) == {"raw": ["raw.s0", "raw.s1", "raw.s10"]}


def _rows():
    rows = []
    force = {"icr": 10.0, "twist": 30.0, "a.s0": 20.0, "a.s1": 40.0, "a.s2": 25.0}
    for c, f in force.items():
        for t in ("circle", "crab"):
            for s in (0, 1):
                rows.append({"controller": c, "track": t, "seed": s, "status": "ok", "completed": c != "a.s2" or s,
                             "rms_lateral_m": 0.01, "slip_energy_J": 1.0, "mean_nullspace_force_N": f + s,
                             "mean_antagonism_N": 0.5 * (f + s)})
    return rows


def test_agent_summary_per_track_aggregate_and_bar():
    from jobs.eval.agents import agent_section, agent_summary

    rows = _rows()
    names = ["icr", "twist", "a.s0", "a.s1", "a.s2"]
    summary = agent_summary(rows, names, ["circle", "crab"], n_resamples=2000)
    g = summary["groups"]["a"]
    assert g["tracks"]["circle"]["mean_nullspace_force_N"]["scores"] == [20.5, 40.5, 25.5]
    assert g["tracks"]["circle"]["mean_nullspace_force_N"]["iqm"] == pytest.approx(86.5 / 3)  # 3 seeds: none cut
    assert g["tracks"]["circle"]["mean_antagonism_N"]["scores"] == [10.25, 20.25, 12.75]
    # 6 scores (3 seeds x 2 tracks) against icr's 10.5: the smallest and largest cut
    assert g["aggregate"]["mean_nullspace_force_N"]["iqm"] == pytest.approx((20.5 + 25.5 + 25.5 + 40.5) / 4 / 10.5)
    assert g["bar"]["met"] == 1 and g["bar"]["by_seed"] == {"0": True, "1": False, "2": False}  # s2 missed a lap
    text = "\n".join(agent_section(summary, rows, ["circle", "crab"], ["icr", "twist"]))
    assert "| a | circle | 3 |" in text and "1 of 3 seeds" in text


def test_correction_cost_is_the_l2_cost_of_the_residual_action():
    from train.envs import make_vector_env

    a = np.array([[0.5, -1.0, 0.2], [0.0, 0.0, 0.0]], dtype=np.float32)
    rewards = {}
    for w in (0.0, 2.0):
        venv = make_vector_env("residual", 2, "circle", env_kwargs={"time_limit_factor": 0.1}, correction_cost=w)
        venv.reset(seed=3)
        _, r, *_ , info = venv.step(a)
        rewards[w] = r
        venv.close()
    want = 2.0 * np.mean(np.clip(a, -1, 1).astype(np.float64) ** 2, axis=1)
    np.testing.assert_allclose(rewards[0.0] - rewards[2.0], want, rtol=0, atol=1e-12)
    assert np.array_equal(info["correction_cost"], want)
    with pytest.raises(ValueError, match="residual"):
        make_vector_env("icr-rate", 2, "circle", correction_cost=1.0)


@pytest.mark.parametrize("argv", [
    ["train", "--engine", "bogus"], ["train", "--correction-cost", "1", "--action", "raw"],
    ["train", "--correction-cost", "-1", "--action", "residual"], ["train", "--env-runners", "2"],
    ["tune", "--storage", "sqlite:////nonexistent-dir/x/study.db"], ["tune", "--storage", "not a url"],
])
def test_bad_engine_cost_and_storage_refused_with_one_line(tmp_path, argv, capsys):
    if argv[0] == "tune":
        pytest.importorskip("optuna")
    rc = main([argv[0], "--out", str(tmp_path / "o"), *argv[1:]])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith(f"azimut {argv[0]}: error:"), err


def test_a_storage_file_that_is_not_a_database_is_refused_with_one_line(tmp_path, capsys):
    pytest.importorskip("optuna")
    db = tmp_path / "study.db"
    db.write_text("not an SQLite database\n")
    rc = main(["tune", "--storage", f"sqlite:///{db}", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "cannot open the Optuna storage" in err[0], err
    assert not (tmp_path / "o").exists() and db.read_text() == "not an SQLite database\n"


def _rllib_importable() -> bool:
    try:
        import ray.rllib  # noqa: F401
    except Exception:  # noqa: BLE001
        return False
    return True


@pytest.mark.skipif(_rllib_importable(), reason="Ray RLlib is installed here")
def test_engine_rllib_without_rllib_is_refused(tmp_path, capsys):
    assert main(["train", "--engine", "rllib", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "rllib" in err[0] and not (tmp_path / "o").exists()


@pytest.mark.skipif(importlib.util.find_spec("optuna") is None, reason="needs optuna (the tune extra)")
def test_train_reads_the_versioned_file_tune_writes(tmp_path, capsys):
    from train.tuning import HYPERPARAMS_FORMAT, read_hyperparams_file

    data = {"format": HYPERPARAMS_FORMAT, "version": 1, "algo": "ppo", "action": "residual",
            "hyperparams": {"n_steps": 64}}
    assert read_hyperparams_file(data, "ppo", "residual") == {"n_steps": 64}
    assert read_hyperparams_file({"n_steps": 32}, "ppo", "raw") == {"n_steps": 32}
    f = tmp_path / "best.json"
    f.write_text(json.dumps(data))
    assert main(["train", "--out", str(tmp_path / "o"), "--action", "raw", "--hyperparams", str(f)]) == 2
    assert "tuned for --algo ppo --action residual" in capsys.readouterr().err
