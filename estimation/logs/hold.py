"""Signals logged at their own times brought onto one clock by sample-and-hold.

Robot code often logs each module's steering angle and wheel speed as separate numbers, each when
it changes (NetworkTables, ``DataLog`` entries) or in separate messages (ROS 2 joint groups). At
each tick of the clock, a signal's value is its latest sample at or before the tick (plus a
look-ahead: samples of the same loop iteration land a few µs after the tick's); a value older
than the maximum age marks the tick stale, to be skipped and counted, not estimated: a signal
that stopped (a frozen encoder, a dropped topic) is not a standing robot.
"""

from __future__ import annotations

import numpy as np

__all__ = ["sample_and_hold", "clock_of", "DEFAULT_MAX_AGE_S"]

#: default maximum age of a held value [s]: an on-change signal of a moving module changes every loop
#: (20 ms on an FRC robot) through encoder noise alone; half a second without a change means a stalled
#: signal or a standing module, and at standstill a held value is exact anyway
DEFAULT_MAX_AGE_S = 0.5


def clock_of(times: list[np.ndarray]) -> int:
    """The index of the signal whose timestamps make the clock: the one logged most often (the first
    of equals), usually a value logged every loop."""
    return int(np.argmax([t.size for t in times]))


def sample_and_hold(clock_ns: np.ndarray, times: list[np.ndarray], values: list[np.ndarray], max_age_ns: int,
                    lookahead_ns: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Each signal's value at each tick of ``clock_ns`` (T,) int64.

    Args:
        times: per signal, its (m_s,) int64 timestamps [ns], non-decreasing (of equal times the last
            sample wins).
        values: per signal, its (m_s,) values.
        max_age_ns: a value older than this at a tick marks the tick stale (NaN is not used for it: a
            value may be NaN in the log itself, which the pipeline counts apart).
        lookahead_ns: a sample up to this much after a tick still counts for it (the same loop).

    Returns:
        held (T, S) float64 values (NaN where a signal has no sample yet) and stale (T,) bool: some
        signal has no sample at or before the tick, or one older than ``max_age_ns``.
    """
    clock = np.asarray(clock_ns, dtype=np.int64)
    held = np.full((clock.size, len(times)), np.nan)
    stale = np.zeros(clock.size, dtype=bool)
    for s, (t, v) in enumerate(zip(times, values)):
        t = np.asarray(t, dtype=np.int64)
        if t.size and np.any(np.diff(t) < 0):
            raise ValueError(f"signal {s}: timestamps decrease")
        j = np.searchsorted(t, clock + lookahead_ns, side="right") - 1
        have = j >= 0
        jj = np.where(have, j, 0)
        if t.size:
            held[have, s] = np.asarray(v, dtype=np.float64)[jj[have]]
            age = clock - t[jj]
            stale |= ~have | (age > max_age_ns)
        else:
            stale[:] = True
    return held, stale
