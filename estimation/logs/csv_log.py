"""Wheel logs as CSV: the layout, a streaming reader and a writer.

The layout (``docs/logs.md``)::

    # any number of comment lines starting with '#'
    t,steer_front_left,wheel_front_left,steer_rear_left,wheel_rear_left,...,x,y,theta
    0.00,0.7853981633974483,0.0,...

* ``t``: the sample's time [s], strictly increasing (any origin);
* ``steer_<module>``: module ``<module>``'s steering angle [rad] (the paper's β by default, or the
  module heading with ``steer_convention="heading"``, see :mod:`estimation.logs.source`);
* ``wheel_<module>``: its wheel spin rate φ̇ [rad/s];
* optional ``x``, ``y``, ``theta``: a reference pose [m, m, rad] (all three or none); ``nan``
  where a row has none.

``<module>`` is a module name of the robot description, every module has both columns, and the
columns may come in any order; other columns are ignored (the report lists them). A value that is
not a number, or a row with another number of fields than the header, refuses the file with the
line number; ``nan`` marks a missing value (that sample is skipped and counted).
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from estimation.geometry import RobotGeometry
from estimation.logs.source import (
                                    STEER_CONVENTIONS,
                                    GroundTruth,
                                    LogSource,
                                    SampleChunk,
                                    beta_from_heading,
                                    fold_coaxial,
)

__all__ = ["CsvLog", "write_csv_log", "csv_columns", "TRUTH_COLUMNS"]

#: the most values one read of rows may hold (a header of many columns reads fewer rows at a time)
_MAX_VALUES_PER_READ = 5_000_000
#: a median sample period above this [s] is not a robot log in seconds (a robot logs at 10-1000 Hz)
_MAX_PERIOD_S = 10.0
#: the largest |t| [s] whose nanoseconds fit an int64
_MAX_T_S = (2**63 - 1) / 1e9 * 0.999

#: the reference pose's columns
TRUTH_COLUMNS = ("x", "y", "theta")


def csv_columns(modules) -> list[str]:
    """The header of a log of robot modules ``modules``, in the order :func:`write_csv_log` writes."""
    return ["t"] + [f"{kind}_{m}" for m in modules for kind in ("steer", "wheel")]


def write_csv_log(path, t_s, steer, phidot, modules, pose=None) -> None:
    """Write a CSV log: ``t_s`` (N,) [s], ``steer`` and ``phidot`` (N, n) [rad], [rad/s], module
    names ``modules`` (n), optional reference ``pose`` (N, 3). Values are written with 17
    significant digits, so that they read back bit for bit."""
    t_s = np.asarray(t_s, dtype=np.float64)
    steer = np.asarray(steer, dtype=np.float64)
    phidot = np.asarray(phidot, dtype=np.float64)
    n = len(modules)
    if steer.shape != (t_s.size, n) or phidot.shape != steer.shape:
        raise ValueError(f"steer and phidot must have shape ({t_s.size}, {n}), got {steer.shape}, {phidot.shape}")
    cols = [t_s[:, None]]
    for k in range(n):
        cols += [steer[:, k:k + 1], phidot[:, k:k + 1]]
    header = csv_columns(modules)
    if pose is not None:
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (t_s.size, 3):
            raise ValueError(f"pose must have shape ({t_s.size}, 3), got {pose.shape}")
        cols.append(pose)
        header += list(TRUTH_COLUMNS)
    np.savetxt(path, np.hstack(cols), fmt="%.17g", delimiter=",", header=",".join(header), comments="")


class CsvLog(LogSource):
    """A CSV wheel log (see the module docstring), read ``size`` rows at a time."""

    format = "CSV log"

    def __init__(self, path, geom: RobotGeometry, modules, steer_convention: str = "beta") -> None:
        super().__init__(path, geom, modules)
        if steer_convention not in STEER_CONVENTIONS:
            raise ValueError(f"steer_convention must be one of {STEER_CONVENTIONS}, got {steer_convention!r}")
        self.steer_convention = steer_convention
        p = Path(path)
        if not p.is_file():
            raise self.error("no such file" if not p.exists() else "not a file")
        self._header_line, header = self._read_header(p)
        self.columns = header
        index = {name: j for j, name in enumerate(header)}
        missing = [c for c in csv_columns(self.modules) if c not in index]
        if missing:
            raise self.error(f"no column {missing[0]!r} (the header has: {', '.join(header)}); the layout is t, "
                             "steer_<module>, wheel_<module> for each module of the robot file"
                             f" ({', '.join(self.modules)})")
        strays = [c for c in header if re.fullmatch(r"(steer|wheel)_.+", c) and c.split("_", 1)[1] not in self.modules]
        if strays:
            raise self.error(f"column {strays[0]!r} names no module of the robot (its modules: "
                             f"{', '.join(self.modules)})")
        truth = [c for c in TRUTH_COLUMNS if c in index]
        if truth and len(truth) != 3:
            raise self.error(f"a reference pose needs the columns x, y and theta; the header has only "
                             f"{', '.join(truth)}")
        self._t_col = index["t"]
        self._steer_cols = [index[f"steer_{m}"] for m in self.modules]
        self._wheel_cols = [index[f"wheel_{m}"] for m in self.modules]
        self._truth_cols = [index[c] for c in TRUTH_COLUMNS] if truth else None
        used = {"t", *csv_columns(self.modules)[1:], *(TRUTH_COLUMNS if truth else ())}
        self.ignored = [c for c in header if c not in used]
        self._truth_rows: list[np.ndarray] = []
        with p.open("rb") as fh:
            lines = sum(buf.count(b"\n") for buf in iter(lambda: fh.read(1 << 20), b""))
        self.n_samples = max(lines - self._header_line, 1)

    def _read_header(self, p: Path) -> tuple[int, list[str]]:
        try:
            with p.open(encoding="utf-8") as fh:
                for lineno, line in enumerate(fh, start=1):
                    if line.startswith("#") or not line.strip():
                        continue
                    header = [c.strip() for c in line.strip().split(",")]
                    if len(set(header)) != len(header):
                        dup = next(c for c in header if header.count(c) > 1)
                        raise self.error(f"line {lineno}: the header names column {dup!r} twice")
                    return lineno, header
        except UnicodeDecodeError:
            raise self.error("not UTF-8 text (not a CSV file?)") from None
        raise self.error("empty: no header line")

    def chunks(self, size: int) -> Iterator[SampleChunk]:
        self._truth_rows = []
        self._period_checked = False
        done = 0
        # rows per read bounded by the values they hold: a header of a million columns must not
        # allocate a million times the chunk (the results do not depend on the chunk)
        size = max(1, min(size, _MAX_VALUES_PER_READ // max(len(self.columns), 1)))
        with open(self.path, encoding="utf-8") as fh:
            for _ in range(self._header_line):
                fh.readline()
            while True:
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore", UserWarning)  # "input contained no data" at the end
                        rows = np.loadtxt(fh, delimiter=",", comments="#", max_rows=size, ndmin=2, dtype=np.float64)
                except ValueError as exc:
                    raise self._row_error(exc, done) from None
                if rows.shape[0] == 0:
                    return
                if rows.shape[1] != len(self.columns):
                    raise self.error(f"the rows after line {self._header_line + done} have {rows.shape[1]} fields, "
                                     f"the header {len(self.columns)}")
                yield self._chunk(rows)
                done += rows.shape[0]
                if rows.shape[0] < size:
                    return

    def _row_error(self, exc: ValueError, done: int) -> Exception:
        msg = str(exc).split(";")[0]
        m = re.search(r"at row (\d+)", msg)
        if m is None:
            return self.error(msg)
        # loadtxt counts the rows of this call from 0 (data rows; blank and comment lines are not counted)
        line = self._header_line + done + int(m.group(1)) + 1
        what = re.sub(r"\s*at row \d+,?", "", msg)
        if "number of columns changed" in msg:
            return self.error(f"near line {line}: a row has another number of fields than the header "
                              f"({len(self.columns)}): a truncated or malformed file")
        return self.error(f"near line {line}: {what}")

    def _chunk(self, rows: np.ndarray) -> SampleChunk:
        t = rows[:, self._t_col]
        if not np.all(np.isfinite(t)):
            k = int(np.flatnonzero(~np.isfinite(t))[0])
            raise self.error(f"a time t is not a finite number ({t[k]}) in the rows after line "
                             f"{self._header_line} (every sample needs its time)")
        if not self._period_checked and t.size > 2:
            self._period_checked = True
            step = float(np.median(np.diff(t)))
            if step > _MAX_PERIOD_S:
                raise self.error(f"the samples are {step:g} s apart (median): t must be in seconds; microseconds or "
                                 "milliseconds? divide the column by 1e6 or 1e3")
        if np.abs(t).max(initial=0.0) > _MAX_T_S:
            k = int(np.argmax(np.abs(t)))
            raise self.error(f"t = {t[k]:g} is not a time in seconds (a nanosecond clock holds ±{_MAX_T_S:.3g} s, 292 "
                             "years): microseconds or nanoseconds? divide the column by 1e6 or 1e9")
        steer = rows[:, self._steer_cols]
        phidot = rows[:, self._wheel_cols]
        if self.steer_convention == "heading":
            steer = beta_from_heading(steer, self.geom)
        beta, phidot = fold_coaxial(steer, phidot, self.geom)
        if self._truth_cols is not None:
            self._truth_rows.append(np.column_stack([t, rows[:, self._truth_cols]]))
        return SampleChunk(np.rint(t * 1e9).astype(np.int64), beta, phidot)

    def ground_truth(self) -> GroundTruth | None:
        """The x, y, theta columns (rows where all three are numbers), once :meth:`chunks` ran."""
        if self._truth_cols is None or not self._truth_rows:
            return None
        rows = np.concatenate(self._truth_rows)
        rows = rows[np.all(np.isfinite(rows[:, 1:]), axis=1)]
        return GroundTruth(np.rint(rows[:, 0] * 1e9).astype(np.int64), rows[:, 1:], "columns x, y, theta")

    def describe(self) -> dict:
        return {"format": self.format, "path": self.path, "steer_convention": self.steer_convention,
                "columns": self.columns, "ignored_columns": self.ignored}
