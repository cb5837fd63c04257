"""Linear solves on the model's fixed free–free pattern.

:class:`FixedPatternSolver` factors with the numba skyline LU (no pivoting, symbolic work done
once per model) and falls back to SuperLU with partial pivoting for the matrices where pivoting
matters: a zero or tiny pivot (indefinite statics near buckling, strongly non-symmetric tangents).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..model.model import Model
from .banded import SingularPivotError, SkylineLU


class SparseLU:
    """SuperLU on the model pattern. The CSR arrays of ``A`` are the CSC arrays of ``Aᵀ``: factor
    that without copying the pattern and solve with ``trans='T'``."""

    def __init__(self, model: Model):
        self.n = model.nsys
        self.indptr = model.indptr
        self.indices = model.indices
        self._lu = None

    def factor(self, data: np.ndarray) -> None:
        a_t = sp.csc_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))
        self._lu = splu(a_t)

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self._lu.solve(b, trans="T")


class FixedPatternSolver:
    """``factor(K, mass=M, coef=c)`` then ``solve(b)`` for ``(K + c M) x = b``.

    Attributes
    ----------
    fallbacks : int — factorizations that needed SuperLU.
    min_pivot_ratio : float — below this |pivot|/max|diag| the skyline result is not trusted.
    """

    def __init__(self, model: Model, *, min_pivot_ratio: float = 1e-10):
        # multipliers (the last rows of the system) are eliminated last, scaled (see SkylineLU)
        self.skyline = SkylineLU(model.nsys, model.indptr, model.indices, late=model.n_multipliers)
        self.superlu = SparseLU(model)
        self.min_pivot_ratio = min_pivot_ratio
        self.fallbacks = 0
        self._buffer = np.zeros(model.nnz)
        self._active = self.skyline

    def factor(self, data: np.ndarray, mass: np.ndarray | None = None, coef: float = 0.0) -> None:
        try:
            if mass is None:
                self.skyline.factor(data)
            else:
                self.skyline.factor(data, mass=mass, coef=coef)
            if self.skyline.min_pivot_ratio >= self.min_pivot_ratio:
                self._active = self.skyline
                return
        except SingularPivotError:
            pass
        self.fallbacks += 1
        if mass is None:
            self._buffer[:] = data
        else:
            np.multiply(mass, coef, out=self._buffer)
            self._buffer += data
        self.superlu.factor(self._buffer)        # raises RuntimeError if truly singular
        self._active = self.superlu

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self._active.solve(b)
