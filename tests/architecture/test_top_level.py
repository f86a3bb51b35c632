"""The repository's top level is the design's layout (the brief: ``pyproject.toml, azimut_env/,
control/, estimation/, train/, tests/, README.md``, ``docs/`` beside them) plus the job layer, the
CI scripts and the project files: nothing a test run or a tool left behind gets committed."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LAYOUT = {"pyproject.toml", "README.md", "ARCHITECTURE.md", "mkdocs.yml", ".gitignore", ".ci", "azimut_env", "control",
          "estimation", "train", "jobs", "tests", "docs"}


def test_tracked_top_level_entries_are_the_layout():
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    names = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout.split(b"\0")
    top = {n.decode("utf-8", "replace").split("/", 1)[0] for n in names if n}
    assert top <= LAYOUT, f"unexpected top-level entries tracked: {sorted(top - LAYOUT)}"
