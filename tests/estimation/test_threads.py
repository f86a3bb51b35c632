"""estimation/threads.py: blocks of rows, the thread count's checks, and the same bits for any count."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numba import njit

from estimation import estimate_eta, estimate_icr
from estimation.datasets import dataset_d1, dataset_d2
from estimation.geometry import RobotGeometry
from estimation.threads import (
    BlockKernel,
    block_bounds,
    check_threads,
    default_threads,
    max_threads,
    set_default_threads,
)

two_threads = pytest.mark.skipif(max_threads() < 2, reason="numba's pool has one thread here")


@given(st.integers(0, 5000), st.integers(1, 64), st.integers(1, 100))
def test_blocks_cover_the_rows_in_order(n, threads, min_rows):
    b = block_bounds(n, threads, min_rows)
    sizes = np.diff(b)
    assert b[0] == 0 and b[-1] == n and (sizes >= 0).all()
    assert len(sizes) == max(1, min(threads, n // min_rows))
    assert sizes.max() - sizes.min() <= 1  # as equal as can be


def test_thread_counts_are_checked_with_the_name():
    assert check_threads(1) == 1
    assert check_threads(np.int64(max_threads())) == max_threads()
    assert 1 <= check_threads(None) <= max_threads()
    assert check_threads(2.0 if max_threads() >= 2 else 1.0) in (1, 2)  # an integral float, as every int argument
    for bad in (0, -1):
        with pytest.raises(ValueError, match="--threads must be >= 1"):
            check_threads(bad, "--threads")
    with pytest.raises(ValueError, match="--threads must be at most .* numba's pool"):
        check_threads(max_threads() + 1, "--threads")
    with pytest.raises(ValueError, match="num_threads must be an integer"):
        check_threads(1.5)
    for bad in (True, "2", [2]):
        with pytest.raises(TypeError, match="num_threads must be an integer"):
            check_threads(bad)


def test_the_default_can_be_set_for_the_process():
    try:
        set_default_threads(1)
        assert default_threads() == 1 and check_threads(None) == 1
        with pytest.raises(ValueError):
            set_default_threads(0)
        assert default_threads() == 1  # a refused value changes nothing
    finally:
        set_default_threads(None)
    assert default_threads() >= 1


@njit(cache=True)
def _row_sums(x, out, lo, hi):
    for i in range(lo, hi):
        s = 0.0
        for j in range(x.shape[1]):
            s += np.sin(x[i, j]) * x[i, j]
        out[i] = s


@two_threads
@pytest.mark.parametrize("n", [1, 3, 7, 64, 1001])
def test_a_block_kernel_gives_the_same_bits_on_any_thread_count(n):
    x = np.random.default_rng(n).normal(size=(n, 33))
    kernel = BlockKernel(_row_sums, min_rows=1)
    outs = []
    for threads in (1, 2, max_threads()):
        out = np.full(n, np.nan)
        kernel.run(threads, n, x, out)
        outs.append(out)
    assert not np.isnan(outs[0]).any()
    for out in outs[1:]:
        np.testing.assert_array_equal(out, outs[0])


@two_threads
def test_numbas_thread_count_is_restored_after_a_parallel_call():
    import numba

    before = numba.get_num_threads()
    BlockKernel(_row_sums, min_rows=1).run(2, 10, np.ones((10, 2)), np.empty(10))
    assert numba.get_num_threads() == before


@two_threads
@pytest.mark.parametrize("method", ["IT", "IT+", "ORACLE", "NE"])
def test_estimators_give_the_same_bits_on_1_and_2_threads(method):
    geom = RobotGeometry.azimut3()
    q1, _ = dataset_d1(geom, 1500 if method != "ORACLE" else 200)
    q2, _ = dataset_d2(geom)
    for q in (q1, q2[:1500] if method != "ORACLE" else q2[:200]):
        one = estimate_icr(q, geom, method, num_threads=1)
        two = estimate_icr(q, geom, method, num_threads=2)
        np.testing.assert_array_equal(one, two)
        phidot = np.random.default_rng(0).normal(size=q.shape)
        for a, b in zip(estimate_eta(q, phidot, geom, method, num_threads=1),
                        estimate_eta(q, phidot, geom, method, num_threads=2)):
            np.testing.assert_array_equal(a, b)


def test_an_estimators_thread_count_is_checked():
    geom = RobotGeometry.azimut3()
    with pytest.raises(ValueError, match="num_threads must be >= 1"):
        estimate_icr(np.zeros(4), geom, num_threads=0)
