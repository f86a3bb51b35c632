"""Ship trained policies small: ``python -m jobs.training.ship SRC DST`` (the ``rl`` extra).

``SRC`` is an ``azimut train`` run folder (``model.zip``, ``vecnormalize.pkl``, ``run.json``) or an
``azimut train --seeds`` folder (its complete ``seed_<n>/`` runs); ``DST`` gets the same layout,
so ``azimut eval --controllers ppo:NAME=DST`` runs the shipped seeds as it would the trained ones.

A shipped model keeps what acts and drops what only learns:

* the optimiser state (Adam's moment estimates: twice the weights) is emptied;
* the networks a deterministic action does not use are zeroed: PPO's value branch
  (``mlp_extractor.value_net``, ``value_net``), SAC's twin critics and their target copies
  (``critic``, ``critic_target``);
* the archive is written deflated (SB3 stores its entries uncompressed; zeroed weights then take
  almost no room).

So a shipped PPO model is about a third of the trained one, and a shipped SAC model (``[256,
256]`` networks) a fifth. It acts exactly as the trained model: :func:`ship_run` checks the
deterministic actions of both on observations drawn around the run's normalisation statistics,
bit for bit, before it writes ``run.json``. It cannot resume training (no value function, no
optimiser state): that needs the full run folder. ``run.json`` is the run's record with a
``"shipped"`` entry saying what was dropped, from where, and the archive's size before and after.

``python -m jobs.training.ship --rows METRICS.json OUT.json GROUP=PREFIX:PATH ...`` records the rows
that the shipped models must reproduce (:func:`record_rows`): the deterministic metrics of every
episode of those groups (and of the reference controllers) in an ``azimut eval`` ``metrics.json``,
with the evaluation's commit and command.
"""

from __future__ import annotations

import json
import shutil
import sys
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["ship_run", "ship", "slim_model", "record_rows", "NOT_ACTING", "ROW_METRICS"]

#: the per-episode metrics :func:`record_rows` keeps (deterministic for a seed and commit)
ROW_METRICS = ("completed", "error", "completion_time_s", "rms_lateral_m", "max_lateral_m", "rms_heading_rad",
               "slip_energy_J", "mean_antagonism_N", "mean_nullspace_force_N", "standstill_share",
               "limit_violation_steps", "reconfigure_events", "return")

#: per algorithm, the policy's sub-modules a deterministic action does not use (zeroed when shipped)
NOT_ACTING = {"ppo": ("mlp_extractor.value_net", "value_net"), "sac": ("critic", "critic_target")}


def slim_model(model, algo: str) -> list[str]:
    """Empty ``model``'s optimiser states and zero its :data:`NOT_ACTING` modules, in place;
    returns the names of the zeroed parameters (``policy.<module>.<param>``)."""
    import torch

    optimizers = [model.policy.optimizer] if algo == "ppo" else [model.actor.optimizer, model.critic.optimizer]
    if getattr(model, "ent_coef_optimizer", None) is not None:
        optimizers.append(model.ent_coef_optimizer)
    for opt in optimizers:
        opt.state.clear()
    zeroed = []
    with torch.no_grad():
        for prefix in NOT_ACTING[algo]:
            module = model.policy.get_submodule(prefix)
            for name, p in module.named_parameters():
                p.zero_()
                zeroed.append(f"policy.{prefix}.{name}")
    return zeroed


def _deflate(path: Path) -> None:
    """Rewrite the zip archive ``path`` with its entries deflated (same names, same contents)."""
    with zipfile.ZipFile(path) as src:
        entries = [(info, src.read(info.filename)) for info in src.infolist()]
    tmp = path.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=9) as dst:
        for info, data in entries:
            dst.writestr(info.filename, data)
    tmp.replace(path)


def _probe_observations(vecnormalize: Path, n: int = 512) -> np.ndarray:
    """``n`` normalised observations drawn around the run's statistics (mean ± 2 standard
    deviations per entry, clipped as the policy sees them), seeded."""
    import pickle

    with open(vecnormalize, "rb") as fh:
        stats = pickle.load(fh)
    rng = np.random.default_rng(0)
    z = rng.normal(0.0, 2.0, size=(n, np.size(stats.obs_rms.mean)))
    return np.clip(z, -stats.clip_obs, stats.clip_obs).astype(np.float32)


def ship_run(src: Path, dst: Path) -> dict:
    """Ship the run folder ``src`` into ``dst`` (see the module docstring); returns the shipped
    ``run.json``. ``ValueError`` (one line) for a folder without a complete run."""
    from stable_baselines3 import PPO, SAC

    from train.saved_files import check_model_file, check_vecnormalize_file

    src, dst = Path(src), Path(dst)
    run_file = src / "run.json"
    if not run_file.is_file():
        raise ValueError(f"{src}: no run.json (not an azimut train run folder)")
    record = json.loads(run_file.read_text())
    algo = record.get("algo")
    if algo not in NOT_ACTING or record.get("engine", "sb3") != "sb3":
        raise ValueError(f"{src}: ships Stable-Baselines3 PPO and SAC runs, not {record.get('engine', 'sb3')} {algo}")
    if record.get("complete") is False:
        raise ValueError(f"{src}: the run stopped before its step budget (run.json 'complete': false)")
    model_path = check_model_file(src / "model.zip")
    vn = check_vecnormalize_file(src / "vecnormalize.pkl" if (src / "vecnormalize.pkl").is_file() else None,
                                 model_path)
    cls = PPO if algo == "ppo" else SAC
    trained = cls.load(str(model_path), device="cpu")
    obs = _probe_observations(vn)
    want, _ = trained.predict(obs, deterministic=True)
    zeroed = slim_model(trained, algo)
    dst.mkdir(parents=True, exist_ok=True)
    out = dst / "model.zip"
    trained.save(str(out))
    _deflate(out)
    got, _ = cls.load(str(out), device="cpu").predict(obs, deterministic=True)
    if not np.array_equal(want, got):
        raise RuntimeError(f"{src}: the shipped model does not act as the trained one (max difference "
                           f"{np.max(np.abs(want - got)):.3g})")
    shutil.copyfile(vn, dst / "vecnormalize.pkl")
    record["shipped"] = {"from": str(src), "optimizer_state": "dropped",
                         "zeroed": [f"policy.{m}" for m in NOT_ACTING[algo]],
                         "zeroed_parameters": len(zeroed), "trained_bytes": model_path.stat().st_size,
                         "shipped_bytes": out.stat().st_size,
                         "check": f"deterministic actions equal to the trained model's on {len(obs)} observations"}
    (dst / "run.json").write_text(json.dumps(record, indent=1, allow_nan=True, default=str) + "\n")
    return record


def ship(src: Path, dst: Path) -> list[dict]:
    """Ship a run folder, or every complete seed of an ``azimut train --seeds`` folder into
    ``dst/seed_<n>/``; returns the shipped records."""
    src, dst = Path(src), Path(dst)
    if (src / "model.zip").is_file():
        return [ship_run(src, dst)]
    seeds = sorted((p for p in src.glob("seed_*") if (p / "model.zip").is_file()),
                   key=lambda p: int(p.name.split("_", 1)[1]) if p.name.split("_", 1)[1].isdigit() else -1)
    if not seeds:
        raise ValueError(f"{src}: neither a run folder (model.zip) nor a --seeds folder (seed_<n>/model.zip)")
    return [ship_run(p, dst / p.name) for p in seeds
            if json.loads((p / "run.json").read_text()).get("complete", True) is not False]


def record_rows(metrics_json: Path, models: dict[str, tuple[str, str]], out: Path, command: str) -> dict:
    """Write ``out``: ``{"commit", "command", "models": {group: {"prefix", "path"}}, "rows": [...]}``,
    the rows the episodes of ``metrics_json`` (an ``azimut eval`` ``metrics.json``) give for the
    controllers of ``models`` (group -> (``ppo``/``sac``, the shipped ``--seeds`` folder), the
    group's controllers named ``GROUP.s<n>``) and for the other controllers of that evaluation (the
    references), with :data:`ROW_METRICS`; ``command`` is the ``azimut eval`` command that wrote it.
    ``ValueError`` if a group has no episode, an episode failed or the evaluation ran on local changes."""
    from jobs.records import write_json

    data = json.loads(Path(metrics_json).read_text())
    campaign = data.get("campaign", {})
    rows = []
    for ep in data["episodes"]:
        if ep.get("status") != "ok":
            raise ValueError(f"{metrics_json}: episode {ep['controller']} {ep['track']} seed {ep['seed']} failed")
        rows.append({"controller": ep["controller"], "track": ep["track"], "seed": ep["seed"],
                     **{k: ep.get(k) for k in ROW_METRICS}})
    for group in models:
        if not any(r["controller"].startswith(group + ".s") for r in rows):
            raise ValueError(f"{metrics_json}: no episode of {group}.s<n>")
    prov = campaign.get("provenance") or {}
    if prov.get("local_changes"):
        raise ValueError(f"{metrics_json}: evaluated with uncommitted local changes: no commit reproduces it")
    record = {"commit": prov.get("commit"), "command": command, "controller_specs": campaign.get("controller_specs"),
              "models": {g: {"prefix": prefix, "path": str(path)} for g, (prefix, path) in models.items()},
              "rows": rows}
    write_json(Path(out), record)
    return record


def _main_rows(argv: list[str]) -> int:
    if len(argv) < 5 or argv[2] != "--command":
        print("usage: python -m jobs.training.ship --rows METRICS.json OUT.json --command 'azimut eval ...' "
              "GROUP=PREFIX:PATH ...", file=sys.stderr)
        return 2
    models = {}
    for item in argv[4:]:
        group, _, spec = item.partition("=")
        prefix, _, path = spec.partition(":")
        if not group or prefix not in NOT_ACTING or not path:
            print(f"ship: error: {item!r} is not GROUP=PREFIX:PATH (PREFIX ppo or sac)", file=sys.stderr)
            return 2
        models[group] = (prefix, path)
    try:
        rec = record_rows(Path(argv[0]), models, Path(argv[1]), argv[3])
    except (ValueError, OSError, KeyError) as exc:
        print(f"ship: error: {exc}", file=sys.stderr)
        return 2
    print(f"{len(rec['rows'])} rows recorded in {argv[1]}", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--rows"]:
        return _main_rows(argv[1:])
    if len(argv) != 2:
        print("usage: python -m jobs.training.ship SRC DST", file=sys.stderr)
        return 2
    try:
        records = ship(Path(argv[0]), Path(argv[1]))
    except ValueError as exc:
        print(f"ship: error: {exc}", file=sys.stderr)
        return 2
    for rec in records:
        s = rec["shipped"]
        print(f"{s['from']} -> {argv[1]}: {s['trained_bytes'] / 1024:.0f} KB -> {s['shipped_bytes'] / 1024:.0f} KB",
              flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
