"""Statistics over seeds: the mean and a percentile-bootstrap interval of each metric.

:func:`bootstrap_ci` (percentile bootstrap of the mean, seeded) and :func:`summarize`, per group
(e.g. controller × track) and metric. The percentile bootstrap is Efron & Tibshirani, *An
Introduction to the Bootstrap* (1993), ch. 13; reporting intervals over seeds follows Agarwal et
al., *Deep Reinforcement Learning at the Edge of the Statistical Precipice* (NeurIPS 2021).
"""

from __future__ import annotations

import json
import math
import zlib
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["bootstrap_ci", "summarize"]


def bootstrap_ci(values: Iterable[float], *, level: float = 0.95, n_resamples: int = 10_000,
                 seed: int = 0) -> dict:
    """Mean and percentile-bootstrap confidence interval of the mean of ``values``.

    NaN and inf values are left out (``n`` counts the finite ones). One value gives a zero-width
    interval; none gives NaNs. The resampling is seeded: same values, same interval.
    """
    x = np.asarray([float(v) for v in values], dtype=np.float64)
    x = x[np.isfinite(x)]
    n = int(x.size)
    if n == 0:
        return {"mean": math.nan, "lo": math.nan, "hi": math.nan, "n": 0}
    mean = float(np.mean(x))
    if n == 1 or np.all(x == x[0]):
        return {"mean": mean, "lo": mean, "hi": mean, "n": n}
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, n, size=(int(n_resamples), n))].mean(axis=1)
    alpha = (1.0 - level) / 2.0
    lo, hi = np.quantile(means, [alpha, 1.0 - alpha])
    return {"mean": mean, "lo": float(lo), "hi": float(hi), "n": n}


def _is_metric(value: Any) -> bool:
    return isinstance(value, (int, float, bool, np.integer, np.floating, np.bool_)) or value is None


def summarize(rows: Sequence[Mapping[str, Any]], group_by: Sequence[str], metrics: Sequence[str] | None = None, *,
              level: float = 0.95, n_resamples: int = 10_000) -> list[dict]:
    """Per group of ``rows`` (same values of ``group_by``, in order of first appearance): the mean
    and bootstrap interval of each metric over the rows (bools as 0/1 shares).

    Each cell's resampling seed is a hash of the group and the metric, and the rows of a group are
    sorted by ``seed`` (when they have one) first, so a cell's interval depends on its values
    alone, not on the other cells or on the order in which the tasks finished.
    """
    groups: dict[tuple, list] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in group_by), []).append(row)
    if metrics is None:
        metrics = []
        for row in rows:
            for k, v in row.items():
                if k not in group_by and k != "seed" and k not in metrics and _is_metric(v) and v is not None:
                    metrics.append(k)
    out = []
    for gkey, grows in groups.items():
        grows = sorted(grows, key=lambda r: r.get("seed", 0))
        cell = {k: v for k, v in zip(group_by, gkey)}
        cell["n"] = len(grows)
        stats = {}
        for m in metrics:
            vals = [r.get(m) for r in grows]
            vals = [math.nan if v is None else float(v) for v in vals]
            seed = zlib.crc32(json.dumps([list(gkey), m], sort_keys=True, separators=(",", ":"),
                                         allow_nan=True).encode())
            stats[m] = bootstrap_ci(vals, level=level, n_resamples=n_resamples, seed=seed)
        cell["metrics"] = stats
        out.append(cell)
    return out
