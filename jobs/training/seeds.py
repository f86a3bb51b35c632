"""``azimut train --seeds 0,1,2``: one agent per seed, run as tasks of :mod:`jobs.campaign.engine`
(serially, on local processes or on Ray), and learning curves as mean ± interval over seeds.

Each seed trains into ``OUT/seed_<n>/`` exactly as ``azimut train --seed n --out OUT/seed_<n>``
would (the task's key holds every argument that changes the result; SB3 and the env are seeded
from it). ``OUT/seeds.json`` (strict JSON) holds the per-seed run records, the aggregates and the
provenance, ``OUT/report.md`` the final evaluation metrics (mean over seeds per track, with a 95%
bootstrap interval where several seeds differ) and a definition of every column, and
``OUT/learning_curves.png`` the evaluation mean return against environment steps, mean over seeds
with its interval (the practice of Agarwal et al., *Deep Reinforcement Learning at the Edge of
the Statistical Precipice*, NeurIPS 2021).

With ``--ray-address`` the seeds run on the cluster's nodes and write their run folders there:
``OUT`` must be a path every node can write (a shared file system).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["train_seed_task", "seed_tasks", "learning_curve_stats", "check_seed_args", "run_seeds"]

#: metrics of the final evaluation summarised over seeds: (key, format, scale); headers from jobs.glossary
FINAL_COLUMNS = [("return", "{:.1f}", 1.0), ("completed", "{:.2f}", 1.0), ("rms_lateral_m", "{:.2f}", 100.0),
                 ("mean_antagonism_N", "{:.2f}", 1.0), ("mean_nullspace_force_N", "{:.2f}", 1.0),
                 ("slip_energy_J", "{:.2f}", 1.0)]


def train_seed_task(algo: str, action: str, track: str, seed: int, steps: int, num_robots: int,
                    eval_tracks: list[str], eval_every: int, checkpoint_every: int, overrides: dict | None,
                    time_limit_min: float, out: str, env_kwargs: dict | None = None, torch_threads: int = 1,
                    resume: bool = False, quiet: bool = True, correction_cost: float = 0.0,
                    env_threads: int | None = None) -> dict:
    """Train one seed into ``out`` (with ``resume``, from its newest checkpoint when it has one
    and no final model, or an interrupted one); returns ``{"run": run.json, "evaluations": [...]}``.
    ``env_threads``: the vector env's threads (None: the worker's numba count)."""
    import torch

    from estimation.threads import set_default_threads

    set_default_threads(env_threads)
    from jobs.records import provenance
    from jobs.training.plots import write_learning_curve
    from train.trainer import latest_checkpoint, train, was_interrupted

    torch.set_num_threads(int(torch_threads))
    folder = Path(out)
    resume = bool(resume) and latest_checkpoint(folder) is not None and (not (folder / "model.zip").exists()
                                                                         or was_interrupted(folder))
    record = train(algo, action, track, int(seed), int(steps), folder, int(num_robots), tuple(eval_tracks),
                   int(eval_every), int(checkpoint_every), resume, overrides, False, quiet,
                   env_kwargs=env_kwargs, time_limit_min=float(time_limit_min),
                   record_extra={"provenance": provenance()}, correction_cost=float(correction_cost))
    write_learning_curve(folder, record)
    evaluations = json.loads((folder / "evaluations.json").read_text())
    return {"run": record, "evaluations": evaluations}


def check_seed_result(result, key: dict) -> None:
    """The schema of a saved :func:`train_seed_task` result read back on ``--resume``: ``{"run":
    run.json's record (num_timesteps, learn_wall_s, final_eval rows), "evaluations": [{timesteps,
    mean_return}, ...]}`` (``TypeError``/``KeyError`` otherwise: the seed is recomputed)."""
    run, evaluations = result.get("run"), result.get("evaluations")
    if not isinstance(run, dict) or not isinstance(evaluations, list) or not evaluations:
        raise TypeError("no 'run' dict and 'evaluations' list")
    for name in ("num_timesteps", "learn_wall_s"):
        if isinstance(run[name], bool) or not isinstance(run[name], (int, float)):
            raise TypeError(f"run[{name!r}] = {run[name]!r} is not a number")
    if not isinstance(run["final_eval"], list) or not all(isinstance(r, dict) for r in run["final_eval"]):
        raise TypeError("run['final_eval'] is not a list of rows")
    for e in evaluations:
        if not isinstance(e, dict) or not isinstance(e["timesteps"], int) \
                or not isinstance(e["mean_return"], (int, float)):
            raise TypeError(f"evaluation {e!r} is not {{timesteps, mean_return}}")


def seed_tasks(args: argparse.Namespace, seeds: Sequence[int], out: Path, env_kwargs: dict | None = None) -> list:
    """One campaign task per seed; the key holds what changes the result, ``out`` does not."""
    from jobs.campaign.engine import Task
    from train.tuning import hyperparams_overrides

    overrides = hyperparams_overrides(args.hyperparams, args.algo, args.action)
    tasks = []
    for seed in seeds:
        key = {"algo": args.algo, "action": args.action, "track": args.track, "seed": int(seed), "steps": args.steps,
               "num_robots": args.num_robots, "eval_tracks": list(args.eval_tracks), "eval_every": args.eval_every,
               "checkpoint_every": args.checkpoint_every, "overrides": overrides,
               "time_limit_min": float(args.time_limit), "env_kwargs": env_kwargs}
        if args.correction_cost:  # only when set: the keys (and so the saved tasks) of earlier runs stay valid
            key["correction_cost"] = float(args.correction_cost)
        tasks.append(Task("jobs.training.seeds:train_seed_task", key,
                          extra={"out": str(out / f"seed_{seed}"), "torch_threads": args.torch_threads,
                                 "resume": bool(args.resume), "env_threads": getattr(args, "threads", None)},
                          label=f"{args.algo}-{args.action}-seed{seed}", cost=float(args.steps),
                          check="jobs.training.seeds:check_seed_result"))
    return tasks


def learning_curve_stats(histories: Sequence[Sequence[dict]], n_resamples: int = 10_000) -> list[dict]:
    """Per evaluation step held by every seed: mean and bootstrap interval of the held-out mean
    return over seeds (``histories``: each seed's ``evaluations.json``)."""
    from jobs.campaign.engine import bootstrap_ci

    per_seed = [{int(e["timesteps"]): float(e["mean_return"]) for e in h} for h in histories if h]
    if not per_seed:
        return []
    common = sorted(set.intersection(*(set(d) for d in per_seed)))
    return [{"timesteps": t, **bootstrap_ci([d[t] for d in per_seed], n_resamples=n_resamples, seed=t)}
            for t in common]


def _plot_curves(out: Path, curve: list[dict], histories: Sequence[Sequence[dict]], seeds: Sequence[int],
                 evaluated_on: str) -> str | None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    n = len(histories)
    for j, (_seed, h) in enumerate(zip(seeds, histories)):
        if h and n > 1:  # as the statistics read them: the final evaluation replaces one at the same step
            pts = sorted({int(e["timesteps"]): float(e["mean_return"]) for e in h}.items())
            ax.plot(*zip(*pts), color="0.7", lw=0.8, label="each seed" if j == 0 else "_nolegend_")
    if curve:
        t = [c["timesteps"] for c in curve]
        ax.plot(t, [c["mean"] for c in curve], "C0o-", label=f"mean over {n} seeds" if n > 1 else "the one seed")
        if len(histories) > 1:
            ax.fill_between(t, [c["lo"] for c in curve], [c["hi"] for c in curve], color="C0", alpha=0.25,
                            label="95% bootstrap interval of the mean")
    ax.set_xlabel("environment steps (all robots)")
    ax.set_ylabel("evaluation return (mean over its tracks)")
    ax.legend(fontsize=8)
    ax.set_title(f"learning curves, {n} seed{'s' if n != 1 else ''}: evaluated on {evaluated_on}\n(the last point: "
                 "the final policy)", fontsize=9)
    fig.savefig(out / "learning_curves.png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    return "learning_curves.png"


def check_seed_args(args: argparse.Namespace) -> None:
    """``--seeds`` with the other flags (``ValueError``, one line)."""
    from jobs.campaign.args import check_executor_args

    if args.seed not in (None, 0) and args.seeds != [args.seed]:
        raise ValueError("give --seed or --seeds, not both")
    check_executor_args(args)
    if args.resume:  # the seeds that will resume from a checkpoint: read and match it now, not in the task
        from jobs.args import robot_args_kwargs
        from train.trainer import check_resume, latest_checkpoint, was_interrupted

        for seed in args.seeds:
            folder = Path(args.out) / f"seed_{seed}"
            if latest_checkpoint(folder) is not None and (not (folder / "model.zip").exists()
                                                          or was_interrupted(folder)):
                check_resume(folder, args.algo, args.action, robot_args_kwargs(args), steps=args.steps)
    if not args.resume:
        for seed in args.seeds:
            if (Path(args.out) / f"seed_{seed}" / "model.zip").exists():
                raise ValueError(f"--out {args.out}/seed_{seed} already holds a trained model (use --resume, which "
                                 "keeps the finished seeds, or another folder)")


def _print_progress(done: int, total: int, task, rec: dict) -> None:
    """One line per finished seed: its steps, wall time and last evaluation, or why it failed."""
    if rec["status"] == "ok":
        run = rec["result"]["run"]
        msg = ("" if run.get("complete", True) else "INCOMPLETE (time-limit guard): ") + (
               f"{run['num_timesteps']} steps in {run['learn_wall_s']:.0f} s, evaluation mean return "
               f"{rec['result']['evaluations'][-1]['mean_return']:.1f}")
    else:
        msg = f"FAILED after {rec['attempts']} attempt(s): {rec.get('error')}"
    print(f"[{done}/{total}] seed {task.key['seed']}: {msg}", flush=True)


def _final_table_lines(cells: list[dict]) -> list[str]:
    """The final evaluation's table rows: mean over seeds per track, with its interval where shown."""
    from jobs.eval.report import format_value, interval_shown

    lines = []
    for cell in cells:
        vals = []
        for k, fmt, scale in FINAL_COLUMNS:
            st = cell["metrics"][k]
            if st["n"] == 0 or not math.isfinite(st["mean"]):
                vals.append("-")
            elif not interval_shown(st):
                vals.append(format_value(k, st["mean"], fmt, scale))
            else:
                vals.append(f"{format_value(k, st['mean'], fmt, scale)} [{format_value(k, st['lo'], fmt, scale)}, "
                            f"{format_value(k, st['hi'], fmt, scale)}]")
        lines.append(f"| {cell['track']} | {cell['n']} | " + " | ".join(vals) + " |")
    return lines


def _curve_lines(plot: str | None, curve: list[dict], n_ok: int) -> list[str]:
    """The learning-curves section: the plot and the table of the mean return per evaluation step."""
    lines = ["", "## Learning curves", ""]
    if plot:
        lines.append(f"![learning curves]({plot})")
    if n_ok > 1:
        if n_ok < 5:
            lines += ["", f"With {n_ok} seeds the bootstrap interval is only indicative (with 2 it is the range of "
                      "the two); use 5 or more seeds for a claim."]
        lines += ["", "| steps | seeds | mean return | 95% interval |", "|---|---|---|---|"]
        lines += [f"| {c['timesteps']} | {c['n']} | {c['mean']:.1f} | [{c['lo']:.1f}, {c['hi']:.1f}] |"
                  for c in curve]
    else:
        lines += ["", "| steps | seeds | mean return |", "|---|---|---|"]
        lines += [f"| {c['timesteps']} | {c['n']} | {c['mean']:.1f} |" for c in curve]
    return lines


def _problem_lines(failed: list[dict], incomplete: list[dict], steps: int) -> list[str]:
    """The failed seeds and those the --time-limit guard stopped early, one bullet each."""
    lines = []
    if failed:
        lines += ["", "Failed seeds:", ""] + [f"- seed {r['key']['seed']}: {r.get('error')}" for r in failed]
    if incomplete:
        lines += ["", "Incomplete seeds (stopped by the --time-limit guard before the step budget; left out of the "
                  "statistics above):", ""]
        lines += [f"- seed {r['key']['seed']}: {r['result']['run']['num_timesteps']} of {steps} steps"
                  for r in incomplete]
    return lines


def _report_lines(args: argparse.Namespace, seeds: Sequence[int], records: list[dict], ok: list[dict],
                  incomplete: list[dict], cells: list[dict], curve: list[dict], plot: str | None, executor: str,
                  wall: float, prov: dict, evaluated_on: str) -> list[str]:
    """``report.md``: the header, the final evaluation table, the learning curves, the failed and
    incomplete seeds and the glossary."""
    from jobs.eval.report import interval_shown
    from jobs.glossary import GLOSSARY, glossary_lines
    from jobs.records import provenance_text
    from jobs.training.plots import training_label

    intervals = any(interval_shown(c["metrics"][k]) for c in cells for k, _, _ in FINAL_COLUMNS)
    stats = ("mean over seeds and, in brackets, the 95% bootstrap interval of the mean (no bracket where every seed "
             "gave the same value)" if intervals else
             "one seed: its values, no interval" if len(ok) == 1 else "mean over seeds, which all gave the same values")
    lines = [f"# azimut train: {args.algo}, action {args.action}, track {args.track}, seeds "
             f"{','.join(map(str, seeds))}", "",
             f"{len(ok)} of {len(records)} seeds trained ({executor}, {args.workers} worker(s)); "
             f"{args.steps} steps each on {training_label(args.track)}; wall time {wall:.0f} s.",
             f"Produced by {provenance_text(prov)}.",
             "", f"## Final evaluation on {evaluated_on}", "",
             f"One deterministic episode per seed and track with the final policy; {stats}.", "",
             "| track | seeds | " + " | ".join(GLOSSARY[k].header for k, _, _ in FINAL_COLUMNS) + " |",
             "|---|---|" + "---|" * len(FINAL_COLUMNS)]
    lines += _final_table_lines(cells)
    lines += _curve_lines(plot, curve, len(ok))
    lines += _problem_lines([r for r in records if r["status"] != "ok"], incomplete, args.steps)
    lines += [""] + glossary_lines(["track", "seeds", *(k for k, _, _ in FINAL_COLUMNS)])
    lines += ["- **steps**: environment steps of training (all robots together) at the evaluation.",
              "- **mean return**: the evaluation return averaged over the evaluation tracks, then over the seeds."]
    if len(ok) > 1:
        lines.append("- **95% interval**: the percentile-bootstrap interval of the mean over seeds.")
    return lines


def run_seeds(args: argparse.Namespace, seeds: Sequence[int], env_kwargs: dict | None = None) -> int:
    """Train every seed (see the module docstring) and write the aggregate report."""
    from jobs.campaign.engine import CampaignInterrupted, resolve_executor, run_tasks, summarize
    from jobs.records import provenance, write_json
    from jobs.training.plots import evaluation_label

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tasks = seed_tasks(args, seeds, out, env_kwargs)
    executor = resolve_executor(args.executor, args.workers, args.ray_address)
    start = time.perf_counter()
    try:
        records = run_tasks(tasks, out / "seeds", executor=executor, workers=args.workers,
                            threads=max(args.torch_threads, getattr(args, "threads", None) or 1),
                            ray_address=args.ray_address, retries=args.retries,
                            resume=args.resume, progress=_print_progress)
    except CampaignInterrupted as exc:
        print(f"azimut train: {exc}; run the same command with --resume", flush=True)
        return 130
    wall = time.perf_counter() - start
    done = [r for r in records if r["status"] == "ok"]
    ok = [r for r in done if r["result"]["run"].get("complete", True)]  # the --time-limit guard: left out
    incomplete = [r for r in done if r not in ok]
    histories = [r["result"]["evaluations"] for r in ok]
    curve = learning_curve_stats(histories)
    final_rows: list[dict[str, Any]] = [{**row, "seed": r["key"]["seed"]}
                                        for r in ok for row in r["result"]["run"]["final_eval"]]
    cells = summarize(final_rows, ("track",), [c[0] for c in FINAL_COLUMNS])
    evaluated_on = evaluation_label(args.track, args.eval_tracks)
    plot = _plot_curves(out, curve, histories, [r["key"]["seed"] for r in ok], evaluated_on)
    prov = provenance()
    write_json(out / "seeds.json",
               {"seeds": list(seeds), "executor": executor, "workers": args.workers, "wall_s": wall,
                "provenance": prov, "learning_curve": curve, "final_summary": cells,
                "runs": [{"seed": r["key"]["seed"], "status": r["status"], "error": r.get("error"),
                          "run": (r.get("result") or {}).get("run")} for r in records]})
    lines = _report_lines(args, seeds, records, ok, incomplete, cells, curve, plot, executor, wall, prov,
                          evaluated_on)
    (out / "report.md").write_text("\n".join(lines) + "\n")
    print(f"{len(ok)} of {len(records)} seeds trained; report written to {out}/report.md", flush=True)
    failed = [r for r in records if r["status"] != "ok"]
    return 0 if not failed and not incomplete else 1
