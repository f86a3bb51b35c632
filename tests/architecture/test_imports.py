"""What importing a package costs: ``import azimut_env`` only registers the envs (its docstring's
promise), and ``estimation``'s names load with their own module on first use."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

#: the project's packages and the heavy dependencies a bare ``import azimut_env`` must not load
WATCHED = ("estimation", "azimut_env", "control", "train", "jobs", "numba", "pymunk", "torch", "scipy")


def _loaded_after(statement: str) -> set[str]:
    code = (f"import sys; {statement}; "
            f"print('\\n'.join(m for m in sys.modules if m.split('.')[0] in {WATCHED!r}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    return set(out.split())


def test_import_azimut_env_only_registers():
    loaded = _loaded_after("import azimut_env, gymnasium; assert 'Azimut-v2' in gymnasium.registry")
    assert loaded == {"azimut_env", "estimation", "estimation.numba_cache"}, sorted(loaded)


def test_a_name_of_estimation_loads_its_module_only():
    loaded = _loaded_after("from estimation import RobotGeometry")
    assert "estimation.geometry" in loaded and "estimation.datasets" not in loaded and "estimation.it" not in loaded


@pytest.mark.parametrize("name", importlib.import_module("estimation").__all__)
def test_estimation_names_are_their_modules(name):
    estimation = importlib.import_module("estimation")
    module = importlib.import_module(f"estimation.{estimation._MODULE_OF[name]}")
    assert getattr(estimation, name) is getattr(module, name)
    assert name in dir(estimation)
