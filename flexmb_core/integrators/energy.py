"""Energies and the CSR mat-vec used by the integrators."""

from __future__ import annotations

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


@njit(cache=True)
def _energies(indptr, indices, data, v, q, q0, fg):
    kin = 0.0
    grav = 0.0
    for i in range(indptr.size - 1):
        s = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            s += data[k] * v[indices[k]]
        kin += v[i] * s
        grav -= fg[i] * (q[i] - q0[i])
    return 0.5 * kin, grav


def energies(model: Model, state: State) -> tuple[float, float]:
    """Kinetic energy ½ vᵀMv and gravity potential −f_g·(q − q0) (J)."""
    return _energies(*model.mass_csr, state.v, state.q, model.q0, model.gravity_vector)
