"""SIGINT and SIGTERM for every ``azimut`` command: within :func:`signals_as_interrupts`, SIGTERM
raises ``KeyboardInterrupt`` as Ctrl-C does, so that a command stops the same way for both; the
exit status is 128 + the signal's number (:data:`EXIT_STATUS`, the shells' convention).
``azimut eval`` saves its finished episodes on it, ``azimut train``/``tune`` stop at the next step
(``train.interrupts``), and ``jobs.cli.main`` turns any other command's interrupt into one line."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["EXIT_STATUS", "signals_as_interrupts"]

#: exit status of an interrupted command, by signal (128 + the signal's number, the shells' convention)
EXIT_STATUS = {signal.SIGINT: 130, signal.SIGTERM: 143}


@contextmanager
def signals_as_interrupts() -> Iterator[dict]:
    """Within: SIGTERM raises ``KeyboardInterrupt`` in the main thread, as Ctrl-C does, so that
    the campaign engine saves what finished and stops the workers; yields a dict whose ``signal``
    is the signal that came (SIGINT when none was seen here). A further SIGTERM while the first is
    being handled is ignored; a SIGTERM ignored by the caller (``SIG_IGN``) stays ignored; outside
    the main thread nothing changes. The previous handlers are put back on exit."""
    state = {"signal": signal.SIGINT}
    if threading.current_thread() is not threading.main_thread():
        yield state
        return
    previous = {signal.SIGTERM: signal.getsignal(signal.SIGTERM)}  # Ctrl-C keeps Python's own handler

    def handler(signum, frame):
        if state.get("fired"):
            return
        state["fired"], state["signal"] = True, signal.Signals(signum)
        raise KeyboardInterrupt(signal.Signals(signum).name)

    for sig, old in previous.items():
        if old is not signal.SIG_IGN:
            signal.signal(sig, handler)
    try:
        yield state
    finally:
        for sig, old in previous.items():
            if old is not None:
                signal.signal(sig, old)

