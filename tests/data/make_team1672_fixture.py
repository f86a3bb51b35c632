"""Write ``tests/data/team1672_trimmed.wpilog``: a 16 s stretch of a real swerve robot's log, its
swerve entries only, for the wpilog reader tests (``tests/logs/test_wpilog_modules.py``).

Attribution: the log is Team 1672 (BroncBotz)'s ``DataLogExports/FRC_20250214_212636.wpilog`` from
the GitHub repository BroncBotz3481/YAGSL-Example (pull request 331, commit 08c9140, "pre flip all
motor inversions"), licensed under the Apache License 2.0 (the repository's ``LICENSE.txt``,
https://www.apache.org/licenses/LICENSE-2.0). The trimmed copy is a derivative: the records of the
entries below between 40 s and 56 s after the first module state (the end of the SysId drive run,
up to 2 m/s with the wheels parallel, then the wheels turned to an X and standstill), plus each
entry's last record before the stretch (its value at the start) and the struct schemas; the records
themselves (timestamps, payloads) are unchanged.

Run it from the repository root with the original log beside the repository (``../shared/data/
real-logs/team1672_20250214_212636.wpilog``, or give its path) and robotpy-wpiutil installed::

    python tests/data/make_team1672_fixture.py [ORIGINAL.wpilog]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ORIGINAL = HERE.parents[2] / "shared/data/real-logs/team1672_20250214_212636.wpilog"
OUT = HERE / "team1672_trimmed.wpilog"
STATES = "NT:/SmartDashboard/swerve/advantagescope/currentStates"
MODULES = ("frontleft", "frontright", "backleft", "backright")
ENTRIES = [STATES,
           "NT:/SmartDashboard/swerve/imu/raw",
           "NT:/SmartDashboard/swerve/advantagescope/robotRotation",
           "NT:/.schema/struct:SwerveModuleState",
           "NT:/.schema/struct:Rotation2d"] + [
    f"NT:/SmartDashboard/swerve/modules/{m}/{what}" for m in MODULES
    for what in ("Raw Absolute Encoder", "Adjusted Absolute Encoder", "Raw Drive Velocity")]
WINDOW_S = (40.0, 56.0)  # after the first module state


def main(original: Path = ORIGINAL, out: Path = OUT) -> None:
    import wpiutil
    from wpiutil.log import RawLogEntry

    sys.path.insert(0, str(HERE.parents[1]))
    from estimation.logs.wpilog import read_wpilog_index

    buf, index, _ = read_wpilog_index(original)
    spans = {name: (typ, eid) for name, typ, eid, *_ in index.spans}
    t_states = index.ts[index.records(STATES)[1]]
    lo, hi = (int(t_states[0] + s * 1e6) for s in WINDOW_S)
    records = []  # (timestamp µs, entry name, payload)
    for name in ENTRIES:
        _, rec = index.records(name)
        ts = index.ts[rec]
        inside = (ts >= lo) & (ts <= hi)
        if name.startswith("NT:/.schema/"):
            inside[:] = True
        before = np.flatnonzero(ts < lo)
        if before.size:
            inside[before[-1]] = True  # the value held at the start of the stretch
        for i in rec[inside]:
            records.append((int(index.ts[i]), name, bytes(buf[index.off[i]:index.off[i] + index.size[i]])))
    records.sort(key=lambda r: r[0])
    out.unlink(missing_ok=True)
    log = wpiutil.DataLogWriter(str(out), extraHeader="trimmed from BroncBotz3481/YAGSL-Example 08c9140 "
                                                      "DataLogExports/FRC_20250214_212636.wpilog (Apache-2.0)")
    entries = {}
    t_first = records[0][0]
    for name in ENTRIES:
        entries[name] = RawLogEntry(log, name, "", spans[name][0], t_first)
    for k, (t, name, payload) in enumerate(records):
        entries[name].append(payload, t)
        if k % 500 == 0:
            log.flush()
    log.flush()
    log.stop()
    print(f"wrote {out} ({out.stat().st_size} bytes, {len(records)} records)")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ORIGINAL)
