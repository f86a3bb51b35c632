"""Learning curves of several ``azimut train`` runs in one figure:
``python -m jobs.training.plots OUT.png RUN_DIR [RUN_DIR ...]`` (needs matplotlib)."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

__all__ = ["plot_runs", "training_returns", "evaluation_history", "training_label", "evaluation_label",
           "write_learning_curve", "learning_curve_figure"]


def training_label(track: str) -> str:
    """What the training episodes ran on, from the run's ``--track``."""
    return "random tracks (a new one per episode)" if track == "random" else f"the {track} track"


def evaluation_label(track: str, eval_tracks: list[str] | tuple[str, ...]) -> str:
    """What the periodic evaluation ran on, from the run's ``--track`` and ``--eval-tracks``: held
    out only when the policy never trained on them."""
    names = ", ".join(eval_tracks)
    if track == "random" or track not in eval_tracks:
        return f"{names} (held out: never trained on)"
    return f"{names} ({track} is also the training track)"


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
    """A run folder's ``evaluations.json`` (the periodic evaluations; empty if there is none)."""
    ev_file = Path(run) / "evaluations.json"
    return json.loads(ev_file.read_text()) if ev_file.is_file() else []


def plot_runs(runs: list[Path], out: Path) -> None:
    """Training episode return (``logs/progress.csv`` or ``tb/progress.csv``) and evaluation mean
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


def write_learning_curve(out: Path, record: dict) -> Path | None:
    """``out/learning_curve.png``: the training episodes' return and the evaluations' mean return
    against environment steps, labelled from the run's record (``run.json``: algorithm, action
    space, seed, training and evaluation tracks). Returns the file, or None without matplotlib
    (with a line on stderr)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("learning_curve.png not written: matplotlib is not installed (pip install 'azimut[plot]')",
              file=sys.stderr)
        return None
    out = Path(out)
    fig = learning_curve_figure(out, record, plt)
    path = out / "learning_curve.png"
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path


def learning_curve_figure(out: Path, record: dict, plt):
    """The figure of :func:`write_learning_curve` (``plt``: ``matplotlib.pyplot``)."""
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    pts = training_returns(out)
    if pts:
        ax.plot(*zip(*pts), color="C0", marker="o" if len(pts) == 1 else None,  # one point: a line shows nothing
                label=f"training: mean return of the last 100 episodes, on {training_label(record['track'])}")
    ev = evaluation_history(out)
    periodic = [e for e in ev if not e.get("final")]
    final = [e for e in ev if e.get("final")]
    tracks = list(record["eval_tracks"])
    what = ("one deterministic episode on " if len(tracks) == 1 else
            "mean of one deterministic episode per track on ") + evaluation_label(record["track"], tracks)
    if periodic:
        ax.plot([e["timesteps"] for e in periodic], [e["mean_return"] for e in periodic], "o-", color="C1",
                label=f"evaluation: {what}")
    if final:
        ax.plot([e["timesteps"] for e in final], [e["mean_return"] for e in final], "*", color="C3", ms=11,
                label="the final policy (model.zip), evaluated the same way" + ("" if periodic else f": {what}"))
    ax.set_xlabel("environment steps (all robots)")
    ax.set_ylabel("episode return (sum of rewards)")
    if pts or ev:
        ax.legend(fontsize=7, loc="best")
    ax.set_title(f"{record['algo'].upper()}, {record['action']} actions, seed {record['seed']}: {out.name}"
                 + ("" if pts else "\n(no training episode finished yet: no training curve)"), fontsize=10)
    return fig


if __name__ == "__main__":
    if len(sys.argv) < 3:
        print("usage: python -m jobs.training.plots OUT.png RUN_DIR [RUN_DIR ...]", file=sys.stderr)
        raise SystemExit(2)
    plot_runs([Path(p) for p in sys.argv[2:]], Path(sys.argv[1]))
