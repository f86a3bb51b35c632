"""The campaign's records: one JSON file per finished task (:class:`TaskStore`), each checked
when it is read back (:func:`record_problem`) so that a torn, foreign or malformed record is
recomputed, never used."""

from __future__ import annotations

import json
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from jobs.campaign.task import Task, canonical, resolve

__all__ = ["TaskStore", "record_problem"]


def record_problem(rec: Any, task: Task) -> str | None:
    """Why ``rec`` (a parsed record file) is not a valid record of ``task``, or None: the envelope
    ``{id, fn, key, status, attempts, ...}`` (the same id, fn and key; status "ok" or "failed";
    attempts an integer >= 1; an ok record's ``result`` a dict) and the task's own schema check of
    the result (:attr:`Task.check`)."""
    if not isinstance(rec, dict):
        kind = {list: "array", str: "string", int: "number", float: "number", bool: "boolean"}.get(type(rec), "null")
        return f"not a record (a JSON {kind})"
    if rec.get("id") != task.id or rec.get("fn") != task.fn or canonical(rec.get("key")) != canonical(dict(task.key)):
        return "another task's record (id, function or key differ)"
    if rec.get("status") not in ("ok", "failed"):
        return f"status {rec.get('status')!r} is not 'ok' or 'failed'"
    attempts = rec.get("attempts")
    if isinstance(attempts, bool) or not isinstance(attempts, int) or attempts < 1:
        return f"attempts {attempts!r} is not an integer >= 1"
    if rec["status"] == "ok":
        if not isinstance(rec.get("result"), dict):
            return "an ok record without a result"
        if task.check:
            try:
                resolve(task.check)(rec["result"], dict(task.key))
            except (ValueError, TypeError, KeyError) as exc:
                return f"its result does not pass {task.check}: {type(exc).__name__}: {exc}"
    return None


class TaskStore:
    """One JSON file per finished task in ``folder``: ``{id, fn, key, status, attempts, ...}``.

    Attributes:
        rejected: ``(path, reason)`` of each record file :meth:`load` found and refused (it is
            recomputed), for the command to report.
    """

    def __init__(self, folder: str | os.PathLike):
        self.folder = Path(folder)
        self.rejected: list[tuple[Path, str]] = []

    def path(self, task: Task) -> Path:
        return self.folder / f"{task.id}.json"

    def load(self, task: Task) -> dict | None:
        """The saved record of ``task``, or None when there is none or it is not valid
        (:func:`record_problem`: not JSON, not a record, another task's, a missing or malformed
        result; it is recomputed, and listed in :attr:`rejected`)."""
        p = self.path(task)
        if not p.exists():
            return None
        problem = None
        if not p.is_file():
            problem = "not a regular file"
        else:
            try:
                rec = json.loads(p.read_text())
            except (OSError, ValueError) as exc:  # a torn or foreign file
                problem = f"unreadable ({type(exc).__name__})"
            else:
                problem = record_problem(rec, task)
        if problem is not None:
            self.rejected.append((p, problem))
            return None
        return rec

    def check_writable(self, tasks: Sequence[Task]) -> None:
        """``ValueError`` (one line) if a record of ``tasks`` could not be written: the folder is
        not a directory, or a record's path is a directory. Checked before any task runs (a
        directory there crashed the campaign after the task had run)."""
        if self.folder.exists() and not self.folder.is_dir():
            raise ValueError(f"{self.folder}: exists and is not a directory (the campaign's records go there)")
        for task in tasks:
            p = self.path(task)
            if p.exists() and not p.is_file():
                raise ValueError(f"{p}: is not a regular file (the record of task {task.id} is written there)")

    def save(self, task: Task, record: dict) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        p = self.path(task)
        tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(record, indent=1, allow_nan=True, default=_json_default))
        os.replace(tmp, p)  # atomic: a reader sees the old file or the whole new one

    def clear(self) -> None:
        """Remove the task records, traces and temporary files a store wrote (a campaign started
        without resume): files named as a store names them (``<label>-<12 hex digits>.json`` or
        ``.npz``, ``.<name>.<pid>.tmp``); a ``.json`` only if it is a task record of its own id.
        Anything else in the folder is the user's and stays."""
        if self.folder.is_dir():
            for p in self.folder.iterdir():
                if p.is_file() and _written_by_a_store(p):
                    p.unlink()


_RECORD_NAME = re.compile(r"^.+-[0-9a-f]{12}\.(json|npz)$")
_TMP_NAME = re.compile(r"^\..+\.\d+\.tmp$")


def _written_by_a_store(p: Path) -> bool:
    """Whether ``p`` is a file :class:`TaskStore` writes: a record (its JSON holds its own id), a
    trace next to the records (``<task id>.npz``) or a temporary file of :meth:`TaskStore.save`."""
    if _TMP_NAME.match(p.name):
        return True
    if not _RECORD_NAME.match(p.name):
        return False
    if p.suffix == ".npz":
        return True
    try:
        rec = json.loads(p.read_text())
    except (OSError, ValueError):
        return False
    return isinstance(rec, dict) and rec.get("id") == p.stem and "fn" in rec and "key" in rec


def _json_default(obj: Any):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")
