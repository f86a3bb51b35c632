"""``train``: PPO and SAC train a few hundred steps, save, load and evaluate; CLI checks; and the
core (env, estimation, control) imports and runs without torch."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")


#: short training episodes (0.1 × the nominal lap) and 1 s evaluations keep the smoke test fast
SHORT = {"time_limit_factor": 0.1}


@pytest.mark.parametrize("algo,action", [("ppo", "raw"), ("sac", "residual")])
def test_train_save_load_evaluate(tmp_path, algo, action):
    from train.policy import load_policy
    from train.rollout import policy_metrics
    from train.trainer import train

    overrides = {"n_steps": 32, "batch_size": 64, "n_epochs": 1} if algo == "ppo" else \
        {"learning_starts": 64, "batch_size": 32, "gradient_steps": 1, "buffer_size": 2000}
    out = tmp_path / f"{algo}_{action}"
    record = train(algo, action, "random", seed=0, steps=256, out=out, num_robots=4, eval_tracks=("crab",),
                   eval_every=128, checkpoint_every=128, overrides=overrides, quiet=True, env_kwargs=SHORT,
                   eval_max_time=1.0)
    assert record["num_timesteps"] >= 256 and record["steps_per_s_in_learn"] > 0
    for name in ("model.zip", "vecnormalize.pkl", "run.json", "evaluations.json"):
        assert (out / name).is_file(), name
    assert list((out / "checkpoints").glob("model_*_steps.zip"))
    if importlib.util.find_spec("tensorboard") is not None:  # the rl extra installs it
        assert list((out / "tb").glob("events.out.tfevents.*")) and (out / "tb" / "progress.csv").is_file()
    policy = load_policy(out / "model.zip")
    assert policy.algo == algo and policy.action == action and policy.obs_rms is not None
    assert policy.env_kwargs == SHORT
    row, log = policy_metrics(policy, "crab", seed=1, max_time=1.0)
    assert {"return", "rms_lateral_m", "mean_antagonism_N", "mean_nullspace_force_N", "slip_energy_J"} <= set(row)
    assert np.isfinite(row["return"]) and log.t.size > 0
    evals = json.loads((out / "evaluations.json").read_text())
    assert evals[-1]["final"] and evals[-1]["rows"][0]["track"] == "crab"
    # Adam's fused kernel is asked for, and run.json's hyperparameters stay the ones given
    from stable_baselines3 import PPO, SAC
    model = (PPO if algo == "ppo" else SAC).load(str(out / "model.zip"), device="cpu")
    optimizers = [model.policy.optimizer] if algo == "ppo" else [model.actor.optimizer, model.critic.optimizer]
    assert all(opt.defaults["fused"] for opt in optimizers)
    assert "optimizer_kwargs" not in json.loads((out / "run.json").read_text())["hyperparams"].get("policy_kwargs", {})


def test_a_run_shorter_than_checkpoint_every_leaves_no_empty_checkpoints_folder(tmp_path):
    from train.trainer import train

    out = tmp_path / "short"
    train("ppo", "raw", "random", seed=0, steps=64, out=out, num_robots=2, eval_tracks=("crab",),
          eval_every=0, checkpoint_every=10_000, overrides={"n_steps": 32, "batch_size": 64, "n_epochs": 1},
          quiet=True, env_kwargs=SHORT, eval_max_time=0.5)
    assert (out / "model.zip").is_file() and not (out / "checkpoints").exists()


def test_ppo_says_what_steps_become_in_whole_rollouts(tmp_path, capsys):
    """SB3's PPO learns whole rollouts of n_steps x robots: a budget that is not a multiple of one
    is rounded up, and the run says so before it starts (and records both counts)."""
    import json

    from train.trainer import train

    out = tmp_path / "rounded"
    record = train("ppo", "raw", "crab", seed=0, steps=40, out=out, num_robots=2, eval_tracks=("crab",),
                   eval_every=0, checkpoint_every=0, overrides={"n_steps": 32, "batch_size": 64, "n_epochs": 1},
                   env_kwargs=SHORT, eval_max_time=0.5)
    said = capsys.readouterr().out
    assert "rollouts of n_steps x robots = 32 x 2 = 64 steps, so 40 steps become 64" in said
    assert record["num_timesteps"] == 64 and json.loads((out / "run.json").read_text())["steps"] == 40


def test_resume_continues_from_the_checkpoint(tmp_path):
    from train.trainer import train

    hp = {"n_steps": 32, "batch_size": 64, "n_epochs": 1}
    out = tmp_path / "run"
    train("ppo", "raw", "crab", seed=0, steps=128, out=out, num_robots=2, eval_tracks=("crab",), eval_every=0,
          checkpoint_every=64, overrides=hp, quiet=True, env_kwargs=SHORT, eval_max_time=1.0)
    (out / "model.zip").unlink()
    rec = train("ppo", "raw", "crab", seed=0, steps=256, out=out, num_robots=2, eval_tracks=("crab",), eval_every=0,
                checkpoint_every=64, overrides=hp, quiet=True, resume=True, env_kwargs=SHORT, eval_max_time=1.0)
    assert rec["resumed_from"] and rec["num_timesteps"] >= 256


def _short_run(out, algo="ppo", action="raw", steps=128, **kw):
    from train.trainer import train

    hp = {"n_steps": 32, "batch_size": 64, "n_epochs": 1} if algo == "ppo" else \
        {"learning_starts": 32, "batch_size": 32, "gradient_steps": 1, "buffer_size": 1000}
    return train(algo, action, "crab", seed=0, steps=steps, out=out, num_robots=2, eval_tracks=("crab",),
                 eval_every=0, checkpoint_every=64, overrides=hp, quiet=True, env_kwargs=SHORT, eval_max_time=0.5,
                 **kw)


def test_resume_steps_are_the_total_and_a_stopped_run_says_why(tmp_path):
    out = tmp_path / "run"
    first = _short_run(out)
    assert (out / "train_args.json").is_file() and first["num_timesteps"] == 128
    (out / "model.zip").unlink()  # interrupted after its checkpoint at 128 steps
    rec = _short_run(out, steps=256, resume=True)
    assert rec["resumed_from"].endswith("model_128_steps.zip")
    assert rec["num_timesteps"] == 256 and rec["complete"]  # 128 more, not 256 more
    limited = _short_run(tmp_path / "limited", steps=100_000, time_limit_min=1e-6)
    assert limited["stopped"] == "time_limit" and not limited["complete"]
    assert first["stopped"] is None


@pytest.mark.parametrize("flags,match", [(["--action", "residual"], "trained with --action raw, not residual"),
                                         (["--algo", "sac"], "trained with --algo ppo, not sac"),
                                         (["--imperfections", "ideal"],
                                          "robot azimut3 (its own imperfections), not azimut3 (imperfections ideal)"),
                                         (["--steps", "128"], "128 steps already, --steps 128 is the run's total")])
def test_resume_with_other_flags_is_refused_in_one_line(tmp_path, flags, match, capsys):
    from jobs.cli import main

    out = tmp_path / "run"
    _short_run(out)
    argv = ["train", "--out", str(out), "--resume", "--quiet", "--eval-every", "0", "--steps", "256",
            "--num-robots", "2"]
    rc = main(argv + flags)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and match in err[0], err


def test_resume_without_a_record_matches_the_checkpoints_own_data(tmp_path):
    from train.trainer import check_resume

    out = tmp_path / "run"
    _short_run(out)
    for name in ("train_args.json", "run.json"):  # a run of an earlier version, interrupted
        (out / name).unlink()
    with pytest.raises(ValueError, match="trained with --algo ppo, not sac"):
        check_resume(out, "sac", "raw", {})
    with pytest.raises(ValueError, match="trained with --action raw, not icr-rate"):
        check_resume(out, "ppo", "icr-rate", {})
    assert check_resume(out, "ppo", "raw", {"robot": "swerve"}).name == "model_128_steps.zip"  # robot: unknown


@pytest.mark.parametrize("argv", [["--algo", "dqn"], ["--action", "joystick"], ["--steps", "0"],
                                  ["--num-robots", "x"], ["--track", "moon"], ["--time-limit", "nan"],
                                  ["--resume"], ["--hyperparams", "/nonexistent.json"]])
def test_cli_refuses_bad_arguments_with_one_line(tmp_path, argv, capsys):
    from jobs.cli import main

    rc = main(["train", "--out", str(tmp_path / "o"), *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("azimut train: error:")


@pytest.mark.parametrize("algo,content,match", [
    ("ppo", {"bogus_key": 1}, "unknown PPO hyperparameter"), ("ppo", {"learning_rate": -1}, "learning_rate"),
    ("ppo", {"n_steps": "x"}, "n_steps"), ("ppo", {"n_steps": 1.5}, "integer"), ("ppo", {"gamma": 2}, "gamma"),
    ("ppo", {"seed": 3}, "cannot be set"), ("ppo", {"policy_kwargs": {"net_arch": "x"}}, "constructor"),
    ("ppo", {"use_sde": 1}, "true or false"), ("sac", {"tau": 0}, "tau"), ("sac", {"clip_range": 0.2}, "unknown SAC"),
])
def test_hyperparams_with_wrong_contents_refused_before_out_is_created(tmp_path, algo, content, match, capsys):
    """New-user trial: valid JSON with a wrong key, type or range gave exit 1, a traceback and an
    empty --out folder; now one line, exit 2, and no folder."""
    from jobs.cli import main

    hp = tmp_path / "hp.json"
    hp.write_text(json.dumps(content))
    rc = main(["train", "--algo", algo, "--hyperparams", str(hp), "--steps", "16", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("azimut train: error:") and match in err[0], err
    assert not (tmp_path / "o").exists()


def test_good_hyperparams_pass_the_check():
    from train.hyperparams import check_hyperparams

    assert check_hyperparams("ppo", "raw", {"n_steps": 128, "learning_rate": 1e-4})["n_steps"] == 128
    assert check_hyperparams("sac", "residual", {"ent_coef": "auto_0.1"})["ent_coef"] == "auto_0.1"


def test_core_imports_and_runs_without_torch():
    code = textwrap.dedent("""
        import sys, importlib.abc
        class Block(importlib.abc.MetaPathFinder):
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in ("torch", "stable_baselines3"):
                    raise ImportError(f"{name} blocked")
                return None
        sys.meta_path.insert(0, Block())
        import numpy as np, gymnasium as gym
        import azimut_env, estimation, control, train
        import jobs.eval.command, control.action_spaces.vector, train.envs, train.hyperparams
        env = gym.make("Azimut-v2", track="crab")
        env.reset(seed=0)
        for _ in range(5):
            env.step(env.action_space.sample())
        from azimut_env.vector_env import AzimutVectorEnv
        from control.action_spaces.vector import VectorControllerAction
        v = VectorControllerAction(AzimutVectorEnv(num_envs=2, track="crab"), action="residual")
        v.reset(seed=0)
        v.step(np.zeros((2, 3)))
        assert "torch" not in sys.modules and "stable_baselines3" not in sys.modules
        from jobs.cli import main
        assert main(["train", "--out", "/tmp/x"]) == 2  # refused in one line: the rl extra is missing
        print("ok")
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0 and res.stdout.strip().endswith("ok"), res.stderr[-2000:]
    assert "needs stable_baselines3" in res.stderr


def test_eval_runs_a_trained_policy_next_to_the_controllers(tmp_path):
    from jobs.cli import main
    from train.trainer import train

    out = tmp_path / "run"
    train("ppo", "raw", "crab", seed=0, steps=64, out=out, num_robots=2, eval_tracks=("crab",), eval_every=0,
          checkpoint_every=0, overrides={"n_steps": 32, "batch_size": 64, "n_epochs": 1}, quiet=True,
          env_kwargs=SHORT, eval_max_time=1.0)
    report = tmp_path / "eval"
    rc = main(["eval", "--controllers", f"icr,ppo:{out / 'model.zip'}", "--tracks", "crab", "--max-time", "0.5",
               "--no-plots", "--out", str(report)])
    assert rc in (0, 1)
    episodes = json.loads((report / "metrics.json").read_text())["episodes"]
    by = {e["controller"]: e for e in episodes}
    assert set(by) == {"icr", "run"}  # a policy is named after its run folder
    for row in by.values():
        assert row["status"] == "ok" and np.isfinite(row["return"]) and "mean_antagonism_N" in row
    named = tmp_path / "named"
    assert main(["eval", "--controllers", f"ppo:tiny={out}", "--tracks", "crab", "--max-time", "0.5", "--no-plots",
                 "--out", str(named)]) in (0, 1)
    rows = json.loads((named / "metrics.json").read_text())["episodes"]
    assert [r["controller"] for r in rows] == ["tiny"] and rows[0]["return"] == by["run"]["return"]
    # the short name's spec (the policy's path) is in the report and metrics.json
    campaign = json.loads((named / "metrics.json").read_text())["campaign"]
    assert campaign["controller_specs"] == {"tiny": f"ppo:tiny={out}"}
    assert f"tiny = ppo:tiny={out};" in (named / "report.md").read_text()
    assert main(["eval", "--controllers", f"ppo:{tmp_path / 'missing.zip'}", "--out", str(report)]) == 2
    assert main(["eval", "--controllers", f"ppo:{out}", "--speed-scale", "0.5", "--out", str(report)]) == 2
    assert main(["eval", "--controllers", f"ppo:{out},ppo:run={out}", "--out", str(report)]) == 2
