"""A campaign task (:class:`Task`): a function named ``"package.module:function"`` and the key, the
JSON-serialisable keyword arguments that define its result; its id is a hash of both."""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Task", "canonical", "resolve", "file_digest"]


def canonical(obj: Any) -> str:
    """The canonical JSON text of ``obj`` (sorted keys, no spaces): what a task id hashes and what
    a saved record's key is compared by."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=True)


@dataclass(frozen=True)
class Task:
    """One unit of work: ``fn(**key, **extra)``.

    Attributes:
        fn: ``"package.module:function"``, importable in every worker; it returns a dict (its
            JSON-serialisable entries are saved; an entry ``"artifacts"`` is handed to the
            campaign's ``on_result`` callback in the driver and not saved).
        key: JSON-serialisable keyword arguments; with ``fn`` they define the task (its id) and
            must determine its result, seeds included.
        extra: keyword arguments that do not change the result (e.g. what to return for plots).
        label: a readable prefix of the id (file-name safe characters are kept).
        cost: an estimate of the run time, to start the longest tasks first (no effect on results).
        check: ``"package.module:function"`` of the schema check of a saved result,
            ``check(result, key)`` raising ``ValueError``/``TypeError``/``KeyError`` when the
            result is not what the campaign reads (a saved record that fails it is recomputed on
            resume); empty: only the record's envelope is checked (:meth:`TaskStore.load`).
        batch: ``"package.module:function"`` that runs several tasks of the same ``fn`` and
            ``group`` at once, ``batch(keys, extras) -> [result, ...]`` (one per key, in order),
            each result what ``fn(**key, **extra)`` returns (``azimut eval``: the episodes of one
            controller stepped as one vector env); empty: the task runs alone. Not part of the id.
        group: tasks with the same ``batch`` and ``group`` may run together (no effect on results).
    """

    fn: str
    key: Mapping[str, Any]
    extra: Mapping[str, Any] = field(default_factory=dict)
    label: str = ""
    cost: float = 1.0
    check: str = ""
    batch: str = ""
    group: str = ""

    def __post_init__(self):
        if not isinstance(self.fn, str) or ":" not in self.fn:
            raise ValueError(f"Task.fn must be 'module:function', got {self.fn!r}")
        if not isinstance(self.batch, str) or (self.batch and ":" not in self.batch):
            raise ValueError(f"Task.batch must be '' or 'module:function', got {self.batch!r}")
        try:
            canonical(dict(self.key))
        except TypeError as exc:
            raise TypeError(f"Task.key must be JSON-serialisable: {exc}") from None

    @property
    def id(self) -> str:
        """A stable id: the label and a hash of ``fn`` and ``key`` (same task, same id, anywhere)."""
        digest = hashlib.sha256(canonical({"fn": self.fn, "key": dict(self.key)}).encode()).hexdigest()[:12]
        label = re.sub(r"[^A-Za-z0-9_.=+-]+", "_", self.label).strip("_")[:80]
        return f"{label}-{digest}" if label else digest


def resolve(fn: str) -> Callable[..., dict]:
    """The function named ``"package.module:function"`` (a task's ``fn`` or ``check``)."""
    module, _, name = fn.partition(":")
    obj: Any = importlib.import_module(module)
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def file_digest(path: str | os.PathLike) -> str:
    """SHA-256 of the content of the file ``path`` (hex): what a task's key holds for each file its
    result depends on (a model, its statistics, a robot description), so that a file changed at
    the same path is a new task, never a stale record."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()
