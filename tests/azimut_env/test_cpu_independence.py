"""The simulation does not depend on NumPy's SIMD dispatch: the same bits with every SIMD level
above NumPy's baseline switched off (``NPY_DISABLE_CPU_FEATURES``), as on a CPU without them.

On a CPU with AVX-512, NumPy's float64 ``arctan2``, ``log1p``, ``exp``, ... are SVML routines
that differ from the C library's in the last place on some inputs (:mod:`estimation.libm`); the
tracks' headings and the quality metric took them, so ``azimut eval``'s metrics differed between
AVX-512 and AVX2 machines in their last digits. What remains machine-dependent (the C library's
version and FMA variant) is not NumPy's and is not switched here."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

_umath = getattr(np, "_core", None) or np.core
#: NumPy's dispatched SIMD levels that this CPU has (switched off in the second run)
DISPATCHED = [f for f in _umath._multiarray_umath.__cpu_dispatch__
              if _umath._multiarray_umath.__cpu_features__.get(f)]

_SCRIPT = r"""
import hashlib, json, sys
import numpy as np
from azimut_env.tracks import make_track
from estimation import RobotGeometry, quality, steering_from_lambda
from estimation.hrep import lambda_distance
from jobs.cli import main

out = {}
for name in ("paper", "circle", "figure8", "square", "crab", "random"):
    track = make_track(name, rng=np.random.default_rng(3)) if name == "random" else make_track(name)
    h = hashlib.sha256()
    for value in (track.xy, track.heading, track.speed, track.s):
        h.update(np.ascontiguousarray(value, dtype=np.float64).tobytes())
    out[name] = h.hexdigest()
rng = np.random.default_rng(0)
geom = RobotGeometry.azimut3()
lam = rng.normal(size=(4000, 3))
q = steering_from_lambda(lam, geom) + rng.normal(0.0, 0.05, (4000, 4))
q = np.clip(q, geom.steer_min + 1e-6, geom.steer_max)
out["quality"] = quality(steering_from_lambda(lam[::-1], geom), q).tobytes().hex()
out["lambda_distance"] = lambda_distance(lam, lam[::-1]).tobytes().hex()
main(["eval", "--no-plots", "--tracks", "paper,figure8,random", "--max-time", "15", "--out", sys.argv[1]])
out["eval"] = [{k: v for k, v in row.items() if k not in ("wall_s", "cpu_s")}
               for row in json.load(open(sys.argv[1] + "/metrics.json"))["episodes"]]
print("RESULT" + json.dumps(out))
"""


def _run(tmp_path, name, disabled):
    env = dict(os.environ)
    env.pop("NPY_DISABLE_CPU_FEATURES", None)
    if disabled:
        env["NPY_DISABLE_CPU_FEATURES"] = " ".join(disabled)
    proc = subprocess.run([sys.executable, "-c", _SCRIPT, str(tmp_path / name)], env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    line = [t for t in proc.stdout.splitlines() if t.startswith("RESULT")][-1]
    return json.loads(line[len("RESULT"):])


@pytest.mark.skipif(not DISPATCHED, reason="this CPU has no NumPy SIMD level above the baseline to switch off")
def test_simulation_is_independent_of_numpy_simd_dispatch(tmp_path):
    full = _run(tmp_path, "full", [])
    baseline = _run(tmp_path, "baseline", DISPATCHED)
    assert full.keys() == baseline.keys()
    for key in full:
        assert full[key] == baseline[key], f"{key} differs with NumPy's {', '.join(DISPATCHED)} switched off"
