"""The packs' n-d views (flexmb_core/integrators/views.py) are ``pack[a:b].reshape(shape)``: same
type (C-contiguous, read-only for a read-only pack), same elements, writes reach the pack, and the
view keeps the pack alive."""

import gc

import numpy as np
from numba import njit

from flexmb_core.integrators.packs import view2, view3, view4


@njit
def _views(p, r2, r3, r4):
    return view2(p, r2), view3(p, r3), view4(p, r4)


def _rows():
    return (np.array([3, 4, 5, 0, 0, 20]), np.array([7, 2, 3, 4, 0, 24]), np.array([1, 2, 1, 3, 2, 12]))


def test_views_equal_the_reshaped_slices_and_write_through():
    p = np.arange(40.0)
    rows = _rows()
    got = _views(p, *rows)
    for v, r in zip(got, rows):
        shape = tuple(int(x) for x in r[1:1 + v.ndim])
        assert v.shape == shape and v.flags.c_contiguous
        np.testing.assert_array_equal(v, p[r[0]:r[0] + r[5]].reshape(shape))
    got[1][1, 2, 3] = -1.0
    assert p[7 + 1 * 12 + 2 * 4 + 3] == -1.0


def test_a_read_only_pack_gives_read_only_views_and_ints_give_ints():
    p = np.arange(40.0)
    p.setflags(write=False)
    got = _views(p, *_rows())
    assert not any(v.flags.writeable for v in got)
    ints = _views(np.arange(40), *_rows())
    assert all(v.dtype == np.int64 and v.flags.writeable for v in ints)
    np.testing.assert_array_equal(ints[2], np.arange(1, 13).reshape(2, 1, 3, 2))


def test_a_view_keeps_its_pack_alive():
    p = np.arange(40.0)
    v2, _, _ = _views(p, *_rows())
    expected = v2.copy()
    del p
    gc.collect()
    _ = [np.full(40, 7.0) for _ in range(100)]      # reuse the freed memory, if it were freed
    np.testing.assert_array_equal(v2, expected)
