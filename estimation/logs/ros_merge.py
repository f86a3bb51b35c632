"""Joint groups published in separate ``sensor_msgs/msg/JointState`` messages (steering joints and
drive joints from two controllers, on one topic or several, each at its own rate), merged onto one
clock.

Each robot joint's value, the ``position`` of a steering joint and the ``velocity`` of a drive
joint, is a signal with its own timestamps (every message that names the joint and holds one value
per name). The signals are brought onto one clock by sample-and-hold
(:func:`~estimation.logs.hold.sample_and_hold`): the clock is the signal logged most often
(:func:`~estimation.logs.hold.clock_of`), its distinct timestamps the ticks, and a sample up to
half its median period after a tick counts for the tick (the same control cycle). A tick where a
signal is older than the maximum age, or has no sample yet, is marked stale
(:data:`~estimation.logs.source.BAD_STALE`): the pipeline skips and counts it.

The topics are read whole into per-joint arrays first (the merge needs every signal's times; a
20-minute log at 100 Hz is a few MB), then given out as chunks.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from estimation.logs.hold import clock_of, sample_and_hold
from estimation.logs.ros_cdr import JointStateBatcher
from estimation.logs.source import BAD_STALE, SampleChunk, beta_from_heading, fold_coaxial

__all__ = ["JointScan", "scan_joints", "merged_chunks"]

#: messages of one layout decoded together while a bag is read whole
_BATCH = 8192


@dataclass
class JointScan:
    """What a pass over the joint-state topics found: the number of messages, of those holding every
    robot joint, and per signal (the steering joints' positions, then the drive joints' velocities,
    in module order) the number of messages that give it; ``names`` every joint seen."""

    n_messages: int
    n_complete: int
    counts: list[int]
    names: set[str]


def _layouts(log, reader, conns) -> Iterator[tuple[int, int, object, tuple[str, ...], int, int]]:
    """(log time, message index, raw bytes or the rosbags message, joint names, #positions,
    #velocities) of every message of ``conns``, in the bag's order; a message of a known layout
    stays raw (the caller decodes it in a batch), any other is decoded by rosbags."""
    batcher = log._batcher(reader)
    for k, (conn, t_log, raw) in enumerate(log._raw_messages(reader, conns)):
        layout = batcher.layout_of(raw)
        if layout is not None:
            yield t_log, k, (layout, raw), layout.names, layout.n_pos, layout.n_vel
        else:
            msg = log._deserialize(reader, conn, raw)
            yield t_log, k, msg, tuple(msg.name), len(msg.position), len(msg.velocity)


def _signal_index(log, names: tuple[str, ...], n_pos: int, n_vel: int) -> list[int]:
    """Per signal, its column in a message of joint ``names`` (-1: the message does not give it)."""
    index = {j: i for i, j in enumerate(names)}
    steer = [index.get(j, -1) if n_pos == len(names) else -1 for j in log.steer_joints]
    drive = [index.get(j, -1) if n_vel == len(names) else -1 for j in log.drive_joints]
    return steer + drive


def scan_joints(log, reader, conns) -> JointScan:
    """One pass over the joint names of every message of ``conns`` (values are not decoded)."""
    kinds: Counter = Counter()
    for _, _, _, names, n_pos, n_vel in _layouts(log, reader, conns):
        kinds[(names, n_pos, n_vel)] += 1
    robot = set(log.steer_joints) | set(log.drive_joints)
    counts = [0] * (2 * log.geom.n)
    complete, seen = 0, set()
    for (names, n_pos, n_vel), c in kinds.items():
        seen.update(names)
        complete += c if robot <= set(names) else 0
        for s, col in enumerate(_signal_index(log, names, n_pos, n_vel)):
            counts[s] += c if col >= 0 else 0
    return JointScan(sum(kinds.values()), complete, counts, seen)


def check_signals(log, scan: JointScan) -> None:
    """Refuse a merge where a robot joint is in no message, or never with its value."""
    n = log.geom.n
    for s, c in enumerate(scan.counts):
        if c:
            continue
        m, joint = log.modules[s % n], (log.steer_joints + log.drive_joints)[s]
        if joint not in scan.names:
            seen = sorted(scan.names)
            raise log.error(f"no joint {joint!r} for module {m!r} in any message of {log.topic} (their joints: "
                            f"{', '.join(seen[:24])}{' ...' if len(seen) > 24 else ''}); name the joints with "
                            "--steer-joint/--drive-joint templates such as '{module}_steer'")
        what = "position (steering angle)" if s < n else "velocity (wheel speed)"
        raise log.error(f"joint {joint!r} of module {m!r} has no {what} in any message of {log.topic}")


def _read_signals(log, reader, conns) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per signal, its times [ns] (per ``log.time``) and values, sorted by time (messages of equal
    times in the bag's order)."""
    n_sig = 2 * log.geom.n
    parts: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(n_sig)]
    t_log, stamp = [], []
    pending: dict = {}

    def put(rows, names, n_pos, n_vel, pos, vel) -> None:
        rows = np.asarray(rows, dtype=np.int64)
        for s, col in enumerate(_signal_index(log, names, n_pos, n_vel)):
            if col >= 0:
                parts[s].append((rows, (pos if s < log.geom.n else vel)[:, col].astype(np.float64)))

    def flush(layout) -> None:
        rows, raws = pending.pop(layout)
        st, pos, vel = JointStateBatcher.decode(raws, layout)
        for r, v in zip(rows, st.tolist()):
            stamp[r] = v
        put(rows, layout.names, layout.n_pos, layout.n_vel, pos, vel)

    for t, k, item, names, n_pos, n_vel in _layouts(log, reader, conns):
        t_log.append(t)
        if isinstance(item, tuple):
            layout, raw = item
            stamp.append(0)
            rows, raws = pending.setdefault(layout, ([], []))
            rows.append(k)
            raws.append(raw)
            if len(rows) == _BATCH:
                flush(layout)
        else:
            stamp.append(int(item.header.stamp.sec) * 1_000_000_000 + int(item.header.stamp.nanosec))
            put([k], names, n_pos, n_vel, np.asarray(item.position, dtype=np.float64)[None],
                np.asarray(item.velocity, dtype=np.float64)[None])
    for layout in list(pending):
        flush(layout)
    if log.time == "header":
        t_msg = np.array(stamp, dtype=np.int64)
        if np.any(t_msg == 0):
            log._time(0, 0, log.topic)  # refuses the log
    else:
        t_msg = np.array(t_log, dtype=np.int64)
    times, values = [], []
    for s in range(n_sig):
        rows = np.concatenate([r for r, _ in parts[s]]) if parts[s] else np.zeros(0, np.int64)
        vals = np.concatenate([v for _, v in parts[s]]) if parts[s] else np.zeros(0)
        order = np.lexsort((rows, t_msg[rows]))
        times.append(t_msg[rows][order])
        values.append(vals[order])
    return times, values


def merge_signals(times: list[np.ndarray], values: list[np.ndarray],
                  max_age_ns: int) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """(the clock signal's index, the ticks (T,) int64, the held values (T, S), stale (T,) bool)."""
    c = clock_of(times)
    ticks = np.unique(times[c])
    lookahead = int(np.median(np.diff(ticks))) // 2 if ticks.size > 1 else 0
    held, stale = sample_and_hold(ticks, times, values, max_age_ns, lookahead)
    return c, ticks, held, stale


def merged_chunks(log, size: int) -> Iterator[SampleChunk]:
    """The merged samples of ``log`` (a :class:`~estimation.logs.ros.RosLog`), ``size`` at a time;
    sets ``log.clock_joint`` and ``log.stale_ticks``."""
    with log._open() as reader:
        conns = [c for c in reader.connections if c.topic in log.topics]
        times, values = _read_signals(log, reader, conns)
    c, ticks, held, stale = merge_signals(times, values, log.max_age_ns)
    n = log.geom.n
    log.clock_joint = (log.steer_joints + log.drive_joints)[c]
    log.stale_ticks = int(stale.sum())
    q = held[:, :n]
    if log.steer_convention == "heading":
        q = beta_from_heading(q, log.geom)
    beta, phidot = fold_coaxial(q, held[:, n:], log.geom)
    bad = np.where(stale, BAD_STALE, 0).astype(np.int8)
    for a in range(0, ticks.size, size):
        b = min(ticks.size, a + size)
        yield SampleChunk(ticks[a:b].copy(), beta[a:b], phidot[a:b], bad[a:b])
