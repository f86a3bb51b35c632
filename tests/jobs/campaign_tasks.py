"""Task functions for tests/jobs/test_campaign.py, importable by worker processes (spawned processes
and local Ray workers get the test process's import path)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np


def seeded_sum(seed: int, n: int = 1000, log_dir: str | None = None) -> dict:
    """A result drawn from the key alone; ``log_dir`` (not part of the key) records each run."""
    if log_dir is not None:
        with open(Path(log_dir) / f"ran-{seed}", "a") as fh:
            fh.write(f"{os.getpid()}\n")
    x = np.random.default_rng(seed).normal(size=n)
    return {"sum": float(np.sum(x)), "max": float(np.max(x))}


def crash_once(seed: int, marker_dir: str, always: bool = False) -> dict:
    """Kills its worker process (``os._exit``) on its first run (or on every run with ``always``),
    as a segfault or an out-of-memory kill would; then returns like :func:`seeded_sum`."""
    marker = Path(marker_dir) / f"crashed-{seed}"
    if always or not marker.exists():
        marker.write_text("x")
        os._exit(13)
    return seeded_sum(seed)


def raise_once(seed: int, marker_dir: str) -> dict:
    """Raises on its first run, then succeeds."""
    marker = Path(marker_dir) / f"raised-{seed}"
    if not marker.exists():
        marker.write_text("x")
        raise RuntimeError("first attempt fails")
    return seeded_sum(seed)


def seeded_sum_batch(keys: list[dict], extras: list[dict]) -> list[dict]:
    """:func:`seeded_sum` of several keys in one call (a campaign batch); records the batch's
    seeds in ``log_dir`` (the first extra's) as ``batch-<seeds>``; a key with ``fail_batch``
    makes the whole batch raise (its tasks are then retried alone)."""
    log_dir = extras[0].get("log_dir")
    if log_dir is not None:
        (Path(log_dir) / ("batch-" + "-".join(str(k["seed"]) for k in keys))).write_text("x")
    if any(k.get("fail_batch") for k in keys):
        raise RuntimeError("this batch fails")
    return [seeded_sum(k["seed"], k.get("n", 1000)) for k in keys]


def seeded_sum_or_fail(seed: int, n: int = 1000, fail_batch: bool = False, log_dir: str | None = None) -> dict:
    """:func:`seeded_sum`, alone (``fail_batch`` only fails batches)."""
    return seeded_sum(seed, n, log_dir)
