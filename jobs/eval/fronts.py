"""The fronts of ``azimut eval --speed-scales``: each controller run at several speed scales, per
track, so that a reader sees who is faster *and* fights less, not one point each.

Per track, a table of (controller, speed scale, done share, lap time, slip energy per metre, RMS
lateral error), means over seeds from the summary cells (:data:`jobs.eval.report.FRONT_COLUMNS`);
a line per speed scale saying which controller dominates which (:func:`dominance`), one over the
fronts whole (:func:`front_text`: one front dominates another when each point of the other is
dominated by one of its points, at any speed scale); and the PNG of
the fronts (:func:`jobs.eval.plots.fronts_plot`). A controller *dominates* another at a speed scale
where both finished every episode (:func:`jobs.eval.verdict.finished_all`) when its mean lap time
and its mean slip energy per metre are both lower.
"""

from __future__ import annotations

from collections.abc import Sequence

from jobs.eval.report import FRONT_COLUMNS, summary_cell
from jobs.eval.verdict import finished_all, mean_of, scale_text
from jobs.glossary import GLOSSARY

__all__ = ["fronts_lines", "dominance", "dominance_text", "front_text"]

#: what dominance compares, each the lower the better: (metric, format, unit)
DOMINANCE_METRICS = (("completion_time_s", "{:.1f}", "s"), ("slip_energy_per_m", "{:.2f}", "J/m"))


def dominance(cells: list[dict]) -> tuple[list[dict], list[tuple[str, str]]]:
    """``(pool, pairs)`` among the cells of one track and speed scale: ``pool``, the cells whose
    controller finished every episode with a lap time and a slip per metre; ``pairs``, (a, b) for
    each controller a of the pool whose lap time and slip per metre are both below b's."""
    pool = [c for c in cells if finished_all(c) and all(mean_of(c, m) is not None for m, *_ in DOMINANCE_METRICS)]
    pairs = [(a["controller"], b["controller"]) for a in pool for b in pool if a is not b and _beats(a, b)]
    return pool, pairs


def _beats(a: dict, b: dict) -> bool:
    """Whether cell ``a``'s mean lap time and slip per metre are both below cell ``b``'s."""
    return all(mean_of(a, m) < mean_of(b, m) for m, *_ in DOMINANCE_METRICS)


def _point(cell: dict) -> str:
    return f"{cell['controller']} " + ", ".join(f"{fmt.format(mean_of(cell, m))} {unit}"
                                                 for m, fmt, unit in DOMINANCE_METRICS)


def dominance_text(cells: list[dict], scale: float, controllers: Sequence[str]) -> str:
    """One Markdown bullet: who dominates whom at ``scale`` among ``cells`` (one track's, that scale)."""
    pool, pairs = dominance(cells)
    head = f"- {scale_text(scale)}: "
    if len(pool) < 2:
        only = f" (only {pool[0]['controller']})" if pool else ""
        return head + f"fewer than two controllers finished every episode{only}; no comparison."
    order = {name: i for i, name in enumerate(controllers)}
    winners = sorted({a for a, _ in pairs}, key=lambda n: order.get(n, len(order)))
    clauses = []
    for a in winners:
        beaten = sorted((b for x, b in pairs if x == a), key=lambda n: order.get(n, len(order)))
        every = " (every other that finished)" if len(beaten) == len(pool) - 1 and len(pool) > 2 else ""
        clauses.append(f"**{a}** dominates {' and '.join(beaten)}{every}")
    related = {frozenset(p) for p in pairs}
    names = [c["controller"] for c in pool]
    trade = [f"{a} and {b}" for i, a in enumerate(names) for b in names[i + 1:] if frozenset((a, b)) not in related]
    if not clauses:
        return head + "no controller dominates another (each is faster or slips less per metre): " \
            + "; ".join(_point(c) for c in pool) + "."
    text = head + "; ".join(clauses) + " (faster and less slip per metre)"
    if trade:
        text += f"; a trade-off between {', '.join(trade)}"
    return text + ": " + "; ".join(_point(c) for c in pool) + "."


def front_text(cells: list[dict], controllers: Sequence[str]) -> str:
    """One Markdown bullet over one track's fronts: the controllers whose front dominates another's
    (each finished point of the other, at any speed scale, is slower and slips more per metre than
    one of its finished points, at any speed scale)."""
    pool, _ = dominance(cells)
    points = {name: [c for c in pool if c["controller"] == name] for name in controllers}
    points = {name: p for name, p in points.items() if p}
    clauses = [f"**{a}**'s front dominates {b}'s" for a in points for b in points
               if a != b and all(any(_beats(p, q) for p in points[a]) for q in points[b])]
    head = "- Across the speed scales: "
    if len(points) < 2:
        return head + "fewer than two controllers have a finished point; no comparison."
    if not clauses:
        return head + "no front dominates another (each controller has a point that no point of the other beats in " \
            "both lap time and slip per metre)."
    return head + "; ".join(clauses) + " (each of its points is beaten in both lap time and slip per metre by one " \
        "of the first's, at some speed scale)."


def fronts_lines(cells: list[dict], tracks: Sequence[str], controllers: Sequence[str], scales: Sequence[float],
                 plots: dict[str, list[str]] | None = None) -> list[str]:
    """The Markdown lines of the report's "Fronts" section: per track its table (controller by
    controller through the speed scales), who dominates at each scale, and its plot (``plots``:
    track -> paths relative to the report; None: no plots were made, ``--no-plots``)."""
    heads = ["controller", GLOSSARY["speed_scale"].header] + [GLOSSARY[k].header for k, _, _ in FRONT_COLUMNS]
    lines = ["", "## Fronts", "",
             f"Each controller at each speed scale ({', '.join(f'{x:g}' for x in scales)}): the lap time against the "
             "slip energy per metre travelled and the RMS lateral error, means over the seeds (lap time: over the "
             "finished episodes; an interval in brackets as in the summary). A controller dominates another at a "
             "speed scale where both finished every episode when its mean lap time and its mean slip per metre are "
             "both lower (means compared, not their intervals). In the plots a hollow marker is a point whose "
             "controller did not finish every episode."]
    for track in tracks:
        mine = [c for c in cells if c["track"] == track]
        lines += ["", f"### Fronts on {track}", "", "| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
        for controller in controllers:
            for cell in sorted((c for c in mine if c["controller"] == controller), key=lambda c: c["speed_scale"]):
                stats = cell.get("metrics", {})
                values = [summary_cell(k, stats.get(k, {}), fmt, scale) for k, fmt, scale in FRONT_COLUMNS]
                lines.append(f"| {controller} | {cell['speed_scale']:g} | " + " | ".join(values) + " |")
        lines += ["", "Who dominates (lower lap time and lower slip per metre):", ""]
        lines += [dominance_text([c for c in mine if c["speed_scale"] == x], x, controllers) for x in scales]
        lines.append(front_text(mine, controllers))
        if plots is not None and plots.get(track):
            lines.append("")
            lines += [f"![{track} fronts]({f})" for f in plots[track]]
        elif plots is not None:
            lines += ["", f"No plot of the fronts on {track}: no episode finished it (a point needs a lap time)."]
    return lines
