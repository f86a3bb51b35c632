"""SIGINT and SIGTERM on a command without its own handling (eval, train and tune have theirs):
one line, exit 130 or 143, never a traceback (issue 31)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest


@pytest.mark.parametrize(("sig", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_long_command_interrupted_says_one_line(sig, status):
    proc = subprocess.Popen([sys.executable, "-m", "jobs.cli", "bench-estimators", "--points", "3000000",
                             "--random", "3000000"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 240
    first = ""
    while "points" not in first and time.monotonic() < deadline:  # the work has started (its progress line)
        first = proc.stderr.readline()
    time.sleep(1.0)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == status, first + err
    lines = [x for x in err.splitlines() if x.strip() and "compiling the numba kernels" not in x]
    assert lines and f"interrupted ({sig.name})" in lines[-1], err
    assert sum("interrupted" in x for x in lines) == 1 and "Traceback" not in err
