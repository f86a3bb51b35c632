"""``azimut eval``'s report reads on its own: every column defined, counts as integers, intervals
promised only where shown, provenance recorded, ``metrics.json`` strict JSON; the plots' stop
shading."""

from __future__ import annotations

import dataclasses
import json
import re

import numpy as np
import pytest

from jobs.cli import main
from jobs.glossary import GLOSSARY
from jobs.records import UNKNOWN, provenance, strict_json


def _strict_load(path):
    """Parse with a strict parser: NaN, Infinity and -Infinity are refused."""
    def refuse(token):
        raise ValueError(f"non-JSON token {token}")

    return json.loads(path.read_text(), parse_constant=refuse)


def _tables(text: str) -> list[list[str]]:
    """The header cells of every Markdown table."""
    lines = text.splitlines()
    return [[c.strip() for c in line.strip().strip("|").split("|")]
            for line, nxt in zip(lines, lines[1:]) if line.startswith("|") and nxt.startswith("|---")]


def _columns_section(text: str) -> str:
    return text.split("## Columns", 1)[1]


@pytest.fixture(scope="module")
def two_seeds(tmp_path_factory):
    """Two seeds of twist on crab, cut at 0.5 s (the track is not finished: undefined values)."""
    out = tmp_path_factory.mktemp("eval2")
    rc = main(["eval", "--controllers", "twist", "--tracks", "crab", "--seeds", "0,1", "--max-time", "0.5",
               "--no-plots", "--out", str(out)])
    assert rc == 0
    return out


@pytest.fixture(scope="module")
def one_seed(tmp_path_factory):
    out = tmp_path_factory.mktemp("eval1")
    rc = main(["eval", "--controllers", "icr,twist", "--tracks", "crab", "--max-time", "0.5", "--no-plots",
               "--out", str(out)])
    assert rc == 0
    return out


def test_every_column_of_every_table_is_defined(one_seed, two_seeds):
    for out in (one_seed, two_seeds):
        text = (out / "report.md").read_text()
        defined = re.findall(r"^- \*\*(.+?)\*\*: .+\.$", _columns_section(text), flags=re.M)
        headers = {h for table in _tables(text) for h in table}
        assert headers and headers <= set(defined), headers - set(defined)
        assert len(defined) == len(set(defined))
    assert "qua" in GLOSSARY["mean_qua"].definition and "(28)–(29)" in GLOSSARY["mean_qua"].definition


def test_counts_print_as_integers_and_intervals_only_where_shown(one_seed, two_seeds):
    text = (one_seed / "report.md").read_text()
    assert "in brackets" not in text and "One seed" in text and "## Per-seed rows" not in text
    header = _tables(text)[0]
    for row in [r for r in text.splitlines() if r.startswith("| twist | crab |")]:
        cells = [c.strip() for c in row.strip().strip("|").split("|")]
        for name in ("limit-exceeded steps", "stop+reconfig"):
            assert re.fullmatch(r"\d+", cells[header.index(name)]), (name, cells[header.index(name)])
        assert "[" not in row
    text = (two_seeds / "report.md").read_text()
    assert "## Per-seed rows" in text
    seed_table = [t for t in _tables(text) if "seed" in t][0]
    for row in [r for r in text.splitlines() if re.match(r"\| twist \| crab \| \d \|", r)]:
        cells = [c.strip() for c in row.strip().strip("|").split("|")]
        assert re.fullmatch(r"\d+", cells[seed_table.index("limit-exceeded steps")])
        assert cells[seed_table.index("done")] in ("yes", "no")
    shown = "[" in text.split("## Per-seed rows")[0].split("## Summary")[1]
    assert ("in brackets" in text) == shown


def test_provenance_and_strict_json(two_seeds):
    data = _strict_load(two_seeds / "metrics.json")  # NaN would raise
    prov = data["campaign"]["provenance"]
    assert set(prov) == {"version", "commit", "local_changes"}
    assert prov == provenance()
    assert f"commit {prov['commit'][:12]}" in (two_seeds / "report.md").read_text()
    # the episode was cut before the end of the track: its completion time is undefined -> null
    assert all(e["completion_time_s"] is None for e in data["episodes"])
    assert "NaN" not in (two_seeds / "metrics.json").read_text()


def test_the_robot_and_its_imperfections_are_named(one_seed):
    """Azimut-v2's default robot has the paper imperfections: the report says so, and metrics.json."""
    assert _strict_load(one_seed / "metrics.json")["campaign"]["imperfections"] == "paper"
    assert "Robot azimut3 (imperfections: paper);" in (one_seed / "report.md").read_text()
    from azimut_env.imperfections import imperfections_of, with_imperfections
    from azimut_env.params import RobotParams

    assert imperfections_of(RobotParams()) == "ideal"
    assert imperfections_of(with_imperfections(RobotParams(), "paper")) == "paper"
    own = RobotParams.preset("swerve")
    own = dataclasses.replace(own, steering=dataclasses.replace(own.steering, friction_coulomb=0.1,
                                                                friction_static=0.2))
    assert imperfections_of(own) is None


def test_strict_json_and_unknown_provenance(monkeypatch, tmp_path):
    assert strict_json({"a": float("nan"), "b": [np.float64(np.inf), np.int64(3)], 4: np.array([1.0, -np.inf])}) \
        == {"a": None, "b": [None, 3], "4": [1.0, None]}
    import jobs.records as records

    monkeypatch.setattr(records, "_source_root", lambda: tmp_path)  # no git checkout there
    prov = records.provenance()
    assert prov["commit"] == UNKNOWN and prov["local_changes"] is None
    assert "commit unknown" in records.provenance_text(prov)


def test_qua_plot_shades_the_stops(tmp_path):
    pytest.importorskip("matplotlib")
    from azimut_env.params import ActuatorLimits
    from azimut_env.tracks import make_track
    from control.episode import EpisodeLog
    from control.icr.config import Mode
    from estimation import RobotGeometry
    from jobs.eval.plots import _pyplot, _shade_stops, write_plots

    t = np.arange(1, 101) * 0.02
    mode = np.zeros(100, dtype=int)
    mode[20:30] = int(Mode.STOPPING)
    mode[30:40] = int(Mode.RECONFIGURING)
    mode[70:80] = int(Mode.STOPPING)
    log = EpisodeLog("icr", make_track("crab"), 0.02, t=t, qua=np.ones(100), mode=mode,
                     lam_hat=np.tile([0.0, 0.0, 1.0], (100, 1)), pose=np.zeros((100, 3)))
    fig, ax = _pyplot().subplots()
    _shade_stops(ax, log)
    spans = list(ax.patches)
    assert len(spans) == 2  # two stops: 20..39 and 70..79
    assert [lbl for lbl in (p.get_label() for p in spans) if not lbl.startswith("_")] == \
        ["controller stopped or turning wheels in place"]
    files = write_plots(log, tmp_path, RobotGeometry.azimut3(), ActuatorLimits())
    assert "icr_crab_qua.png" in files


def test_kick_study_columns_are_defined(tmp_path):
    from jobs.eval.command import _kick_section
    from jobs.glossary import KICK_GLOSSARY

    text = _kick_section(["twist"], 1, 0, tmp_path)
    defined = set(re.findall(r"^- \*\*(.+?)\*\*: ", text, flags=re.M))
    assert set(_tables(text)[0]) - {"controller"} <= defined
    assert defined == {c.header for c in KICK_GLOSSARY.values()}
    _strict_load(tmp_path / "kicks_twist.json")


def test_learning_curve_is_labelled_from_the_run(tmp_path):
    pytest.importorskip("matplotlib")
    from jobs.eval.plots import _pyplot
    from jobs.training.plots import evaluation_label, learning_curve_figure, training_label

    assert "held out" in evaluation_label("random", ["circle", "crab"])
    assert "held out" in evaluation_label("square", ["circle"])
    assert "held out" not in evaluation_label("circle", ["circle", "crab"])
    assert training_label("crab") == "the crab track" and "random" in training_label("random")
    (tmp_path / "evaluations.json").write_text(json.dumps(
        [{"timesteps": 64, "mean_return": 1.0}, {"timesteps": 128, "mean_return": 2.0, "final": True}]))
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "progress.csv").write_text("time/total_timesteps,rollout/ep_rew_mean\n64,0.5\n128,1.5\n")
    record = {"algo": "ppo", "action": "raw", "seed": 3, "track": "circle", "eval_tracks": ["circle"]}
    fig = learning_curve_figure(tmp_path, record, _pyplot())
    legend = " ".join(t.get_text() for t in fig.axes[0].get_legend().get_texts())
    assert "the circle track" in legend and "circle is also the training track" in legend
    assert "random tracks" not in legend and "held out" not in legend and "final policy" in legend
    assert "PPO, raw actions, seed 3" in fig.axes[0].get_title()
