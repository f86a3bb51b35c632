"""The packages' import order (ARCHITECTURE.md): estimation <- azimut_env <- control <- train <- jobs.

Every ``import`` statement of every module is read from its source (lazy imports inside functions
included): a module may import its own package and the packages below it, never one above, and
the modules' import graph has no cycle. Inside ``azimut_env``, the ground floor (parameters, the
action map) imports none of the subpackages built on it (physics, task, tracks).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LAYERS = ("estimation", "azimut_env", "control", "train", "jobs")


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in LAYERS:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> list[tuple[str, int]]:
    """(imported module, line) of every import in the file, resolved to a module of the project
    where it names one (``from pkg import mod`` -> ``pkg.mod``)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                full = f"{base}.{alias.name}"
                found.append((full if full in MODULES else base, node.lineno))
    return [(mod, line) for mod, line in found if mod.split(".")[0] in LAYERS]


def _resolve(mod: str) -> str | None:
    while mod and mod not in MODULES:
        mod = mod.rpartition(".")[0]
    return mod or None


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_upward_import(name):
    rank = LAYERS.index(name.split(".")[0])
    upward = [f"line {line}: {mod}" for mod, line in _imports(name, MODULES[name])
              if LAYERS.index(mod.split(".")[0]) > rank]
    assert not upward, f"{name} imports a layer above it: {'; '.join(upward)}"


#: azimut_env's ground floor, the modules its subpackages import (parameters, the action map, the
#: input checks, the robot files), and the subpackages above it (ARCHITECTURE.md)
ENV_GROUND = ("azimut_env.action_map", "azimut_env.params", "azimut_env.validation", "azimut_env.imperfections",
              "azimut_env.robot_file", "azimut_env.typed_lists")
ENV_UPPER = ("azimut_env.physics", "azimut_env.task", "azimut_env.tracks")


@pytest.mark.parametrize("name", ENV_GROUND)
def test_env_ground_floor_imports_no_subpackage(name):
    upward = [f"line {line}: {mod}" for mod, line in _imports(name, MODULES[name])
              if mod.startswith(tuple(f"{pkg}." for pkg in ENV_UPPER)) or mod in ENV_UPPER]
    assert not upward, f"{name} imports a floor of azimut_env above it: {'; '.join(upward)}"


def test_no_import_cycle():
    graph = {name: {r for mod, _ in _imports(name, path) if (r := _resolve(mod)) and r != name}
             for name, path in MODULES.items()}
    # a package's __init__ importing its own submodules is not a cycle with them
    for name in graph:
        graph[name] = {m for m in graph[name] if not (m.startswith(name + ".") and MODULES[name].name == "__init__.py")}
    state: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles[:5])


def test_module_size():
    long = {name: n for name, path in MODULES.items() if (n := len(path.read_text().splitlines())) > 500}
    assert not long, f"modules over 500 lines: {long}"
