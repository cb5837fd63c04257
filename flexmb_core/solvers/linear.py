"""Linear solves on the model's fixed pattern: the skyline LU, checked where it could be wrong.

:class:`FixedPatternSolver` factors with the numba skyline LU of :mod:`.banded` (no pivoting,
symbolic work done once per model; a (near-)zero pivot is replaced by a small one of its sign:
static pivoting). Factors are *suspect* when they replaced a pivot or their smallest pivot is below
``min_pivot_ratio`` · max |diag|: tangents near a critical point of statics, slack tendons, stiff
parts beside soft ones, rigid corners by multipliers. A solve with suspect factors is refined
against the matrix itself and its backward error checked; above
:data:`~.banded.BACKWARD_ERROR_TOL` the matrix is taken as singular (:class:`SingularMatrixError`).
The numba steps of dynamics and statics do the same in their kernels
(:func:`~flexmb_core.integrators.packs.factor_packed`, :func:`~flexmb_core.integrators.packs.solve_packed`).

Suspect factors used to go to SuperLU with partial pivoting instead (until 2026-11-29). On every
such tangent of the test suite the skyline's solve had the same backward error as SuperLU's (3e-17
to 2e-16 against 4e-17 to 3e-16), and the (near-)zero pivots that stopped it were mechanisms and
the zero leading minors of multiplier models, which static pivoting, the augmented system and
refinement solve. :class:`~flexmb_core.integrators.critical.TangentLU` (the inertia count of path
following and of the snap-through monitor) factors and refines the same way.
"""

from __future__ import annotations

import numpy as np

from ..errors import FlexmbError
from ..model.model import Model
from .banded import BACKWARD_ERROR_TOL, STATIC_PIVOT, SkylineLU


class SingularMatrixError(FlexmbError, RuntimeError):
    """A solve's backward error stayed above :data:`~.banded.BACKWARD_ERROR_TOL` after refinement:
    the matrix is singular to working precision."""


class FixedPatternSolver:
    """``factor(K, mass=M, coef=c)`` then ``solve(b)`` for ``(K + c M) x = b``.

    Attributes
    ----------
    skyline : SkylineLU — the factors (static pivoting on).
    min_pivot_ratio : float — below this |pivot|/max|diag| the factors are suspect.
    refined : int — suspect factorizations so far (their solves were refined and checked).
    """

    def __init__(self, model: Model, *, min_pivot_ratio: float = 1e-10):
        # multipliers (the last rows of the system) are eliminated last, scaled (see SkylineLU)
        self.skyline = SkylineLU(model.nsys, model.indptr, model.indices, late=model.n_multipliers,
                                 static_pivot=STATIC_PIVOT)
        self.min_pivot_ratio = min_pivot_ratio
        self.refined = 0
        self._matrix = np.zeros(model.nnz)       # the suspect factors' matrix, to refine against
        self._suspect = False

    def factor(self, data: np.ndarray, mass: np.ndarray | None = None, coef: float = 0.0) -> None:
        """Factor ``data + coef · mass``; :class:`~.banded.SingularPivotError` (a RuntimeError) on a
        non-finite pivot or a zero matrix."""
        if mass is None:
            self.skyline.factor(data)
        else:
            self.skyline.factor(data, mass=mass, coef=coef)
        sky = self.skyline
        self._suspect = sky.replaced_pivots > 0 or sky.min_pivot_ratio < self.min_pivot_ratio
        if self._suspect:
            self.refined += 1
            if mass is None:
                self._matrix[:] = data
            else:
                np.multiply(mass, coef, out=self._matrix)
                self._matrix += data

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``x`` (nsys,); :class:`SingularMatrixError` when suspect factors cannot give a solve
        with a backward error of at most :data:`~.banded.BACKWARD_ERROR_TOL`."""
        x = self.skyline.solve(b)
        if self._suspect:
            omega = self.skyline.refine(self._matrix, b, x)
            if not omega <= BACKWARD_ERROR_TOL:
                raise SingularMatrixError(f"singular matrix: backward error {omega:.1e} after refinement, above "
                                          f"{BACKWARD_ERROR_TOL:.0e}")
        return x
