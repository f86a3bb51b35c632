"""The documentation's tables, generated from their definitions: ``python -m azimut_env.doc_tables --write``.

The observation, reward, termination and ``info`` tables of the env's docstring
(:class:`~azimut_env.env.AzimutEnv`; the vector env's refers to it) and of ``docs/env.md`` are the
output of the tables' own renderers
(:func:`~azimut_env.task.observation.observation_table`,
:func:`~azimut_env.task.reward.reward_table`,
:func:`~azimut_env.task.termination.termination_table`,
:func:`~azimut_env.task.info.info_table`), written between markers::

    <!-- generated: reward-table -->
    | name | weight | ...
    <!-- end generated -->

never pasted: after a change of a table, ``--write`` rewrites every marked block (at the marker's
indentation); ``--check`` (and ``tests/azimut_env/test_doc_tables.py``) fails while one is stale.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Callable
from pathlib import Path

__all__ = ["TABLES", "FILES", "render", "stale_files", "write", "main"]

ROOT = Path(__file__).resolve().parent.parent


def _tables() -> dict[str, Callable[[], str]]:
    from azimut_env.task.info import info_table
    from azimut_env.task.observation import observation_table
    from azimut_env.task.reward import reward_table
    from azimut_env.task.termination import termination_table

    return {"observation-table": observation_table, "reward-table": reward_table,
            "termination-table": termination_table, "info-table": info_table}


#: the marker names, each the table of a renderer
TABLES = ("observation-table", "reward-table", "termination-table", "info-table")
#: the files with marked tables, relative to the repository root
FILES = ("azimut_env/env.py", "docs/env.md")

_BLOCK = re.compile(r"^(?P<indent>[ \t]*)<!-- generated: (?P<name>[\w-]+) -->\n.*?^(?P=indent)<!-- end generated -->$",
                    re.MULTILINE | re.DOTALL)


def render(text: str, tables: dict[str, Callable[[], str]] | None = None) -> str:
    """``text`` with every marked block holding its table's current output (``KeyError`` for an
    unknown marker name)."""
    tables = _tables() if tables is None else tables

    def block(m: re.Match) -> str:
        indent, name = m.group("indent"), m.group("name")
        body = "\n".join(indent + line for line in tables[name]().splitlines())
        return f"{indent}<!-- generated: {name} -->\n{body}\n{indent}<!-- end generated -->"

    return _BLOCK.sub(block, text)


def stale_files(root: Path = ROOT) -> list[str]:
    """The files of :data:`FILES` whose marked tables are not their tables' current output."""
    texts = {f: (root / f).read_text(encoding="utf-8") for f in FILES}
    return [f for f, text in texts.items() if render(text) != text]


def write(root: Path = ROOT) -> list[str]:
    """Rewrite the stale files; returns their names."""
    stale = stale_files(root)
    for f in stale:
        path = root / f
        path.write_text(render(path.read_text(encoding="utf-8")), encoding="utf-8")
    return stale


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m azimut_env.doc_tables", description=__doc__.splitlines()[0])
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--write", action="store_true", help="rewrite the stale tables")
    group.add_argument("--check", action="store_true", help="exit 1 if a table is stale")
    args = parser.parse_args(argv)
    if args.write:
        for f in write():
            print(f"rewrote {f}")
        return 0
    stale = stale_files()
    for f in stale:
        print(f"{f}: generated tables are stale: run python -m azimut_env.doc_tables --write")
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
