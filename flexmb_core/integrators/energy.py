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


def energies(model: Model, state: State, mass_csr: tuple | None = None) -> tuple[float, float]:
    """Kinetic energy ½ vᵀMv and gravity potential −f_g·(q − q0) (J); ``mass_csr`` the model's
    mass matrix or :func:`compact_csr` of it (same values)."""
    return _energies(*(model.mass_csr if mass_csr is None else mass_csr), state.v, state.q, model.q0,
                     model.gravity_vector)


def compact_csr(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray) -> tuple[np.ndarray, ...]:
    """The CSR matrix without its stored zeros. The element mass matrices are assembled as dense
    blocks ``m ⊗ I₃``, so two thirds of the stored entries are zeros; products skip them and give
    the same sums (adding a zero product leaves a finite sum unchanged)."""
    keep = data != 0.0
    rows = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))[keep]
    ptr = np.zeros(indptr.size, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=indptr.size - 1), out=ptr[1:])
    out = (ptr, np.ascontiguousarray(indices[keep], dtype=np.int64), np.ascontiguousarray(data[keep]))
    for a in out:
        a.setflags(write=False)     # read-only like the model's: the kernels keep one signature
    return out
