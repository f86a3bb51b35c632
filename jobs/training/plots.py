"""Learning curves of several ``azimut train`` runs in one figure:
``python -m jobs.training.plots OUT.png RUN_DIR [RUN_DIR ...]`` (needs matplotlib)."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

__all__ = ["plot_runs", "training_returns", "evaluation_history"]


def training_returns(run: Path) -> list[tuple[float, float]]:
    """(environment steps, mean training episode return) rows of a run folder's SB3
    ``progress.csv`` (``logs/`` or ``tb/``); empty if there is none."""
    csv_file = next(iter(Path(run).glob("*/progress.csv")), None)
    if csv_file is None:
        return []
    with csv_file.open() as fh:
        rows = list(csv.DictReader(fh))
    return [(float(r["time/total_timesteps"]), float(r["rollout/ep_rew_mean"])) for r in rows
            if r.get("rollout/ep_rew_mean") not in (None, "") and r.get("time/total_timesteps") not in (None, "")]


def evaluation_history(run: Path) -> list[dict]:
    """A run folder's ``evaluations.json`` (the held-out evaluations; empty if there is none)."""
    ev_file = Path(run) / "evaluations.json"
    return json.loads(ev_file.read_text()) if ev_file.is_file() else []


def plot_runs(runs: list[Path], out: Path) -> None:
    """Training episode return (``logs/progress.csv`` or ``tb/progress.csv``) and held-out mean
    return (``evaluations.json``) against environment steps, one colour per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for i, run in enumerate(map(Path, runs)):
        meta = json.loads((run / "run.json").read_text()) if (run / "run.json").is_file() else {}
        label = f"{meta.get('algo', '?')} {meta.get('action', '?')} s{meta.get('seed', '?')} ({run.name})"
        pts = training_returns(run)
        if pts:
            axes[0].plot(*zip(*pts), color=f"C{i}", label=label)
        ev = evaluation_history(run)
        if ev:
            axes[1].plot([e["timesteps"] for e in ev], [e["mean_return"] for e in ev], "o-", color=f"C{i}", label=label)
    axes[0].set_title("training episodes: mean return")
    axes[1].set_title("evaluation tracks (deterministic episodes): mean return")
    for ax in axes:
        ax.set_xlabel("environment steps")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    if len(sys.argv) < 3:
        print("usage: python -m jobs.training.plots OUT.png RUN_DIR [RUN_DIR ...]", file=sys.stderr)
        raise SystemExit(2)
    plot_runs([Path(p) for p in sys.argv[2:]], Path(sys.argv[1]))
