"""``jobs.training.ship``: a shipped model acts as the trained one (its evaluation row equal, bit for
bit) at a fraction of the size; incomplete runs and evaluations on local changes are refused; and
the learning curves over seeds (``python -m jobs.training.plots --seeds``) are the IQM over seeds."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from jobs.cli import main  # noqa: E402
from jobs.training.ship import main as ship_main  # noqa: E402
from jobs.training.ship import record_rows, ship  # noqa: E402

SHORT = {"time_limit_factor": 0.1}
HP = {"ppo": {"n_steps": 32, "batch_size": 64, "n_epochs": 1},
      "sac": {"learning_starts": 64, "batch_size": 32, "gradient_steps": 1, "buffer_size": 2000}}


def _train(out: Path, algo: str, seed: int = 0) -> Path:
    from train.trainer import train

    train(algo, "residual", "circle", seed=seed, steps=256, out=out, num_robots=2, eval_tracks=("crab",),
          eval_every=0, checkpoint_every=0, overrides=HP[algo], quiet=True, env_kwargs=SHORT, eval_max_time=1.0)
    return out


def _eval_row(spec: str, out: Path) -> dict:
    assert main(["eval", "--controllers", spec, "--tracks", "crab", "--max-time", "2", "--no-plots", "--out",
                 str(out)]) == 0
    rows = json.loads((out / "metrics.json").read_text())["episodes"]
    assert len(rows) == 1 and rows[0]["status"] == "ok"
    return {k: v for k, v in rows[0].items() if k not in ("controller", "attempts")}


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_a_shipped_model_acts_as_the_trained_one_and_is_smaller(tmp_path, algo):
    run = _train(tmp_path / "run", algo)
    rec = ship(run, tmp_path / "shipped")[0]
    shipped = tmp_path / "shipped"
    assert {p.name for p in shipped.iterdir()} == {"model.zip", "vecnormalize.pkl", "run.json"}
    s = rec["shipped"]
    assert s["shipped_bytes"] < 0.4 * s["trained_bytes"] and s["optimizer_state"] == "dropped"
    assert s["zeroed"] == (["policy.mlp_extractor.value_net", "policy.value_net"] if algo == "ppo"
                           else ["policy.critic", "policy.critic_target"])
    assert json.loads((shipped / "run.json").read_text())["shipped"] == s
    assert _eval_row(f"{algo}:m={shipped}", tmp_path / "e1") == _eval_row(f"{algo}:m={run}", tmp_path / "e0")


def test_ship_keeps_the_seeds_layout_and_refuses_incomplete_runs(tmp_path, capsys):
    seeds = tmp_path / "seeds"
    for seed in (0, 1):
        _train(seeds / f"seed_{seed}", "ppo", seed)
    rec = json.loads((seeds / "seed_1" / "run.json").read_text())
    (seeds / "seed_1" / "run.json").write_text(json.dumps({**rec, "complete": False}))
    assert [r["seed"] for r in ship(seeds, tmp_path / "out")] == [0]
    assert not (tmp_path / "out" / "seed_1").exists()
    assert ship_main([str(seeds / "seed_1"), str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "step budget" in err[0] and not (tmp_path / "x").exists()
    assert ship_main([str(tmp_path / "nothing"), str(tmp_path / "y")]) == 2


def _metrics(tmp_path: Path, local_changes: bool = False, status: str = "ok") -> Path:
    eps = [{"controller": c, "track": "circle", "seed": 0, "status": status, "completed": True, "return": 1.0,
            "rms_lateral_m": 0.002, "extra": 5} for c in ("icr", "g.s0", "g.s1")]
    f = tmp_path / "metrics.json"
    f.write_text(json.dumps({"campaign": {"provenance": {"commit": "abc", "local_changes": local_changes},
                                          "controller_specs": {"g.s0": "ppo:g.s0=P/seed_0"}}, "episodes": eps}))
    return f


def test_record_rows_keeps_the_deterministic_metrics_and_refuses_local_changes(tmp_path):
    rec = record_rows(_metrics(tmp_path), {"g": ("ppo", "P")}, tmp_path / "rows.json", "azimut eval X")
    assert rec["commit"] == "abc" and rec["command"] == "azimut eval X" and rec["models"] == {
        "g": {"prefix": "ppo", "path": "P"}}
    assert [r["controller"] for r in rec["rows"]] == ["icr", "g.s0", "g.s1"] and "extra" not in rec["rows"][0]
    assert json.loads((tmp_path / "rows.json").read_text()) == rec
    with pytest.raises(ValueError, match="local changes"):
        record_rows(_metrics(tmp_path, local_changes=True), {"g": ("ppo", "P")}, tmp_path / "r.json", "c")
    with pytest.raises(ValueError, match="failed"):
        record_rows(_metrics(tmp_path, status="failed"), {"g": ("ppo", "P")}, tmp_path / "r.json", "c")
    with pytest.raises(ValueError, match="no episode"):
        record_rows(_metrics(tmp_path), {"h": ("ppo", "P")}, tmp_path / "r.json", "c")


def test_seed_curve_is_the_iqm_over_complete_seeds(tmp_path):
    from jobs.campaign.statistics import iqm
    from jobs.training.plots import _main, seed_curve

    values = {0: [1.0, 2.0], 1: [3.0, 5.0], 2: [2.0, 9.0], 3: [4.0, 4.0], 4: [100.0, 0.0]}
    for seed, (a, b) in values.items():
        d = tmp_path / f"seed_{seed}"
        d.mkdir()
        (d / "run.json").write_text(json.dumps({"complete": seed != 4}))
        other = {"mean_antagonism_N": 1.0, "rms_lateral_m": 0.01, "return": 0.0, "mean_sq_action": 0.01}
        ev = [{"timesteps": t, "mean_return": v,
               "rows": [{"track": "circle", "mean_nullspace_force_N": 2 * v, **other},
                        {"track": "crab", "mean_nullspace_force_N": 0.0, **other}]}
              for t, v in ((100, a), (200, b))]
        (d / "evaluations.json").write_text(json.dumps(ev))
    curve = seed_curve(tmp_path, None, "return")
    assert [c["timesteps"] for c in curve] == [100, 200]
    assert curve[1]["scores"] == [2.0, 5.0, 9.0, 4.0] and curve[1]["iqm"] == iqm([2.0, 5.0, 9.0, 4.0]) == 4.5
    assert curve[1]["lo"] <= 4.5 <= curve[1]["hi"]
    assert [c["iqm"] for c in seed_curve(tmp_path, "circle", "mean_nullspace_force_N")] == [5.0, 9.0]
    assert seed_curve(tmp_path, None, "mean_nullspace_force_N")[0]["scores"] == [1.0, 3.0, 2.0, 4.0]
    pytest.importorskip("matplotlib")
    assert _main(["--seeds", str(tmp_path / "c.png"), f"g={tmp_path}"]) == 0 and (tmp_path / "c.png").stat().st_size
    assert _main(["--seeds", str(tmp_path / "e.png"), "--drift", f"g={tmp_path}"]) == 0
    assert (tmp_path / "e.png").is_file()
    assert _main(["--seeds", str(tmp_path / "d.png"), "no-equals-sign"]) == 2
    assert np.isfinite(curve[0]["iqm"])
