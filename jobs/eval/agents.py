"""Trained agents over training seeds in ``azimut eval``: the rliable protocol (Agarwal et al.,
*Deep Reinforcement Learning at the Edge of the Statistical Precipice*, NeurIPS 2021).

``--controllers ppo:NAME=DIR`` with ``DIR`` an ``azimut train --seeds`` folder (``DIR/seed_<n>/
model.zip``) expands to one policy per trained seed, named ``NAME.s<n>``
(:func:`expand_seed_folders`; a seed stopped by the ``--time-limit`` guard is left out, and said
so). Controllers named ``NAME.s<n>`` (two or more) form the agent group ``NAME``
(:func:`agent_groups`).

Per group, track and metric, each training seed's score is the mean of its evaluation episodes
(the campaign's ``--seeds``); the table gives the interquartile mean (IQM) of the seeds' scores
and its 95% stratified-bootstrap percentile interval
(:func:`jobs.campaign.statistics.stratified_bootstrap_iqm`). The aggregate over tracks divides
each score by the ICR controller's mean on the same track and episodes (1: as the ICR
controller; the tracks are the strata of the bootstrap); the done share is aggregated as it is.
The bar (:data:`BAR`): the share of a group's seeds that finish ``circle`` in every evaluation
episode with a mean null-space force ≤ 30 N (the quantity the bar was set on, called internal force
then: the minimum-norm null-space force, :data:`jobs.glossary.GLOSSARY`).
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from jobs.campaign.statistics import stratified_bootstrap_iqm

__all__ = ["expand_seed_folders", "agent_groups", "agent_summary", "agent_section", "write_agents", "AGENT_METRICS",
           "BAR"]

#: the metrics of the agents' table: (key, header, format, scale)
AGENT_METRICS = [("completed", "done share", "{:.2f}", 1.0), ("rms_lateral_m", "RMS lat [cm]", "{:.2f}", 100.0),
                 ("slip_energy_J", "slip energy [J]", "{:.2f}", 1.0),
                 ("mean_antagonism_N", "mean antagonism [N]", "{:.2f}", 1.0),
                 ("mean_nullspace_force_N", "mean null-space force [N]", "{:.2f}", 1.0)]
#: metrics shown too when the episodes carry them
OPTIONAL_METRICS: list[tuple[str, str, str, float]] = []
#: the raw-action bar: finish ``track`` in every evaluation episode with ``metric`` ≤ ``max``
BAR = {"track": "circle", "metric": "mean_nullspace_force_N", "max": 30.0}
_GROUPED = re.compile(r"^(?P<group>.+)\.s(?P<seed>\d+)$")


def _seed_folders(path: Path) -> list[Path]:
    return sorted((p for p in path.glob("seed_*") if p.is_dir() and (p / "model.zip").is_file()),
                  key=lambda p: int(p.name.split("_", 1)[1]) if p.name.split("_", 1)[1].isdigit() else -1)


def expand_seed_folders(items: Sequence[str], stream=None) -> list[str]:
    """``items`` with every ``PREFIX:NAME=DIR`` (or ``PREFIX:DIR``) whose ``DIR`` is an
    ``azimut train --seeds`` folder (no ``model.zip``, ``seed_<n>/model.zip`` inside) replaced by
    ``PREFIX:NAME.s<n>=DIR/seed_<n>/model.zip`` per complete seed (``run.json`` without
    ``"complete": false``); a left-out incomplete seed is said on ``stream`` (stderr)."""
    import json

    stream = stream if stream is not None else sys.stderr
    out: list[str] = []
    for item in items:
        prefix, sep, arg = item.partition(":")
        if not sep or prefix not in ("ppo", "sac"):
            out.append(item)
            continue
        head, eq, tail = arg.partition("=")
        name, path = (head, Path(tail)) if eq and tail else (None, Path(arg))
        if not path.is_dir() or (path / "model.zip").is_file() or not _seed_folders(path):
            run = next((p / "run.json" for p in (path, path.parent) if (p / "run.json").is_file()), None)
            record = json.loads(run.read_text()) if run is not None else {}
            if record.get("complete", True) is False:
                print(f"azimut eval: note: {run.parent} is an incomplete run (stopped by "
                      f"{record.get('stopped') or 'its guard'} before its step budget); evaluated as it is",
                      file=stream)
            out.append(item)
            continue
        name = name or path.resolve().name
        for folder in _seed_folders(path):
            run = folder / "run.json"
            if run.is_file() and json.loads(run.read_text()).get("complete", True) is False:
                print(f"azimut eval: {folder} left out: its run stopped at the --time-limit guard before its step "
                      "budget", file=stream)
                continue
            out.append(f"{prefix}:{name}.s{folder.name.split('_', 1)[1]}={folder / 'model.zip'}")
    return out


def agent_groups(names: Sequence[str]) -> dict[str, list[str]]:
    """Group -> its controllers' names, for the names ``GROUP.s<n>`` of two or more seeds."""
    groups: dict[str, list[str]] = {}
    for name in names:
        m = _GROUPED.match(name)
        if m:
            groups.setdefault(m["group"], []).append(name)
    return {g: sorted(v, key=lambda n: int(_GROUPED.match(n)["seed"])) for g, v in groups.items() if len(v) >= 2}


def _per_seed(rows: list[dict], controller: str, track: str, key: str) -> float:
    vals = [float(r[key]) for r in rows if r.get("status") == "ok" and r["controller"] == controller
            and r["track"] == track and r.get(key) is not None and math.isfinite(float(r[key]))]
    return float(np.mean(vals)) if vals else math.nan


def agent_summary(rows: list[dict], names: Sequence[str], tracks: Sequence[str], *, n_resamples: int = 10_000,
                  reference: str = "icr") -> dict:
    """Per agent group: per track and metric the IQM and interval over its seeds, the aggregate over
    ``tracks`` normalised by ``reference`` (when it ran), the seeds' scores, and the bar's share."""
    groups = agent_groups(names)
    present = {k for r in rows for k in r}
    metrics = AGENT_METRICS + [m for m in OPTIONAL_METRICS if m[0] in present]
    out: dict = {"metrics": [m[0] for m in metrics], "reference": reference if reference in names else None,
                 "groups": {}}
    for g, members in groups.items():
        seed_of = {n: int(_GROUPED.match(n)["seed"]) for n in members}
        per_track: dict = {}
        for track in tracks:
            cell = {}
            for key, *_ in metrics:
                scores = [_per_seed(rows, n, track, key) for n in members]
                stats = stratified_bootstrap_iqm([scores], n_resamples=n_resamples,
                                                 seed=_seed(g, track, key))
                cell[key] = {**stats, "scores": scores}
            per_track[track] = cell
        aggregate = {}
        for key, *_ in metrics:
            strata = []
            for track in tracks:
                scores = per_track[track][key]["scores"]
                if key != "completed":
                    ref = _per_seed(rows, reference, track, key) if reference in names else math.nan
                    scores = [s / ref if math.isfinite(ref) and ref > 0 else math.nan for s in scores]
                strata.append(scores)
            aggregate[key] = stratified_bootstrap_iqm(strata, n_resamples=n_resamples, seed=_seed(g, "*", key))
        bar = None
        if BAR["track"] in tracks:
            met = []
            for n in members:
                eps = [r for r in rows if r["controller"] == n and r["track"] == BAR["track"]]
                finished = bool(eps) and all(r.get("status") == "ok" and r.get("completed") for r in eps)
                value = _per_seed(rows, n, BAR["track"], BAR["metric"])
                met.append(bool(finished and math.isfinite(value) and value <= BAR["max"]))
            bar = {**BAR, "met": sum(met), "seeds": len(met), "by_seed": dict(zip(map(str, seed_of.values()), met))}
        out["groups"][g] = {"seeds": list(seed_of.values()), "controllers": members, "tracks": per_track,
                            "aggregate": aggregate, "bar": bar}
    return out


def _seed(*parts) -> int:
    import zlib

    return zlib.crc32(repr(parts).encode())


def _fmt(stats: dict, fmt: str, scale: float) -> str:
    if stats.get("n", 0) == 0 or not math.isfinite(stats["iqm"]):
        return "-"
    v = fmt.format(scale * stats["iqm"])
    if stats["lo"] == stats["hi"]:
        return v
    return f"{v} [{fmt.format(scale * stats['lo'])}, {fmt.format(scale * stats['hi'])}]"


def agent_section(summary: dict, rows: list[dict], tracks: Sequence[str], references: Sequence[str]) -> list[str]:
    """The report's Markdown section of :func:`agent_summary` (empty without groups)."""
    if not summary["groups"]:
        return []
    metrics = [m for m in AGENT_METRICS + OPTIONAL_METRICS if m[0] in summary["metrics"]]
    lines = ["", "## Trained agents over training seeds", "",
             "Per agent group (the controllers NAME.s<n>, one per training seed): each seed's score on a track is "
             "the mean over its evaluation episodes; a cell is the interquartile mean (IQM) of the seeds' scores and, "
             "in brackets, its 95% stratified-bootstrap percentile interval (Agarwal et al., NeurIPS 2021). The "
             "reference controllers' cells are their means over the same episodes.", "",
             "| agent | track | seeds | " + " | ".join(m[1] for m in metrics) + " |",
             "|---|---|---|" + "---|" * len(metrics)]
    for track in tracks:
        for ref in references:
            vals = [_per_seed(rows, ref, track, k) for k, *_ in metrics]
            cells = ["-" if not math.isfinite(v) else fmt.format(scale * v)
                     for v, (_, _, fmt, scale) in zip(vals, metrics)]
            lines.append(f"| {ref} | {track} | - | " + " | ".join(cells) + " |")
        for g, data in summary["groups"].items():
            cell = data["tracks"][track]
            lines.append(f"| {g} | {track} | {len(data['seeds'])} | "
                         + " | ".join(_fmt(cell[k], fmt, scale) for k, _, fmt, scale in metrics) + " |")
    ref = summary.get("reference")
    if ref:
        lines += ["", f"Aggregate over the tracks {', '.join(tracks)}: each seed's score divided by {ref}'s on the "
                  "same track (1 = as the reference; done share as it is), IQM over all seeds and tracks, the "
                  "interval from the bootstrap stratified by track.", "",
                  "| agent | seeds × tracks | " + " | ".join(m[1].split(" [")[0] + (" (share)" if m[0] == "completed"
                                                                                        else f" / {ref}")
                                                             for m in metrics) + " |",
                  "|---|---|" + "---|" * len(metrics)]
        for g, data in summary["groups"].items():
            agg = data["aggregate"]
            lines.append(f"| {g} | {len(data['seeds'])} × {len(tracks)} | "
                         + " | ".join(_fmt(agg[k], "{:.2f}", 1.0) for k, *_ in metrics) + " |")
    bars = {g: d["bar"] for g, d in summary["groups"].items() if d["bar"]}
    if bars:
        b = next(iter(bars.values()))
        lines += ["", f"Bar: finish `{b['track']}` in every evaluation episode with a mean null-space force ≤ "
                  f"{b['max']:g} N (each seed's mean over its episodes):", ""]
        lines += [f"- {g}: {b['met']} of {b['seeds']} seeds ("
                  + ", ".join(f"s{s} {'met' if ok else 'not met'}" for s, ok in b["by_seed"].items()) + ")"
                  for g, b in bars.items()]
    from jobs.glossary import GLOSSARY, Column, glossary_lines

    columns = {"agent": Column("agent", "an agent group NAME (its training seeds NAME.s<n>) or a reference controller"),
               "seeds": Column("seeds", "the training seeds of the group with an episode on the track"),
               "seeds × tracks": Column("seeds × tracks", "the scores the aggregate is taken over"),
               **{k: GLOSSARY.get(k, Column(h, "the episodes' metric of that name")) for k, h, *_ in metrics}}
    return lines + [""] + glossary_lines(columns, columns, "### Columns of this section")


def write_agents(out: Path, rows: list[dict], names: Sequence[str], tracks: Sequence[str],
                 n_resamples: int = 10_000) -> dict | None:
    """With agent groups among ``names``: ``out/agents.json`` (:func:`agent_summary`, strict JSON)
    and its section appended to ``out/report.md``; None without groups."""
    from jobs.records import write_json

    summary = agent_summary(rows, names, tracks, n_resamples=n_resamples)
    if not summary["groups"]:
        return None
    write_json(Path(out) / "agents.json", summary)
    grouped = {n for members in agent_groups(names).values() for n in members}
    references = [n for n in names if n not in grouped]
    report = Path(out) / "report.md"
    text = report.read_text() if report.is_file() else ""
    report.write_text(text + "\n".join(agent_section(summary, rows, tracks, references)) + "\n")
    return summary
