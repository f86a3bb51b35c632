"""The opening of ``azimut eval``'s report: which controller is best at what, in a few lines,
computed from the summary cells (mean over seeds per controller × track).

Per track (and per speed scale, with ``--speed-scales``: controllers compared at equal speed
scale), among the controllers that finished every episode on it (one that never moves has no slip
and must not win): the fastest finisher (the least completion time), the least slip, ranked by the
slip energy per metre travelled (a controller does not lower it by crawling or standing still), and
the least RMS lateral error; with several seeds, a best whose 95% interval overlaps the runner-up's
is said to be not separated from it. With several tracks (or speed scales), a last line counts the
tracks (or track and speed scale pairs) each controller is best on, per criterion.
"""

from __future__ import annotations

import math

__all__ = ["CRITERIA", "verdict_lines", "finished_all", "mean_of", "scale_text"]

#: (metric, words, unit, scale, format): what the verdict ranks, each the lower the better
CRITERIA = [("completion_time_s", "fastest finisher", "s", 1.0, "{:.1f}"),
            ("slip_energy_per_m", "least slip per metre", "J/m", 1.0, "{:.2f}"),
            ("rms_lateral_m", "least lateral error", "cm RMS", 100.0, "{:.2f}")]


def mean_of(cell: dict, metric: str) -> float | None:
    """The mean over seeds of ``metric`` in a summary cell, or None where it has none (or not finite)."""
    stats = cell.get("metrics", {}).get(metric) or {}
    value = stats.get("mean")
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


def finished_all(cell: dict) -> bool:
    """Whether the cell's controller finished every episode (done share 1, no failed episode)."""
    done = mean_of(cell, "completed")
    return done is not None and done >= 1.0 and cell.get("failed", 0) == 0


def _overlap(a: dict, b: dict, metric: str) -> bool:
    sa, sb = a["metrics"].get(metric) or {}, b["metrics"].get(metric) or {}
    if min(sa.get("n", 0), sb.get("n", 0)) < 2 or any(not isinstance(s.get(k), (int, float)) for s in (sa, sb)
                                                      for k in ("lo", "hi")):
        return False
    return sa["hi"] >= sb["lo"] and sb["hi"] >= sa["lo"]


def _best(cells: list[dict], metric: str, words: str, unit: str, scale: float, fmt: str) -> tuple[str, str | None]:
    """``(clause, winner)`` of one criterion on one track's cells."""
    # every criterion among the controllers that finished every episode: one that never moves has no slip
    # and, on a straight path, no lateral error, and must not win them
    finishers = [c for c in cells if finished_all(c)]
    pool = [c for c in finishers if mean_of(c, metric) is not None]
    if not pool:
        return (f"{words}: none (no controller finished every episode)" if not finishers
                else f"{words}: no value"), None
    pool.sort(key=lambda c: mean_of(c, metric))
    best = pool[0]
    text = f"{words} **{best['controller']}** ({fmt.format(scale * mean_of(best, metric))} {unit}"
    if len(pool) > 1:
        second = pool[1]
        text += f"; next {second['controller']} {fmt.format(scale * mean_of(second, metric))}"
        if _overlap(best, second, metric):
            text += ", not separated by the 95% intervals"
    elif len(cells) > 1:
        text += "; the only one to finish every episode" if len(finishers) == 1 else "; the only one with a value"
    if metric != "completion_time_s" and len(finishers) < len(cells) and not (len(pool) == 1 and len(finishers) == 1):
        text += "; among those that finished every episode"
    return text + ")", best["controller"]


def scale_text(scale) -> str:
    """A speed scale as the report writes it: ``×0.8``."""
    return f"×{scale:g}" if isinstance(scale, (int, float)) else f"×{scale}"


def verdict_lines(cells: list[dict], tracks: list[str], controllers: list[str]) -> list[str]:
    """The verdict as Markdown lines: one bullet per track (per track and speed scale when the
    cells hold several ``speed_scale``), and a tally over them when there are several. ``cells``:
    the summary cells (``controller``, ``track``, ``speed_scale``, ``metrics`` of mean/lo/hi/n,
    ``ok``, ``failed``)."""
    lines = []
    wins: dict[str, dict[str, int]] = {words: {} for _, words, *_ in CRITERIA}
    scales = list(dict.fromkeys(c.get("speed_scale") for c in cells))
    groups = [(track, scale) for track in tracks for scale in scales]
    for track, scale in groups:
        where = f"**{track}**" + (f" at {scale_text(scale)}" if len(scales) > 1 else "")
        mine = [c for c in cells if c["track"] == track and c.get("speed_scale") == scale and c.get("n", 0) > 0]
        if not mine:
            lines.append(f"- {where}: no episode finished without an error")
            continue
        clauses = []
        for metric, words, unit, factor, fmt in CRITERIA:
            clause, winner = _best(mine, metric, words, unit, factor, fmt)
            clauses.append(clause)
            if winner is not None:
                wins[words][winner] = wins[words].get(winner, 0) + 1
        not_done = [c["controller"] for c in mine if not finished_all(c)]
        tail = (f"; did not finish every episode: {', '.join(not_done)}" if not_done and len(not_done) < len(mine)
                else "")
        lines.append(f"- {where}: " + "; ".join(clauses) + tail + ".")
    if len(groups) > 1 and len(controllers) > 1:
        tally = []
        for words, counts in wins.items():
            if counts:
                ranked = sorted(counts.items(), key=lambda kv: (-kv[1], controllers.index(kv[0])
                                                                 if kv[0] in controllers else 0))
                tally.append(f"{words}: " + ", ".join(f"{name} on {n} of {len(groups)}" for name, n in ranked))
        if tally:
            over = "the tracks" if len(scales) == 1 else "the (track, speed scale) pairs"
            lines.append(f"- **Over {over}**: " + "; ".join(tally) + ".")
    return lines
