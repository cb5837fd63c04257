"""The per-step statistics of the real-time loop: exact percentiles of the newest values, in a ring
and a scratch buffer allocated once (a node reports them every second for hours)."""

import tracemalloc

import numpy as np
import pytest

from flexmb_io.realtime import Samples, Series


@pytest.mark.parametrize("count", [0, 1, 7, 100, 250])
@pytest.mark.parametrize("last", [None, 1, 30, 100, 1000])
def test_percentiles_are_those_of_the_newest_values(count, last):
    rng = np.random.default_rng(count)
    values = rng.normal(size=count)
    s = Samples(capacity=100)
    for v in values:
        s.add(v)
    kept = values[-100:] if last is None else values[-min(100, last):]
    got = s.percentiles((1, 50, 99), sign=-1.0, last=last)
    assert got["count"] == kept.size
    if kept.size:
        assert got["max"] == pytest.approx((-kept).max())
        for q in (1, 50, 99):
            assert got[f"p{q}"] == pytest.approx(np.percentile(-kept, q))
    assert s.count == count and s.total == pytest.approx(values.sum())


def test_percentiles_leave_the_values_in_place():
    s = Samples(capacity=64)
    for v in range(100):
        s.add(float(v))
    first = s.percentiles((50, 99))
    assert s.percentiles((50, 99)) == first            # in-place partitioning worked on a copy


def test_percentiles_allocate_nothing_of_the_buffers_size():
    """The regression of the node's RSS growth (issue 15): no temporary as large as the buffer."""
    s = Samples(capacity=1 << 16)
    for v in np.linspace(0.0, 1.0, 1 << 16):
        s.add(v)
    s.percentiles((50, 99))                           # numpy's own one-time set-up
    tracemalloc.start()
    try:
        s.percentiles((50, 99))
        s.percentiles((1, 50), sign=-1.0, last=1000)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 0.05 * (1 << 16) * 8, f"{peak} bytes allocated for percentiles of a 512 kB buffer"


def test_series_keeps_every_value_at_eight_bytes_each():
    s = Series(capacity=4)
    for v in range(1000):
        s.add(float(v))
    assert len(s) == 1000
    np.testing.assert_array_equal(s.values, np.arange(1000.0))


def test_series_of_rows_keeps_them_in_order_across_growth():
    s = Series(capacity=2, width=3)
    rows = np.arange(30.0).reshape(10, 3)
    for r in rows:
        s.add(tuple(r))
    assert s.values.shape == (10, 3)
    np.testing.assert_array_equal(s.values, rows)
