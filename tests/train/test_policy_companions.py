"""Issue 20: a policy load checks its companions against the env before any episode and says
what it found (normalisation statistics, action space, observation space)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

from jobs.cli import main  # noqa: E402
from train.policy import load_policy  # noqa: E402


def _save_run(folder: Path, action: str = "raw", env_kwargs: dict | None = None, stats_env_kwargs: dict | None = None,
              meta_action: str | None = None, meta_env_kwargs: dict | None = None) -> Path:
    """An untrained PPO policy of ``action`` on an env of ``env_kwargs`` saved as ``azimut train``
    saves a run (model.zip, vecnormalize.pkl, run.json); ``stats_*``/``meta_*`` make a companion
    disagree."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from train.envs import make_sb3_env

    folder.mkdir(parents=True, exist_ok=True)
    venv = make_sb3_env(action, 1, "paper", env_kwargs)
    PPO("MlpPolicy", venv, n_steps=64, batch_size=32, device="cpu").save(str(folder / "model.zip"))
    stats_venv = venv if stats_env_kwargs is None else make_sb3_env(action, 1, "paper", stats_env_kwargs)
    VecNormalize(stats_venv).save(str(folder / "vecnormalize.pkl"))
    (folder / "run.json").write_text(json.dumps({"algo": "ppo", "action": meta_action or action,
                                                 "env_kwargs": meta_env_kwargs or env_kwargs or {}}))
    return folder / "model.zip"


@pytest.fixture(scope="module")
def good_run(tmp_path_factory) -> Path:
    return _save_run(tmp_path_factory.mktemp("run") / "good")


def test_a_consistent_run_loads(good_run):
    policy = load_policy(good_run)
    assert policy.action == "raw" and policy.obs_rms is not None


def test_missing_vecnormalize_is_refused_not_ignored(good_run, tmp_path, capsys):
    """``azimut eval --controllers ppo:PATH`` with ``vecnormalize.pkl`` missing ran the policy on
    unnormalised observations without a word."""
    run = tmp_path / "run"
    shutil.copytree(good_run.parent, run)
    (run / "vecnormalize.pkl").unlink()
    with pytest.raises(ValueError, match="no VecNormalize statistics beside it"):
        load_policy(run / "model.zip")
    code = main(["eval", "--controllers", f"ppo:{run / 'model.zip'}", "--tracks", "paper", "--no-plots",
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "no VecNormalize statistics" in err
    assert not (tmp_path / "out").exists()  # refused before any episode


def test_a_model_of_another_action_space_is_refused(tmp_path):
    """A model of another action space passed the argument check and then failed every episode."""
    model = _save_run(tmp_path / "run", action="raw", meta_action="residual")
    with pytest.raises(ValueError, match=r"the model acts in Box\(-1, 1, \(8,\)\), the 'residual' action space"):
        load_policy(model)


def test_observations_of_another_env_are_refused(tmp_path):
    model = _save_run(tmp_path / "a", meta_env_kwargs={"lookahead_count": 2})
    with pytest.raises(ValueError, match="the model observes"):
        load_policy(model)
    model = _save_run(tmp_path / "b", stats_env_kwargs={"lookahead_count": 2})
    with pytest.raises(ValueError, match="VecNormalize statistics are of observations of shape"):
        load_policy(model)


@pytest.mark.parametrize("text", ["[]", "{", '{"algo": "ppo", "action": "warp"}', '{"algo": "ppo", "env_kwargs": 3}'])
def test_a_broken_run_record_is_refused(good_run, tmp_path, text):
    run = tmp_path / "run"
    shutil.copytree(good_run.parent, run)
    (run / "run.json").write_text(text)
    with pytest.raises(ValueError, match="run.json"):
        load_policy(run / "model.zip")


def test_eval_resume_after_retraining_at_the_same_path_recomputes(tmp_path, capsys):
    """``eval --resume`` after retraining a model at the same path reused the old episodes (the
    episode key held only the path, not the model's content)."""
    from stable_baselines3 import PPO

    from train.envs import make_sb3_env

    model = _save_run(tmp_path / "run")
    argv = ["eval", "--controllers", f"ppo:{model}", "--tracks", "paper", "--max-time", "0.2", "--no-plots",
            "--out", str(tmp_path / "out")]
    assert main(argv) == 0 and "[1/1]" in capsys.readouterr().out
    assert main(argv + ["--resume"]) == 0 and "[1/1]" not in capsys.readouterr().out  # the same files: reused
    PPO("MlpPolicy", make_sb3_env("raw", 1, "paper"), seed=123, device="cpu").save(str(model))  # "retrained"
    assert main(argv + ["--resume"]) == 0 and "[1/1]" in capsys.readouterr().out  # a new episode
    assert main(argv + ["--resume"]) == 0 and "[1/1]" not in capsys.readouterr().out


@pytest.mark.parametrize("robot_args", [["--robot", "swerve"], ["--imperfections", "ideal"]],
                         ids=["another-preset", "other-imperfections"])
def test_a_policy_on_another_robot_than_it_learned_is_refused(good_run, tmp_path, capsys, robot_args):
    """The run learned the default robot (azimut3 with the paper's imperfections): evaluating it on
    another is refused in one line, before any episode, and nothing is written."""
    out = tmp_path / "eval"
    code = main(["eval", "--controllers", f"ppo:{good_run}", "--tracks", "circle", "--max-time", "0.2", "--no-plots",
                 "--out", str(out), *robot_args])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "trained on the robot azimut3" in err
    assert not out.exists()


def test_the_same_robot_named_another_way_is_accepted(good_run, tmp_path):
    """``--robot azimut3``, ``--imperfections paper`` and the shipped azimut3.toml are the default robot."""
    root = Path(__file__).resolve().parents[2]
    for robot_args in (["--robot", "azimut3"], ["--imperfections", "paper"],
                       ["--robot-file", str(root / "azimut_env" / "robots" / "azimut3.toml")]):
        assert main(["eval", "--controllers", f"ppo:{good_run}", "--tracks", "circle", "--max-time", "0.1",
                     "--no-plots", "--out", str(tmp_path / robot_args[0].strip("-")), *robot_args]) == 0


def test_a_model_loaded_as_the_other_algorithm_is_refused_by_name(good_run, tmp_path, capsys):
    code = main(["eval", "--controllers", f"sac:{good_run}", "--tracks", "circle", "--max-time", "0.1", "--no-plots",
                 "--out", str(tmp_path / "eval")])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "trained with PPO" in err and "ppo:PATH" in err
