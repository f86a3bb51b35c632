"""What an ``azimut eval`` episode's result depends on besides its options, as content digests in
its key (``key["inputs"]``), so that ``--resume`` never reuses an episode computed by other code:

* ``azimut``: a digest of the package's own sources that an episode runs (:func:`azimut_digest`:
  the packages of :data:`estimation.numba_cache.PACKAGES`, whose digest also keys the compiled
  kernels, and ``train``, which a trained policy runs, with the numba and Python versions);
* ``code``: for a ``package.module:Attr`` controller, the source of its module and of every module
  of the user's that it imports, transitively (:func:`user_module_digests`);
* the files a controller reads (a trained policy's model, statistics and run.json:
  :func:`jobs.eval.controllers.controller_files`).

A module is the user's when its source file lies outside the standard library, the installed
packages (site-packages) and the azimut sources (which ``azimut`` covers): a module of the
current folder, of a ``PYTHONPATH`` entry or of an editable install of theirs. The imports are
read from the sources (``import x``, ``from x import y``, relative imports, and ``y`` when it is a
submodule), not from ``sys.modules``, so the digest does not depend on what else a process has
imported; an import made by a string at run time (``importlib.import_module(name)``) is not seen.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.util
import os
import sys
import sysconfig
from pathlib import Path

from jobs.campaign.task import file_digest

__all__ = ["azimut_digest", "user_module_digests", "controller_inputs"]

#: the azimut packages an episode runs beyond the compiled ones (a trained policy's code)
_EXTRA_PACKAGES = ("train",)
_ROOT = Path(__file__).resolve().parents[2]  # the folder that holds the azimut packages


@functools.lru_cache(maxsize=1)
def azimut_digest() -> str:
    """SHA-256 (16 hex digits) of the azimut sources an episode runs: the digest of
    :func:`estimation.numba_cache.source_digest` (``estimation``, ``azimut_env``, ``control``,
    numba and Python versions) and every ``.py`` file of ``train``."""
    from estimation.numba_cache import source_digest

    h = hashlib.sha256(source_digest(_ROOT).encode())
    for pkg in _EXTRA_PACKAGES:
        for path in sorted((_ROOT / pkg).rglob("*.py")):
            h.update(str(path.relative_to(_ROOT)).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=1)
def _not_user_folders() -> tuple[str, ...]:
    """Folders whose modules are not the user's: the standard library, site-packages (all of
    them: the interpreter's, the user's and a virtual environment's) and the azimut packages."""
    paths = {sysconfig.get_path(name) for name in ("stdlib", "platstdlib", "purelib", "platlib")}
    paths |= {p for p in sys.path if p and Path(p).name in ("site-packages", "dist-packages")}
    paths |= {str(_ROOT / pkg) for pkg in ("estimation", "azimut_env", "control", "train", "jobs")}
    return tuple(sorted(os.path.realpath(p) + os.sep for p in paths if p))


def _is_user_file(origin: str | None) -> bool:
    if not origin or not origin.endswith(".py") or not os.path.isfile(origin):
        return False
    real = os.path.realpath(origin)
    return not any(real.startswith(folder) for folder in _not_user_folders())


def _find(name: str) -> str | None:
    """The source file of the module ``name`` (without importing it beyond its parents), or None."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError, AttributeError):
        return None
    return getattr(spec, "origin", None) if spec is not None else None


def _imports(path: str, module: str) -> set[str]:
    """The names of the modules the source ``path`` of ``module`` imports (relative imports made
    absolute; ``from x import y`` gives ``x`` and ``x.y``, of which only modules are kept later)."""
    try:
        tree = ast.parse(Path(path).read_bytes(), filename=path)
    except (OSError, SyntaxError, ValueError):
        return set()
    is_package = Path(path).name == "__init__.py"
    package = module if is_package else module.rpartition(".")[0]
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".") if package else []
                parts = parts[:len(parts) - (node.level - 1)] if node.level > 1 else parts
                base = ".".join(parts + ([node.module] if node.module else []))
            if base:
                names.add(base)
                names |= {f"{base}.{alias.name}" for alias in node.names if alias.name != "*"}
    # a submodule's parents run first (their __init__)
    return names | {".".join(n.split(".")[:k]) for n in names for k in range(1, n.count(".") + 1)}


def user_module_digests(module: str) -> dict[str, str]:
    """``{module name: content digest}`` of ``module`` and of every module of the user's that it
    imports, transitively (see the module docstring); empty when ``module`` is not the user's."""
    out: dict[str, str] = {}
    todo = [module]
    seen: set[str] = set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        origin = _find(name)
        if not _is_user_file(origin):
            continue
        out[name] = file_digest(origin)
        todo += sorted(_imports(origin, name) - seen)
    return dict(sorted(out.items()))


def controller_inputs(spec: str) -> dict:
    """The inputs of an episode of the controller ``spec`` for its key: ``azimut``
    (:func:`azimut_digest`), the digests of the files it reads by role
    (:func:`~jobs.eval.controllers.controller_files`) and, for a ``package.module:Attr`` spec,
    ``code``: :func:`user_module_digests` of its module."""
    from control.controller import controller_names, is_prefixed
    from jobs.eval.controllers import controller_files

    inputs: dict = {"azimut": azimut_digest()}
    inputs.update({role: file_digest(p) for role, p in controller_files(spec).items()})
    if ":" in spec and not is_prefixed(spec) and spec not in controller_names():
        code = user_module_digests(spec.split(":", 1)[0])
        if code:
            inputs["code"] = code
    return inputs
