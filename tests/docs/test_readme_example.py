"""The README's Python example (the env driven by the ICR controller and the path follower) runs
as printed: the test executes the README's block itself, with its step count shortened."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LOOP = "range(5000)"  # the example's loop; the default test run shortens it


def readme_example() -> str:
    """The README's one Python block that drives the env with the ICR controller."""
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(encoding="utf-8"), flags=re.S)
    example = [b for b in blocks if "ICRController" in b and "gym.make" in b]
    assert len(example) == 1, f"expected one README block driving the env with ICRController, found {len(example)}"
    return example[0]


def run_example(steps: int | None) -> dict:
    code = readme_example()
    assert code.count(LOOP) == 1, f"the README example's loop is no longer `for step in {LOOP}:`; update this test"
    if steps is not None:
        code = code.replace(LOOP, f"range({steps})")
    namespace: dict = {}
    try:
        exec(compile(code, str(ROOT / "README.md"), "exec"), namespace)
    finally:
        if "env" in namespace:
            namespace["env"].close()
    return namespace


def test_readme_example_drives_the_robot_along_the_track(capsys):
    ns = run_example(steps=100)
    info = ns["info"]
    assert ns["step"] == 99 and not (ns["terminated"] or ns["truncated"])
    assert "error" not in info
    assert info["progress"] > 0.1  # 2 s from rest on `paper`: it moves along the track
    assert abs(info["lateral_error"]) < 0.03  # and stays on it
    assert capsys.readouterr().out.startswith("finished: False, lateral error ")


@pytest.mark.slow
def test_readme_example_finishes_the_track():
    ns = run_example(steps=None)
    assert ns["terminated"] and ns["info"]["finished"] and not ns["info"]["off_track"]
