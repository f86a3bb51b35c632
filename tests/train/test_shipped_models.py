"""The trained models behind ``docs/results/rl.md``, shipped in ``docs/results/rl/models/`` (one
``azimut train --seeds`` layout per agent group, made small by :mod:`jobs.training.ship`), reproduce
their recorded rows (``docs/results/rl/eval_rows.json``, the per-episode metrics of the results'
``azimut eval`` run) through ``azimut eval --controllers ppo:NAME=PATH``.

The default run checks the first seed of every group on ``circle`` (one ``azimut eval``); ``-m slow``
checks the other seeds.
A change of the physics, the reward or the controllers moves these rows: re-run the results'
evaluation (its command is in ``eval_rows.json`` and on the results page) and re-record them."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import pytest

from jobs.cli import main

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "docs" / "results" / "rl"
ROWS = RESULTS / "eval_rows.json"
#: the metrics compared, all deterministic for a seed and commit
METRICS = ("completed", "completion_time_s", "rms_lateral_m", "max_lateral_m", "slip_energy_J", "mean_antagonism_N",
           "mean_nullspace_force_N", "return")
#: the track of the check: every group's agents finish it, within a 20 s lap
TRACK = "circle"

pytestmark = pytest.mark.skipif(importlib.util.find_spec("stable_baselines3") is None,
                                reason="needs the rl extra")


def _record() -> dict:
    return json.loads(ROWS.read_text())


def _models(first: bool) -> list[tuple[str, str]]:
    """(controller name GROUP.s<n>, spec) of every group's first shipped seed, or of the others."""
    if not ROWS.is_file():
        return []
    out = []
    for group, info in _record()["models"].items():
        seeds = sorted(int(p.name.split("_")[1]) for p in (ROOT / info["path"]).glob("seed_*"))
        for seed in seeds[:1] if first else seeds[1:]:
            name = f"{group}.s{seed}"
            out.append((name, f"{info['prefix']}:{name}={ROOT / info['path'] / f'seed_{seed}'}"))
    return out


def test_the_record_names_shipped_small_models_for_every_group():
    rec = _record()
    assert {"commit", "command", "models", "rows"} <= set(rec) and rec["commit"]
    total = 0
    for group, info in rec["models"].items():
        folder = ROOT / info["path"]
        seeds = sorted(folder.glob("seed_*"))
        assert len(seeds) >= 5, f"{group}: {len(seeds)} seeds shipped"
        for s in seeds:
            for f in ("model.zip", "vecnormalize.pkl", "run.json"):
                assert (s / f).is_file(), s / f
            run = json.loads((s / "run.json").read_text())
            assert run["complete"] and run["num_timesteps"] >= run["steps"] and run["shipped"]["optimizer_state"]
            size = (s / "model.zip").stat().st_size
            assert size < 400_000, f"{s}: {size} bytes"
            total += sum(p.stat().st_size for p in s.iterdir())
            rows = [r for r in rec["rows"] if r["controller"] == f"{group}.{s.name.replace('seed_', 's')}"]
            assert rows, f"no recorded row of {group} {s.name}"
    assert total < 6_000_000


@pytest.mark.parametrize("first", [pytest.param(True, id="first-seeds"),
                                   pytest.param(False, id="other-seeds", marks=pytest.mark.slow)])
def test_shipped_models_reproduce_their_recorded_rows(first, tmp_path):
    """One ``azimut eval`` of the shipped models (every group's first seed; ``-m slow``: the
    other seeds) on ``circle``, evaluation seed 0: each row equals the recorded one."""
    rec = _record()
    models = _models(first)
    assert models
    out = tmp_path / "eval"
    assert main(["eval", "--controllers", ",".join(spec for _, spec in models), "--tracks", TRACK, "--seed", "0",
                 "--no-plots", "--out", str(out)]) == 0
    got = {r["controller"]: r for r in json.loads((out / "metrics.json").read_text())["episodes"]}
    assert set(got) == {name for name, _ in models}
    for name, _ in models:
        want = [r for r in rec["rows"] if r["controller"] == name and r["track"] == TRACK and r["seed"] == 0]
        assert len(want) == 1, f"no recorded {TRACK} row of {name} on evaluation seed 0"
        assert got[name]["status"] == "ok", got[name]
        for key in METRICS:
            w, g = want[0][key], got[name][key]
            if isinstance(w, float) and isinstance(g, float):
                assert math.isclose(g, w, rel_tol=1e-9, abs_tol=1e-12), f"{name} {key}: {g!r} != recorded {w!r}"
            else:
                assert g == w, f"{name} {key}: {g!r} != recorded {w!r}"


@pytest.mark.parametrize("group", ["ppo-raw", "sac-residual"])
def test_a_policy_acts_on_a_batch_as_on_each_row_alone(group):
    """A deterministic action of a robot does not depend on the other rows of its batch (PyTorch's
    batched products round with the batch size): an episode of a batched campaign is the episode
    stepped alone."""
    import numpy as np

    from train.policy import load_policy

    policy = load_policy(RESULTS / "models" / group / "seed_0")
    obs = np.random.default_rng(0).normal(size=(33, *policy.model.observation_space.shape)).astype(np.float32)
    batch = policy.act(obs)
    alone = np.concatenate([policy.act(obs[i:i + 1]) for i in range(len(obs))])
    assert np.array_equal(batch, alone)
