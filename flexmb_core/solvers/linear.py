"""Sparse LU on the model's fixed free–free pattern (scipy SuperLU)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..model.model import Model


class SparseLU:
    """Factor ``A`` given as CSR data on the model pattern; solve ``A x = b``.

    The CSR arrays of ``A`` are the CSC arrays of ``Aᵀ``: factor that without copying the pattern
    and solve with ``trans='T'``.
    """

    def __init__(self, model: Model):
        self.n = model.nfree
        self.indptr = model.indptr
        self.indices = model.indices
        self._lu = None

    def factor(self, data: np.ndarray) -> None:
        a_t = sp.csc_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))
        self._lu = splu(a_t)

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self._lu.solve(b, trans="T")
