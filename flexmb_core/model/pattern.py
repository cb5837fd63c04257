"""The fixed CSR sparsity pattern of the system matrix (free DOFs, then Lagrange multipliers) and the
scatter maps that let kernels add element blocks straight into its data (a compile stage of
:func:`flexmb_core.model.compile.compile_scene`)."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np


class Pattern:
    """CSR pattern of an ``nsys × nsys`` system, rows sorted, from the sorted unique keys
    ``r·nsys + c`` of its nonzeros.

    Attributes: ``keys (nnz,)`` int64, ``nsys``, ``indptr (nsys + 1,)`` and ``indices (nnz,)``
    (read-only), ``free_index (ndof,)`` (DOF → row among the free DOFs, −1 if prescribed) to map
    DOF ids.
    """

    def __init__(self, keys: np.ndarray, nsys: int, free_index: np.ndarray):
        self.keys = keys
        self.nsys = nsys
        self.free_index = free_index
        rows = keys // nsys
        self.indices = (keys % nsys).astype(np.int64)
        indptr = np.zeros(nsys + 1, dtype=np.int64)
        np.add.at(indptr, rows + 1, 1)
        self.indptr = np.cumsum(indptr).astype(np.int64)
        self.indices.setflags(write=False)
        self.indptr.setflags(write=False)

    @classmethod
    def from_blocks(cls, blocks: Iterable[np.ndarray], nsys: int, free_index: np.ndarray) -> Pattern:
        """The pattern holding every (row, col) pair within each block of system indices
        ``(ne, k)`` (entries < 0, prescribed DOFs, take no part), block by block without
        repeat/tile copies (a 10⁴-element frame scene has 1.3·10⁷ pairs)."""
        parts = [_block_keys(idx, nsys) for idx in blocks]
        keys = _sorted_unique(np.concatenate(parts))
        del parts
        return cls(keys, nsys, free_index)

    def map_sys(self, idx: np.ndarray) -> np.ndarray:
        """CSR position of every (row, col) pair of system indices ``idx (k,)``, row-major
        ``(k²,)`` (−1 where either index is < 0)."""
        r = np.repeat(idx, idx.size)
        c = np.tile(idx, idx.size)
        out = np.full(r.size, -1, dtype=np.int64)
        ok_ = (r >= 0) & (c >= 0)
        out[ok_] = np.searchsorted(self.keys, r[ok_] * self.nsys + c[ok_])
        return out

    def map(self, ed: np.ndarray) -> np.ndarray:
        """:meth:`map_sys` of the DOF ids ``ed (k,)`` (prescribed DOFs map to −1)."""
        return self.map_sys(self.free_index[ed])

    def maps(self, edofs: np.ndarray) -> np.ndarray:
        """:meth:`map` of every row of ``edofs (ne, k)`` at once: ``(ne, k²)``."""
        idx = self.free_index[edofs]
        ne, k = idx.shape
        out = (idx[:, :, None] * self.nsys + idx[:, None, :]).reshape(ne, k * k)
        ok_ = ((idx[:, :, None] >= 0) & (idx[:, None, :] >= 0)).reshape(ne, k * k)
        out[ok_] = np.searchsorted(self.keys, out[ok_])
        out[~ok_] = -1
        return out


def _block_keys(idx: np.ndarray, nsys: int) -> np.ndarray:
    """Keys ``r·nsys + c`` of the (row, col) pairs of system indices ``idx (ne, k)`` within each
    row, where both are ≥ 0: ``(≤ ne·k²,)`` int64."""
    k = (idx[:, :, None] * nsys + idx[:, None, :]).ravel()
    both = ((idx[:, :, None] >= 0) & (idx[:, None, :] >= 0)).ravel()
    return k[both]


def _sorted_unique(a: np.ndarray) -> np.ndarray:
    """``np.unique`` of an int64 array by sort and compare (numpy's hash-based default is several
    times slower on the 10⁷ CSR keys of a 10⁴-element frame scene); the same values."""
    a = np.sort(a, kind="stable")
    keep = np.empty(a.size, dtype=bool)
    keep[:1] = True
    np.not_equal(a[1:], a[:-1], out=keep[1:])
    return a[keep]
