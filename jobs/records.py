"""What every artefact of a job records about itself, and strict JSON.

* :func:`provenance`: the package version and the git commit of the code that produced an artefact
  (``"unknown"`` when they cannot be found: an installed wheel has no git checkout), for
  ``report.md``, ``metrics.json``, ``run.json``, ``seeds.json``.
* :func:`strict_json`: a value as strict JSON (RFC 8259) accepts it: non-finite floats (NaN, ±inf,
  which Python's ``json`` writes as the non-JSON tokens ``NaN`` and ``Infinity``) become ``null``,
  NumPy scalars and arrays become numbers and lists; :func:`write_json` writes a file with it.
"""

from __future__ import annotations

import json
import math
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["UNKNOWN", "provenance", "provenance_text", "strict_json", "write_json"]

UNKNOWN = "unknown"


def _source_root() -> Path:
    """The folder holding the packages (``jobs/`` and its siblings) that are running."""
    return Path(__file__).resolve().parent.parent


def provenance() -> dict[str, Any]:
    """``{"version", "commit", "local_changes"}``: the installed ``azimut`` version, the commit of
    the git checkout the running code comes from, and whether that checkout has uncommitted changes
    to tracked files (None when unknown); ``"unknown"`` for what cannot be found."""
    try:
        version = metadata.version("azimut")
    except metadata.PackageNotFoundError:
        version = UNKNOWN
    commit, dirty = UNKNOWN, None
    root = _source_root()
    if (root / ".git").exists():
        try:
            commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                                    timeout=10, check=True).stdout.strip() or UNKNOWN
            status = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                                    capture_output=True, text=True, timeout=10, check=True).stdout
            dirty = bool(status.strip())
        except (OSError, subprocess.SubprocessError):
            commit, dirty = UNKNOWN, None
    return {"version": version, "commit": commit, "local_changes": dirty}


def provenance_text(prov: dict[str, Any]) -> str:
    """One sentence for a report: ``azimut 0.1.0, commit 1a2b3c4d5e6f (with local changes)``."""
    commit = prov.get("commit", UNKNOWN)
    commit = commit[:12] if commit != UNKNOWN else "unknown"
    extra = " (with uncommitted local changes)" if prov.get("local_changes") else ""
    return f"azimut {prov.get('version', UNKNOWN)}, commit {commit}{extra}"


def strict_json(value: Any) -> Any:
    """``value`` with every non-finite float as None and NumPy values as Python ones (dicts,
    lists and tuples recursively; dict keys as strings)."""
    if isinstance(value, dict):
        return {str(k): strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return strict_json(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(path: Path, value: Any, indent: int = 1) -> None:
    """Write ``value`` as strict JSON (:func:`strict_json`; objects JSON cannot hold as strings)."""
    Path(path).write_text(json.dumps(strict_json(value), indent=indent, allow_nan=False, default=str) + "\n")
