"""Energies and the CSR mat-vec used by the integrators."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..model.model import Model
from ..model.workspace import State


@njit(cache=True)
def csr_matvec(indptr, indices, data, x, out):
    """``out = A x`` for a CSR matrix (no allocation)."""
    for i in range(indptr.size - 1):
        s = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            s += data[k] * x[indices[k]]
        out[i] = s


def energies(model: Model, state: State, mv: np.ndarray) -> tuple[float, float]:
    """Kinetic energy ½ vᵀMv and gravity potential −f_g·(q − q0) (J); ``mv (ndof,)`` scratch."""
    csr_matvec(*model.mass_csr, state.v, mv)
    kin = 0.5 * float(state.v @ mv)
    grav = -float(model.gravity_vector @ (state.q - model.q0))
    return kin, grav
