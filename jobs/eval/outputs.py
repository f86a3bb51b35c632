"""What ``azimut eval`` writes in its output folder (:func:`output_layout`, checked before any work
by :func:`jobs.args.check_output_layout`) and the names of its episodes (:func:`episode_label`)."""

from __future__ import annotations

import argparse
import re
from collections.abc import Sequence

__all__ = ["PLOT_ENDING", "episode_label", "is_own_plot", "output_layout"]

#: the ending of each PNG file :mod:`jobs.eval.plots` writes, by plot (one run's five, a track's two
#: comparisons: ``compare_<track>`` + the trajectory's or the slip force's ending)
PLOT_ENDING = {"trajectory": "_trajectory.png", "beta_pairs": "_beta_pairs.png", "qua": "_qua.png",
               "icr_sphere": "_icr_sphere.png", "commands": "_commands.png", "slip_force": "_slip_force.png"}
PLOT_ENDINGS = tuple(PLOT_ENDING.values())


def is_own_plot(name: str) -> bool:
    """Whether a file in ``OUT/plots`` is named as :mod:`jobs.eval.plots` names its PNGs (a new run
    without ``--resume`` removes those, and leaves any other file there)."""
    return name.endswith(PLOT_ENDINGS)


def episode_label(name: str, track: str, seed: int) -> str:
    """An episode's label: its task id's prefix and its export's folder name (sanitised)."""
    return f"{name}-{track}-s{seed}"



def output_layout(args: argparse.Namespace, seeds: Sequence[int]) -> tuple[list[str], dict[str, tuple[str, ...]]]:
    """What ``azimut eval`` writes in its output folder, for :func:`jobs.args.check_output_layout`:
    the files (``metrics.json``, ``report.md``, the kick study's ``kicks_<controller>.json``) and
    the folders with the suffixes of the files written in them (``episodes/``: the records and
    traces ``--resume`` reads; ``plots/``; ``videos/``; ``exports/<episode>/`` for the campaign's
    ``seeds``; ``kicks/<controller>/``)."""
    files = ["metrics.json", "report.md"]
    dirs: dict[str, tuple[str, ...]] = {"episodes": (".json", ".npz")}
    if not getattr(args, "no_plots", True):
        dirs["plots"] = (".png",)
    if getattr(args, "video", None):
        dirs["videos"] = (".gif", ".mp4")
    if getattr(args, "export", None):  # one bag folder per episode, replaced: each must be a folder if it exists
        names = getattr(args, "controller_names", None) or {}
        tracks = args.tracks if isinstance(args.tracks, list) else [t for t in str(args.tracks).split(",") if t]
        dirs["exports"] = ()
        for spec in args.controllers:
            for track in tracks:
                for seed in seeds:
                    label = re.sub(r"[^A-Za-z0-9_.-]+", "_", episode_label(names.get(spec, spec), track, seed))
                    dirs[f"exports/{label}"] = ()
    if getattr(args, "kick_runs", 0):  # the study runs every controller but the trained policies, by name
        from jobs.eval.controllers import is_policy

        names = getattr(args, "controller_names", None) or {}
        for spec in [c for c in args.controllers if not is_policy(c)]:
            files.append(f"kicks_{names.get(spec, spec)}.json")
            dirs[f"kicks/{names.get(spec, spec)}"] = (".json",)
    return files, dirs
