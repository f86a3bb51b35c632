"""``azimut eval --speed-scales``: the flag (parsed, refused in one line before any work), one
episode per (controller, track, seed, speed scale) whose key and label carry the scale (so
``--resume`` works across scales), the verdict per speed scale ranking the slip per metre, who
dominates on the fronts (computed), the fronts plot, and a small end-to-end run."""

from __future__ import annotations

import json
import re

import pytest

from jobs.cli import main
from jobs.eval.command import arg_speed_scales


def _cell(controller, scale, done=1.0, time_s=10.0, per_m=1.0, lat=0.01, track="line", failed=0):
    stats = {"completed": done, "completion_time_s": time_s, "slip_energy_per_m": per_m, "rms_lateral_m": lat}
    return {"controller": controller, "track": track, "speed_scale": scale, "n": 1, "ok": 1, "failed": failed,
            "metrics": {k: {"mean": v, "lo": v, "hi": v, "n": 1} for k, v in stats.items()}}


def test_speed_scales_parse_in_order():
    assert arg_speed_scales("0.6,0.8,1.0,1.2,1.4") == [0.6, 0.8, 1.0, 1.2, 1.4]
    assert arg_speed_scales(" 1.2 , 0.5") == [1.2, 0.5]
    assert arg_speed_scales("2") == [2.0]


@pytest.mark.parametrize("value, message", [("0.8,abc", "expected a number"), ("0,1", "must be > 0"),
                                            ("0.8,0.8", "repeated"), ("1,1.0", "repeated"),
                                            (",", "at least one"), ("0.8,,1", "empty entry"),
                                            ("11", "must be <= 10"), ("nan", "finite")])
def test_a_bad_speed_scales_list_is_refused_in_one_line_before_any_work(value, message, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["eval", "--speed-scales", value, "--no-plots", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "argument --speed-scales" in err and message in err and "Traceback" not in err
    assert not out.exists()


def test_speed_scale_and_speed_scales_are_exclusive(tmp_path, capsys):
    assert main(["eval", "--speed-scale", "1.2", "--speed-scales", "0.8,1.2", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "argument --speed-scales: not allowed with argument --speed-scale" in err


def test_each_scale_is_an_episode_whose_key_and_label_carry_it():
    """The scale is in the key (and the id); a scale-1 episode keeps the label it had before."""
    from jobs.eval.campaign import episode_tasks

    tasks = episode_tasks(["twist"], ["crab"], [0], speed_scales=[0.8, 1.0])
    assert [t.key["speed_scale"] for t in tasks] == [0.8, 1.0]
    assert tasks[0].id.startswith("twist-crab-s0-x0.8-") and tasks[1].id.startswith("twist-crab-s0-")
    assert tasks[1].id == episode_tasks(["twist"], ["crab"], [0])[0].id  # --speed-scale 1 resumes it
    assert tasks[0].id == episode_tasks(["twist"], ["crab"], [0], speed_scale=0.8)[0].id
    assert tasks[0].group != tasks[1].group  # each scale is its own batch (one controller speed each)


def test_the_verdict_compares_at_equal_speed_scale_by_slip_per_metre():
    from jobs.eval.verdict import verdict_lines

    cells = [_cell("a", 0.8, time_s=12.0, per_m=0.5), _cell("b", 0.8, time_s=10.0, per_m=2.0),
             _cell("a", 1.2, time_s=8.0, per_m=3.0), _cell("b", 1.2, time_s=9.0, per_m=1.0)]
    lines = verdict_lines(cells, ["line"], ["a", "b"])
    assert lines[0].startswith("- **line** at ×0.8:") and "least slip per metre **a** (0.50 J/m" in lines[0]
    assert "fastest finisher **b**" in lines[0]
    assert lines[1].startswith("- **line** at ×1.2:") and "least slip per metre **b** (1.00 J/m" in lines[1]
    assert "Over the (track, speed scale) pairs" in lines[2] and "a on 1 of 2, b on 1 of 2" in lines[2]


def test_dominance_is_computed_where_both_finished():
    from jobs.eval.fronts import dominance, dominance_text

    cells = [_cell("icr", 1.0, time_s=9.0, per_m=0.5), _cell("twist", 1.0, time_s=10.0, per_m=2.0),
             _cell("setpoint", 1.0, time_s=8.0, per_m=3.0)]
    _, pairs = dominance(cells)
    assert pairs == [("icr", "twist")]
    text = dominance_text(cells, 1.0, ["icr", "twist", "setpoint"])
    assert text.startswith("- ×1: **icr** dominates twist (faster and less slip per metre)")
    assert "a trade-off between icr and setpoint, twist and setpoint" in text
    unfinished = [_cell("icr", 1.0, time_s=1.0, per_m=0.1, done=0.5), _cell("twist", 1.0)]
    assert "fewer than two controllers finished every episode (only twist)" in dominance_text(unfinished, 1.0,
                                                                                             ["icr", "twist"])
    none = dominance_text([_cell("a", 1.0, time_s=9.0, per_m=2.0), _cell("b", 1.0, time_s=10.0, per_m=1.0)], 1.0,
                          ["a", "b"])
    assert "no controller dominates another" in none and "a 9.0 s, 2.00 J/m; b 10.0 s, 1.00 J/m" in none
    from jobs.eval.fronts import front_text

    # across the scales: icr at 1.2 beats twist at 0.8 and at 1.2; twist beats nothing of icr's
    front = [_cell("icr", 0.8, time_s=21.0, per_m=0.6), _cell("icr", 1.2, time_s=14.9, per_m=0.7),
             _cell("twist", 0.8, time_s=20.4, per_m=11.8), _cell("twist", 1.2, time_s=13.0, per_m=7.7)]
    assert "no front dominates another" in front_text(front, ["icr", "twist"])  # twist at 1.2 is the fastest
    front[1] = _cell("icr", 1.2, time_s=12.9, per_m=0.7)
    assert "**icr**'s front dominates twist's" in front_text(front, ["icr", "twist"])
    every = dominance_text(cells[:2] + [_cell("slow", 1.0, time_s=11.0, per_m=4.0)], 1.0, ["icr", "twist", "slow"])
    assert "**icr** dominates twist and slow (every other that finished)" in every


def test_the_fronts_plot_is_written(tmp_path):
    pytest.importorskip("matplotlib")
    from jobs.eval.plots import fronts_plot

    cells = [_cell(c, x, time_s=t / x, per_m=p * x, done=1.0 if x < 1.3 else 0.0)
             for c, t, p in (("icr", 10.0, 0.5), ("twist", 8.0, 2.0)) for x in (0.8, 1.0, 1.4)]
    files = fronts_plot("my/line.csv", cells, ["icr", "twist"], tmp_path)
    assert files == ["my_line.csv_fronts.png"] and (tmp_path / files[0]).stat().st_size > 1000
    no_lap = [_cell("icr", 0.8, time_s=float("nan"))]
    assert fronts_plot("line", no_lap, ["icr"], tmp_path) == []


def test_eval_at_two_speed_scales_writes_both_and_the_fronts(tmp_path):
    out = tmp_path / "out"
    assert main(["eval", "--controllers", "icr,twist-setpoint", "--tracks", "circle", "--speed-scales", "0.8,1.2",
                 "--seeds", "0", "--max-time", "5", "--no-plots", "--out", str(out)]) == 0
    data = json.loads((out / "metrics.json").read_text())
    assert data["campaign"]["speed_scales"] == [0.8, 1.2] and data["campaign"]["speed_scale"] is None
    assert {(r["controller"], r["speed_scale"]) for r in data["episodes"]} == \
        {(c, x) for c in ("icr", "twist-setpoint") for x in (0.8, 1.2)}
    assert {(c["controller"], c["speed_scale"]) for c in data["summary"]} == \
        {(c, x) for c in ("icr", "twist-setpoint") for x in (0.8, 1.2)}
    for row in data["episodes"]:
        assert row["slip_energy_per_m"] == pytest.approx(row["slip_energy_J"] / row["distance_m"])
    report = (out / "report.md").read_text()
    assert "## Fronts" in report and "### Fronts on circle" in report
    fronts = report.split("### Fronts on circle", 1)[1]
    assert "| icr | 0.8 |" in fronts and "| twist-setpoint | 1.2 |" in fronts
    assert "- ×0.8:" in fronts and "- ×1.2:" in fronts  # who dominates, per scale (5 s: no lap finished)
    assert "- **circle** at ×0.8:" in report and "speed scales 0.8, 1.2" in report
    lines = report.splitlines()
    headers = {c.strip() for line, nxt in zip(lines, lines[1:]) if line.startswith("|") and nxt.startswith("|---")
               for c in line.strip().strip("|").split("|")}
    defined = set(re.findall(r"^- \*\*(.+?)\*\*: ", report.split("## Columns", 1)[1], flags=re.M))
    assert {"speed ×", "slip per m [J/m]", "antagonism over distance [N]", "standstill slip [J]"} <= headers <= defined
