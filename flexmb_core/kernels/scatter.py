"""Scatter of a local matrix into the system CSR data through a precomputed map."""

from numba import njit

from ..jit import KERNEL


@njit(**KERNEL)
def scatter_matrix(smap_row, ke, kdata):
    """``kdata[smap_row[k]] += ke.flat[k]`` for every local entry with a position (≥ 0).

    ``smap_row (n²,)`` int64 — CSR position of each row-major entry of ``ke (n, n)`` (−1: none).
    """
    n = ke.shape[0]
    k = 0
    for i in range(n):
        for j in range(n):
            s = smap_row[k]
            if s >= 0:
                kdata[s] += ke[i, j]
            k += 1
