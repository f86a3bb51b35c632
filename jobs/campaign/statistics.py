"""Statistics over seeds: the mean and a percentile-bootstrap interval of each metric.

:func:`bootstrap_ci` (percentile bootstrap of the mean, seeded) and :func:`summarize`, per group
(e.g. controller × track) and metric. The percentile bootstrap is Efron & Tibshirani, *An
Introduction to the Bootstrap* (1993), ch. 13; reporting intervals over seeds follows Agarwal et
al., *Deep Reinforcement Learning at the Edge of the Statistical Precipice* (NeurIPS 2021).

Trained agents over training seeds (the rliable protocol of Agarwal et al. 2021): :func:`iqm`, the
interquartile mean (the mean of the middle 50% of the scores, as ``scipy.stats.trim_mean(x, 0.25)``:
``k = floor(n/4)`` scores cut at each end of the sorted n), and :func:`stratified_bootstrap_iqm`,
its 95% percentile interval from the stratified bootstrap: each resample draws, for every task
(track) independently, as many runs (training seeds) as that task has, with replacement, and
takes the IQM of all the drawn scores together. One task gives the plain bootstrap of the IQM.
"""

from __future__ import annotations

import json
import math
import zlib
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["bootstrap_ci", "summarize", "iqm", "stratified_bootstrap_iqm"]


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


def _trimmed_mean_rows(x: np.ndarray) -> np.ndarray:
    """IQM of each row of ``x`` (R, n): the mean of the sorted row without its ``floor(n/4)``
    smallest and largest entries."""
    n = x.shape[-1]
    k = int(0.25 * n)
    return np.sort(x, axis=-1)[..., k:n - k].mean(axis=-1)


def iqm(values: Iterable[float]) -> float:
    """Interquartile mean of ``values`` (flattened; NaN and inf left out; NaN if none is left):
    ``scipy.stats.trim_mean(values, 0.25)``, the aggregate of Agarwal et al. (NeurIPS 2021)."""
    x = np.asarray(list(values) if not isinstance(values, np.ndarray) else values, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    return float(_trimmed_mean_rows(x[None, :])[0]) if x.size else math.nan


def stratified_bootstrap_iqm(scores: Sequence[Sequence[float]], *, level: float = 0.95, n_resamples: int = 10_000,
                             seed: int = 0) -> dict:
    """IQM over all runs and tasks of ``scores`` and its stratified-bootstrap percentile interval.

    ``scores``: one sequence per task (stratum) of the runs' scores on it (e.g. per track, one
    score per training seed, itself the mean over evaluation episodes); tasks may hold different
    numbers of runs; NaN and inf are left out. Returns ``{"iqm", "lo", "hi", "n"}`` (``n``: the
    scores used); a single score or all-equal scores give a zero-width interval, none gives NaNs.
    The resampling is seeded (same scores, same interval)."""
    if level <= 0.0 or level >= 1.0:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    strata = [np.asarray([float(v) for v in task], dtype=np.float64) for task in scores]
    strata = [t[np.isfinite(t)] for t in strata]
    strata = [t for t in strata if t.size]
    flat = np.concatenate(strata) if strata else np.zeros(0)
    n = int(flat.size)
    if n == 0:
        return {"iqm": math.nan, "lo": math.nan, "hi": math.nan, "n": 0}
    point = float(_trimmed_mean_rows(flat[None, :])[0])
    if n == 1 or np.all(flat == flat[0]):
        return {"iqm": point, "lo": point, "hi": point, "n": n}
    rng = np.random.default_rng(seed)
    r = int(n_resamples)
    drawn = np.concatenate([t[rng.integers(0, t.size, size=(r, t.size))] for t in strata], axis=1)
    stats = _trimmed_mean_rows(drawn)
    alpha = (1.0 - level) / 2.0
    lo, hi = np.quantile(stats, [alpha, 1.0 - alpha])
    return {"iqm": point, "lo": float(lo), "hi": float(hi), "n": n}
