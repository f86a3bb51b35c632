"""Where numba caches the compiled kernels: a folder keyed by the project's sources.

numba's on-disk cache (``@njit(cache=True)``) is invalidated by the time stamp of the file that
defines a kernel, not by the files of the functions it calls and inlines: after an update that
changes only a callee's module, a kernel would keep running the old compiled code, silently. So the
cache lives in a folder named by a digest of every source file of the packages that hold kernels
(``estimation``, ``azimut_env``, ``control``: by the layer order a kernel can reach nothing above
them, and ``train`` and ``jobs`` define none, which a test keeps true) and the numba and Python
versions: any change of those sources selects a fresh folder, and the kernels are compiled again
once.

The folder is ``$AZIMUT_CACHE_DIR/numba/<digest>``, by default under the user's cache directory
(``$XDG_CACHE_HOME`` or ``~/.cache``, ``azimut``). A ``NUMBA_CACHE_DIR`` set by the user is
respected as the base instead (the digest folder goes inside it). If no such folder can be
created, numba's own default (``__pycache__`` beside the sources) is left in place.

This module is imported first by every package, before any kernel is defined (the cache
location is read by numba when a ``cache=True`` function is decorated). It does not import numba
itself (``import azimut_env``, which only registers the envs, stays light): the folder goes into
``NUMBA_CACHE_DIR``, which numba reads when it is imported, and into ``numba.config`` as well
where numba is already loaded.
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

__all__ = ["PACKAGES", "CACHE_DIR", "source_digest", "cache_dir", "configure", "structref_constructor"]

#: the packages whose sources key the cache: those that define compiled kernels (the layers below
#: ``train`` and ``jobs`` in ARCHITECTURE.md's order)
PACKAGES = ("estimation", "azimut_env", "control")


def source_digest(root: Path | None = None) -> str:
    """SHA-256 (16 hex digits) of every ``.py`` file of :data:`PACKAGES` under ``root`` (default:
    where this package is installed), their relative paths included, and the numba and Python
    versions (numba's from its installed metadata: numba is not imported)."""
    from importlib.metadata import version

    root = Path(__file__).resolve().parents[1] if root is None else Path(root)
    h = hashlib.sha256(f"numba {version('numba')}; python {sys.version_info[:3]}".encode())
    for pkg in PACKAGES:
        base = root / pkg
        if not base.is_dir():
            continue
        for path in sorted(base.rglob("*.py")):
            h.update(str(path.relative_to(root)).encode())
            h.update(b"\0")
            h.update(path.read_bytes())
            h.update(b"\0")
    return h.hexdigest()[:16]


def _base() -> Path:
    """The base folder: a user's ``NUMBA_CACHE_DIR`` or ``AZIMUT_CACHE_DIR``, else the user cache.
    A ``NUMBA_CACHE_DIR`` that an azimut parent process set (a spawned worker inherits it) is not
    the user's: the parent's base is used instead, so each checkout keys its own folder."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    if user and user == os.environ.get("_AZIMUT_NUMBA_CACHE_SET"):
        user = os.environ.get("_AZIMUT_NUMBA_CACHE_BASE")
    base = user or os.environ.get("AZIMUT_CACHE_DIR")
    if base:
        return Path(base)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "azimut"


def cache_dir() -> Path:
    """The cache folder of this checkout's sources (see the module docstring)."""
    return _base() / "numba" / source_digest()


def configure() -> Path | None:
    """Point numba's cache at :func:`cache_dir` (the environment, which numba reads when it is
    imported, spawned workers inherit and a config reload reads again; and ``numba.config`` where
    numba is loaded already); the folder, or None where it cannot be created."""
    try:
        base = _base()
        path = base / "numba" / source_digest()
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    if not os.access(path, os.W_OK):
        return None
    os.environ["NUMBA_CACHE_DIR"] = str(path)
    os.environ["_AZIMUT_NUMBA_CACHE_SET"] = str(path)
    os.environ["_AZIMUT_NUMBA_CACHE_BASE"] = str(base)
    if "numba.core.config" in sys.modules:
        sys.modules["numba.core.config"].CACHE_DIR = str(path)
    return path


def structref_constructor(struct_type, names, filename: str, module: str):
    """The cached compiled constructor of a numba ``StructRef`` type, ``new(*fields)`` with the
    fields ``names`` in order: its source is generated from the field table and compiled as if in
    ``filename`` (the caller's module ``module``), under a name that hashes the source, so that
    numba's disk cache keys it by its fields (a kernel's struct and its table stay one concept).

    With ``NUMBA_DISABLE_JIT=1`` (the kernels run as plain Python, as the tests that pin them do)
    a StructRef cannot be built: ``new`` returns a named tuple of the same fields instead, which
    the Python kernels read by the same names."""
    from numba import njit
    from numba.core import config
    from numba.experimental import structref

    names = list(names)
    if config.DISABLE_JIT:
        from collections import namedtuple

        return namedtuple(struct_type.__class__.__name__.removesuffix("Type"), names, module=module)
    src = (f"def _new({', '.join(names)}):\n    st = structref.new(_TYPE)\n"
           + "".join(f"    st.{name} = {name}\n" for name in names) + "    return st\n")
    name = "_new_" + hashlib.sha256(src.encode()).hexdigest()[:16]
    namespace = {"structref": structref, "_TYPE": struct_type, "__name__": module}
    exec(compile(src.replace("def _new(", f"def {name}("), filename, "exec"), namespace)
    return njit(cache=True)(namespace[name])


CACHE_DIR = configure()
