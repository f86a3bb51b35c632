"""What ``azimut eval`` writes from its episodes' records: each episode's trace
(``episodes/<id>.npz``: :func:`save_trace`), its ROS 2 bag (:func:`export_episode`), and the
rows, statistics, plots and report (:func:`write_results`)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from jobs.campaign.engine import summarize
from jobs.eval.report import SCENARIO_COLUMNS, SUMMARY_COLUMNS, write_campaign_report

__all__ = ["TRACE_ARRAYS", "save_trace", "export_episode", "row_of", "write_results"]

#: the arrays of an episode's trace (``episodes/<id>.npz``), by name: (EpisodeLog attribute, meaning);
#: one row per logged control step (``track_xy``: the track's sampled points)
TRACE_ARRAYS = {
    "t": ("t", "time at the end of each control step [s], (T,)"),
    "pose": ("pose", "true pose (x [m], y [m], θ [rad]), (T, 3)"),
    "lateral": ("lateral", "signed lateral error to the track [m], (T,)"),
    "slip_power": ("slip_power", "slip power Σ|F·v_slip| [W], (T,)"),
    "antagonism": ("antagonism", "antagonism of the tire forces [N], (T,)"),
    "nullspace_force": ("nullspace_force", "null-space force of the tire forces [N], (T,)"),
    "beta_cmd": ("beta_cmd", "the controller's steering set-points β_c [rad], (T, n)"),
    "phidot_cmd": ("phidot_cmd", "the controller's wheel-speed set-points φ̇_c [rad/s], (T, n)"),
    "beta_meas": ("beta_meas", "measured steering angles β (encoders, with their noise) [rad], (T, n)"),
    "phidot_meas": ("phidot_meas", "measured wheel speeds φ̇ [rad/s], (T, n)"),
    "beta_true": ("beta_true", "true steering angles [rad], (T, n)"),
    "track_xy": (None, "the track's points (x, y) [m], (P, 2)"),
}


def save_trace(path: Path, log) -> None:
    """Write an episode's trace (:data:`TRACE_ARRAYS`) to ``path`` (compressed NumPy archive)."""
    arrays = {name: np.asarray(getattr(log, attr)) for name, (attr, _) in TRACE_ARRAYS.items() if attr}
    np.savez_compressed(path, track_xy=log.track.xy, **arrays)


def export_episode(log, folder: Path, label: str, robot: str | None, storage: str) -> str:
    """Write one episode as a ROS 2 bag ``folder/<label>`` (replacing an earlier one); returns its
    path relative to the report folder."""
    import shutil

    from control.export import export_episode as export

    target = folder / re.sub(r"[^A-Za-z0-9_.-]+", "_", label)
    if target.exists():
        shutil.rmtree(target)
    folder.mkdir(parents=True, exist_ok=True)
    export(log, target, robot=robot or "azimut3", storage=storage)
    return f"{folder.name}/{target.name}"


def row_of(record: dict, names: dict[str, str], records_folder: Path | None = None) -> dict:
    """An episode's row of ``metrics.json`` from its record (a failed one: its error and, with
    ``records_folder``, the record that holds its traceback)."""
    key = record["key"]
    if record["status"] == "ok":
        row = dict(record["result"]["metrics"])
        row["status"] = "ok"
    else:
        row = {"controller": names.get(key["controller"], key["controller"]), "track": key["track"],
               "seed": key["seed"], "status": "failed",
               "error": record.get("error")}
        if records_folder is not None:
            row["record"] = str(records_folder / f"{record['id']}.json")
    row["speed_scale"] = float(key.get("speed_scale", 1.0))  # from the key: a record of any version has it
    row["attempts"] = record.get("attempts", 1)
    return row


def _metric_names(ok_rows: list[dict]) -> list[str]:
    """The metrics summarised: the summary columns, then every other number of an ok row, then the
    scenario columns some row has."""
    skip = ("controller", "track", "seed", "status", "error", "attempts", "kick", "robot", "imperfections", "record",
            "speed_scale")
    metrics = [c[0] for c in SUMMARY_COLUMNS] + [k for k in (ok_rows[0] if ok_rows else {})
                                                 if k not in {c[0] for c in SUMMARY_COLUMNS} and k not in skip
                                                 and isinstance(ok_rows[0][k], (int, float))]
    metrics += [c[0] for c in SCENARIO_COLUMNS if c[0] not in metrics and any(c[0] in r for r in ok_rows)]
    return metrics


def _summary_cells(rows: list[dict], tracks: Sequence[str], scales: list[float], controllers: list[str],
                   robots: dict[str, dict], n_resamples: int) -> list[dict]:
    """One cell per track × speed scale × controller, empty ones included: the statistics over
    seeds of the ok rows, the counts of ok and failed episodes, the controller's robot."""
    ok_rows = [r for r in rows if r["status"] == "ok"]
    several = len(scales) > 1
    # grouped by speed scale only when there are several: a campaign of one keeps its cells' bootstrap seeds
    # (a hash of the group) and so its intervals
    cells = summarize(ok_rows, ("controller", "track") + (("speed_scale",) if several else ()), _metric_names(ok_rows),
                      n_resamples=n_resamples)
    for cell in cells:
        cell.setdefault("speed_scale", scales[0])
    by = {(c["controller"], c["track"], c["speed_scale"]): c for c in cells}
    full = []
    for track, scale, controller in ((t, x, c) for t in tracks for x in scales for c in controllers):
        n_failed = sum(1 for r in rows if r["controller"] == controller and r["track"] == track
                       and r["speed_scale"] == scale and r["status"] != "ok")
        cell = by.get((controller, track, scale), {"controller": controller, "track": track, "speed_scale": scale,
                                                   "n": 0, "metrics": {}})
        cell["ok"], cell["failed"] = cell["n"], n_failed
        if controller in robots:
            cell["robot"], cell["imperfections"] = robots[controller]["robot"], robots[controller]["imperfections"]
        full.append(cell)
    return full


def _plots_and_comparisons(out: Path, at_reference: list[dict], tasks: Sequence, tracks: Sequence[str],
                           names: dict[str, str], records_folder: Path, plot_seed: int, reference: float):
    """The per-run plots of the first seed at the reference scale, by (controller, track), and the
    comparison plots of the controllers per track from their traces."""
    from jobs.eval.plots import comparison_plots

    plots: dict[tuple[str, str], list[str]] = {}
    comparisons: dict[str, list[str]] = {}
    for rec in at_reference:
        if rec["key"]["seed"] == plot_seed and rec["result"].get("plots"):
            plots[(names.get(rec["key"]["controller"]), rec["key"]["track"])] = rec["result"]["plots"]
    for track in tracks:
        traces = {}
        for task in tasks:
            npz = records_folder / f"{task.id}.npz"
            if (task.key["track"] == track and task.key["seed"] == plot_seed
                    and task.key.get("speed_scale", 1.0) == reference and npz.is_file()):
                traces[names.get(task.key["controller"])] = dict(np.load(npz))
        if traces:
            (out / "plots").mkdir(exist_ok=True)
            comparisons[track] = [f"plots/{f}" for f in comparison_plots(track, traces, out / "plots")]
    return plots, comparisons


def _campaign_facts(campaign: dict, controllers: list[str], tracks, seeds, specs, names: dict[str, str],
                    robots: dict[str, dict], videos: dict, exports: dict) -> dict:
    """``campaign`` completed: the controllers, tracks, seeds, robots (one, or per controller),
    videos, exports and the provenance."""
    from jobs.eval.robots import robot_sentence
    from jobs.records import provenance

    distinct = {(r["robot"], r["imperfections"]) for r in robots.values()}
    one = next(iter(distinct)) if len(distinct) == 1 else ("per controller (see robots)", None)
    return {"controllers": controllers, "tracks": list(tracks), "seeds": list(seeds), **campaign,
            "videos": videos, "robot": one[0], "imperfections": one[1],
            "robots": {name: {"robot": r["robot"], "imperfections": r["imperfections"]}
                       for name, r in robots.items()},
            "robot_sentence": robot_sentence(robots),
            "env_kwargs": {name: r.get("other", {}) for name, r in robots.items()},
            "controller_specs": {names.get(c, c): c for c in specs if names.get(c, c) != c},
            "exports": exports, "provenance": provenance()}


def write_results(out: Path, records: list[dict], tasks: Sequence, specs: Sequence[str], tracks: Sequence[str],
                  seeds: Sequence[int], names: dict[str, str], robots: dict[str, dict], campaign: dict,
                  records_folder: Path, *, n_resamples: int, video: bool, compare: bool) -> tuple[int, int]:
    """The rows, the summary cells (mean and interval over seeds per controller × track × speed
    scale), the comparison plots of the first seed (at the reference speed scale,
    ``campaign["reference_scale"]``), the fronts with several speed scales
    (:mod:`jobs.eval.fronts`) and ``report.md``/``metrics.json``
    (:func:`jobs.eval.report.write_campaign_report`); ``campaign``: the run's facts so far
    (completed here). Returns (episodes ok, episodes)."""
    from jobs.eval.agents import write_agents
    from jobs.eval.fronts import fronts_lines
    from jobs.eval.plots import fronts_plot

    rows = [row_of(r, names, records_folder) for r in records]
    for row in rows:  # the robot each episode ran
        r = robots.get(row["controller"])
        if r is not None:
            row["robot"], row["imperfections"] = r["robot"], r["imperfections"]
    controllers = [names.get(c, c) for c in specs]  # the report speaks of names
    n_ok = sum(1 for r in rows if r["status"] == "ok")
    scales = [float(x) for x in campaign.get("speed_scales") or [campaign.get("speed_scale") or 1.0]]
    reference = campaign.get("reference_scale", scales[0])
    several = len(scales) > 1
    full = _summary_cells(rows, tracks, scales, controllers, robots, n_resamples)
    ok = [rec for rec in records if rec["status"] == "ok"]
    at_reference = [rec for rec in ok if rec["key"].get("speed_scale", 1.0) == reference]
    videos = {f"{names.get(rec['key']['controller'])} on {rec['key']['track']}": rec["result"]["video"]
              for rec in at_reference if video and rec["result"].get("video")}
    exports = {f"{names.get(rec['key']['controller'])} on {rec['key']['track']}, seed {rec['key']['seed']}"
               + (f", speed ×{rec['key']['speed_scale']:g}" if several else ""): rec["result"]["export"]
               for rec in ok if rec["result"].get("export")}
    plots, comparisons = (_plots_and_comparisons(out, at_reference, tasks, tracks, names, records_folder, seeds[0],
                                                 reference) if compare else ({}, {}))
    campaign = _campaign_facts(campaign, controllers, tracks, seeds, specs, names, robots, videos, exports)
    fronts: list[str] = []
    if several:  # per track, each controller through its speed scales
        pngs = None
        if compare:
            (out / "plots").mkdir(exist_ok=True)
            pngs = {track: [f"plots/{f}" for f in fronts_plot(track, [c for c in full if c["track"] == track],
                                                              controllers, out / "plots")] for track in tracks}
        fronts = fronts_lines(full, list(tracks), controllers, scales, pngs)
    write_campaign_report(out, rows, full, campaign, plots, comparisons, fronts=fronts)
    # agents over training seeds, if any: at the reference speed scale (their statistics are over seeds alone)
    write_agents(out, [r for r in rows if r["speed_scale"] == reference], controllers, list(tracks),
                 n_resamples=n_resamples)
    return n_ok, len(rows)
