"""What ``azimut eval`` says while it runs: one line per finished episode (:func:`progress_printer`;
a failed one names its error, where its traceback is, and whether it was retried), and SIGTERM
taken as Ctrl-C (:func:`signals_as_interrupts`: the finished episodes are saved, one line, exit
status 143, ``--resume`` goes on)."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path

from jobs.interrupts import EXIT_STATUS, signals_as_interrupts

__all__ = ["progress_printer", "failure_text", "where_raised", "signals_as_interrupts", "EXIT_STATUS", "say"]


def say(text: str, stream) -> bool:
    """Print a line on ``stream``; False, quietly, when its reader went away (``azimut eval ... |
    head -1``: a BrokenPipeError), the stream then pointed at the null device so that nothing more
    is written there, nor at exit (Python's flush of a closed pipe)."""
    if getattr(stream, "_azimut_closed", False):
        return False
    try:
        print(text, file=stream, flush=True)
        return True
    except BrokenPipeError:
        import os

        try:
            stream._azimut_closed = True
        except AttributeError:
            pass
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), stream.fileno())
        except (OSError, ValueError, AttributeError):
            pass
        return False


_FRAME = re.compile(r'^\s*File "(?P<file>[^"]+)", line (?P<line>\d+), in (?P<fn>\S+)', re.M)


def where_raised(traceback_text: str | None) -> str | None:
    """``file:line in function`` of the innermost frame of a formatted traceback, or None."""
    frames = list(_FRAME.finditer(traceback_text or ""))
    if not frames:
        return None
    last = frames[-1]
    return f"{Path(last['file']).name}:{last['line']} in {last['fn']}"


def failure_text(rec: dict, record_path: Path | str) -> str:
    """A failed episode in words: its error, where it was raised, how many attempts and why no
    more, and where its traceback is (``record_path``, the episode's record)."""
    attempts = rec.get("attempts", 1)
    text = f"FAILED after {attempts} attempt(s): {rec.get('error')}"
    where = where_raised(rec.get("traceback"))
    if where:
        text += f" (at {where})"
    if rec.get("transient") is False:
        text += "; not retried (an error the episode's code raised comes back on every try)"
    if rec.get("traceback"):
        text += f"; traceback in {record_path}"
    else:
        text += f"; no traceback (the worker died); record in {record_path}"
    return text


def progress_printer(names: dict[str, str], stream, records_folder: Path, show_scale: bool = False) -> Callable:
    """The ``progress(done, total, task, rec)`` callback of :func:`jobs.campaign.engine.run_tasks`
    that prints one line per finished episode on ``stream`` (with its speed scale, ``×0.8``, when
    ``show_scale``: a campaign of several)."""
    width = max(len(n) for n in names.values()) if names else 6

    def progress(done: int, total: int, task, rec: dict) -> None:
        k = task.key
        if rec["status"] == "ok":
            m = rec["result"]["metrics"]
            qua = m.get("mean_qua_moving")
            qua = f"{qua:.4f}" if qua is not None and math.isfinite(qua) else "- (no moving step)"
            took = (f"batch of {rec['batch']}: {rec['elapsed_s']:.1f} s" if rec.get("batch")
                    else f"{rec['elapsed_s']:.1f} s")
            per_m = m.get("slip_energy_per_m")
            per_m = f" ({per_m:.2f} J/m)" if isinstance(per_m, (int, float)) and math.isfinite(per_m) else ""
            msg = (f"RMS lat {100 * m['rms_lateral_m']:.2f} cm, slip {m['slip_energy_J']:.2f} J{per_m}, "
                   f"antagonism {m['mean_antagonism_N']:.2f} N, null-space force {m['mean_nullspace_force_N']:.2f} N, "
                   f"qua moving {qua}, limit-exceeded steps {m['limit_violation_steps']}, "
                   f"stop+reconfig {m['reconfigure_events']}, {took}")
        else:
            msg = failure_text(rec, records_folder / f"{task.id}.json")
        name = names.get(k["controller"], k["controller"])
        scale = f"×{k.get('speed_scale', 1.0):<4g} " if show_scale else ""
        say(f"[{done}/{total}] {name:<{width}} {k['track']:<8} {scale}seed {k['seed']:<3} {msg}", stream)

    return progress


