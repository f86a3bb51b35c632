"""The command line's checks: ``argparse`` ``type=`` converters and output-path checks.

The ``arg_*`` functions are ``argparse`` ``type=`` converters: they raise
``argparse.ArgumentTypeError``, which argparse reports as one line on stderr with exit status 2
(``azimut X: error: argument --flag: ...``), before the command starts any work.
:func:`check_output_path` checks a file the command will write (its directory exists and is
writable, the path is not a directory and not under a file) for the same early refusal, and
:func:`check_output_layout` every file and folder a command writes inside its output folder. The
numeric checks they share with the constructors are :mod:`azimut_env.validation`'s.
"""

from __future__ import annotations

import argparse
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence

from azimut_env.validation import check_range

__all__ = ["arg_int", "arg_float", "arg_choice_list", "arg_output_path", "check_output_path", "check_output_layout",
           "require_module", "arg_robot", "arg_robot_file", "arg_imperfections", "add_robot_arguments",
           "robot_description", "robot_params",
           "robot_env_kwargs", "robot_args_kwargs", "robot_label", "check_robot_stability", "arg_name_list",
           "arg_threads", "arg_threads_list", "add_threads_argument"]


def _scientific_int(text) -> int | None:
    """The integer a whole number in scientific notation spells (``1e6``, ``2.5E5``), else None."""
    if not isinstance(text, str) or not re.fullmatch(r"[+-]?\d+(\.\d+)?[eE]\+?\d+", text.strip()):
        return None
    v = float(text)
    return int(v) if math.isfinite(v) and v == int(v) and abs(v) < 2**53 else None


def arg_int(min_value: int | None = None, max_value: int | None = None) -> Callable[[str], int]:
    """``type=`` for an integer flag in [min_value, max_value]."""

    def convert(text: str) -> int:
        try:
            v = int(text, 10)
        except (TypeError, ValueError):
            v = _scientific_int(text)
            if v is None:
                raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if min_value is not None and v < min_value:
            raise argparse.ArgumentTypeError(f"must be >= {min_value}, got {v}")
        if max_value is not None and v > max_value:
            raise argparse.ArgumentTypeError(f"must be <= {max_value}, got {v}")
        return v

    convert.__name__ = "integer"
    return convert


def arg_threads(text: str) -> int:
    """``type=`` for ``--threads``: an integer from 1 to numba's thread pool (``NUMBA_NUM_THREADS``)."""
    from estimation.threads import max_threads

    try:
        return arg_int(1, max_threads())(text)
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"{exc} (threads: 1 to numba's pool on this machine, NUMBA_NUM_THREADS)"
                                         ) from None


def arg_threads_list(text: str) -> list[int]:
    """``type=`` for a comma-separated list of thread counts (``1,2``), each as :func:`arg_threads`."""
    items = [x.strip() for x in str(text).split(",")]
    if not all(items):
        raise argparse.ArgumentTypeError(f"expected thread counts separated by commas, got {text!r}")
    out = [arg_threads(x) for x in items]
    if len(set(out)) != len(out):
        raise argparse.ArgumentTypeError(f"a thread count is repeated in {text!r}")
    return out


def add_threads_argument(parser: argparse.ArgumentParser, what: str) -> None:
    """``--threads N``: the threads of ``what`` (default: the cores this process may use)."""
    parser.add_argument("--threads", type=arg_threads, default=None, metavar="N",
                        help=f"threads of {what} (default: the cores this process may use; any count gives the "
                             "same results)")


def arg_float(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
              hi_open: bool = False) -> Callable[[str], float]:
    """``type=`` for a finite real flag in [lo, hi] (``lo_open``/``hi_open`` exclude the bound)."""

    def convert(text: str) -> float:
        try:
            v = float(text)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        try:
            return check_range("value", v, lo, hi, lo_open=lo_open, hi_open=hi_open)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e).removeprefix("value ")) from None

    convert.__name__ = "number"
    return convert


def arg_choice_list(choices: Sequence[str], *, allow_empty: bool = False) -> Callable[[str], list[str]]:
    """``type=`` for a comma-separated subset of ``choices`` (order kept, duplicates refused)."""

    def convert(text: str) -> list[str]:
        items = [t.strip() for t in text.split(",") if t.strip()]
        bad = [t for t in items if t not in choices]
        if bad:
            raise argparse.ArgumentTypeError(f"unknown {', '.join(map(repr, bad))}; choose from {', '.join(choices)}")
        if len(set(items)) != len(items):
            raise argparse.ArgumentTypeError(f"repeated entries in {text!r}")
        if not items and not allow_empty:
            raise argparse.ArgumentTypeError(f"give at least one of {', '.join(choices)}")
        return items

    convert.__name__ = "list"
    return convert


def _writable_dir(path: str) -> bool:
    """Whether a file can be created in the directory ``path``: tried for real (a temporary file,
    removed at once), since permission bits say nothing for root or a read-only mount."""
    import tempfile

    if not os.access(path, os.W_OK | os.X_OK):
        return False
    try:
        fd, name = tempfile.mkstemp(dir=path, prefix=".azimut-write-check-")
    except OSError:
        return False
    os.close(fd)
    try:
        os.unlink(name)
    except OSError:
        pass
    return True


def _check_links(text: str, path: str) -> None:
    """``ValueError`` when ``path`` or a folder on its way is a symbolic link to nothing (a dangling
    link: ``os.path.exists`` is False, yet nothing can be created there)."""
    q = path
    while True:
        if os.path.islink(q) and not os.path.exists(q):
            raise ValueError(f"{text}: {q} is a symbolic link to {os.readlink(q)!r}, which does not exist")
        parent = os.path.dirname(q)
        if parent == q:
            return
        q = parent


def _first_existing(path: str) -> str:
    while not os.path.exists(path):
        parent = os.path.dirname(path)
        if parent == path:
            break
        path = parent
    return path


def check_output_path(path: str | os.PathLike, *, directory: bool = False) -> str:
    """Check that ``path`` can be written before any work starts; return it as ``str``.

    A file path must not be an existing directory, its parent must be an existing directory in
    which a file can be created, and an existing file must be writable (it is overwritten). With
    ``directory=True`` the path is a directory to create (with its parents) or fill: it must not
    be a file, nothing on its way may be a file, and the directory (or its first existing
    ancestor) must accept a new file. Raises ``ValueError`` with one line.
    """
    try:
        text = os.fspath(path)
    except TypeError:
        raise TypeError(f"path must be a str or os.PathLike, got {type(path).__name__}") from None
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if not text or "\0" in text:
        raise ValueError(f"invalid path {text!r}")
    p = os.path.abspath(text)
    _check_links(text, p)
    if directory:
        if os.path.exists(p) and not os.path.isdir(p):
            raise ValueError(f"{text}: exists and is not a directory")
        anc = _first_existing(p)
        if not os.path.isdir(anc):
            raise ValueError(f"{text}: {anc} is not a directory")
        if not _writable_dir(anc):
            raise ValueError(f"{text}: directory {anc} is not writable")
        return text
    if os.path.isdir(p):
        raise ValueError(f"{text}: is a directory")
    parent = os.path.dirname(p)
    anc = _first_existing(parent)
    if not os.path.isdir(anc):
        raise ValueError(f"{text}: {anc} is not a directory")
    if anc != parent:
        raise ValueError(f"{text}: directory {parent} does not exist")
    if not _writable_dir(parent):
        raise ValueError(f"{text}: directory {parent} is not writable")
    if os.path.exists(p) and not os.access(p, os.W_OK):
        raise ValueError(f"{text}: file is not writable")
    return text


def require_module(module: str, why: str) -> None:
    """``ValueError`` (one line) if ``module`` cannot be imported, e.g. an optional extra."""
    import importlib.util

    try:
        found = importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        found = False
    if not found:
        raise ValueError(f"{why} needs {module}, which is not installed")


def check_output_layout(out: str | os.PathLike, files: Sequence[str] = (),
                        dirs: Mapping[str, Sequence[str]] | None = None) -> None:
    """Check, before any work, every path a command will write under its output folder ``out``:
    what exists there must be of the kind the command writes (``ValueError``, one line, naming
    the path, otherwise). Before, a file ``episodes`` or a directory ``metrics.json`` in the
    folder crashed the command, some only after every episode had run.

    ``files``: relative paths of files it writes (an existing one must be a writable file, not a
    directory). ``dirs``: relative paths of folders it writes (or fills), each with the suffixes
    of the files it writes inside (an existing folder must be a writable directory, and no entry
    in it with one of those suffixes may be a directory). Nothing on the way from ``out`` to a
    path may be a file. ``out`` itself is :func:`check_output_path`'s (``directory=True``)."""
    root = os.path.abspath(os.fspath(out))

    def check_parents(rel: str) -> None:
        parts = os.path.normpath(rel).split(os.sep)[:-1]
        for i in range(len(parts)):
            q = os.path.join(root, *parts[:i + 1])
            if os.path.exists(q) and not os.path.isdir(q):
                raise ValueError(f"{q}: exists and is not a directory (the output folder needs a folder "
                                 f"{os.path.join(*parts[:i + 1])}/ there)")

    for rel in files:
        check_parents(rel)
        p = os.path.join(root, rel)
        if os.path.isdir(p):
            raise ValueError(f"{p}: is a directory (the output folder's file {rel} is written there)")
        if os.path.lexists(p) and not os.path.isfile(p):
            raise ValueError(f"{p}: exists and is not a regular file (the output folder's file {rel})")
        if os.path.exists(p) and not os.access(p, os.W_OK):
            raise ValueError(f"{p}: file is not writable")
    for rel, suffixes in (dirs or {}).items():
        check_parents(rel)
        p = os.path.join(root, rel)
        if os.path.lexists(p) and not os.path.isdir(p):
            raise ValueError(f"{p}: exists and is not a directory (the output folder's {rel}/ folder is written "
                             "there)")
        if not os.path.isdir(p):
            continue
        if not _writable_dir(p):
            raise ValueError(f"{p}: directory is not writable")
        if suffixes:
            with os.scandir(p) as entries:
                for entry in entries:
                    if entry.name.endswith(tuple(suffixes)) and entry.is_dir():
                        raise ValueError(f"{entry.path}: is a directory (files of {rel}/ are written there)")


def arg_name_list(choices: Sequence[str]) -> Callable[[str], list[str]]:
    """:func:`arg_choice_list` of names spelt with ``-`` that also takes them with ``_``
    (``icr_rate`` for ``icr-rate``, as the tables print them); returns the ``-`` spellings."""
    inner = arg_choice_list(choices)

    def convert(text: str) -> list[str]:
        return inner(text.replace("_", "-") if isinstance(text, str) else text)

    convert.__name__ = "list"
    return convert


def arg_output_path(*, directory: bool = False) -> Callable[[str], str]:
    """``type=`` for an output file (or directory) flag, checked with :func:`check_output_path`."""

    def convert(text: str) -> str:
        try:
            return check_output_path(text, directory=directory)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    convert.__name__ = "path"
    return convert




def _checked(check, text: str) -> str:
    """``check(text)``, its ``ValueError`` as argparse's refusal (the message as it is)."""
    try:
        return check(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def arg_robot(text: str) -> str:
    """``type=`` of ``--robot``: a preset's name (``azimut_env.robot_file.PRESET_NAMES``)."""
    from azimut_env.robot_file import check_preset_name

    return _checked(check_preset_name, text)


def arg_robot_file(text: str) -> str:
    """``type=`` of ``--robot-file``: a robot description file, read and checked now (every
    refusal of ``RobotParams.from_file``: one line naming the file, the key and the value).
    Returns the path as given."""
    from azimut_env.params import RobotParams

    try:
        RobotParams.from_file(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e).splitlines()[0]) from None
    return text


def arg_imperfections(text: str) -> str:
    """``type=`` of ``--imperfections``: a preset of :mod:`azimut_env.imperfections`."""
    from azimut_env.imperfections import check_imperfections

    return _checked(check_imperfections, text)


def add_robot_arguments(parser: argparse.ArgumentParser, *, imperfections: bool = False,
                        several: bool = False) -> None:
    """``--robot NAME`` and ``--robot-file PATH`` (exclusive: one robot per run), and with
    ``imperfections`` the ``--imperfections`` flag (``several``: a comma-separated list, each
    timed in turn by ``azimut bench-env``; default None: the robot as chosen)."""
    from azimut_env.imperfections import IMPERFECTION_PRESETS
    from azimut_env.robot_file import PRESET_NAMES

    group = parser.add_mutually_exclusive_group()
    group.add_argument("--robot", type=arg_robot, default=None, metavar="NAME",
                       help=f"the robot, a preset among {', '.join(PRESET_NAMES)} (default azimut3, the AZIMUT-3 "
                            "stand-in with the paper's imperfections; docs/robots.md)")
    group.add_argument("--robot-file", type=arg_robot_file, default=None, metavar="PATH",
                       help="the robot, from a description file (TOML, schema in docs/robots.md)")
    if imperfections:
        names = ", ".join(IMPERFECTION_PRESETS)
        parser.add_argument("--imperfections", default=None,
                            type=arg_choice_list(IMPERFECTION_PRESETS) if several else arg_imperfections,
                            metavar="NAME[,NAME...]" if several else "NAME",
                            help=f"the imperfections preset ({names}) put on the robot (default: the one its "
                                 "description file names, paper for azimut3, ideal for swerve, tri, hex; "
                                 "azimut_env/imperfections.py)"
                                 + ("; several: each in turn, with the ratio to the first" if several else ""))


def robot_args_kwargs(args: argparse.Namespace) -> dict:
    """:func:`robot_env_kwargs` of ``--robot``/``--robot-file`` and ``--imperfections`` (its first
    preset where it takes several)."""
    value = getattr(args, "imperfections", None)
    return robot_env_kwargs(getattr(args, "robot", None), getattr(args, "robot_file", None),
                            value[0] if isinstance(value, list) else value)


def robot_description(args: argparse.Namespace):
    """The robot of ``--robot``/``--robot-file`` read whole, each package's part
    (``azimut_env.robot_file.read_robot``: the geometry, the module names, the ``RobotParams`` as
    the file gives them, without ``--imperfections``); the default robot when none is given."""
    from pathlib import Path

    from azimut_env.params import RobotParams
    from azimut_env.robot_file import DEFAULT_PRESET, read_robot

    path = getattr(args, "robot_file", None)
    if path:  # a file whatever its suffix; the path as given names it in messages
        return read_robot(path if str(path).endswith(".toml") else Path(path), RobotParams)
    return read_robot(getattr(args, "robot", None) or DEFAULT_PRESET, RobotParams)


def robot_params(args: argparse.Namespace):
    """The ``RobotParams`` the envs make of ``--robot``/``--robot-file`` and ``--imperfections``;
    the default robot when none is given."""
    from azimut_env.task.config import robot_of

    return robot_of(robot_args_kwargs(args))


def robot_env_kwargs(robot: str | None = None, robot_file: str | None = None,
                     imperfections: str | None = None) -> dict:
    """The env keyword arguments of a robot given by preset name or file path and of an
    imperfections preset (empty for the default robot as it is): ``{"robot": name}`` or
    ``{"robot": absolute path}``, and ``{"imperfections": name}``, plain strings (JSON-safe)."""
    kwargs = {"robot": os.path.abspath(robot_file)} if robot_file else ({"robot": robot} if robot else {})
    return {**kwargs, "imperfections": imperfections} if imperfections else kwargs


def check_robot_stability(args: argparse.Namespace) -> None:
    """For a command without a ``--substeps`` flag: the robot of ``--robot-file`` (with
    ``--imperfections``) must be inside the physics' stability budget at the envs' substeps, or
    ``ValueError`` naming the file, the figures and the likely keys (before, the command crashed
    with a traceback whose advice, raise substeps, no flag of it allows)."""
    if not getattr(args, "robot_file", None) or hasattr(args, "substeps"):
        return
    from azimut_env.physics.stability import stability_hint
    from azimut_env.task.config import TaskConfig

    cfg = TaskConfig()
    hint = stability_hint(robot_params(args), cfg.control_period / cfg.substeps)
    if hint:
        raise ValueError(f"argument --robot-file: robot file {args.robot_file}: outside the simulation's stability "
                         f"budget at the envs' {cfg.substeps} substeps per {cfg.control_period:g} s step: {hint} "
                         "(a unit mistake? docs/robots.md#plausibility)")


def robot_label(args: argparse.Namespace) -> str:
    """What the report says the robot is: the preset's name, the file, or azimut3."""
    if getattr(args, "robot_file", None):
        return f"file {args.robot_file}"
    return getattr(args, "robot", None) or "azimut3"
