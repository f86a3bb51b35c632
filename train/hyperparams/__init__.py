"""Versioned default hyperparameters per algorithm × action space (``ppo.json``, ``sac.json``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["load_hyperparams", "ALGOS"]

ALGOS = ("ppo", "sac")


def load_hyperparams(algo: str, action_key: str) -> tuple[dict[str, Any], int]:
    """(keyword arguments of the SB3 algorithm, file version) for ``algo`` and ``action_key``
    (``raw``, ``residual``, ``icr_rate``)."""
    if algo not in ALGOS:
        raise ValueError(f"unknown algorithm {algo!r}; choose from {', '.join(ALGOS)}")
    data = json.loads((Path(__file__).parent / f"{algo}.json").read_text())
    if action_key not in data:
        raise ValueError(f"{algo}.json has no defaults for action space {action_key!r}")
    return dict(data[action_key]), int(data["version"])
