"""``azimut train --seeds``: one agent per seed as campaign tasks, learning curves over seeds."""

from __future__ import annotations

import json

import pytest

from jobs.cli import main

pytest.importorskip("stable_baselines3")


def test_learning_curve_stats_over_seeds():
    from jobs.training.seeds import learning_curve_stats

    hist = [[{"timesteps": 10, "mean_return": 1.0}, {"timesteps": 20, "mean_return": 3.0}],
            [{"timesteps": 10, "mean_return": 2.0}, {"timesteps": 20, "mean_return": 5.0},
             {"timesteps": 30, "mean_return": 9.0}]]
    curve = learning_curve_stats(hist)
    assert [c["timesteps"] for c in curve] == [10, 20]  # only the steps every seed reached
    assert curve[1]["mean"] == 4.0 and curve[1]["n"] == 2 and 3.0 <= curve[1]["lo"] <= 4.0 <= curve[1]["hi"] <= 5.0
    assert learning_curve_stats([]) == []


@pytest.mark.parametrize("flags", [["--seeds", "0,0"], ["--seeds", "0-1", "--seed", "3"],
                                   ["--seeds", "1", "--workers", "0"],
                                   ["--seeds", "0-1", "--ray-address", "auto", "--executor", "process"],
                                   ["--workers", "2"], ["--executor", "ray"], ["--ray-address", "auto"],
                                   ["--retries", "3"]])
def test_train_refuses_bad_seed_flags(flags, tmp_path, capsys):
    assert main(["train", "--out", str(tmp_path / "o")] + flags) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("azimut train: error:")


def test_train_refuses_to_overwrite_a_trained_seed(tmp_path, capsys):
    (tmp_path / "o" / "seed_1").mkdir(parents=True)
    (tmp_path / "o" / "seed_1" / "model.zip").write_text("x")
    assert main(["train", "--out", str(tmp_path / "o"), "--seeds", "0,1"]) == 2
    assert "seed_1" in capsys.readouterr().err


def test_resuming_a_seed_with_another_action_is_refused(tmp_path, capsys):
    from train.trainer import train

    train("ppo", "raw", "crab", seed=1, steps=64, out=tmp_path / "o" / "seed_1", num_robots=2,
          eval_tracks=("crab",), eval_every=0, checkpoint_every=64, quiet=True, eval_max_time=0.5,
          overrides={"n_steps": 32, "batch_size": 64, "n_epochs": 1})
    (tmp_path / "o" / "seed_1" / "model.zip").unlink()  # interrupted after its checkpoint
    assert main(["train", "--out", str(tmp_path / "o"), "--seeds", "0,1", "--resume", "--action", "icr-rate"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "seed_1 was trained with --action raw, not icr-rate" in err[0]


@pytest.mark.slow
def test_two_seeds_on_two_workers_equal_the_serial_runs(tmp_path):
    """Two tiny PPO runs per executor (about a minute on a quiet machine): the same final metrics
    and learning curve serially and on 2 worker processes; report and plot written."""
    import jobs.training.command as tcli
    from jobs.cli import CommandParser
    from jobs.training.seeds import run_seeds

    hp = tmp_path / "hp.json"
    hp.write_text(json.dumps({"n_steps": 32, "batch_size": 64, "n_epochs": 1}))
    results = {}
    for executor in ("serial", "process"):
        parser = CommandParser()
        tcli.add_arguments(parser)
        out = tmp_path / executor
        args = parser.parse_args(["--out", str(out), "--seeds", "0,1", "--steps", "128", "--num-robots", "2",
                                  "--eval-tracks", "crab", "--eval-every", "64", "--checkpoint-every", "0",
                                  "--hyperparams", str(hp), "--workers", "2", "--executor", executor, "--quiet"])
        tcli.check_args(args)
        assert run_seeds(args, args.seeds, env_kwargs={"time_limit_factor": 0.1}) == 0
        data = json.loads((out / "seeds.json").read_text())
        results[executor] = ([r["run"]["final_eval"] for r in data["runs"]], data["learning_curve"])
        assert (out / "report.md").is_file() and (out / "seed_1" / "model.zip").is_file()
        assert data["learning_curve"][-1]["n"] == 2
    assert results["process"] == results["serial"]
