"""The controllers ``azimut eval --controllers`` takes, by spec (:mod:`control.controller`).

``ppo:NAME=DIR`` with ``DIR`` an ``azimut train --seeds`` folder stands for its trained seeds,
``ppo:NAME.s<n>=DIR/seed_<n>/model.zip`` each (:func:`jobs.eval.agents.expand_seed_folders`).

Importing this module registers the trained-policy prefixes: ``ppo:PATH`` and ``sac:PATH`` (PATH
the ``model.zip`` that ``azimut train`` wrote, or its run folder; its VecNormalize statistics
beside it; needs the ``rl`` extra), or ``ppo:NAME=PATH`` to name it (default: the run folder's
name). The built-in names and ``package.module:Attr`` specs need no registration.

Every module that makes controllers from specs (the eval command, its campaign tasks, the kick
study) imports this one, so the prefixes are registered in every worker process too.
"""

from __future__ import annotations

import argparse
import functools
import zipfile

from control.controller import (
    Controller,
    ControllerSpecError,
    check_spec,
    controller_names,
    is_prefixed,
    make_controller,
    register_controller,
)
from train.policy import model_file, policy_controller, policy_files, policy_name

__all__ = ["POLICY_PREFIXES", "is_policy", "arg_controllers", "controller_options", "build_controller",
           "check_controllers", "controller_files", "check_env_kwargs", "RESERVED_KEYS"]

#: prefixes of trained policies in ``--controllers``
POLICY_PREFIXES = ("ppo", "sac")
for _algo in POLICY_PREFIXES:
    register_controller(_algo, functools.partial(policy_controller, _algo), prefix=True)


#: the env keyword arguments the episode loop passes itself: a controller's ``env_kwargs`` may not
#: (its ``time_limit_factor`` is replaced by the loop's, as a trained policy's env_kwargs carry one)
RESERVED_KEYS = ("track", "num_envs", "autoreset_mode")


def check_env_kwargs(spec: str, controller) -> dict:
    """A controller's ``env_kwargs`` (``{}`` without): ``ValueError`` (one line naming the
    controller) when it is not a dict or holds a key the eval sets itself (:data:`RESERVED_KEYS`)."""
    kw = getattr(controller, "env_kwargs", None)
    if kw is None:
        return {}
    if not isinstance(kw, dict):
        raise ValueError(f"controller {spec!r}: env_kwargs must be a dict, got {type(kw).__name__}")
    bad = [k for k in kw if not isinstance(k, str) or k in RESERVED_KEYS]
    if bad:
        raise ValueError(f"controller {spec!r}: env_kwargs may not set {bad[0]!r} (the eval sets "
                         f"{', '.join(RESERVED_KEYS)} itself)")
    return dict(kw)


def is_policy(spec: str) -> bool:
    """Whether a ``--controllers`` entry names a trained policy (``ppo:...`` or ``sac:...``)."""
    return is_prefixed(spec) and spec.split(":", 1)[0] in POLICY_PREFIXES


def _check_policy_file(spec: str) -> None:
    """The model file of a policy spec exists and is a saved model (a zip archive)."""
    try:
        _, path = policy_name(spec.split(":", 1)[1])
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    model = model_file(path)
    if not model.is_file():
        where = f"no model.zip in {path}" if path.is_dir() else f"no model file {path}"
        raise argparse.ArgumentTypeError(f"{spec}: {where}")
    if not zipfile.is_zipfile(model):  # SB3 saves zip archives
        raise argparse.ArgumentTypeError(f"{spec}: {model} is not a saved model (not a zip archive)")


def arg_controllers(text: str) -> list[str]:
    """``type=`` of ``--controllers``: comma-separated specs, each a registered name, a policy
    (its model file must exist) or an importable ``package.module:Attr``."""
    items = [t.strip() for t in text.split(",") if t.strip()]
    if not items:
        raise argparse.ArgumentTypeError(f"give at least one of {', '.join(controller_names())}, or "
                                         "package.module:Class")
    if len(set(items)) != len(items):
        raise argparse.ArgumentTypeError(f"repeated entries in {text!r}")
    from jobs.eval.agents import expand_seed_folders

    try:
        items = expand_seed_folders(items)  # an azimut train --seeds folder: one policy per trained seed
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    for item in items:
        if is_policy(item):
            _check_policy_file(item)
            continue
        try:
            check_spec(item)
        except ControllerSpecError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    return items


def controller_options(spec: str, speed_scale: float = 1.0) -> dict:
    """The options ``azimut eval`` makes a controller with: ``speed_scale`` when it is not 1 (so
    a controller of yours need not take it unless asked to drive slower or faster)."""
    return {} if speed_scale == 1.0 else {"speed_scale": float(speed_scale)}


@functools.lru_cache(maxsize=16)
def _cached(spec: str, options: tuple) -> Controller:
    return make_controller(spec, **dict(options))


def build_controller(spec: str, speed_scale: float = 1.0) -> Controller:
    """A fresh controller of ``spec`` with ``azimut eval``'s options (a trained policy is loaded
    once per process and shared: its controller state is rebuilt at every episode's reset)."""
    options = controller_options(spec, speed_scale)
    if is_policy(spec):
        return _cached(spec, tuple(sorted(options.items())))
    return make_controller(spec, **options)


def check_controllers(specs: list[str], speed_scale: float = 1.0) -> dict[str, str]:
    """Make every controller once (policies loaded, user classes checked against the
    :class:`~control.controller.Controller` protocol); ``ValueError`` (one line) on the first
    that fails or on two controllers with the same name. Returns spec -> name."""
    names: dict[str, str] = {}
    for spec in specs:
        try:
            controller = build_controller(spec, speed_scale)
            names[spec] = controller.name
        except ControllerSpecError as exc:
            if is_policy(spec):
                raise ValueError(f"argument --controllers: {spec}: cannot load the model ({exc.detail})") from None
            raise ValueError(f"argument --controllers: {exc}") from None
        check_env_kwargs(spec, controller)  # a dict without the keys the eval sets itself
    seen: dict[str, str] = {}
    for spec, name in names.items():
        if name in seen:
            raise ValueError(f"argument --controllers: {seen[name]!r} and {spec!r} are both named {name!r}; "
                             "name a policy with ppo:NAME=PATH")
        seen[name] = spec
    return names


def controller_files(spec: str) -> dict[str, str]:
    """The files a controller of ``spec`` reads, by role: a trained policy's model, statistics and
    run.json (:func:`train.policy.policy_files`); a ``package.module:Attr`` controller's module
    source (a module of the user's, which may change between runs). Built-in names: none (the
    package's own code)."""
    if is_policy(spec):
        return {role: str(p) for role, p in policy_files(policy_name(spec.split(":", 1)[1])[1]).items()}
    if ":" in spec and not is_prefixed(spec) and spec not in controller_names():
        import importlib.util

        try:
            origin = getattr(importlib.util.find_spec(spec.split(":", 1)[0]), "origin", None)
        except (ImportError, ValueError):
            origin = None
        if origin and origin not in ("built-in", "frozen"):
            return {"module": origin}
    return {}
