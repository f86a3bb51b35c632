"""The documentation matches the code: the docs pages' Python examples run, every repository path
and every dotted ``package.module.name`` they name exists, and the env page's observation, reward
and info tables are the ones the code generates. (``mkdocs build --strict`` in ``.ci/run`` checks the links between
pages and their anchors.)"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = sorted([ROOT / "README.md", ROOT / "ARCHITECTURE.md", *(ROOT / "docs").rglob("*.md")])
PACKAGES = ("estimation", "azimut_env", "control", "train", "jobs")

#: a repository path: a top-level folder of the repository, then a path (globs allowed)
PATH_RE = re.compile(r"(?<![\w/.-])((?:estimation|azimut_env|control|train|jobs|tests|docs|\.ci)/[\w./*-]*[\w*/])")
#: a dotted name inside backticks that starts with one of the packages (``jobs.cli:main`` too)
DOTTED_RE = re.compile(r"`((?:" + "|".join(PACKAGES) + r")(?:\.[A-Za-z_]\w*)+(?::[A-Za-z_]\w*)?)")


def _rel(page: Path) -> str:
    return str(page.relative_to(ROOT))


FENCE_RE = re.compile(r"```(\w*)\n(.*?)```", flags=re.S)
#: the file a ``toml`` block is: the last backticked ``*.toml`` name in the prose just above it
TOML_NAME_RE = re.compile(r"`([\w.-]+\.toml)`")


def pages_with_examples() -> list[Path]:
    """The docs pages with Python blocks (the README's is run by test_readme_example.py, with a
    shorter loop)."""
    return [p for p in PAGES if p.name != "README.md" and "```python\n" in p.read_text(encoding="utf-8")]


def page_examples(page: Path) -> tuple[dict[str, str], list[str]]:
    """(files, python blocks) of a page: each ``toml`` block that the prose above it names
    (\"a robot file (`my_robot.toml`, ...)\") is that file, for the examples that read it."""
    text = page.read_text(encoding="utf-8")
    files, blocks, last_end = {}, [], 0
    for m in FENCE_RE.finditer(text):
        lang, body = m.group(1), m.group(2)
        if lang == "toml":
            names = TOML_NAME_RE.findall(text[last_end:m.start()])
            if names:
                files[names[-1]] = body
        elif lang == "python":
            blocks.append(body)
        last_end = m.end()
    return files, blocks


@pytest.mark.parametrize("page", pages_with_examples(), ids=_rel)
def test_docs_python_examples_run(page, tmp_path, monkeypatch):
    """A page's Python blocks run in order, in a fresh folder holding the page's named TOML files
    (what a reader following the page has)."""
    monkeypatch.chdir(tmp_path)
    files, blocks = page_examples(page)
    for name, body in files.items():
        (tmp_path / name).write_text(body, encoding="utf-8")
    for index, code in enumerate(blocks):
        namespace: dict = {}
        exec(compile(code, f"{_rel(page)} (python block {index})", "exec"), namespace)
        for value in namespace.values():  # close what the example made and left open
            close = getattr(value, "close", None)
            if callable(close) and type(value).__module__.startswith(("azimut_env", "gymnasium")):
                close()


def test_every_repository_path_named_in_the_docs_exists():
    missing = []
    for page in PAGES:
        for path in {p.removesuffix("**") for p in PATH_RE.findall(page.read_text(encoding="utf-8"))}:
            if not (any(ROOT.glob(path.rstrip("/"))) if "*" in path else (ROOT / path).exists()):
                missing.append(f"{_rel(page)}: {path}")
    assert not missing, "paths named in the docs that do not exist:\n" + "\n".join(sorted(missing))


def _resolve(name: str) -> None:
    module_part, _, attr_after_colon = name.partition(":")
    parts = module_part.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError as exc:
            if exc.name is not None and exc.name.split(".")[0] not in PACKAGES:
                raise  # a missing dependency, not a missing module of ours
            continue
        for attr in parts[cut:] + ([attr_after_colon] if attr_after_colon else []):
            obj = getattr(obj, attr)
        return
    raise ModuleNotFoundError(name)


def test_every_dotted_name_in_the_docs_resolves():
    missing = []
    for page in PAGES:
        for name in sorted(set(DOTTED_RE.findall(page.read_text(encoding="utf-8")))):
            try:
                _resolve(name)
            except (ImportError, AttributeError) as exc:
                missing.append(f"{_rel(page)}: {name} ({type(exc).__name__}: {exc})")
    assert not missing, "names in the docs that the code does not have:\n" + "\n".join(missing)


def test_markdown_links_of_the_root_pages_exist():
    """README.md and ARCHITECTURE.md live outside docs/, where mkdocs does not check links."""
    missing = []
    for page in (ROOT / "README.md", ROOT / "ARCHITECTURE.md"):
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+://", target):
                continue
            path = target.split("#")[0]
            if path and not (page.parent / path).exists():
                missing.append(f"{_rel(page)}: {target}")
    assert not missing, "broken links:\n" + "\n".join(missing)


def test_the_env_page_shows_the_generated_tables():
    """The observation, reward and info tables of docs/env.md are the ones the code generates."""
    from azimut_env.task.info import info_table
    from azimut_env.task.observation import observation_table
    from azimut_env.task.reward import reward_table

    page = (ROOT / "docs" / "env.md").read_text(encoding="utf-8")
    for name, table in (("observation", observation_table()), ("reward", reward_table()), ("info", info_table())):
        assert table in page, f"docs/env.md's {name} table is not {name}_table()'s output: paste it again"
