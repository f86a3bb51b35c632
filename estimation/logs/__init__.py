"""Robot logs in: steering angles and wheel speeds read from CSV, ROS 2 bags (MCAP, SQLite3) and
WPILib data logs, estimated sample by sample (:func:`estimate_log`); and ROS 2 bags out
(:class:`~estimation.logs.ros.BagWriter`), which ``control.export`` uses to write episodes.

``docs/logs.md`` shows each format end to end. ROS 2 bags need the ``rosbags`` package (the
``logs`` extra), imported only when a bag is read or written; CSV and ``.wpilog`` need nothing
beyond the core install.
"""

from __future__ import annotations

from pathlib import Path

from estimation.logs.pipeline import (
                                      DEFAULT_METHODS,
                                      LogEstimate,
                                      compare_estimators,
                                      compose_increments,
                                      estimate_log,
                                      odometry_drift,
)
from estimation.logs.source import (
                                    BAD_REASONS,
                                    STEER_CONVENTIONS,
                                    ArrayLog,
                                    GroundTruth,
                                    LogError,
                                    LogSource,
                                    SampleChunk,
                                    YawTrack,
                                    beta_from_heading,
                                    default_module_names,
                                    fold_coaxial,
)

__all__ = ["FORMATS", "detect_format", "open_log", "DEFAULT_METHODS", "LogEstimate", "estimate_log",
           "compare_estimators", "compose_increments", "odometry_drift", "BAD_REASONS", "STEER_CONVENTIONS",
           "ArrayLog", "GroundTruth", "LogError", "LogSource", "SampleChunk", "YawTrack", "beta_from_heading",
           "default_module_names", "fold_coaxial"]

#: the formats :func:`open_log` reads
FORMATS = ("csv", "ros", "wpilog")

_MAGICS = {b"WPILOG": "wpilog", b"\x89MCAP": "ros", b"SQLite format 3\x00": "ros"}
_SUFFIXES = {".csv": "csv", ".mcap": "ros", ".db3": "ros", ".wpilog": "wpilog"}


def detect_format(path) -> str:
    """The format of ``path`` (one of :data:`FORMATS`): a directory is a ROS 2 bag; a file by its
    first bytes (WPILib's and MCAP's magic, SQLite's header), else by its suffix. ``LogError`` when
    the path does not exist or its format cannot be told."""
    p = Path(path)
    if p.is_dir():
        if (p / "metadata.yaml").is_file() or any(p.glob("*.mcap")) or any(p.glob("*.db3")):
            return "ros"
        raise LogError(f"log {path}: a directory without metadata.yaml, .mcap or .db3 file (not a ROS 2 bag)")
    if not p.exists():
        raise LogError(f"log {path}: no such file or directory")
    try:
        with p.open("rb") as fh:
            head = fh.read(16)
    except OSError as exc:
        raise LogError(f"log {path}: cannot be read ({exc.strerror or exc})") from None
    for magic, fmt in _MAGICS.items():
        if head.startswith(magic):
            return fmt
    fmt = _SUFFIXES.get(p.suffix.lower())
    if fmt is None:
        raise LogError(f"log {path}: cannot tell its format from its content or suffix; name it (--format "
                       f"{'|'.join(FORMATS)})")
    return fmt


def open_log(path, geom, modules=None, fmt: str | None = None, **options) -> LogSource:
    """Open a log of robot ``geom`` for :func:`estimate_log`.

    Args:
        path: a CSV file, a ``.wpilog``, a ROS 2 bag directory or a bare ``.mcap`` / ``.db3``.
        modules: the module names in the robot's wheel order (default ``module_0`` ...): the CSV
            column suffixes and the ROS joint names' ``{module}``.
        fmt: one of :data:`FORMATS` (default: :func:`detect_format`).
        options: the reader's own (:class:`~estimation.logs.csv_log.CsvLog`,
            :class:`~estimation.logs.ros.RosLog`, :class:`~estimation.logs.wpilog.WpiLog`); a wpilog
            with ``steer_entry`` and ``wheel_entry`` (per-module entries) is read by
            :class:`~estimation.logs.wpilog_modules.WpiModuleLog`.

    Raises :class:`LogError` for a log that cannot be used, ``ValueError`` for a bad option.
    """
    fmt = detect_format(path) if fmt is None else fmt
    if fmt not in FORMATS:
        raise ValueError(f"fmt must be one of {FORMATS}, got {fmt!r}")
    modules = default_module_names(geom.n) if modules is None else modules
    if fmt == "csv":
        from estimation.logs.csv_log import CsvLog

        return CsvLog(path, geom, modules, **options)
    if fmt == "ros":
        from estimation.logs.ros import RosLog

        return RosLog(path, geom, modules, **options)
    if "steer_entry" in options or "wheel_entry" in options:
        if "steer_entry" not in options or "wheel_entry" not in options:
            raise ValueError("per-module entries need both steer_entry and wheel_entry (--steer-entry and "
                             "--wheel-entry)")
        if options.get("states_entry") is not None:
            raise ValueError("states_entry (--states-entry) does not apply to per-module entries (--steer-entry, "
                             "--wheel-entry)")
        options.pop("states_entry", None)
        from estimation.logs.wpilog_modules import WpiModuleLog

        return WpiModuleLog(path, geom, modules, **options)
    from estimation.logs.wpilog import WpiLog

    return WpiLog(path, geom, modules, **options)
