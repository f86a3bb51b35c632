"""The controller interface: :class:`Controller`, and the registry of controllers by name.

A controller drives the N robots of an :class:`~azimut_env.vector_env.AzimutVectorEnv` (N = 1 for
one episode). It reads the env's controller interface
(:class:`~azimut_env.interface.VectorControllerInterface`: ``measured_beta`` and
``measured_phidot`` (N, n), ``estimated_eta`` ((N, 3), (N,)), ``estimated_pose`` (N, 3),
``progress`` (N,), ``tracks``, ``geometry``, ``limits``, ``control_period``) and the observation
(N, D), and returns a :class:`~control.commands.WheelCommand` of (N, n) arrays. The episode loop
(:func:`control.rollout.run_episodes`) is the one place that steps an env with a controller:
``azimut eval``, the kick study, ``azimut sim-paper``, ``azimut record-d2`` and a trained policy's
evaluation all go through it.

A minimal controller (every robot holds its wheels and stands still)::

    class Hold:
        name = "hold"

        def reset(self, env, rows):
            pass

        def act(self, env, obs):
            beta = env.measured_beta
            return WheelCommand(beta=beta, phidot=np.zeros_like(beta))

Registry: :func:`make_controller` turns a spec into a controller. A spec is

* a registered name (built in: ``icr``, ``twist``, ``twist-setpoint``, ``feedforward``; add yours with
  :func:`register_controller`);
* ``PREFIX:ARG`` for a prefix an upper layer registered (``azimut eval`` registers ``ppo`` and
  ``sac``: ``ppo:PATH`` or ``ppo:NAME=PATH``, a trained policy);
* ``package.module:Attr``: a class or factory of yours, imported; what it returns must be a
  :class:`Controller`.

Options (``make_controller(spec, **options)``) go to the factory: the built-ins take
``speed_scale`` and their tuning; a factory that does not take an option is refused with a
:class:`ControllerSpecError` naming it.
"""

from __future__ import annotations

import importlib
import inspect
import re
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np

from control.commands import WheelCommand

__all__ = ["Controller", "ControllerSpecError", "register_controller", "make_controller", "check_spec",
           "controller_names", "is_prefixed", "env_threads"]


def env_threads(env: Any) -> int:
    """The threads a batched controller's compiled step takes: the env's own (``num_threads`` of
    the vector env, :mod:`estimation.threads`), 1 for an env without that attribute. Any count
    gives the same commands."""
    return int(getattr(env, "num_threads", 1))


@runtime_checkable
class Controller(Protocol):
    """What every controller implements (see the module docstring).

    Optional attributes the episode loop reads when present: ``speed_scale`` (float: the speed
    scale of the track's profile the controller drives at; the default time limit of an
    episode is 3 × the nominal duration at that scale + 10 s) and ``env_kwargs`` (dict: keyword
    arguments the env must be built with, e.g. a trained policy's observation settings).

    Required: the robots of a batch are independent. Row i of the command may depend only on
    robot i (its row of the env's interface and of ``obs``, and what the controller kept of
    robot i since ``reset``), never on the other rows, on how many robots there are or on the
    order ``act`` handles them in (no mean over the batch, no random generator drawn for all
    robots in turn). ``azimut eval`` splits a controller's episodes into batches over its
    workers: a controller that is not independent gives results that depend on ``--workers``
    and on which episodes share a batch, silently. :func:`control.checks.check_batch_independence`
    runs two robots as a batch and each alone and says where they differ.

    A batched controller runs its compiled step on the env's threads (:func:`env_threads`): its
    rows in blocks, one per thread, which independence makes the same bits for any count.

    The episode loop checks what ``act`` returns (:func:`control.commands.checked_command`) and
    counts the commanded limits the set-points exceed from the set-points themselves
    (:class:`control.limits.SetpointLimitCheck`), whatever rates the command declares.
    """

    #: a short name, used in every metrics row, legend and file name
    name: str

    def reset(self, env: Any, rows: np.ndarray) -> None:
        """(Re)start the robots ``rows`` (sorted integer indices into the env's N robots) from the
        env's current state, right after their episode's reset."""

    def act(self, env: Any, obs: np.ndarray) -> WheelCommand:
        """The commands of all N robots for this control period, from the env's controller
        interface and the observation ``obs`` (N, D): β and φ̇ set-points (N, n) and, where the
        controller knows them, β̇, β̈, φ̈ (for the commanded-limit check); optionally the env
        action (N, 2n) float32 to send as it is, the mode and the reconfigure events (N,)."""


class ControllerSpecError(ValueError):
    """A controller spec that cannot be made into a :class:`Controller` (the message is one line
    naming the spec; ``detail``: the failure alone, e.g. the factory's exception)."""

    def __init__(self, message: str, detail: str | None = None) -> None:
        super().__init__(message)
        self.detail = detail if detail is not None else message


#: name -> factory, or "module:attr" of a built-in (imported when first made)
_NAMES: dict[str, Callable[..., Any] | str] = {
    "icr": "control.path_controllers:ICRPathController",
    "twist": "control.path_controllers:TwistPathController",
    "twist-setpoint": "control.path_controllers:SetpointPathController",
    "feedforward": "control.feedforward:FeedForwardController",
}
#: prefix -> factory(arg, **options)
_PREFIXES: dict[str, Callable[..., Any]] = {}
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_-]*$")
_MODULE_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*:[A-Za-z_][A-Za-z0-9_]*$")


def register_controller(name: str, factory: Callable[..., Any], *, prefix: bool = False) -> None:
    """Make ``name`` a spec of :func:`make_controller`: ``factory(**options)`` builds the
    controller; with ``prefix``, specs ``name:ARG`` call ``factory(ARG, **options)``.

    Registering a name again replaces it. A registration lives in the process that made it: for
    campaigns on several processes, register in a module the tasks import, or give the
    ``package.module:Attr`` spec instead."""
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise ValueError(f"controller name must be a word (letters, digits, '_', '-'), got {name!r}")
    if not callable(factory):
        raise TypeError(f"factory of {name!r} must be callable, got {type(factory).__name__}")
    (_PREFIXES if prefix else _NAMES)[name] = factory
    (_NAMES if prefix else _PREFIXES).pop(name, None)


def controller_names() -> tuple[str, ...]:
    """The registered names (the built-ins first), then the prefixes as ``PREFIX:...``."""
    return tuple(_NAMES) + tuple(f"{p}:..." for p in _PREFIXES)


def is_prefixed(spec: str) -> bool:
    """Whether ``spec`` is ``PREFIX:ARG`` with a registered prefix."""
    return isinstance(spec, str) and ":" in spec and spec.split(":", 1)[0] in _PREFIXES


def _import(target: str, spec: str) -> Any:
    module, attr = target.split(":", 1)
    try:
        mod = importlib.import_module(module)
    except Exception as exc:  # noqa: BLE001 (any import failure is the spec's: one line)
        hint = ("; the azimut command imports from the installed packages and PYTHONPATH, not from the current "
                "folder: run it with PYTHONPATH=. or install your package") if isinstance(exc, ModuleNotFoundError) \
            else ""
        raise ControllerSpecError(f"controller {spec!r}: cannot import {module!r} "
                                  f"({type(exc).__name__}: {exc}){hint}") from None
    try:
        return getattr(mod, attr)
    except AttributeError:
        raise ControllerSpecError(f"controller {spec!r}: module {module!r} has no attribute {attr!r}") from None


def _resolve(spec: str) -> tuple[Callable[..., Any], tuple]:
    """(factory, leading arguments) of a spec."""
    if not isinstance(spec, str) or not spec.strip():
        raise ControllerSpecError(f"controller spec must be a non-empty string, got {spec!r}")
    if spec in _NAMES:
        factory = _NAMES[spec]
        return (_import(factory, spec) if isinstance(factory, str) else factory), ()
    if ":" in spec:
        prefix, arg = spec.split(":", 1)
        if prefix in _PREFIXES:
            if not arg:
                raise ControllerSpecError(f"controller {spec!r}: give {prefix}:ARG")
            return _PREFIXES[prefix], (arg,)
        if _MODULE_RE.match(spec):
            return _import(spec, spec), ()
    choices = ", ".join(controller_names())
    raise ControllerSpecError(f"unknown controller {spec!r}: choose from {choices}, or package.module:Class")


def check_spec(spec: str) -> None:
    """Refuse (:class:`ControllerSpecError`) a spec that names no controller: an unknown name or
    prefix, or a ``package.module:Attr`` that cannot be imported. Builds nothing."""
    _resolve(spec)


def _check_options(factory: Callable[..., Any], spec: str, args: tuple, options: dict) -> None:
    """Refuse options the factory does not take, before calling it (one line naming them)."""
    try:
        sig = inspect.signature(factory)
    except (TypeError, ValueError):  # a builtin without a signature: let the call decide
        return
    try:
        sig.bind(*args, **options)
    except TypeError as exc:
        given = ", ".join(sorted(options)) or "no options"
        raise ControllerSpecError(f"controller {spec!r} does not take {given} ({exc})") from None


def make_controller(spec: str, **options: Any) -> Controller:
    """The :class:`Controller` of ``spec`` (see the module docstring), built with ``options``.

    Raises:
        ControllerSpecError: (a ``ValueError``) an unknown name or prefix, a module or attribute
            that cannot be imported, options the factory does not take, a factory that fails,
            or a result that is not a :class:`Controller`; the message is one line.
    """
    factory, args = _resolve(spec)
    _check_options(factory, spec, args, options)
    try:
        ctl = factory(*args, **options)
    except ControllerSpecError:
        raise
    except Exception as exc:  # noqa: BLE001 (the user's factory: its failure in one line)
        detail = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
        raise ControllerSpecError(f"controller {spec!r}: {detail}", detail) from None
    if not isinstance(ctl, Controller):
        missing = [m for m in ("name", "reset", "act") if not hasattr(ctl, m)]
        raise ControllerSpecError(f"controller {spec!r} made a {type(ctl).__name__}, not a Controller "
                                  f"(missing {', '.join(missing)})")
    if not isinstance(ctl.name, str) or not ctl.name:
        raise ControllerSpecError(f"controller {spec!r}: its name must be a non-empty string, got {ctl.name!r}")
    return ctl
