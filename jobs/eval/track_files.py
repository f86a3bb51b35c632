"""A path of the user's in ``azimut eval --tracks``: a CSV file of waypoints
(:func:`read_track_file`), made into a :class:`~azimut_env.tracks.Track` with
:meth:`Track.from_waypoints <azimut_env.tracks.Track.from_waypoints>`.

The format (``docs/control.md``, "A path of your own"): one waypoint per line, ``x,y`` in metres,
optionally ``heading`` [rad] (the chassis orientation to hold there; default 0 everywhere, the
omnidirectional robot keeps its orientation) and ``speed`` [m/s] (the progress speed, 0 to
:data:`MAX_SPEED` and above 0 somewhere; default :data:`DEFAULT_SPEED`), in that order; or a first
line naming the columns (``x``, ``y``, ``heading``, ``speed``, in any order; ``theta`` and ``v``
are taken for ``heading`` and ``speed``). Lines starting with ``#`` and blank lines are skipped.
The waypoints are joined by straight segments (sampled every 2 cm); a last waypoint within 1 mm of
the first closes the loop (a closed track), otherwise the track is open and its speed ramps up from
and down to rest over 0.3 m.

In a campaign the track is named by the path as given on the command line, and its content is in
each episode's key (``track_file``: the absolute path and the file's digest), so an edited file is
a new episode on ``--resume``.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np

from jobs.campaign.task import file_digest

__all__ = ["COLUMNS", "DEFAULT_SPEED", "looks_like_a_file", "read_track_file", "track_file_entry", "episode_track"]

#: the columns of a track file, in their order without a header line
COLUMNS = ("x", "y", "heading", "speed")
_ALIASES = {"theta": "heading", "v": "speed"}
#: the progress speed [m/s] of a file without a speed column
DEFAULT_SPEED = 0.5
#: the highest progress speed [m/s] a track file may ask for
MAX_SPEED = 20.0
#: a last waypoint this close to the first [m] closes the track
CLOSE_TOLERANCE = 1e-3


def looks_like_a_file(text: str) -> bool:
    """Whether a ``--tracks`` entry names a file rather than a built-in track: it has a path
    separator or a suffix, or it exists."""
    return "/" in text or "\\" in text or Path(text).suffix != "" or Path(text).is_file()


def _number(cell: str, where: str) -> float:
    try:
        value = float(cell)
    except ValueError:
        raise ValueError(f"{where}: {cell.strip()!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{where}: {cell.strip()!r} is not a finite number")
    return value


def _waypoint_lines(path: Path) -> list[tuple[int, list[str]]]:
    """The file's waypoint lines (header included), numbered from 1, comments and blank lines skipped."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read the track file ({type(exc).__name__}: "
                         f"{getattr(exc, 'strerror', None) or exc})") from None
    rows = [(k, row) for k, row in enumerate(csv.reader(io.StringIO(text)), start=1)
            if row and "".join(row).strip() and not row[0].lstrip().startswith("#")]
    if not rows:
        raise ValueError(f"{path}: no waypoints (one 'x,y' line per waypoint, in metres)")
    return rows


def _columns(path: Path, rows: list) -> tuple[list[str], list]:
    """The column names (from the header line, if the first line is one, else :data:`COLUMNS`) and
    the rows after the header."""
    columns = list(COLUMNS)
    first = rows[0][1]
    try:
        [float(c) for c in first]
    except ValueError:  # a header line
        header = True
    else:
        header = False
    if header:
        columns = [_ALIASES.get(c.strip().lower(), c.strip().lower()) for c in first]
        unknown = [c for c in columns if c not in COLUMNS]
        if unknown or len(set(columns)) != len(columns) or not {"x", "y"} <= set(columns):
            raise ValueError(f"{path}: line {rows[0][0]}: the header must name the columns x, y and optionally "
                             f"heading, speed (each once), got {','.join(c.strip() for c in first)!r}")
        rows = rows[1:]
    return columns, rows


def _check_speeds(path: Path, speeds: np.ndarray, lines: list[int]) -> None:
    """The speed column: within [0, :data:`MAX_SPEED`] and above 0 somewhere (``ValueError`` naming the line)."""
    fast = np.flatnonzero(speeds > MAX_SPEED)
    if fast.size:
        raise ValueError(f"{path}: line {lines[fast[0]]}: speed {speeds[fast[0]]:g} m/s is above "
                         f"{MAX_SPEED:g} m/s (the speed column is in m/s)")
    slow = np.flatnonzero(speeds < 0.0)
    if slow.size:
        raise ValueError(f"{path}: line {lines[slow[0]]}: speed {speeds[slow[0]]:g} m/s is negative")
    if not np.any(speeds > 0.0):
        raise ValueError(f"{path}: line {lines[0]}: the speed is 0 at every waypoint (the robot would never "
                         "move; give a speed > 0 m/s somewhere)")


def read_track_file(path: str | Path, name: str | None = None):
    """The :class:`~azimut_env.tracks.Track` of the waypoint file ``path`` (the format of the
    module docstring), named ``name`` (default: the file's stem). ``ValueError`` (one line naming
    the file and the line) for a file that cannot be read or is not one."""
    from azimut_env.tracks import Track

    path = Path(path)
    columns, rows = _columns(path, _waypoint_lines(path))
    width = len(columns) if columns != list(COLUMNS) else None
    values = []
    for k, row in rows:
        where = f"{path}: line {k}"
        if (width is not None and len(row) != width) or (width is None and not 2 <= len(row) <= 4):
            raise ValueError(f"{where}: {len(row)} values; expected "
                             + (f"{width} ({','.join(columns)})" if width else "2 to 4 (x,y[,heading[,speed]])"))
        values.append([_number(c, where) for c in row])
    if len({len(v) for v in values}) > 1:
        raise ValueError(f"{path}: the lines have different numbers of values")
    if len(values) < 2:
        raise ValueError(f"{path}: {len(values)} waypoint(s); a track needs at least 2")
    table = np.array(values, dtype=np.float64)
    if "speed" in columns:
        _check_speeds(path, table[:, columns.index("speed")], [k for k, _ in rows])
    cols = {c: table[:, j] for j, c in enumerate(columns[:table.shape[1]])}
    xy = np.stack([cols["x"], cols["y"]], axis=1)
    heading = cols.get("heading", 0.0)
    speed = cols.get("speed", DEFAULT_SPEED)
    closed = len(xy) > 2 and float(np.hypot(*(xy[-1] - xy[0]))) <= CLOSE_TOLERANCE
    if closed:
        xy = xy[:-1]
        heading = heading[:-1] if isinstance(heading, np.ndarray) else heading
        speed = speed[:-1] if isinstance(speed, np.ndarray) else speed
    if np.any(np.hypot(*np.diff(xy, axis=0).T) == 0.0):
        raise ValueError(f"{path}: two consecutive waypoints are the same point")
    try:
        return Track.from_waypoints(xy, heading=heading, speed=speed, closed=closed, name=name or path.stem)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{path}: {exc}") from None


def track_file_entry(track: str) -> dict | None:
    """``{"path": absolute path, "digest": content digest}`` of a ``--tracks`` entry that is a
    file (what an episode's key holds), None for a built-in track's name."""
    from azimut_env.tracks import ALL_TRACK_NAMES

    if track in ALL_TRACK_NAMES:
        return None
    return {"path": str(Path(track).resolve()), "digest": file_digest(track)}


def episode_track(track: str, params=None, seed: int = 0, track_file: dict | None = None):
    """The track of an episode: the file of ``track_file`` (its content must still be the one of
    the key's digest), else the built-in or scenario ``track`` for the robot ``params`` (the
    ``random`` track drawn from ``seed``)."""
    if track_file is None:
        from azimut_env.tracks import named_track

        return named_track(track, params, rng=np.random.default_rng(seed))
    if file_digest(track_file["path"]) != track_file["digest"]:
        raise ValueError(f"{track_file['path']}: the track file changed since the campaign started")
    return read_track_file(track_file["path"], name=Path(track_file["path"]).stem)
