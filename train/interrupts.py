"""Ctrl-C (SIGINT) and SIGTERM while training or tuning: the work stops at the next environment
step, :func:`train.trainer.train` saves what it has (checkpoint, model, ``run.json`` with
``"interrupted"``) and the commands end with one line and exit status 128 + the signal (130 for
SIGINT, 143 for SIGTERM), as ``azimut eval`` does, instead of a traceback.

:func:`signals_as_interrupts` is what ``azimut train`` and ``azimut tune`` run under. The first
SIGINT or SIGTERM only records the request (:func:`requested`): raising from a signal handler
lands wherever the main thread is, a numba compilation's ctypes callback included, where the
exception is swallowed and the compilation torn; the training loop asks at every step
(:class:`train.callbacks.StopOnSignal`) and stops there. A second signal raises
:class:`Interrupted` at once (a stop that cannot wait). A signal the calling shell ignores
(``SIG_IGN``: a background job of a script) stays ignored.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["Interrupted", "signals_as_interrupts", "signal_name", "exit_code", "requested", "raise_if_requested"]

_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_state: dict = {"signum": None}


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM (``signum``) stopped the work; ``record`` is what was saved (the run
    record of :func:`train.trainer.train`), or None when nothing was."""

    def __init__(self, signum: int = signal.SIGINT, record: dict | None = None) -> None:
        super().__init__(signal_name(signum))
        self.signum, self.record = int(signum), record


def signal_name(signum: int) -> str:
    """``SIGINT``, ``SIGTERM``, ... of a signal number."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


def exit_code(exc: BaseException) -> int:
    """The exit status of a command ended by ``exc`` (a ``KeyboardInterrupt``): 128 + the signal,
    130 for a plain ``KeyboardInterrupt`` (SIGINT)."""
    return 128 + int(getattr(exc, "signum", signal.SIGINT))


def requested() -> int | None:
    """The signal that asked the work to stop inside :func:`signals_as_interrupts`, None if none did."""
    return _state["signum"]


def raise_if_requested() -> None:
    """Raise :class:`Interrupted` if a signal asked the work to stop."""
    if _state["signum"] is not None:
        raise Interrupted(_state["signum"])


def _handler(signum, frame) -> None:  # noqa: ARG001 (the signal module's signature)
    if _state["signum"] is None:
        _state["signum"] = int(signum)  # stop at the next step
        return
    raise Interrupted(_state["signum"])  # a second signal: at once


@contextmanager
def signals_as_interrupts() -> Iterator[None]:
    """SIGINT and SIGTERM ask the work inside the block to stop (see the module docstring); the
    previous handlers come back after it. Outside the main thread it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {}
    for sig in _SIGNALS:
        current = signal.getsignal(sig)
        if current is signal.SIG_IGN:
            continue
        previous[sig] = current
        signal.signal(sig, _handler)
    _state["signum"] = None
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        _state["signum"] = None
