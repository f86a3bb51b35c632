"""``--action icr_rate`` (as the tables print it) is ``icr-rate`` for azimut train and tune (issue 31)."""

from __future__ import annotations

import importlib

import pytest

from jobs.cli import CommandParser


@pytest.mark.parametrize("module", ["jobs.training.command", "jobs.training.tune"])
def test_action_accepts_the_tables_spelling(module, capsys):
    mod = importlib.import_module(module)
    parser = CommandParser(prog="azimut x")
    mod.add_arguments(parser)
    extra = ["--out", "unused"]
    for given, want in (("icr_rate", "icr-rate"), ("icr-rate", "icr-rate"), ("residual", "residual")):
        assert parser.parse_args(["--action", given, *extra]).action == want
    with pytest.raises(SystemExit):
        parser.parse_args(["--action", "icr__rate", *extra])
    assert "invalid choice" in capsys.readouterr().err
