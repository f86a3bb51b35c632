"""D2 recorded from the simulated robot under the ICR controller (``azimut record-d2``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from estimation import RobotGeometry
from estimation.datasets import dataset_d2
from jobs.record_d2 import DEFAULT_OUT, record_d2


def test_shipped_d2_is_the_recorded_one():
    geom = RobotGeometry.azimut3()
    q, source = dataset_d2(geom)
    assert source == "recorded"
    assert q.shape == (2450, 4)
    assert np.unique(q, axis=0).shape[0] == len(q)
    assert np.all(q > geom.steer_min - 0.1) and np.all(q <= geom.steer_max + 0.1)
    with np.load(DEFAULT_OUT) as data:
        meta = json.loads(str(data["meta"]))
    assert meta["track"] == "paper" and meta["controller"] == "icr" and meta["completed"]


def test_record_d2_rejects_bad_arguments():
    with pytest.raises(ValueError):
        record_d2(points=0)
    with pytest.raises(ValueError):
        record_d2(speed_scale=-1.0)


@pytest.mark.slow
def test_record_d2_regenerates_the_shipped_file():
    q, meta = record_d2()
    with np.load(DEFAULT_OUT) as data:
        np.testing.assert_array_equal(q, data["q"])
