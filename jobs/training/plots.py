"""Learning curves of several ``azimut train`` runs in one figure:
``python -m jobs.training.plots OUT.png RUN_DIR [RUN_DIR ...]``; of several ``azimut train --seeds``
campaigns over their seeds: ``python -m jobs.training.plots --seeds OUT.png [--drift] NAME=DIR ...``
(:func:`plot_seed_groups`; ``--drift``: the :data:`DRIFT_PANELS` of residual agents; needs matplotlib)."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

__all__ = ["plot_runs", "training_returns", "evaluation_history", "training_label", "evaluation_label",
           "write_learning_curve", "learning_curve_figure", "seed_curve", "plot_seed_groups", "SEED_CURVE_PANELS",
           "DRIFT_PANELS"]

#: the panels of :func:`plot_seed_groups`: (title, track or None for the mean over the evaluation
#: tracks, the evaluation row's key, scale, y label[, a horizontal line: (value, its label)])
SEED_CURVE_PANELS = [("evaluation return (mean over the run's evaluation tracks)", None, "return", 1.0, "return"),
                     ("circle: mean null-space force", "circle", "mean_nullspace_force_N", 1.0, "N",
                      (30.0, "the raw-action bar, 30 N")),
                     ("circle: mean antagonism", "circle", "mean_antagonism_N", 1.0, "N"),
                     ("circle: RMS lateral error", "circle", "rms_lateral_m", 100.0, "cm")]
#: the panels of ``--drift``: how far residual agents move from their reference controller
DRIFT_PANELS = [("circle: mean squared correction (clipped action)", "circle", "mean_sq_action", 1.0, "mean a²"),
                ("figure8: mean squared correction (clipped action)", "figure8", "mean_sq_action", 1.0, "mean a²"),
                ("circle: RMS lateral error", "circle", "rms_lateral_m", 100.0, "cm"),
                ("figure8: RMS lateral error", "figure8", "rms_lateral_m", 100.0, "cm"),
                ("circle: mean antagonism", "circle", "mean_antagonism_N", 1.0, "N"),
                ("figure8: mean antagonism", "figure8", "mean_antagonism_N", 1.0, "N")]


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


def _complete_seed_runs(folder: Path) -> list[Path]:
    """The seed runs of an ``azimut train --seeds`` folder that reached their step budget."""
    runs = []
    for p in sorted(Path(folder).glob("seed_*"), key=lambda q: int(q.name.split("_", 1)[1])
                    if q.name.split("_", 1)[1].isdigit() else -1):
        rec = p / "run.json"
        if rec.is_file() and json.loads(rec.read_text()).get("complete", True) is not False:
            runs.append(p)
    return runs


def seed_curve(folder: Path, track: str | None, key: str, n_resamples: int = 2_000) -> list[dict]:
    """Per evaluation step held by every complete seed of an ``azimut train --seeds`` folder: the
    IQM of the seeds' values of ``key`` (on ``track``'s evaluation row; None: the entry's
    ``mean_return`` when ``key`` is ``return``, else the mean over its rows) and its 95%
    bootstrap interval (:func:`jobs.campaign.statistics.stratified_bootstrap_iqm`, one stratum),
    with every seed's value (``"scores"``). The final evaluation stands at its step."""
    from jobs.campaign.statistics import stratified_bootstrap_iqm

    per_seed = []
    for run in _complete_seed_runs(folder):
        values = {}
        for e in evaluation_history(run):
            if track is None:
                v = e["mean_return"] if key == "return" else sum(float(r[key]) for r in e["rows"]) / len(e["rows"])
            else:
                rows = [r for r in e["rows"] if r["track"] == track]
                if not rows:
                    continue
                v = float(rows[0][key])
            values[int(e["timesteps"])] = float(v)
        per_seed.append(values)
    if not per_seed:
        return []
    common = sorted(set.intersection(*(set(d) for d in per_seed)))
    return [{"timesteps": t, "scores": [d[t] for d in per_seed],
             **stratified_bootstrap_iqm([[d[t] for d in per_seed]], n_resamples=n_resamples, seed=t)}
            for t in common]


def plot_seed_groups(groups: dict[str, Path], out: Path, panels=None) -> list[str]:
    """One figure: per panel of ``panels`` (default :data:`SEED_CURVE_PANELS`), per group (name ->
    ``azimut train --seeds`` folder), the IQM over the seeds against environment steps with its
    95% bootstrap interval (shaded) and each seed (thin lines). Returns one line per panel and group:
    the IQM and interval at the first and the last evaluation step (the figures the plot shows)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = panels or SEED_CURVE_PANELS
    cols = 2
    rows = (len(panels) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(12, 3.6 * rows), squeeze=False)
    summary = []
    for ax, (title, track, key, scale, unit, *line) in zip(axes.flat, panels):
        if line:
            ax.axhline(line[0][0], color="k", ls="--", lw=0.8, label=line[0][1])
        for i, (name, folder) in enumerate(groups.items()):
            curve = seed_curve(Path(folder), track, key)
            if not curve:
                continue
            t = [c["timesteps"] for c in curve]
            n = len(curve[0]["scores"])
            for j in range(n):
                ax.plot(t, [scale * c["scores"][j] for c in curve], color=f"C{i}", lw=0.6, alpha=0.35)
            ax.plot(t, [scale * c["iqm"] for c in curve], "o-", ms=3, color=f"C{i}", label=f"{name} ({n} seeds)")
            ax.fill_between(t, [scale * c["lo"] for c in curve], [scale * c["hi"] for c in curve], color=f"C{i}",
                            alpha=0.2)
            ends = "; ".join(f"{c['timesteps']} steps: {scale * c['iqm']:.4g} [{scale * c['lo']:.4g}, "
                             f"{scale * c['hi']:.4g}]" for c in (curve[0], curve[-1]))
            summary.append(f"{title} [{unit}], {name} ({n} seeds): {ends}")
        ax.set_title(title, fontsize=9)
        ax.set_xscale("log")
        ax.set_xlabel("environment steps (all robots)")
        ax.set_ylabel(unit)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, "no evaluation on this track", ha="center", va="center", transform=ax.transAxes)
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    fig.suptitle("IQM over training seeds (thick), 95% bootstrap interval (shaded), each seed (thin)", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return summary


def _main(argv: list[str]) -> int:
    if len(argv) >= 3 and argv[0] == "--seeds":
        drift = argv[2] == "--drift"
        groups = {}
        for item in argv[3 if drift else 2:]:
            name, sep, folder = item.partition("=")
            if not sep or not Path(folder).is_dir():
                print(f"plots: error: {item!r} is not NAME=DIR with DIR an azimut train --seeds folder",
                      file=sys.stderr)
                return 2
            groups[name] = Path(folder)
        if not groups:
            print("plots: error: no NAME=DIR given", file=sys.stderr)
            return 2
        for line in plot_seed_groups(groups, Path(argv[1]), DRIFT_PANELS if drift else None):
            print(line)
        return 0
    if len(argv) < 2:
        print("usage: python -m jobs.training.plots OUT.png RUN_DIR [RUN_DIR ...]\n"
              "       python -m jobs.training.plots --seeds OUT.png [--drift] NAME=DIR [NAME=DIR ...]", file=sys.stderr)
        return 2
    plot_runs([Path(p) for p in argv[1:]], Path(argv[0]))
    return 0


if __name__ == "__main__":
    raise SystemExit(_main(sys.argv[1:]))
