"""The documentation's tables are generated (``python -m azimut_env.doc_tables --write``), never
pasted: every marked block of the envs' docstrings and of ``docs/env.md`` is its table's current
output, and a changed table makes the files stale."""

from __future__ import annotations

import textwrap

import pytest

from azimut_env import doc_tables
from azimut_env.env import AzimutEnv
from azimut_env.task.info import info_table
from azimut_env.task.observation import observation_table
from azimut_env.task.reward import reward_table
from azimut_env.task.termination import termination_table
from azimut_env.vector_env import AzimutVectorEnv


def test_the_generated_tables_are_current():
    assert doc_tables.stale_files() == [], "run: python -m azimut_env.doc_tables --write"
    assert doc_tables.main(["--check"]) == 0


def test_every_table_is_in_the_docstrings_and_the_env_page():
    page = (doc_tables.ROOT / "docs" / "env.md").read_text(encoding="utf-8")
    single = textwrap.dedent(AzimutEnv.__doc__)
    for table in (observation_table(), reward_table(), termination_table(), info_table()):
        assert table in page and table in single
    assert "AzimutEnv" in AzimutVectorEnv.__doc__ and "INFO_FIELDS" in AzimutVectorEnv.__doc__  # refers to it


def test_a_changed_table_is_rewritten_between_its_markers():
    text = "Intro\n    <!-- generated: reward-table -->\n    | stale |\n    <!-- end generated -->\nOutro\n"
    out = doc_tables.render(text, {"reward-table": lambda: "| a |\n|---|\n| 1 |"})
    assert out == "Intro\n    <!-- generated: reward-table -->\n    | a |\n    |---|\n    | 1 |\n" \
                  "    <!-- end generated -->\nOutro\n"
    assert doc_tables.render(out, {"reward-table": lambda: "| a |\n|---|\n| 1 |"}) == out  # idempotent
    with pytest.raises(KeyError):
        doc_tables.render("<!-- generated: nothing -->\n<!-- end generated -->", {})
