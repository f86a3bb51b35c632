"""What ``azimut eval`` writes in its output folder (:func:`output_layout`, checked before any work
by :func:`jobs.args.check_output_layout`), the names of its episodes (:func:`episode_label`) and
the speed scales they run at (:func:`speed_scales_of`)."""

from __future__ import annotations

import argparse
import re
from collections.abc import Sequence

__all__ = ["PLOT_ENDING", "episode_label", "is_own_plot", "output_layout", "speed_scales_of"]

#: the ending of each PNG file :mod:`jobs.eval.plots` writes, by plot (one run's five, a track's two
#: comparisons: ``compare_<track>`` + the trajectory's or the slip force's ending; a track's fronts
#: with ``--speed-scales``: ``<track>_fronts.png``)
PLOT_ENDING = {"trajectory": "_trajectory.png", "beta_pairs": "_beta_pairs.png", "qua": "_qua.png",
               "icr_sphere": "_icr_sphere.png", "commands": "_commands.png", "slip_force": "_slip_force.png",
               "fronts": "_fronts.png"}
PLOT_ENDINGS = tuple(PLOT_ENDING.values())


def is_own_plot(name: str) -> bool:
    """Whether a file in ``OUT/plots`` is named as :mod:`jobs.eval.plots` names its PNGs (a new run
    without ``--resume`` removes those, and leaves any other file there)."""
    return name.endswith(PLOT_ENDINGS)


def episode_label(name: str, track: str, seed: int, speed_scale: float = 1.0) -> str:
    """An episode's label: its task id's prefix and its export's folder name (sanitised); the
    speed scale, ``-x0.8``, when it is not 1 (the label of a scale-1 episode is as before
    ``--speed-scales``, so its records are found again)."""
    return f"{name}-{track}-s{seed}" + ("" if float(speed_scale) == 1.0 else f"-x{float(speed_scale):g}")



def speed_scales_of(args: argparse.Namespace) -> list[float]:
    """The campaign's speed scales: ``--speed-scales``, else ``[--speed-scale]``."""
    scales = getattr(args, "speed_scales", None)
    return [float(s) for s in scales] if scales is not None else [float(getattr(args, "speed_scale", 1.0))]


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
        speed_scales = speed_scales_of(args)
        for spec in args.controllers:
            for track in tracks:
                for seed, scale in ((s, x) for s in seeds for x in speed_scales):
                    label = re.sub(r"[^A-Za-z0-9_.-]+", "_", episode_label(names.get(spec, spec), track, seed, scale))
                    dirs[f"exports/{label}"] = ()
    if getattr(args, "kick_runs", 0):  # the study runs every controller but the trained policies, by name
        from jobs.eval.controllers import is_policy

        names = getattr(args, "controller_names", None) or {}
        for spec in [c for c in args.controllers if not is_policy(c)]:
            files.append(f"kicks_{names.get(spec, spec)}.json")
            dirs[f"kicks/{names.get(spec, spec)}"] = (".json",)
    return files, dirs
