"""``azimut tune`` end to end (slow) and ``azimut train --engine rllib`` on a local Ray instance
(run where Ray RLlib is installed: ``.ci/run`` runs it in a venv of its own, ``-k rllib``)."""

from __future__ import annotations

import importlib.util
import json

import pytest

from jobs.cli import main


def _rllib_importable() -> bool:
    try:
        import ray.rllib  # noqa: F401
    except Exception:  # noqa: BLE001 (a missing dependency of RLlib raises ImportError or others)
        return False
    return True


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("optuna") is None or importlib.util.find_spec("stable_baselines3") is None,
                    reason="needs the tune and rl extras")
def test_tune_four_trials_end_to_end_and_train_reads_its_best(tmp_path):
    """``azimut tune --trials 4 --steps 20000`` (minutes on a quiet machine): 4 trials in the
    SQLite study, trials.json, best_hyperparams.json; ``azimut train --hyperparams`` takes it."""
    import optuna

    out = tmp_path / "tune"
    assert main(["tune", "--trials", "4", "--steps", "20000", "--out", str(out), "--eval-tracks", "crab",
                 "--num-robots", "8"]) == 0
    best = json.loads((out / "best_hyperparams.json").read_text())
    assert best["format"] == "azimut-hyperparams" and best["algo"] == "ppo" and best["action"] == "residual"
    study = optuna.load_study(study_name="tune-ppo-residual", storage=f"sqlite:///{out / 'study.db'}")
    assert len(study.trials) == 4 and best["trial"] == study.best_trial.number
    assert len(json.loads((out / "trials.json").read_text())["trials"]) == 4
    run = tmp_path / "run"
    assert main(["train", "--action", "residual", "--hyperparams", str(out / "best_hyperparams.json"), "--steps",
                 "256", "--num-robots", "2", "--eval-every", "0", "--checkpoint-every", "0", "--eval-tracks", "crab",
                 "--quiet", "--out", str(run)]) == 0
    rec = json.loads((run / "run.json").read_text())
    assert all(rec["hyperparams"][k] == v for k, v in best["hyperparams"].items() if k != "policy_kwargs")


@pytest.mark.skipif(not _rllib_importable(), reason="needs Ray RLlib (the rllib extra, in a venv of its own)")
def test_rllib_engine_trains_on_a_local_ray_instance_and_its_model_runs_in_eval(tmp_path):
    """``azimut train --engine rllib --steps 20000`` on a local Ray instance (one remote env
    runner): run folder as an SB3 run's, the exported policy equal to the RLModule's (checked when
    written), and ``azimut eval --controllers ppo:NAME=OUT`` runs it."""
    out = tmp_path / "rllib"
    assert main(["train", "--engine", "rllib", "--steps", "20000", "--num-robots", "8", "--eval-tracks", "crab",
                 "--eval-every", "10000", "--quiet", "--out", str(out)]) == 0
    rec = json.loads((out / "run.json").read_text())
    assert rec["engine"] == "rllib" and rec["complete"] and rec["num_timesteps"] >= 20000
    evals = json.loads((out / "evaluations.json").read_text())
    assert evals[-1]["final"] and len(evals) >= 2 and (out / "model.pt").is_file()
    report = tmp_path / "eval"
    assert main(["eval", "--controllers", f"icr,ppo:rl={out}", "--tracks", "crab", "--max-time", "2", "--no-plots",
                 "--out", str(report)]) == 0
    rows = json.loads((report / "metrics.json").read_text())["episodes"]
    assert {r["controller"] for r in rows} == {"icr", "rl"} and all(r["status"] == "ok" for r in rows)
